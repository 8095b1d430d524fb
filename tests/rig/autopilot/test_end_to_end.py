"""The autopilot process flown through the real rig: ``run_scenario`` with the TLM sensor
chips, quad_model's F450, PX4's simulator link, and a pymavlink ground station on the
autopilot's GCS link (UDP 18570+i) while the rig runs.

The ground station acts from the rig's progress callback (every 0.1 s of simulated time):
the rig holds the next sensor frame meanwhile, and the autopilot serves UDP between frames,
so each request is answered, and takes effect, at a known frame. The GPS-loss failsafe is
flown in ``tests/rig/test_closed_loop.py``; here the rest of the issue's list.
"""

import math

import numpy as np
import pytest
import pyulog

from quad_model.environment import Environment
from quad_model.frames import ned_to_geodetic
from rig.autopilots.reference.navigator import Px4AutoMode, Px4MainMode
from rig.errors import RigError
from rig.lockstep.loop import Progress, RunOptions, run_scenario
from rig.mavlink.px4_api import Ports, mavlink
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import scenario_from_dict
from tests.rig.autopilot.gcs_client import GcsClient

pytestmark = pytest.mark.closed_loop

#: IMU at 250 Hz (PX4's IMU_INTEG_RATE, Gazebo's rate): 1 kHz adds nothing to these checks.
RATES = {"imu_hz": 250}
#: The GPS origin is set and the gyro calibrated at rest within the first 2 s.
WARM_UP_S = 2.0
ALTITUDE_BOUND_M = 0.5


def fly(tmp_path, instance, name, duration_s, on_progress=None, **scenario):
    """Run a short scenario with the reference autopilot; returns the rig's ground truth."""
    document = {"name": name, "vehicle": "f450_high_precision", "duration_s": duration_s,
                "seed": scenario.pop("seed", 21), "rates": RATES, **scenario}  # fmt: skip
    options = RunOptions(instance=instance, out_dir=tmp_path / name,
                         timeouts=LinkTimeouts(connect_s=60, answer_s=30))  # fmt: skip
    result = run_scenario(scenario_from_dict(document), options, on_progress)
    return result, pyulog.ULog(str(result.rig_log)).get_dataset(
        "vehicle_local_position_groundtruth"
    ).data


def at(truth, time_s: float, key: str) -> float:
    return float(truth[key][np.searchsorted(truth["timestamp"] / 1e6, time_s)])


class ScriptedGcs:
    """A ground station whose steps run once each at a simulated time (progress callback)."""

    def __init__(self, instance: int, steps) -> None:
        ports = Ports(instance)
        self.client = GcsClient(ports.gcs_local_udp, ports.system_id)
        self.steps = sorted(steps, key=lambda step: step[0])

    def __call__(self, progress: Progress) -> None:
        self.client.collect()
        while self.steps and progress.time_s >= self.steps[0][0] - 1e-9:
            _, step = self.steps.pop(0)
            step(self.client)


def _arm(client: GcsClient) -> None:
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == 0


def _mission_items(client: GcsClient) -> list:
    """Four waypoints 5 m above home on a 6 m square, 1 m acceptance radius."""
    home = Environment().home
    corners = [(6.0, 0.0), (6.0, 6.0), (0.0, 6.0), (0.0, 0.0)]
    items = []
    for seq, (north, east) in enumerate(corners):
        lat, lon, _ = ned_to_geodetic((north, east, 0.0), home.lat_deg, home.lon_deg,
                                      home.alt_amsl_m)  # fmt: skip
        items.append(client.mav.mission_item_int_encode(
            client.target_system, 1, seq, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            mavlink.MAV_CMD_NAV_WAYPOINT, 0, 1, 0.0, 1.0, 0.0, math.nan,
            round(lat * 1e7), round(lon * 1e7), 5.0))  # fmt: skip
    return items


def test_four_waypoint_mission_uploaded_over_udp_flies_and_reports_each_item(
    tmp_path, free_instance
):
    """Upload, MISSION_START and arm from the GCS link: it climbs, flies the square and
    reports MISSION_ITEM_REACHED 0, 1, 2, 3 in order; the true position at the end is the last
    corner (home) at 5 m, and the mission reads back as uploaded. Meanwhile the link shows
    what QGroundControl needs: a PX4 quadrotor in AUTO/MISSION, attitude, position, landed
    state, per-link stream rates and an unsupported command refused as such."""
    instance = free_instance()
    uploaded = []

    def upload_and_start(client: GcsClient) -> None:
        client.heartbeat()
        uploaded.extend(_mission_items(client))
        assert client.upload_mission(uploaded) == mavlink.MAV_MISSION_ACCEPTED
        assert client.command(mavlink.MAV_CMD_MISSION_START, 0, 0).result == 0
        _arm(client)

    def telemetry(client: GcsClient) -> None:
        beat = client.wait_for("HEARTBEAT")
        assert (beat.type, beat.autopilot) == (mavlink.MAV_TYPE_QUADROTOR,
                                               mavlink.MAV_AUTOPILOT_PX4)  # fmt: skip
        assert beat.custom_mode == (Px4MainMode.AUTO << 16) | (Px4AutoMode.MISSION << 24)
        assert beat.get_srcSystem() == Ports(instance).system_id
        client.wait_for("ATTITUDE")
        client.wait_for("GLOBAL_POSITION_INT", lambda m: m.relative_alt > 1000)
        client.wait_for("EXTENDED_SYS_STATE",
                        lambda m: m.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR)  # fmt: skip
        ack = client.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                             mavlink.MAVLINK_MSG_ID_ATTITUDE, -1)  # fmt: skip
        assert ack.result == mavlink.MAV_RESULT_ACCEPTED
        assert client.command(31000, 0).result == mavlink.MAV_RESULT_UNSUPPORTED

    def no_attitude_since(client: GcsClient) -> None:
        client.collect()
        assert "ATTITUDE" not in {m.get_type() for m in client.received}

    def read_back(client: GcsClient) -> None:
        client.send(client.mav.mission_request_list_encode(client.target_system, 1))
        assert client.wait_for("MISSION_COUNT").count == 4
        client.send(client.mav.mission_request_int_encode(client.target_system, 1, 2))
        assert client.wait_for("MISSION_ITEM_INT").x == uploaded[2].x

    steps = [(WARM_UP_S, upload_and_start), (10.0, telemetry),
             (10.1, lambda client: client.received.clear()), (12.0, no_attitude_since),
             (31.9, read_back)]  # fmt: skip
    gcs = ScriptedGcs(instance, steps)
    _, truth = fly(tmp_path, instance, "mission", 32.0, gcs)
    gcs.client.collect()
    assert gcs.client.reached == [0, 1, 2, 3]
    assert math.hypot(at(truth, 31.9, "x"), at(truth, 31.9, "y")) < 1.5
    assert -at(truth, 31.9, "z") == pytest.approx(5.0, abs=ALTITUDE_BOUND_M)
    gcs.client.close()


def test_parameter_round_trip_changes_the_takeoff_height_and_it_lands_and_disarms(
    tmp_path, free_instance
):
    """PARAM_SET MIS_TAKEOFF_ALT = 3.5 (PX4's default is 2.5) is echoed and reads back; a
    NAV_TAKEOFF without an altitude then climbs to 3.5 m (true altitude). NAV_LAND brings it
    down, and it disarms on its own (land detector, COM_DISARM_LAND) within 10 s of
    touchdown: the HEARTBEAT's armed flag clears."""
    instance = free_instance()

    def set_and_get(client: GcsClient) -> None:
        client.heartbeat()
        client.send(client.mav.param_set_encode(client.target_system, 1, b"MIS_TAKEOFF_ALT",
                                                3.5, mavlink.MAV_PARAM_TYPE_REAL32))  # fmt: skip
        echo = client.wait_for("PARAM_VALUE", lambda m: m.param_id == "MIS_TAKEOFF_ALT")
        assert echo.param_value == pytest.approx(3.5)
        client.send(client.mav.param_request_read_encode(client.target_system, 1,
                                                         b"MIS_TAKEOFF_ALT", -1))  # fmt: skip
        read = client.wait_for("PARAM_VALUE", lambda m: m.param_id == "MIS_TAKEOFF_ALT")
        assert read.param_value == pytest.approx(3.5)
        nan = math.nan
        ack = client.command(mavlink.MAV_CMD_NAV_TAKEOFF, -1, 0, 0, nan, nan, nan, nan)
        assert ack.result == 0
        _arm(client)

    def land(client: GcsClient) -> None:
        assert client.command(mavlink.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan).result == 0

    gcs = ScriptedGcs(instance, [(WARM_UP_S, set_and_get), (11.0, land)])
    _, truth = fly(tmp_path, instance, "param", 28.0, gcs)
    assert -at(truth, 10.9, "z") == pytest.approx(3.5, abs=ALTITUDE_BOUND_M)
    t = truth["timestamp"] / 1e6
    on_ground = (t > 11.0) & (-truth["z"] < 0.02)
    assert on_ground.any(), "it never touched down"
    touchdown_s = float(t[on_ground][0])
    beats = [m for m in gcs.client.received if m.get_type() == "HEARTBEAT"]
    disarmed = [m for m in beats if not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED]
    assert disarmed, f"still armed at the end (touchdown at {touchdown_s:.1f} s)"
    assert touchdown_s + 10.0 < 28.0
    assert "Disarmed: landed (COM_DISARM_LAND)" in gcs.client.statustexts
    gcs.client.close()


def test_arming_refused_with_the_reason_when_the_magnetometer_is_missing(tmp_path, free_instance):
    """The IST8310 stops answering from t = 0 (scenario fault ``chip_mute``): no field ever
    reaches the autopilot, and the scenario's arm command is refused with PX4's reason; the
    rig ends the run with it as one line."""
    with pytest.raises(RigError, match=r"refused arm.*Preflight Fail: Compass Sensor 0 missing"):
        fly(tmp_path, free_instance(), "no_mag", 3.0,
            commands=[{"at_s": WARM_UP_S, "action": "arm"}],
            faults=[{"kind": "chip_mute", "start_s": 0.0, "chip": "ist8310"}])  # fmt: skip


def test_fuzzed_gcs_and_api_links_leave_it_flying(tmp_path, free_instance):
    """From 6 s to 10 s of a 3 m hover, every 0.1 s: random bytes and truncated valid frames
    on both UDP links. It keeps answering every sensor frame (the run completes), holds its
    height, stays armed, and counts what it discarded (SYS_STATUS.errors_comm)."""
    instance = free_instance()
    ports = Ports(instance)
    api = GcsClient(ports.api_local_udp, ports.system_id)
    rng = np.random.default_rng(99)
    mav = api.mav
    valid = [
        mav.command_long_encode(1, 1, 400, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav),
        mav.param_set_encode(1, 1, b"MPC_XY_P", 1.0, 9).pack(mav),
        mav.mission_item_int_encode(1, 1, 5, 6, 16, 0, 1, 0, 0, 0, 0, 1, 2, 3).pack(mav),
    ]

    def fuzz(client: GcsClient) -> None:
        for station in (client, api):
            station.send_raw(rng.bytes(int(rng.integers(1, 300))))
            frame = valid[int(rng.integers(len(valid)))]
            station.send_raw(frame[: int(rng.integers(1, len(frame)))])

    steps = [(5.9, GcsClient.heartbeat)] + [(6.0 + 0.1 * k, fuzz) for k in range(40)]
    gcs = ScriptedGcs(instance, steps)
    commands = [{"at_s": 0.5, "action": "arm"},
                {"at_s": 0.6, "action": "takeoff", "altitude_m": 3.0}]  # fmt: skip
    result, truth = fly(tmp_path, instance, "fuzz", 12.0, gcs, commands=commands)
    assert result.frames == 12 * RATES["imu_hz"]
    altitude = -truth["z"][truth["timestamp"] / 1e6 >= 6.0]
    assert np.abs(altitude - 3.0).max() < ALTITUDE_BOUND_M
    gcs.client.collect()
    beats = [m for m in gcs.client.received if m.get_type() == "HEARTBEAT"]
    assert beats[-1].base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    status = [m for m in gcs.client.received if m.get_type() == "SYS_STATUS"][-1]
    assert status.errors_comm >= 40  # at least the truncated frames, counted
    api.close()
    gcs.client.close()
