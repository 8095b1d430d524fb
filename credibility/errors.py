"""The exceptions a user of the credibility package sees."""

from typing import Literal

#: Why a test got no score although every file could be read: a topic or field the log
#: lacks, a log that does not cover the segment, a signal the method cannot use (NaNs,
#: dropouts, no step, no coherence), an error threshold ε of 0 (η undefined), or a vehicle
#: not in the state the test compares (armed or disarmed) over the segment.
Reason = Literal[
    "missing_topic", "short_signal", "unusable_signal", "unscorable_epsilon", "state_mismatch"
]


class CredibilityError(ValueError):
    """Bad input: a plan, a log or a value the method cannot use.

    The message is one line that names the file, the field and the value, so the CLI can
    print it as it is and a pipeline can grep it.
    """


class NotScorable(CredibilityError):
    """A readable log from which one test cannot be scored; ``reason`` says what kind of
    problem, so the report can list the test as not scored instead of stopping."""

    def __init__(self, reason: Reason, message: str) -> None:
        super().__init__(message)
        self.reason: Reason = reason
