"""Opening a ULog the project did not write: pyulog, guarded so that a damaged file is one
line (:class:`LogError`), never a traceback or an endless parse."""

from __future__ import annotations

import contextlib
import io
import struct
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pyulog import ULog
from pyulog.core import ULogException

from px4_logs.errors import LogError


class _ParserLooped(ULogException):
    """pyulog stepped back to where it had already resumed: it would loop for ever."""


class _LoopGuard:
    """The file as pyulog reads it, refusing a resynchronisation that goes backwards.

    Why: after a damaged message header pyulog seeks back by the size the header claimed
    (``seek(-2 - size, 1)``) to resume one byte later; when the file ended inside that
    message the read was short, the seek lands before the header, and pyulog parses the
    same bytes again for ever (pyulog 1.x, found by ``tests/fuzz``). Each backward relative
    seek of a resync lands further into the file than the one before, so one that does not
    is that loop.
    """

    def __init__(self, stream: io.BufferedReader) -> None:
        self._stream = stream
        self._resumed_at = -1

    def read(self, size: int = -1) -> bytes:
        return self._stream.read(size)

    def tell(self) -> int:
        return self._stream.tell()

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        position = self._stream.seek(offset, whence)
        if whence == io.SEEK_CUR and offset < 0:
            if position <= self._resumed_at:
                raise _ParserLooped(f"a damaged message at byte {position} ends past the file")
            self._resumed_at = position
        return position

    def close(self) -> None:
        self._stream.close()


def read_ulog(path: Path, topics: Sequence[str] | None = None) -> tuple[ULog, tuple[str, ...]]:
    """Parse a ULog (only ``topics`` if given) → (ULog, pyulog's warnings as lines).

    The one place the project opens a ULog it did not write: a damaged file is a one-line
    :class:`LogError`, never a traceback. The caller checks that the file exists.
    """
    # pyulog reports corruption with print(); capture it and surface it as warning lines.
    captured = io.StringIO()
    try:
        # pyulog leaves its own file handle open when parsing fails; pass it ours.
        with path.open("rb") as stream, contextlib.redirect_stdout(captured):
            ulog = ULog(_LoopGuard(stream), None if topics is None else list(topics))
    # A damaged file can fail anywhere in pyulog's parser; each of these means "not readable"
    # (OSError: a bogus length makes pyulog seek before the file's start).
    except (ULogException, ValueError, IndexError, KeyError, struct.error, UnicodeError,
            OSError) as exc:  # fmt: skip
        raise LogError(f"{path}: not a readable ULog file ({exc})") from None
    warnings = tuple(
        f"{path.name}: {line.strip()}" for line in captured.getvalue().splitlines() if line.strip()
    )
    if ulog.file_corruption and not warnings:
        warnings = (f"{path.name}: pyulog flagged the file as corrupt; damaged messages skipped",)
    # Every reader takes a topic's time from its 'timestamp': a topic whose definition lost
    # it (a damaged format message) or that holds no sample cannot be placed in time.
    timed = [len(d.data.get("timestamp", ())) > 0 for d in ulog.data_list]
    warnings += tuple(f"{path.name}: topic {d.name} has no timestamped samples "
                      "(a damaged definition?); skipped"
                      for d, ok in zip(ulog.data_list, timed, strict=True) if not ok)  # fmt: skip
    ulog.data_list[:] = [d for d, ok in zip(ulog.data_list, timed, strict=True) if ok]
    return ulog, warnings


def firmware_name(info: Mapping[str, Any]) -> str:
    """A PX4 log's firmware as its header names it: version, release type, git hash, board
    (``ver_sw_release`` packs major, minor, patch and the type: 255 release, ≥ 192 rc,
    ≥ 128 beta, ≥ 64 alpha, else a development build)."""
    release = int(info.get("ver_sw_release", 0) or 0)
    kind = release & 0xFF
    suffix = ("" if kind == 255 else "rc" if kind >= 192 else "beta" if kind >= 128
              else "alpha" if kind >= 64 else "dev")  # fmt: skip
    version = f"v{release >> 24 & 0xFF}.{release >> 16 & 0xFF}.{release >> 8 & 0xFF}{suffix}"
    git = str(info.get("ver_sw", ""))[:8]
    return (
        f"{info.get('sys_name', 'PX4')} {version} (git {git or '?'}) on {info.get('ver_hw', '?')}"
    )
