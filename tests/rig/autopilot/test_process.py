"""The autopilot process over real loopback sockets: PX4's simulator link on TCP and a
pymavlink ground station on UDP (parameters, arming checks, missions, failsafe, fuzz)."""

import math
import struct

import numpy as np
import pytest

from rig.autopilot.navigator import Px4AutoMode, Px4MainMode
from rig.autopilot.process import gps_fix, sensor_frame
from rig.px4_sim_api import Ports, mavlink
from rig.sim_messages import hil_gps, hil_sensor
from tests.rig.autopilot.mini_rig import GroundStation, MiniRig
from tests.rig.autopilot.plant import HOME, QuadPlant

pytestmark = pytest.mark.closed_loop


def test_hil_messages_decode_to_si_units():
    mav = mavlink.MAVLink(None)
    sensor = hil_sensor(mav, 1000, accel_mps2=(0.1, -0.2, -9.8), gyro_radps=(0.01, 0.0, -0.02),
                        mag_gauss=(0.2, 0.01, 0.43), baro=(95000.0, 20.0))  # fmt: skip
    frame = sensor_frame(sensor, None)
    assert frame.accel_mps2 == pytest.approx([0.1, -0.2, -9.8], abs=0.005)  # int16 FIFO step
    assert frame.gyro_radps == pytest.approx([0.01, 0.0, -0.02], abs=1e-3)
    assert frame.mag_gauss == pytest.approx([0.2, 0.01, 0.43])
    assert frame.baro_pressure_pa == pytest.approx(95000.0)
    no_mag = sensor_frame(
        hil_sensor(mav, 2000, accel_mps2=(0, 0, -9.8), gyro_radps=(0, 0, 0)), None
    )
    assert no_mag.mag_gauss is None
    assert no_mag.baro_pressure_pa is None
    fix = gps_fix(hil_gps(mav, 1000, lat_deg=47.5, lon_deg=8.5, alt_amsl_m=500.25,
                          vel_ned_mps=(1.0, -2.0, 0.5), eph_m=0.8, epv_m=1.2, fix_type=3,
                          satellites_visible=10))  # fmt: skip
    assert (fix.lat_deg, fix.lon_deg, fix.alt_amsl_m) == pytest.approx((47.5, 8.5, 500.25))
    assert fix.velocity_ned_mps == pytest.approx((1.0, -2.0, 0.5))
    assert (fix.eph_m, fix.epv_m) == pytest.approx((0.8, 1.2))


@pytest.fixture
def rig(request, tmp_path):
    """A started autopilot (instance from the test's marker) with its plant and two GCSs."""
    instance, kwargs = request.param
    plant = QuadPlant(np.random.default_rng(instance))
    mini = MiniRig(instance, plant, tmp_path / "autopilot.ulg", **kwargs)
    ports = Ports(instance)
    api = GroundStation(ports.api_local_udp, ports.system_id)
    gcs = GroundStation(ports.gcs_local_udp, ports.system_id)
    api.send(api.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID,
                                      0, 0, 0))  # fmt: skip
    gcs.send(gcs.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID,
                                      0, 0, 0))  # fmt: skip
    yield mini, api, gcs, tmp_path / "autopilot.ulg"
    api.close()
    gcs.close()
    assert mini.close() == 0


def _takeoff(mini, api, altitude_m=5.0, seconds=10.0):
    mini.step(2.0, [api])  # warm-up: gyro calibrated, GPS origin set
    ack = api.command(mavlink.MAV_CMD_NAV_TAKEOFF, -1, 0, 0, math.nan, math.nan, math.nan,
                      HOME[2] + altitude_m)  # fmt: skip
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert api.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == 0
    mini.step(seconds, [api])


@pytest.mark.parametrize("rig", [(41, {})], indirect=True)
def test_heartbeat_identity_and_telemetry(rig):
    mini, api, gcs, _ = rig
    mini.step(1.5, [api, gcs])
    for station in (api, gcs):
        beat = station.wait_for("HEARTBEAT")
        assert (beat.type, beat.autopilot) == (
            mavlink.MAV_TYPE_QUADROTOR,
            mavlink.MAV_AUTOPILOT_PX4,
        )
        assert beat.custom_mode == (Px4MainMode.AUTO << 16) | (Px4AutoMode.LOITER << 24)
        assert beat.get_srcSystem() == 42  # instance 41 → system id 42
        station.wait_for("ATTITUDE")
        station.wait_for("GLOBAL_POSITION_INT", lambda m: abs(m.lat * 1e-7 - HOME[0]) < 1e-4)
        station.wait_for(
            "EXTENDED_SYS_STATE", lambda m: m.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
        )
    ack = api.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE, -1)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    api.collect()
    api.received.clear()
    mini.step(0.5, [api])
    assert not [m for m in api.received if m.get_type() == "ATTITUDE"]
    ack = api.command(31000, 0)  # a command it does not have
    assert ack.result == mavlink.MAV_RESULT_UNSUPPORTED


@pytest.mark.parametrize("rig", [(43, {"mag": False})], indirect=True)
def test_arming_refused_with_reason_when_a_sensor_is_missing(rig):
    mini, api, _, _ = rig
    mini.step(2.0, [api])
    ack = api.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    assert "Preflight Fail: Compass Sensor 0 missing" in api.statustexts
    mini.step(0.2, [api])
    assert not mini.armed


@pytest.mark.parametrize("rig", [(45, {})], indirect=True)
def test_parameter_round_trip_changes_the_takeoff_altitude(rig):
    mini, api, _, _ = rig
    api.send(api.mav.param_request_list_encode(46, 1))
    first = api.wait_for("PARAM_VALUE")
    names = {first.param_id}
    for _ in range(first.param_count - 1):
        names.add(api.wait_for("PARAM_VALUE").param_id)
    assert {"MC_ROLLRATE_P", "MPC_XY_VEL_P_ACC", "MIS_TAKEOFF_ALT"} <= names
    api.send(
        api.mav.param_set_encode(46, 1, b"MIS_TAKEOFF_ALT", 4.0, mavlink.MAV_PARAM_TYPE_REAL32)
    )
    assert api.wait_for("PARAM_VALUE", lambda m: m.param_id == "MIS_TAKEOFF_ALT").param_value == 4.0
    api.send(api.mav.param_request_read_encode(46, 1, b"MIS_TAKEOFF_ALT", -1))
    assert api.wait_for("PARAM_VALUE").param_value == pytest.approx(4.0)
    # int32 travels bytewise, as PX4 encodes it
    bits = struct.unpack("<f", struct.pack("<i", 0))[0]
    api.send(api.mav.param_set_encode(46, 1, b"SYS_HAS_BARO", bits, mavlink.MAV_PARAM_TYPE_INT32))
    answer = api.wait_for("PARAM_VALUE", lambda m: m.param_id == "SYS_HAS_BARO")
    assert answer.param_type == mavlink.MAV_PARAM_TYPE_INT32
    assert struct.unpack("<i", struct.pack("<f", answer.param_value))[0] == 0
    # out of range: refused with the reason, the old value echoed
    api.send(api.mav.param_set_encode(46, 1, b"MPC_XY_P", 9.0, mavlink.MAV_PARAM_TYPE_REAL32))
    assert api.wait_for("PARAM_VALUE", lambda m: m.param_id == "MPC_XY_P").param_value == (
        pytest.approx(0.95)
    )
    # takeoff without an altitude goes to MIS_TAKEOFF_ALT: now 4 m, not PX4's 2.5 m
    mini.step(2.0, [api])
    assert api.command(mavlink.MAV_CMD_NAV_TAKEOFF, -1, 0, 0, math.nan, math.nan, math.nan,
                       math.nan).result == 0  # fmt: skip
    assert api.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == 0
    mini.step(9.0, [api])
    assert -mini.plant.position[2] == pytest.approx(4.0, abs=0.4)


def _mission_items(mav, system_id):
    square = [(10.0, 0.0), (10.0, 10.0), (0.0, 10.0), (0.0, 0.0)]
    items = []
    for seq, (north, east) in enumerate(square):
        from quad_model.frames import ned_to_geodetic

        lat, lon, _ = ned_to_geodetic((north, east, 0.0), *HOME)
        items.append(mav.mission_item_int_encode(
            system_id, 1, seq, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            mavlink.MAV_CMD_NAV_WAYPOINT, 0, 1, 0.0, 1.0, 0.0, math.nan,
            round(lat * 1e7), round(lon * 1e7), 5.0))  # fmt: skip
    return items


@pytest.mark.parametrize("rig", [(47, {})], indirect=True)
def test_four_waypoint_mission_flies_and_reports_each_item(rig):
    mini, api, gcs, _ = rig
    mini.step(2.0, [api, gcs])
    items = _mission_items(gcs.mav, 48)
    gcs.send(gcs.mav.mission_count_encode(48, 1, len(items), mavlink.MAV_MISSION_TYPE_MISSION))
    for _ in items:
        request = gcs.wait_for("MISSION_REQUEST_INT")
        gcs.send(items[request.seq])
    assert gcs.wait_for("MISSION_ACK").type == mavlink.MAV_MISSION_ACCEPTED
    assert gcs.command(mavlink.MAV_CMD_MISSION_START, 0, 0).result == 0
    assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == 0
    reached = []
    for _ in range(12):  # up to 36 s of flight
        mini.step(3.0, [gcs])
        reached = [m.seq for m in gcs.received if m.get_type() == "MISSION_ITEM_REACHED"]
        if len(reached) == 4:
            break
    assert reached == [0, 1, 2, 3]
    assert math.hypot(*mini.plant.position[:2]) < 1.5  # back at the last corner (0, 0)
    assert -mini.plant.position[2] == pytest.approx(5.0, abs=0.5)
    # the mission reads back as uploaded
    gcs.send(gcs.mav.mission_request_list_encode(48, 1))
    assert gcs.wait_for("MISSION_COUNT").count == 4
    gcs.send(gcs.mav.mission_request_int_encode(48, 1, 2))
    assert gcs.wait_for("MISSION_ITEM_INT").x == items[2].x


@pytest.mark.parametrize("rig", [(49, {})], indirect=True)
def test_failsafe_on_gps_loss_descends_and_lands(rig):
    mini, api, _, _ = rig
    _takeoff(mini, api)
    assert -mini.plant.position[2] == pytest.approx(5.0, abs=0.5)
    mini.plant.gps_enabled = False
    mini.step(3.0, [api])
    assert any("no position" in text for text in api.statustexts)
    beat = api.wait_for("HEARTBEAT", lambda m: m.custom_mode >> 24 == Px4AutoMode.LAND)
    assert beat.system_status == mavlink.MAV_STATE_CRITICAL
    mini.step(14.0, [api])
    assert mini.plant.position[2] == pytest.approx(0.0, abs=0.05)  # on the ground
    assert not mini.armed  # and disarmed after landing


@pytest.mark.parametrize("rig", [(51, {})], indirect=True)
def test_fuzzed_links_leave_it_flying(rig):
    """Random bytes and truncated frames on the GCS and API links, and noise between frames on
    the simulator link, while hovering: it keeps answering every frame, keeps its height, and
    counts what it discarded."""
    mini, api, gcs, _ = rig
    _takeoff(mini, api)
    rng = np.random.default_rng(99)
    valid = [api.mav.command_long_encode(1, 1, 400, 0, 0, 0, 0, 0, 0, 0, 0).pack(api.mav),
             api.mav.param_set_encode(46, 1, b"MPC_XY_P", 1.0, 9).pack(api.mav),
             api.mav.mission_item_int_encode(1, 1, 5, 6, 16, 0, 1, 0, 0, 0, 0, 1, 2, 3).pack(
                 api.mav)]  # fmt: skip
    for _ in range(200):
        for station in (api, gcs):
            station.send_raw(rng.bytes(int(rng.integers(1, 300))))
            frame = valid[int(rng.integers(len(valid)))]
            station.send_raw(frame[: int(rng.integers(1, len(frame)))])
        # on the TCP stream only bytes that cannot start a frame: a bogus header there would
        # swallow the next real frame (a stream has no resynchronisation; PX4 alike)
        noise = rng.bytes(int(rng.integers(1, 50)))
        mini.send_raw(noise.replace(b"\xfd", b"\x00").replace(b"\xfe", b"\x00"))
        mini.step(0.02, [api])
    api.received.clear()
    mini.step(2.0, [api])
    assert mini.armed
    assert -mini.plant.position[2] == pytest.approx(5.0, abs=0.5)
    status = [m for m in api.received if m.get_type() == "SYS_STATUS"][-1]
    assert status.errors_comm > 100  # the discarded garbage is counted
