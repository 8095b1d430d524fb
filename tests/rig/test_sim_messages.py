"""Protocol tests: every simulator-link message the rig sends, decoded by pymavlink's parser.

Each message is packed, framed as MAVLink 2 and parsed back by a separate pymavlink
instance (CRC_EXTRA from the message definitions), then checked field by field against
the units PX4's SimulatorMavlink.cpp expects.
"""

import math

import numpy as np
import pytest

from rig.errors import AutopilotProtocolError
from rig.mavlink.px4_api import ActuatorMode, HilSensorFields, mavlink
from rig.mavlink.sim_messages import (
    ACCEL_FIFO_SCALE_MPS2,
    COG_UNKNOWN,
    GYRO_FIFO_SCALE_RADPS,
    actuator_controls_from_frame,
    autopilot_messages_from_read,
    decode_actuator_controls,
    frame_bytes,
    hil_gps,
    hil_sensor_frame,
    hil_state_quaternion_frame,
    pressure_altitude_m,
    single_frame_fields,
)


def _parsed(frame):
    assert frame[0] == 0xFD  # MAVLink 2 start byte: PX4 needs v2 for HIL_SENSOR.id
    (parsed,) = mavlink.MAVLink(None, 255, 0).parse_buffer(frame)
    return parsed


def _round_trip(message):
    parsed = _parsed(message.pack(mavlink.MAVLink(None, 1, 51)))
    assert parsed.get_type() == message.get_type()
    return parsed


@pytest.fixture
def mav():
    return mavlink.MAVLink(None, 1, 51)


def test_hil_sensor_imu_only_frame_sets_accel_and_gyro_groups(mav):
    msg = _parsed(
        hil_sensor_frame(mav, 1_000, accel_mps2=(0.1, -0.2, -9.81), gyro_radps=(0.01, 0.02, -0.03))
    )
    assert msg.fields_updated == 0b111111
    assert msg.time_usec == 1_000
    assert msg.id == 0
    assert (msg.xacc, msg.yacc, msg.zacc) == pytest.approx((0.1, -0.2, -9.81), abs=1e-6)
    assert (msg.xgyro, msg.ygyro, msg.zgyro) == pytest.approx((0.01, 0.02, -0.03), abs=1e-7)


def test_hil_sensor_full_frame_units_and_masks(mav):
    msg = _parsed(
        hil_sensor_frame(
            mav,
            20_000,
            accel_mps2=(0, 0, -9.81),
            gyro_radps=(0, 0, 0),
            mag_gauss=(0.214, 0.011, 0.430),
            baro=(95_461.0, 21.5),
        )
    )
    assert msg.fields_updated == 0x1FFF & ~0x400  # every group but differential pressure
    assert msg.fields_updated & HilSensorFields.BARO == HilSensorFields.BARO
    assert msg.fields_updated & HilSensorFields.DIFF_PRESSURE == 0
    assert (msg.xmag, msg.ymag, msg.zmag) == pytest.approx((0.214, 0.011, 0.430), abs=1e-6)
    assert msg.abs_pressure == pytest.approx(954.61, abs=1e-3)  # hPa
    assert msg.temperature == pytest.approx(21.5)  # °C
    assert msg.pressure_alt == pytest.approx(500.0, abs=1.0)  # ISA: 954.61 hPa ≈ 500 m


def test_pressure_altitude_matches_isa_table():
    # ICAO standard atmosphere: 1013.25 hPa at 0 m, 898.76 hPa at 1000 m, 795.01 hPa at 2000 m.
    assert pressure_altitude_m(101_325.0) == pytest.approx(0.0, abs=1e-9)
    assert pressure_altitude_m(89_876.0) == pytest.approx(1000.0, abs=1.0)
    assert pressure_altitude_m(79_501.0) == pytest.approx(2000.0, abs=1.0)


def test_hil_sensor_imu0_is_clamped_to_px4_int16_range(mav):
    msg = _parsed(
        hil_sensor_frame(mav, 1, accel_mps2=(200.0, -200.0, 0.0), gyro_radps=(50.0, -50.0, 0.0))
    )
    # PX4 stores value/scale as int16: full scale is 32767 counts, −full scale −32768.
    assert msg.xacc / ACCEL_FIFO_SCALE_MPS2 == pytest.approx(32767, abs=0.01)
    assert msg.yacc / ACCEL_FIFO_SCALE_MPS2 == pytest.approx(-32768, abs=0.01)
    assert msg.xgyro / GYRO_FIFO_SCALE_RADPS == pytest.approx(32767, abs=0.01)
    assert msg.ygyro / GYRO_FIFO_SCALE_RADPS == pytest.approx(-32768, abs=0.01)
    assert math.degrees(msg.xgyro) == pytest.approx(2000.0, abs=0.1)  # ±2000 °/s
    assert msg.xacc / 9.80665 == pytest.approx(16.0, abs=0.001)  # ±16 g


def test_hil_sensor_other_imus_are_not_clamped(mav):
    msg = _parsed(hil_sensor_frame(mav, 1, accel_mps2=(200, 0, 0), gyro_radps=(50, 0, 0), imu_id=1))
    assert (msg.xacc, msg.xgyro, msg.id) == (200.0, 50.0, 1)


def test_hil_sensor_rejects_zero_time(mav):
    with pytest.raises(ValueError, match=r"time_usec must be > 0 .* got 0"):
        hil_sensor_frame(mav, 0, accel_mps2=(0, 0, 0), gyro_radps=(0, 0, 0))


def test_hil_gps_integer_units(mav):
    msg = _round_trip(
        hil_gps(
            mav,
            100_000,
            lat_deg=47.397742,
            lon_deg=8.545594,
            alt_amsl_m=488.123,
            vel_ned_mps=(3.0, 4.0, -0.5),
            eph_m=0.8,
            epv_m=1.2,
            fix_type=3,
            satellites_visible=12,
        )
    )
    assert (msg.lat, msg.lon, msg.alt) == (473977420, 85455940, 488123)  # degE7, mm
    assert (msg.vn, msg.ve, msg.vd, msg.vel) == (300, 400, -50, 500)  # cm/s, ground speed
    assert msg.cog == round(math.degrees(math.atan2(4, 3)) * 100)  # cdeg: 5313
    assert (msg.eph, msg.epv) == (80, 120)  # cm, as PX4 reads them
    assert (msg.fix_type, msg.satellites_visible) == (3, 12)


def test_hil_gps_course_unknown_when_hovering_and_west_wraps_to_positive(mav):
    still = hil_gps(mav, 1, lat_deg=0, lon_deg=0, alt_amsl_m=0, vel_ned_mps=(0.1, 0, 0),
                    eph_m=1, epv_m=1, fix_type=3, satellites_visible=10)  # fmt: skip
    west = hil_gps(mav, 1, lat_deg=0, lon_deg=0, alt_amsl_m=0, vel_ned_mps=(0, -2, 0),
                   eph_m=1, epv_m=1, fix_type=3, satellites_visible=10)  # fmt: skip
    assert still.cog == COG_UNKNOWN
    assert _round_trip(west).cog == 27000


def test_hil_state_quaternion_units(mav):
    half = math.sqrt(0.5)
    msg = _parsed(
        hil_state_quaternion_frame(
            mav,
            5_000,
            q_body_to_ned=(half, 0.0, 0.0, half),
            rates_frd_radps=(0.1, -0.2, 0.3),
            lat_deg=47.397742,
            lon_deg=8.545594,
            alt_amsl_m=490.0,
            vel_ned_mps=(1.0, -2.0, 2.0),
            specific_force_frd_mps2=(0.0, 0.0, -9.80665),
        )
    )
    assert msg.attitude_quaternion == pytest.approx([half, 0, 0, half])
    assert (msg.rollspeed, msg.pitchspeed, msg.yawspeed) == pytest.approx((0.1, -0.2, 0.3))
    assert (msg.lat, msg.lon, msg.alt) == (473977420, 85455940, 490000)
    assert (msg.vx, msg.vy, msg.vz) == (100, -200, 200)  # cm/s NED
    assert msg.true_airspeed == 300  # |v| = 3 m/s (still air)
    assert (msg.xacc, msg.yacc, msg.zacc) == (0, 0, -1000)  # mG


def _actuators(controls, mode, flags=1, time_us=10):
    mav = mavlink.MAVLink(None, 1, 1)
    return _round_trip(
        mav.hil_actuator_controls_encode(time_us, controls + [0.0] * 12, mode, flags)
    )


def test_actuator_controls_armed_clamped_to_unit_range():
    armed = ActuatorMode.CUSTOM_MODE_ENABLED | ActuatorMode.SAFETY_ARMED
    decoded = decode_actuator_controls(_actuators([0.5, -0.4, 1.3, 0.25], int(armed)), 4)
    assert decoded.motors == (0.5, 0.0, 1.0, 0.25)
    assert decoded.armed
    assert decoded.lockstep
    assert decoded.time_us == 10


def test_actuator_controls_disarmed_means_zero_whatever_is_sent():
    decoded = decode_actuator_controls(_actuators([0.5, 0.5, 0.5, 0.5], 1, flags=0), 4)
    assert decoded.motors == (0.0, 0.0, 0.0, 0.0)
    assert not decoded.armed
    assert not decoded.lockstep


def test_actuator_controls_nan_is_rejected_with_the_frame_time():
    with pytest.raises(AutopilotProtocolError, match=r"time_usec=10 has non-finite"):
        decode_actuator_controls(_actuators([math.nan, 0, 0, 0], 129), 4)


@pytest.mark.parametrize("motors", [6, 8])
def test_a_hexa_or_octo_gets_a_motor_per_output_from_the_first(motors):
    """PX4 SITL sends output i (PWM_MAIN_FUNCi+1 = Motor i+1) as controls[i]: motors 5 to 8
    arrive in controls[4..7]; the outputs past the vehicle's motors are not motors."""
    commands = [0.1 * k for k in range(1, 9)]
    mav = mavlink.MAVLink(None, 1, 1)
    for mode, expected in ((129, commands[:motors]), (0, [0.0] * motors)):
        message = _round_trip(mav.hil_actuator_controls_encode(10, commands + [0.9] * 8, mode, 1))
        assert decode_actuator_controls(message, motors).motors == pytest.approx(expected)


def _actuator_frame(controls, mode, flags, time_us, seq=0, **packing):
    mav = mavlink.MAVLink(None, 1, 1)
    mav.seq = seq
    return mav.hil_actuator_controls_encode(time_us, controls, mode, flags).pack(mav, **packing)


def test_actuator_controls_from_a_frame_equal_pymavlinks_decoding():
    """The hand-unpacked fast path against pymavlink's parser, including payloads whose
    trailing zeros MAVLink 2 dropped (all outputs 0 and disarmed: 17 of 81 bytes left)."""
    rng = np.random.default_rng(7)
    cases = [([0.0] * 16, 0, 0, 0), ([0.0] * 16, 0, 1, 2**63 + 5)]
    for _ in range(300):
        controls = [float(np.float32(c)) for c in rng.uniform(-1.5, 1.5, 16)]
        cut = int(rng.integers(4, 17))
        controls = controls[:cut] + [0.0] * (16 - cut)
        cases.append((controls, int(rng.choice([0, 1, 129, 128 | 64])), int(rng.integers(0, 2)),
                      int(rng.integers(0, 2**40))))  # fmt: skip
    for k, (controls, mode, flags, time_us) in enumerate(cases):
        frame = _actuator_frame(controls, mode, flags, time_us, seq=time_us % 256)
        (parsed,) = mavlink.MAVLink(None, 255, 0).parse_buffer(frame)
        motors = (4, 6, 8)[k % 3]
        fast = actuator_controls_from_frame(frame, motors)
        assert fast == decode_actuator_controls(parsed, motors)


def test_hil_sensor_from_a_frame_equals_pymavlinks_decoding():
    """The reference autopilot's fast path for HIL_SENSOR against pymavlink's parser: the
    frames the rig sends (IMU only, with mag and baro, another IMU's id), and a frame whose
    trailing zeros MAVLink 2 dropped (a zero id and zero groups). With ground truth in the
    same read, both come out, in order (HIL_STATE_QUATERNION's quaternion as a list)."""
    rng = np.random.default_rng(11)
    mav = mavlink.MAVLink(None, 1, 51)
    frames = [mav.hil_sensor_encode(1, *[0.0] * 13, 0, 0).pack(mav)]
    for k in range(300):
        groups = {"mag_gauss": tuple(rng.normal(0, 0.5, 3))} if k % 3 else {}
        if k % 5 == 0:
            groups["baro"] = (float(rng.uniform(80e3, 101e3)), float(rng.uniform(-10, 40)))
        time_us = int(rng.integers(1, 2**40))
        imu = {"accel_mps2": rng.normal(0, 9, 3), "gyro_radps": rng.normal(0, 2, 3)}
        frames.append(hil_sensor_frame(mav, time_us, **imu, imu_id=k % 3 // 2, **groups))
    assert len(frames[0]) < 10 + mavlink.MAVLink_hil_sensor_message.unpacker.size + 2
    truth = mav.hil_state_quaternion_encode(
        7, [0.5, -0.5, 0.5, 0.5], 0.1, -0.2, 0.3, 473977000, 85456000, 488000, -12, 34, 5,
        36, 36, 1, -2, -1000,
    ).pack(mav)  # fmt: skip
    reads = [*frames, frames[1] + truth, truth + frames[2] + frames[3]]
    for read in reads:
        parsed = mavlink.MAVLink(None, 255, 0).parse_buffer(read)
        fast = autopilot_messages_from_read(read)
        assert fast is not None
        assert [m.to_dict() for m in fast] == [m.to_dict() for m in parsed]
        quaternions = [
            m.attitude_quaternion for m in fast if m.get_type() == "HIL_STATE_QUATERNION"
        ]
        assert len(quaternions) == (truth in read)
        assert all(isinstance(q, list) for q in quaternions)
    # a read with any other message, or ending in part of a frame, goes to pymavlink whole
    gps = mav.hil_gps_encode(1, 3, 0, 0, 0, 100, 100, 0, 0, 0, 0, 65535, 10).pack(mav)
    for read in (frames[1] + gps, gps + frames[1], frames[1] + truth[:-3], frames[1] + b"\0"):
        assert autopilot_messages_from_read(read) is None


def test_hil_sensor_frames_are_pymavlinks_packing_byte_for_byte():
    """The frame the rig sends every frame, packed by hand, parsed by pymavlink (which
    checks the CRC) and packed again by pymavlink with the same sender: each field group,
    another IMU's id, clamped values, the sender's system, component and sequence, and
    payloads whose trailing zeros MAVLink 2 drops."""
    rng = np.random.default_rng(13)
    mav = mavlink.MAVLink(None, 1, 51)
    for k in range(300):
        groups = {"mag_gauss": tuple(rng.normal(0, 0.5, 3))} if k % 3 else {}
        if k % 5 == 0:
            groups["baro"] = (float(rng.uniform(80e3, 101e3)), float(rng.uniform(-10, 40)))
        imu = {"accel_mps2": rng.normal(0, 200, 3), "gyro_radps": rng.normal(0, 40, 3)}
        mav.seq, mav.srcSystem, mav.srcComponent = k % 256, 1 + k % 3, 51 + k % 7
        time_us = int(rng.integers(1, 2**40))
        inputs = {**imu, "imu_id": k % 3 // 2, **groups}
        frame = hil_sensor_frame(mav, time_us, **inputs)
        parsed = _parsed(frame)
        assert parsed.get_type() == "HIL_SENSOR"
        assert parsed.pack(mav) == frame
    with pytest.raises(ValueError, match="time_usec must be > 0"):
        hil_sensor_frame(mav, 0, accel_mps2=(0, 0, 0), gyro_radps=(0, 0, 0))


def test_hil_state_quaternion_frames_are_pymavlinks_packing_byte_for_byte():
    """Ground truth packed by hand, parsed by pymavlink and packed again by it: attitudes,
    rates, positions, speeds and specific forces, clamped ones among them, from varying
    senders."""
    rng = np.random.default_rng(17)
    mav = mavlink.MAVLink(None, 1, 51)
    for k in range(300):
        mav.seq, mav.srcSystem, mav.srcComponent = k % 256, 1 + k % 3, 51 + k % 7
        q = rng.normal(size=4)
        frame = hil_state_quaternion_frame(
            mav, int(rng.integers(1, 2**40)), q_body_to_ned=q / np.linalg.norm(q),
            rates_frd_radps=rng.normal(0, 2, 3), lat_deg=float(rng.uniform(-90, 90)),
            lon_deg=float(rng.uniform(-180, 180)), alt_amsl_m=float(rng.uniform(-100, 9000)),
            vel_ned_mps=rng.normal(0, 5 if k % 4 else 500, 3),
            specific_force_frd_mps2=rng.normal(0, 10 if k % 5 else 500, 3),
        )  # fmt: skip
        parsed = _parsed(frame)
        assert parsed.get_type() == "HIL_STATE_QUATERNION"
        assert parsed.pack(mav) == frame


def test_a_packed_frame_keeps_one_payload_byte_and_unpacks_to_its_fields():
    """An all-zero payload keeps one byte, as pymavlink's; the fast unpacking of a frame
    gives back the fields it was packed from (wire order: HIL_ACTUATOR_CONTROLS's flags
    come before its controls)."""
    mav = mavlink.MAVLink(None, 1, 1)
    actuator = mavlink.MAVLink_hil_actuator_controls_message
    zeros = (0, 0, *[0.0] * 16, 0)
    frame = frame_bytes(mav, actuator, zeros)
    assert frame == mav.hil_actuator_controls_encode(0, [0.0] * 16, 0, 0).pack(mav)
    assert frame[1] == 1
    fields = (2**40 + 3, 1, *[0.25] * 4, *[0.0] * 12, 129)
    frame = frame_bytes(mav, actuator, fields)
    assert single_frame_fields(frame, actuator) == fields
    message = mav.hil_actuator_controls_encode(2**40 + 3, [0.25] * 4 + [0.0] * 12, 129, 1)
    assert frame == message.pack(mav)


def _sensor_frame(time_us, **packing):
    """HIL_SENSOR (accel and gyro) as pymavlink packs it, with its packing options."""
    mav = mavlink.MAVLink(None, 1, 1)
    fields = (0.1, 0.2, -9.8, 0.0, 0.1, 0.2, *[0.0] * 7, 0b111111)
    return mav.hil_sensor_encode(time_us, *fields).pack(mav, **packing)


#: Each message with a single-frame fast path: a good frame (packing options in) and the
#: fast path's decoding (None: left to pymavlink).
FAST_PATHS = {
    "HIL_ACTUATOR_CONTROLS": (
        lambda **packing: _actuator_frame([0.5] * 4 + [0.0] * 12, 129, 1, 4000, **packing),
        lambda frame: actuator_controls_from_frame(frame, 4),
    ),
    "HIL_SENSOR": (
        lambda **packing: _sensor_frame(4000, **packing),
        autopilot_messages_from_read,
    ),
}
#: Damage that a read of several frames survives: each whole frame decodes.
READ_OF_FRAMES = {("HIL_SENSOR", "two frames")}


@pytest.mark.parametrize("kind", FAST_PATHS)
@pytest.mark.parametrize(
    "damage",
    ["crc", "truncated", "two frames", "signed", "other message", "mavlink 1", "empty"],
)
def test_a_damaged_or_foreign_read_is_left_to_pymavlink(kind, damage):
    """Each fast path decodes only reads it can vouch for; the rest go to pymavlink's
    parser. The autopilot's path also takes a read of several whole HIL_SENSOR frames."""
    good, fast_path = FAST_PATHS[kind]
    frame = bytearray(good())
    assert fast_path(bytes(frame)) is not None
    if damage == "crc":
        frame[20] ^= 0x01
    elif damage == "truncated":
        frame = frame[:-1]
    elif damage == "two frames":
        frame = frame + frame
    elif damage == "signed":
        frame[2] |= mavlink.MAVLINK_IFLAG_SIGNED
    elif damage == "other message":
        mav = mavlink.MAVLink(None, 1, 1)
        frame = bytearray(mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav))
    elif damage == "mavlink 1":
        frame = bytearray(good(force_mavlink1=True))
    else:
        frame = bytearray()
    if (kind, damage) in READ_OF_FRAMES:
        assert len(fast_path(bytes(frame))) == 2
    else:
        assert fast_path(bytes(frame)) is None


def test_a_non_finite_motor_in_a_good_frame_is_rejected_on_the_fast_path_too():
    frame = _actuator_frame([0.5, math.inf, 0.5, 0.5] + [0.0] * 12, 129, 1, 8000)
    with pytest.raises(AutopilotProtocolError, match=r"time_usec=8000 has non-finite"):
        actuator_controls_from_frame(frame, 4)
