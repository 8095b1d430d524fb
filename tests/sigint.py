"""SIGINT as the processes a test starts inherit it, set in the test's own process."""

import contextlib
import signal
from collections.abc import Iterator


@contextlib.contextmanager
def sigint_in_children(ignored: bool) -> Iterator[None]:
    """SIGINT in the processes started inside: ignored, as a shell starts a background job,
    or at its default, as from a terminal (a handler of Python's is the default after
    ``exec``). Set here for the moment rather than in a ``preexec_fn``, which would run
    Python in a forked copy of this process and its threads (other tests' rigs, gRPC)."""
    action = signal.SIG_IGN if ignored else signal.default_int_handler
    previous = signal.signal(signal.SIGINT, action)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
