"""What a user, a file or a peer can hand the rig, as hypothesis strategies, and the checks
each input path must pass: it works or it says what is wrong in one line, never a traceback.

The same property tests run in ``make test`` (a few dozen random inputs each) and under
``make fuzz`` (coverage-guided by atheris through ``fuzz_one_input``, for a set time).
"""

from __future__ import annotations

import contextlib
import functools
import io
import struct
from pathlib import Path

import pyulog
from hypothesis import strategies as st
from pymavlink.generator.mavcrc import x25crc

from rig.mavlink.px4_api import mavlink

REPO = Path(__file__).resolve().parents[2]
X500_LOG = REPO / "data" / "flight_logs" / "px4_x500v2_v6xrt_flight_2026-03-20.ulg"
#: The topics replay and identify read, kept in the seed log (the rest only slows the fuzz).
SEED_TOPICS = (
    "vehicle_land_detected", "vehicle_local_position", "battery_status", "vehicle_status",
    "trajectory_setpoint", "vehicle_attitude_setpoint", "vehicle_rates_setpoint",
    "actuator_outputs", "actuator_motors", "sensor_combined", "vehicle_angular_velocity",
    "vehicle_attitude", "vehicle_thrust_setpoint", "vehicle_local_position_setpoint",
)  # fmt: skip
SEED_SECONDS = 8.0


def one_line(error: BaseException) -> None:
    """The error a user sees: one line that says something."""
    text = str(error)
    assert text, repr(error)
    assert "\n" not in text, repr(text)
    assert "Traceback" not in text, text


@functools.cache
def seed_log() -> bytes:
    """The first seconds of a real PX4 flight log (X500 V2), re-written by pyulog."""
    with contextlib.redirect_stdout(io.StringIO()):  # pyulog prints what it skips
        log = pyulog.ULog(str(X500_LOG), list(SEED_TOPICS))
    end_us = min(dataset.data["timestamp"][0] for dataset in log.data_list) + SEED_SECONDS * 1e6
    for dataset in log.data_list:
        keep = dataset.data["timestamp"] < end_us
        dataset.data = {field: values[keep] for field, values in dataset.data.items()}
    out = io.BytesIO()
    log.write_ulog(out)
    return out.getvalue()


@st.composite
def damaged_logs(draw: st.DrawFn) -> bytes:
    """The seed log cut short, with bytes flipped, inserted, deleted or blocks swapped."""
    data = bytearray(seed_log())
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(data)))
        operation = draw(st.sampled_from(("truncate", "flip", "insert", "delete", "swap")))
        if operation == "truncate":
            del data[at:]
        elif operation == "flip" and at < len(data):
            data[at] = draw(st.integers(0, 255))
        elif operation == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=64))
        elif operation == "delete":
            del data[at : at + draw(st.integers(1, 64))]
        elif operation == "swap" and len(data) > 2:
            other, size = draw(st.integers(0, len(data) - 1)), draw(st.integers(1, 256))
            first, second = sorted((at, other))
            if first + size <= second:
                data[first : first + size], data[second : second + size] = (
                    data[second : second + size], data[first : first + size])  # fmt: skip
    return bytes(data)


#: Every message pymavlink knows: a fuzzed frame may be any of them.
_MESSAGES = sorted(mavlink.mavlink_map.items())


@st.composite
def mavlink_datagrams(draw: st.DrawFn) -> bytes:
    """A UDP datagram (or TCP chunk) for a MAVLink parser.

    Random bytes (often starting with a v1/v2 magic byte), or well-framed messages of any
    type whose payload is random (NaNs, huge counts, bad enums), with a right or wrong CRC,
    cut short or not, several back to back.
    """
    frames = []
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(("noise", "v2", "v1")))
        if kind == "noise":
            magic = draw(st.sampled_from((b"", b"\xfd", b"\xfe")))
            frames.append(magic + draw(st.binary(max_size=300)))
            continue
        msg_id, message = draw(st.sampled_from(_MESSAGES))
        if kind == "v1" and msg_id > 255:
            kind = "v2"
        full = message.unpacker.size
        size = draw(st.integers(1 if kind == "v2" else full, full))
        payload = draw(st.binary(min_size=size, max_size=size))
        seq, system, component = (draw(st.integers(0, 255)) for _ in range(3))
        if kind == "v2":
            header = struct.pack("<BBBBBBBHB", 0xFD, size, 0, 0, seq, system, component,
                                 msg_id & 0xFFFF, msg_id >> 16)  # fmt: skip
        else:
            header = struct.pack("<BBBBBB", 0xFE, size, seq, system, component, msg_id)
        crc = x25crc(header[1:])
        crc.accumulate(payload)
        crc.accumulate(bytes([message.crc_extra]))
        checksum = crc.crc if draw(st.booleans()) or draw(st.booleans()) else crc.crc ^ 0x5A5A
        frame = header + payload + struct.pack("<H", checksum)
        frames.append(frame[: draw(st.integers(len(frame) - 4, len(frame)))])
    return b"".join(frames)


_KEYS = st.sampled_from((
    "name", "vehicle", "duration_s", "seed", "sensor_layer", "constraint", "rates", "imu_hz",
    "commands", "at_s", "action", "altitude_m", "faults", "kind", "start_s", "motor",
    "start", "environment", "wind", "mass_kg", "body", "propulsion", "battery", "tests",
    "signals", "logs", "values", "axes", "criteria", "parameter", "description",
)) | st.text(max_size=12)  # fmt: skip
_SCALARS = (st.integers(-(2**63), 2**63 - 1) | st.floats() | st.text(max_size=20)
            | st.booleans())  # fmt: skip
_VALUES = st.recursive(
    _SCALARS,
    lambda children: st.lists(children, max_size=4) | st.dictionaries(_KEYS, children, max_size=5),
    max_leaves=20,
)


def toml_documents() -> st.SearchStrategy[str]:
    """TOML text: documents of the files' own keys with values of any type, or raw text."""
    import tomli_w

    def dumped(document: dict) -> str:
        try:
            return tomli_w.dumps(document)
        except (TypeError, ValueError):  # e.g. a list of mixed tables: not expressible
            return ""

    documents = st.dictionaries(_KEYS, _VALUES, max_size=8).map(dumped)
    return documents | st.text(max_size=300)
