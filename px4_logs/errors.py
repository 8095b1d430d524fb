"""The one exception of the log readers."""


class LogError(ValueError):
    """A log that cannot give what a tool asked of it: a file that is not a readable ULog,
    a topic or field it lacks, a value no vehicle can have. The message is one line naming
    the file, the topic or field and the value, so a command line prints it as it is."""
