"""The one exception a user of the credibility package sees."""


class CredibilityError(ValueError):
    """Bad input: a plan, a log or a value the method cannot use.

    The message is one line that names the file, the field and the value, so the CLI can
    print it as it is and a pipeline can grep it.
    """
