"""SI values → the MAVLink messages of PX4's simulator API, and actuator controls → SI.

One encoder per message the rig sends (HIL_SENSOR, HIL_GPS, HIL_STATE_QUATERNION,
DISTANCE_SENSOR) and one decoder for what it receives (HIL_ACTUATOR_CONTROLS); the
messages of every lockstep frame also decode without pymavlink's parser (the rig's answer,
the reference autopilot's HIL_SENSOR and ground truth). Units, masks and
ranges follow PX4-Autopilot ``src/modules/simulation/simulator_mavlink/SimulatorMavlink.cpp``
(``update_sensors``, ``handle_message_hil_gps``, ``publish_distance_topic``,
``actuator_controls_from_outputs``). Pure functions: no sockets, so the protocol tests can check
every field against pymavlink's message definitions.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from fastcrc.crc16 import mcrf4xx

from rig.errors import AutopilotProtocolError
from rig.mavlink.px4_api import (
    ACCEL_FIELDS,
    BARO_FIELDS,
    GYRO_FIELDS,
    LOCKSTEP_FLAG,
    MAG_FIELDS,
    SAFETY_ARMED,
    mavlink,
)

#: PX4's CONSTANTS_ONE_G (m/s²); its simulated IMU 0 is a FIFO of int16 counts.
STANDARD_GRAVITY_MPS2 = 9.80665
#: IMU 0 quantisation in PX4 (SimulatorMavlink.cpp: ACCEL_FIFO_SCALE = g/2048, ±16 g).
ACCEL_FIFO_SCALE_MPS2 = STANDARD_GRAVITY_MPS2 / 2048.0
#: IMU 0 quantisation in PX4 (GYRO_FIFO_SCALE = radians(2000/32768), ±2000 °/s).
GYRO_FIFO_SCALE_RADPS = math.radians(2000.0 / 32768.0)
_INT16_MIN, _INT16_MAX = -32768, 32767
#: HIL_GPS.cog when the course is unknown (MAVLink common.xml).
COG_UNKNOWN = 65535
#: Below this ground speed the course over ground is noise: report it as unknown.
COG_MIN_SPEED_MPS = 0.5
#: ISA sea-level pressure and the troposphere exponent for ``pressure_alt`` (ICAO Doc 7488).
_ISA_P0_PA, _ISA_T0_K, _ISA_LAPSE_KPM, _ISA_EXPONENT = 101325.0, 288.15, 0.0065, 0.190263
#: PX4's int16 FIFO range in SI units: (low, high) for accel (m/s²) and gyro (rad/s).
_ACCEL_LIMITS = (_INT16_MIN * ACCEL_FIFO_SCALE_MPS2, _INT16_MAX * ACCEL_FIFO_SCALE_MPS2)
_GYRO_LIMITS = (_INT16_MIN * GYRO_FIFO_SCALE_RADPS, _INT16_MAX * GYRO_FIFO_SCALE_RADPS)


def _int16_limited(
    values: Sequence[float], limits: tuple[float, float]
) -> tuple[float, float, float]:
    """Clamp to what PX4's int16 FIFO can hold, so a saturated sensor reads full scale.

    PX4 divides by its FIFO scale and stores int16 without a range check: an out-of-range
    value would wrap to the opposite sign (``SimulatorMavlink::update_sensors``: IMU 0 is a
    simulated FIFO, accel g/2048 per count, gyro 2000/32768 °/s per count).
    """
    low, high = limits
    x, y, z = values
    return (min(max(float(x), low), high), min(max(float(y), low), high),
            min(max(float(z), low), high))  # fmt: skip


def pressure_altitude_m(pressure_pa: float) -> float:
    """ISA pressure altitude: PX4 ignores ``pressure_alt`` but a ground station shows it."""
    return _ISA_T0_K / _ISA_LAPSE_KPM * (1.0 - (pressure_pa / _ISA_P0_PA) ** _ISA_EXPONENT)


def hil_sensor_frame(
    mav: mavlink.MAVLink,
    time_us: int,
    *,
    accel_mps2: Sequence[float],
    gyro_radps: Sequence[float],
    mag_gauss: Sequence[float] | None = None,
    baro: tuple[float, float] | None = None,
    imu_id: int = 0,
) -> bytes:
    """HIL_SENSOR for one IMU frame, plus the mag and baro groups when they have new data,
    as the MAVLink 2 frame pymavlink's ``pack`` makes of it (:func:`frame_bytes`): the
    message of every lockstep frame, sent without a message object.

    Every frame carries accel and gyro (a frame without gyro advances PX4's clock but gets
    no answer, which stalls lockstep). ``baro`` is ``(pressure_pa, temperature_degc)``:
    temperature only travels with the baro group, as PX4 reads it only then. Units sent:
    m/s² FRD specific force, rad/s, gauss, hPa, °C.
    """
    fields = _hil_sensor_fields(time_us, accel_mps2, gyro_radps, mag_gauss, baro, imu_id)
    return frame_bytes(mav, _SENSOR, fields)


def _hil_sensor_fields(
    time_us: int,
    accel_mps2: Sequence[float],
    gyro_radps: Sequence[float],
    mag_gauss: Sequence[float] | None,
    baro: tuple[float, float] | None,
    imu_id: int,
) -> tuple[int | float, ...]:
    """HIL_SENSOR's fields in wire order (which is also its constructor's order)."""
    if time_us <= 0:
        raise ValueError(
            f"HIL_SENSOR time_usec must be > 0 (PX4 sleeps in real time), got {time_us}"
        )
    fields = ACCEL_FIELDS | GYRO_FIELDS
    accel: tuple[float, ...]
    gyro: tuple[float, ...]
    if imu_id == 0:
        accel = _int16_limited(accel_mps2, _ACCEL_LIMITS)
        gyro = _int16_limited(gyro_radps, _GYRO_LIMITS)
    else:
        accel = tuple(map(float, accel_mps2))
        gyro = tuple(map(float, gyro_radps))
    mag: tuple[float, ...] = (0.0, 0.0, 0.0)
    if mag_gauss is not None:
        fields |= MAG_FIELDS
        mag = tuple(map(float, mag_gauss))
    pressure_hpa = altitude_m = temperature_degc = 0.0
    if baro is not None:
        fields |= BARO_FIELDS
        pressure_pa, temperature_degc = baro
        pressure_hpa = pressure_pa / 100.0
        altitude_m = pressure_altitude_m(pressure_pa)
    return (time_us, *accel, *gyro, *mag, pressure_hpa, 0.0, altitude_m, temperature_degc,
            fields, imu_id)  # fmt: skip


def hil_gps(
    mav: mavlink.MAVLink,
    time_us: int,
    *,
    lat_deg: float,
    lon_deg: float,
    alt_amsl_m: float,
    vel_ned_mps: Sequence[float],
    eph_m: float,
    epv_m: float,
    fix_type: int,
    satellites_visible: int,
) -> mavlink.MAVLink_hil_gps_message:
    """HIL_GPS in MAVLink's integer units: degE7, mm AMSL, cm/s, cdeg.

    ``eph``/``epv`` are sent in centimetres of accuracy, which is how PX4 reads them
    (``gps.eph = hil_gps.eph * 1e-2f``), although MAVLink documents them as DOP×100.
    """
    vn, ve, vd = (float(v) for v in vel_ned_mps)
    ground_speed_mps = math.hypot(vn, ve)
    cog = COG_UNKNOWN
    if ground_speed_mps >= COG_MIN_SPEED_MPS:
        cog = round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100.0) % 36000
    return mav.hil_gps_encode(
        time_us,
        int(fix_type),
        round(lat_deg * 1e7),
        round(lon_deg * 1e7),
        round(alt_amsl_m * 1000.0),
        _uint16_cm(eph_m),
        _uint16_cm(epv_m),
        _uint16_cm(ground_speed_mps),
        _int16_cm(vn),
        _int16_cm(ve),
        _int16_cm(vd),
        cog,
        int(satellites_visible),
    )


def _floats(values: Iterable[float]) -> list[float]:
    """Python floats of a vector: an array's by ``tolist`` (``float()`` of each of its
    elements costs several times as much, and the rig sends ground truth at 200 Hz)."""
    if isinstance(values, np.ndarray):
        return values.astype(float, copy=False).tolist()
    return [float(v) for v in values]


def hil_state_quaternion_frame(
    mav: mavlink.MAVLink,
    time_us: int,
    *,
    q_body_to_ned: Iterable[float],
    rates_frd_radps: Iterable[float],
    lat_deg: float,
    lon_deg: float,
    alt_amsl_m: float,
    vel_ned_mps: Iterable[float],
    specific_force_frd_mps2: Iterable[float],
) -> bytes:
    """HIL_STATE_QUATERNION (ground truth) in its units: q (w, x, y, z), rad/s, degE7, mm,
    cm/s, mG; as the MAVLink 2 frame pymavlink's ``pack`` makes of it (:func:`frame_bytes`:
    the autopilot asks for it at up to 200 Hz, and this takes about 60 % of the time of
    pymavlink's message object and ``pack``)."""
    vn, ve, vd = _floats(vel_ned_mps)
    speed_cmps = _uint16_cm(math.sqrt(vn * vn + ve * ve + vd * vd))
    milli_g = [
        min(max(round(a / STANDARD_GRAVITY_MPS2 * 1000.0), _INT16_MIN), _INT16_MAX)
        for a in _floats(specific_force_frd_mps2)
    ]
    return frame_bytes(mav, _STATE, (
        time_us, *_floats(q_body_to_ned), *_floats(rates_frd_radps),
        round(lat_deg * 1e7), round(lon_deg * 1e7), round(alt_amsl_m * 1000.0),
        _int16_cm(vn), _int16_cm(ve), _int16_cm(vd), speed_cmps, speed_cmps, *milli_g,
    ))  # fmt: skip


def distance_sensor(
    mav: mavlink.MAVLink,
    time_us: int,
    *,
    distance_m: float,
    signal_quality: int,
    min_m: float,
    max_m: float,
) -> mavlink.MAVLink_distance_sensor_message:
    """DISTANCE_SENSOR of a downward laser rangefinder, as PX4's own driver publishes it.

    PX4's ``publish_distance_topic`` reads the distances in cm, ignores ``time_boot_ms``
    (it stamps the arrival), maps ``orientation`` PITCH_270 to downward facing and turns
    MAVLink's quality (0 unknown, 1..100) into uORB's (-1 unknown, 0..100) as
    ``100·(q − 1)/99`` in integers: uORB 0 (a reading the estimator must not use) is sent
    as 1, 100 % as 100, and every uORB value arrives as itself except 99, which no q gives
    (it arrives as 98). ``signal_quality`` is the uORB value (0..100).
    """
    if not 0 <= signal_quality <= 100:
        raise ValueError(f"signal_quality must be 0..100 (uORB), not {signal_quality}")
    quality = 1 + math.ceil(signal_quality * 99 / 100)
    return mav.distance_sensor_encode(
        time_us // 1000, _uint16_cm(min_m), _uint16_cm(max_m), _uint16_cm(distance_m),
        mavlink.MAV_DISTANCE_SENSOR_LASER, 0, mavlink.MAV_SENSOR_ROTATION_PITCH_270, 0,
        signal_quality=quality,
    )  # fmt: skip


def hil_optical_flow(
    mav: mavlink.MAVLink,
    time_us: int,
    *,
    pixel_flow_rad: tuple[float, float],
    integration_timespan_us: int,
    quality: int,
) -> mavlink.MAVLink_hil_optical_flow_message:
    """HIL_OPTICAL_FLOW of a flow sensor without a gyro or a range (a PMW3901), as PX4's
    driver publishes ``sensor_optical_flow``.

    PX4's ``simulator_mavlink`` (v1.14 to v1.17 alike) copies ``integrated_x/y`` into
    ``pixel_flow``, ``integration_time_us`` and ``quality`` as they are, stamps the
    arrival as the sample time, takes the integrated gyro only when all three are finite
    (NaN here: PX4 then integrates its own gyro over the window, as it does for the real
    chip) and the distance only when it is not negative (-1 here: the height comes from
    the rangefinder's DISTANCE_SENSOR).
    """
    if not 0 <= quality <= 255:
        raise ValueError(f"quality must be 0..255, not {quality}")
    nan = math.nan
    return mav.hil_optical_flow_encode(
        time_us, 0, integration_timespan_us, float(pixel_flow_rad[0]), float(pixel_flow_rad[1]),
        nan, nan, nan, 0, quality, 0, -1.0,
    )  # fmt: skip


@dataclass(frozen=True)
class ActuatorControls:
    """One decoded HIL_ACTUATOR_CONTROLS: motor commands 0..1 in PX4's motor order
    (``CA_ROTORn``), one per rotor of the vehicle."""

    time_us: int
    motors: tuple[float, ...]
    armed: bool
    lockstep: bool


def decode_actuator_controls(
    message: mavlink.MAVLink_hil_actuator_controls_message, motor_count: int
) -> ActuatorControls:
    """The first ``motor_count`` outputs (PX4 SITL's ``PWM_MAIN_FUNCi`` = Motor i, the
    vehicle's rotors): disarmed → all zero; armed → clamped to 0..1.

    PX4 may send −0.4 for an armed motor in failsafe and sends 0 for every output while
    disarmed (``actuator_controls_from_outputs``), so the clamp is part of the protocol.
    A NaN command is rejected: silently treating it as zero thrust would hide a bug.
    """
    return _actuator_controls(message.time_usec, message.controls, message.mode,
                              message.flags, motor_count)  # fmt: skip


def actuator_controls_from_frame(frame: bytes, motor_count: int) -> ActuatorControls | None:
    """:func:`decode_actuator_controls` straight from ``frame`` when it is exactly one
    HIL_ACTUATOR_CONTROLS (:func:`single_frame_fields`); None for anything else.

    The one message the rig receives every frame: in the PX4 loop at 250 Hz reading an
    answer took 24 µs through pymavlink's parser (its long path is cold by the time the
    answer comes; 7 µs when hot) and takes 11 µs so (4 when hot).
    """
    fields = single_frame_fields(frame, _ACTUATOR)
    if fields is None:
        return None
    time_usec, flags, *rest = fields  # wire order: time_usec, flags, controls[16], mode
    return _actuator_controls(time_usec, rest[:-1], rest[-1], flags, motor_count)


def autopilot_messages_from_read(data: bytes) -> list[mavlink.MAVLink_message] | None:
    """pymavlink's messages of one read when it is whole frames of HIL_SENSOR and
    HIL_STATE_QUATERNION only, each one :func:`single_frame_fields` takes; None for
    anything else (the caller then hands the read to pymavlink's parser).

    What the reference autopilot receives every frame: HIL_SENSOR alone, and with ground
    truth every fifth frame at 1 kHz. Through pymavlink's parser the two took a third of
    the autopilot's time on those frames, and the rig waits for its answer.
    """
    messages = []
    start = 0
    while start < len(data):
        if len(data) - start < _HEADER_BYTES + 2:
            return None
        message = _AUTOPILOT_READS.get(int.from_bytes(data[start + 7 : start + 10], "little"))
        if message is None:
            return None
        end = start + _HEADER_BYTES + data[start + 1] + 2
        fields = single_frame_fields(data[start:end], message)
        if fields is None:
            return None
        messages.append(message(*_grouped(fields, message.array_lengths)))
        start = end
    return messages or None


def _grouped(fields: tuple[Any, ...], array_lengths: Sequence[int]) -> list[Any]:
    """Wire-order fields with each array field's elements gathered into one list."""
    grouped: list[Any] = []
    i = 0
    for length in array_lengths:
        grouped.append(list(fields[i : i + length]) if length else fields[i])
        i += length or 1
    return grouped


def single_frame_fields(
    frame: bytes, message: type[mavlink.MAVLink_message]
) -> tuple[Any, ...] | None:
    """The payload fields of ``frame``, in wire order, when it is exactly one unsigned
    MAVLink 2 frame of ``message`` with a good checksum; None for anything else (the caller
    then hands it to pymavlink's parser, which also reports what is bad).

    Unpacked by hand for the messages of every lockstep frame, whose reads are mostly one
    frame each. The layout, the checksum and its CRC_EXTRA come from pymavlink's own
    definitions; the tests check equality with its decoder.
    """
    unpacker: struct.Struct = message.unpacker
    length = len(frame) - _HEADER_BYTES - 2
    if not (0 < length <= unpacker.size and frame[0] == mavlink.PROTOCOL_MARKER_V2
            and frame[1] == length and frame[2] == 0
            and int.from_bytes(frame[7:10], "little") == message.id):  # fmt: skip
        return None  # not one whole unsigned frame of this message
    sent_checksum = int.from_bytes(frame[-2:], "little")
    if _checksum(frame[: _HEADER_BYTES + length], message.crc_extra) != sent_checksum:
        return None
    # MAVLink 2 drops a payload's trailing zero bytes: put them back.
    payload = frame[_HEADER_BYTES : _HEADER_BYTES + length].ljust(unpacker.size, b"\0")
    return unpacker.unpack(payload)


_HEADER_BYTES = 10  # STX, length, incompat and compat flags, sequence, system, component, id
_HEADER = struct.Struct("<BBBBBBBHB")  # the same, the 24-bit id as its low 16 and high 8 bits


def frame_bytes(
    mav: mavlink.MAVLink, message: type[mavlink.MAVLink_message], fields: Sequence[Any]
) -> bytes:
    """One unsigned MAVLink 2 frame of ``message`` with its payload ``fields`` in wire
    order, from ``mav``'s system, component and sequence: byte for byte what pymavlink's
    ``pack`` makes (the inverse of :func:`single_frame_fields`).

    Written by hand for the message of every lockstep frame: pymavlink's ``pack`` builds a
    header object and a bytearray for each frame (5 µs hot, and HIL_SENSOR's message
    object 4 µs more); this takes under 2 µs. The tests check equality with ``pack``.
    """
    # MAVLink 2 drops a payload's trailing zero bytes, keeping at least one.
    payload = message.unpacker.pack(*fields).rstrip(b"\0") or b"\0"
    header = _HEADER.pack(mavlink.PROTOCOL_MARKER_V2, len(payload), 0, 0, mav.seq, mav.srcSystem,
                          mav.srcComponent, message.id & 0xFFFF, message.id >> 16)  # fmt: skip
    frame = header + payload
    return frame + _checksum(frame, message.crc_extra).to_bytes(2, "little")


def _checksum(frame: bytes, crc_extra: int) -> int:
    """MAVLink's CRC-16/MCRF4XX over a frame's bytes after STX, then the message's
    CRC_EXTRA (pymavlink computes it with fastcrc too, but through an object per frame)."""
    return mcrf4xx(frame[1:] + bytes((crc_extra,)), 0xFFFF)


_ACTUATOR = mavlink.MAVLink_hil_actuator_controls_message
_SENSOR = mavlink.MAVLink_hil_sensor_message
_STATE = mavlink.MAVLink_hil_state_quaternion_message
#: The messages :func:`autopilot_messages_from_read` decodes, by id: their constructors
#: take the fields in wire order (array fields gathered), as :func:`frame_bytes` packs them.
_AUTOPILOT_READS = {m.id: m for m in (_SENSOR, _STATE)}
assert all(m.fieldnames == m.ordered_fieldnames for m in _AUTOPILOT_READS.values())


def _actuator_controls(time_usec: int, controls: Sequence[float], mode: int, flags: int,
                       motor_count: int) -> ActuatorControls:  # fmt: skip
    motors = controls[:motor_count]  # plain floats: numpy costs more for a few
    if not math.isfinite(sum(motors)):  # a NaN or an infinity anywhere makes the sum one
        raise AutopilotProtocolError(
            f"HIL_ACTUATOR_CONTROLS at time_usec={time_usec} has non-finite motor "
            f"commands {list(motors)}"
        )
    armed = bool(mode & SAFETY_ARMED)
    return ActuatorControls(
        time_us=int(time_usec),
        motors=tuple([min(max(c, 0.0), 1.0) for c in motors]) if armed else (0.0,) * motor_count,
        armed=armed,
        lockstep=bool(flags & LOCKSTEP_FLAG),
    )


def _uint16_cm(value_m: float) -> int:
    return min(max(round(float(value_m) * 100.0), 0), 65535)


def _int16_cm(value_m: float) -> int:
    return min(max(round(float(value_m) * 100.0), _INT16_MIN), _INT16_MAX)
