"""Streaming ULog writer: PX4's log format, written as the run goes.

pyulog (the reader the whole project uses) can only write back a log it holds entirely in
memory, so a run that crashes or is interrupted would lose everything. This writer
streams instead: the definitions section first, then each data message as it comes, flushed
at least every ``flush_interval_s`` of wall time, so a killed process leaves a file pyulog
reads up to the last flush. The writer buffers whole messages itself and a failed write (a
full disk) is cut back to the last whole message, so the file always ends on one. Format: https://docs.px4.io/main/en/dev_log/ulog_file_format
(little endian; header, definitions, data).

Topics use PX4's uORB names and fields (``vehicle_attitude.q[4]`` ...), so a rig log, a PX4
SITL log and a real flight log are read by the same credibility test plan.
"""

from __future__ import annotations

import re
import struct
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from rig.errors import LogWriteFailed

_MAGIC = b"ULog\x01\x12\x35"
_FILE_VERSION = 1
_TYPES = {  # ULog type → struct code
    "int8_t": "b", "uint8_t": "B", "int16_t": "h", "uint16_t": "H",
    "int32_t": "i", "uint32_t": "I", "int64_t": "q", "uint64_t": "Q",
    "float": "f", "double": "d", "bool": "?", "char": "c",
}  # fmt: skip
#: A data message's header: size, type ``D``, message id.
_DATA_HEADER = struct.Struct("<HBH")
#: Buffered bytes that trigger a write before the flush interval is up.
_FLUSH_BYTES = 1 << 20
_FIELD = re.compile(r"^(?P<type>[a-z0-9_]+)(\[(?P<n>\d+)\])?$")
#: PX4's log levels (syslog): the level byte of a logged string.
LOG_LEVELS = {"emerg": 0, "alert": 1, "crit": 2, "err": 3, "warn": 4, "notice": 5, "info": 6,
              "debug": 7}  # fmt: skip


class ULogWriteError(ValueError):
    """A topic, field or value that cannot be written as ULog."""


@dataclass(frozen=True)
class _Topic:
    name: str
    msg_id: int
    fields: tuple[tuple[str, int], ...]  # (name, array length or 0), timestamp excluded
    packer: struct.Struct

    #: One data message as a packed numpy record: the header (``_header``), then
    #: ``timestamp`` and the fields, laid out as ``packer`` packs them.
    record: np.dtype


def _parse_fields(topic: str, fields: Sequence[tuple[str, str]]) -> list[tuple[str, str, int]]:
    parsed = []
    for field_type, field_name in fields:
        match = _FIELD.match(field_type)
        if not match or match["type"] not in _TYPES:
            raise ULogWriteError(
                f"topic {topic!r}: field {field_name!r} has unknown type {field_type!r}"
            )
        if field_name == "timestamp":
            raise ULogWriteError(f"topic {topic!r}: 'timestamp' is implicit, do not declare it")
        parsed.append((match["type"], field_name, int(match["n"] or 0)))
    return parsed


def _record(parsed: list[tuple[str, str, int]]) -> np.dtype:
    """A data message of these fields as a packed numpy record (see ``_Topic.record``)."""
    layout: list[tuple[Any, ...]] = [("_header", f"V{_DATA_HEADER.size}"), ("timestamp", "<u8")]
    for ulog_type, name, length in parsed:
        if ulog_type == "char":
            layout.append((name, f"S{length or 1}"))
        else:
            code = np.dtype(f"<{_TYPES[ulog_type]}")
            layout.append((name, code, (length,)) if length else (name, code))
    return np.dtype(layout)


class ULogWriter:
    """Write a ULog file incrementally.

    All topic formats are declared up front (the format places definitions before data);
    instances of a topic (``multi_id``) are subscribed on first use.

    Parameters
    ----------
    path
        Output file; its folder is created.
    topics
        ``{topic: [(type, field), ...]}`` with ULog types such as ``"float"`` or
        ``"float[4]"``. The ``uint64_t timestamp`` field (µs) is added first.
    info
        Information messages (``sys_name``, ``ver_hw``, ...), written as ``char[n]`` strings.
    parameters
        Initial parameter values: ``int`` → ``int32_t``, ``float`` → ``float``.
    start_time_us
        The header timestamp.
    flush_interval_s
        Wall-clock period after which buffered data is flushed to the OS.

    Examples
    --------
    >>> import tempfile, pyulog
    >>> path = Path(tempfile.mkdtemp()) / "demo.ulg"
    >>> with ULogWriter(path, {"vehicle_air_data": [("float", "baro_alt_meter")]}) as log:
    ...     log.write("vehicle_air_data", 1000, baro_alt_meter=488.0)
    >>> pyulog.ULog(str(path)).get_dataset("vehicle_air_data").data["baro_alt_meter"][0]
    np.float32(488.0)
    """

    def __init__(
        self,
        path: str | Path,
        topics: Mapping[str, Sequence[tuple[str, str]]],
        *,
        info: Mapping[str, str] | None = None,
        parameters: Mapping[str, int | float] | None = None,
        start_time_us: int = 0,
        flush_interval_s: float = 0.5,
    ) -> None:
        self.path = Path(path)
        self._flush_interval_s = flush_interval_s
        self._topics: dict[str, _Topic] = {}
        #: Header and message id of each subscribed (topic, instance), in order.
        self._data_prefixes: dict[tuple[str, int], bytes] = {}
        definitions = bytearray()
        definitions += _message(b"B", bytes(16) + bytes(24))  # no compat/incompat flags
        for msg_id, (name, fields) in enumerate(topics.items()):
            parsed = _parse_fields(name, fields)
            text = f"{name}:uint64_t timestamp;" + "".join(
                f"{t}[{n}] {f};" if n else f"{t} {f};" for t, f, n in parsed
            )
            definitions += _message(b"F", text.encode())
            code = "<Q" + "".join(f"{n or ''}{_TYPES[t]}" if t != "char" else f"{n or 1}s"
                                  for t, _, n in parsed)  # fmt: skip
            self._topics[name] = _Topic(name, msg_id, tuple((f, n) for _, f, n in parsed),
                                        struct.Struct(code), _record(parsed))  # fmt: skip
        for key, text in (info or {}).items():
            encoded = str(text).encode()
            definitions += _key_value(b"I", f"char[{len(encoded)}] {key}", encoded)
        for name, value in (parameters or {}).items():
            definitions += _parameter(name, value)

        self.path.parent.mkdir(parents=True, exist_ok=True)
        # Unbuffered: the writer buffers whole messages in ``_pending`` (see flush).
        self._file = open(self.path, "wb", buffering=0)  # noqa: SIM115 - closed in close()
        self._pending = bytearray()
        self._written = 0  # bytes on disk, all of them whole messages
        self._failure: str | None = None  # why writing stopped (then writes are dropped)
        self._pending += _MAGIC + bytes([_FILE_VERSION]) + struct.pack("<Q", start_time_us)
        self._pending += definitions
        self.flush()

    def write(self, topic: str, timestamp_us: int, multi_id: int = 0, **values: Any) -> None:
        """Append one sample of ``topic``; every declared field must be given: a number, a
        string (char[n]), or an array or sequence of numbers.

        Runs for every logged sample, so it avoids numpy conversions: scalars go to
        ``struct`` as they are, arrays as their flattened list.
        """
        spec = self._topic(topic)
        if len(values) != len(spec.fields):
            raise _field_error(spec, values)
        prefix = self._data_prefixes.get((topic, multi_id)) or self._subscribe(spec, multi_id)
        flat: list[object] = [int(timestamp_us)]
        try:
            for name, length in spec.fields:
                value = values[name]
                if not length:
                    flat.append(value)
                elif isinstance(value, str | bytes):  # char[n]: one string
                    flat.append(value.encode() if isinstance(value, str) else value)
                else:
                    items = value.ravel().tolist() if isinstance(value, np.ndarray) else list(value)
                    if len(items) != length:
                        raise ULogWriteError(
                            f"topic {topic!r}: field {name!r} needs {length} values, "
                            f"got {len(items)}"
                        )
                    flat.extend(items)
            payload = spec.packer.pack(*flat)
        except KeyError:
            raise _field_error(spec, values) from None
        except struct.error as error:
            raise ULogWriteError(f"topic {topic!r}: {error}") from None
        self._pending += prefix
        self._pending += payload
        self._maybe_flush()

    def row_writer(self, topic: str, multi_id: int = 0) -> Callable[..., None]:
        """A writer of ``topic`` that takes a sample as its format's values in order
        (timestamp first, arrays flattened), for the topics a run logs every frame.

        :meth:`write` matches values to fields by name, which costs more than packing them;
        a caller that builds the row itself skips that (the rig log's tests check its rows
        against :meth:`write`'s).
        """
        spec = self._topic(topic)
        prefix = self._data_prefixes.get((topic, multi_id)) or self._subscribe(spec, multi_id)
        pack, pending, maybe_flush = spec.packer.pack, self._pending, self._maybe_flush

        def write_row(*values: object) -> None:
            try:
                payload = pack(*values)
            except struct.error as error:
                raise ULogWriteError(f"topic {topic!r}: {error}") from None
            pending.extend(prefix)  # the writer's buffer: flush() empties it in place
            pending.extend(payload)
            maybe_flush()

        return write_row

    def records(self, topic: str, rows: int) -> np.ndarray:
        """``rows`` zeroed samples of ``topic`` as numpy records (``timestamp`` and the
        declared fields by name), to fill and hand to :meth:`write_records`."""
        return np.zeros(rows, self._topic(topic).record)

    def write_records(self, topic: str, records: np.ndarray, multi_id: int = 0) -> None:
        """Append many samples of ``topic`` at once, from :meth:`records` (their headers are
        set here).

        For a topic a run gathers in blocks: filling arrays field by field costs a fraction
        of packing each row (the rig's ground truth, five topics every frame).
        """
        spec = self._topic(topic)
        if records.dtype != spec.record:
            raise ULogWriteError(f"topic {topic!r}: records not made by records({topic!r})")
        prefix = self._data_prefixes.get((topic, multi_id)) or self._subscribe(spec, multi_id)
        records["_header"] = np.void(prefix)
        self._pending += records.tobytes()
        self._maybe_flush()

    def _topic(self, topic: str) -> _Topic:
        spec = self._topics.get(topic)
        if spec is None:
            raise ULogWriteError(f"topic {topic!r} was not declared when the log was opened")
        return spec

    def _subscribe(self, spec: _Topic, multi_id: int) -> bytes:
        """Add the subscription of an instance; returns its data-message prefix."""
        msg_id = len(self._data_prefixes)
        self._pending += _message(b"A", struct.pack("<BH", multi_id, msg_id) + spec.name.encode())
        prefix = _DATA_HEADER.pack(2 + spec.packer.size, ord("D"), msg_id)
        self._data_prefixes[(spec.name, multi_id)] = prefix
        return prefix

    def log(self, level: str, timestamp_us: int, text: str) -> None:
        """Append a logged string (shown by Flight Review and pyulog as a log message)."""
        body = struct.pack("<BQ", LOG_LEVELS[level] + ord("0"), timestamp_us) + text.encode()
        self._pending += _message(b"L", body)
        self._maybe_flush()

    def set_parameter(self, name: str, value: int | float) -> None:
        """Record a parameter change during the run (as PX4 logs ``param set``)."""
        self._pending += _parameter(name, value)
        self._maybe_flush()

    def flush(self) -> None:
        """Write the buffered messages. If the disk refuses them (full, or a file size
        limit), cut the file back to its last whole message and raise
        :class:`LogWriteFailed` once; the writer then drops what it is given."""
        self._last_flush = time.monotonic()
        if self._failure is not None:
            self._pending.clear()
            return
        pending = memoryview(self._pending)
        try:
            while pending:
                pending = pending[self._file.write(pending) :]
        except OSError as error:
            pending.release()
            self._failure = error.strerror or str(error)
            self._pending.clear()
            self._file.truncate(self._written)
            raise LogWriteFailed(
                f"{self.path}: cannot write ({self._failure}); the log is whole up to its "
                f"last complete message ({self._written} bytes)"
            ) from None
        pending.release()
        self._written += len(self._pending)
        self._pending.clear()

    def close(self) -> None:
        if not self._file.closed:
            try:
                self.flush()
            finally:
                self._file.close()

    def __enter__(self) -> ULogWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _maybe_flush(self) -> None:
        if (len(self._pending) >= _FLUSH_BYTES
                or time.monotonic() - self._last_flush >= self._flush_interval_s):  # fmt: skip
            self.flush()


def _field_error(spec: _Topic, values: Mapping[str, object]) -> ULogWriteError:
    declared = [name for name, _ in spec.fields]
    missing = [name for name in declared if name not in values]
    if missing:
        return ULogWriteError(f"topic {spec.name!r}: field {missing[0]!r} missing")
    return ULogWriteError(
        f"topic {spec.name!r}: unknown fields {sorted(set(values) - set(declared))}"
    )


def _message(kind: bytes, body: bytes) -> bytes:
    return struct.pack("<HB", len(body), kind[0]) + body


def _key_value(kind: bytes, key: str, value: bytes) -> bytes:
    encoded = key.encode()
    return _message(kind, bytes([len(encoded)]) + encoded + value)


def _parameter(name: str, value: int | float) -> bytes:
    if isinstance(value, bool | int | np.integer):
        return _key_value(b"P", f"int32_t {name}", struct.pack("<i", int(value)))
    return _key_value(b"P", f"float {name}", struct.pack("<f", float(value)))
