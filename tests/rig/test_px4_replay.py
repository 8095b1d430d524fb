"""``rig replay LOG --autopilot px4``: the real X500 flight flown by PX4 SITL with the log's
own parameters, sticks, mode switches and mission.

The plan is checked against the log's facts without PX4 (a stand-in build whose parameter
list holds the log's names); the flight test needs PX4 (``$PX4_DIR``; CI points it at
``../shared/px4_sitl``) and skips without it. Times are the log's boot seconds.
"""

import json
import lzma
import math
from pathlib import Path

import numpy as np
import pytest
import pyulog

from quad_model.environment import GeoPoint
from quad_model.frames import geodetic_to_ned
from rig.autopilots.px4 import PX4_DIR_ENV, build_parameters, find_px4, sitl_parameters
from rig.cli import main
from rig.lockstep.loop import RunOptions
from rig.mavlink.ground_link import GroundLink
from rig.mavlink.px4_api import Ports, mavlink
from rig.mavlink.simulator_link import LinkTimeouts
from rig.replay import ReplayError, ReplayOptions, plan_replay, run_replay
from rig.replay.parameters import YAW_RATE_LIMIT_FLOOR_DEG_S
from rig.replay.plan import PX4_BOOT_S, PX4_SETUP_S
from rig.replay.timeline import ARM_MODE_LEAD_S, EventKind, FlightEvent, ReplayLog
from rig.scenarios.scenario import (
    SetHome,
    SetMode,
    SetParam,
    SetpointTrack,
    Track,
    UploadMission,
)
from rig.scenarios.script import HEARTBEAT_PERIOD_US, STICKS_PERIOD_US, CommandScript
from tests.instances import free_test_instance

LOGS = Path(__file__).resolve().parents[2] / "data/flight_logs"
X500 = LOGS / "px4_x500v2_v6xrt_flight_2026-03-20.ulg"
#: The X500 log's first timestamp and its arming (vehicle_status.armed_time, "Armed by RC
#: switch"), mode switches (nav_state_user_intention) and disarm ("Disarmed by landing").
FIRST_S, ARMED_S = 407.404345, 408.889359
MISSION_S, TAKEOVER_S, LAND_S, DISARMED_S = 437.862, 455.431, 481.566, 503.072
POSCTL, ALTCTL, MISSION, HOLD, LAND = 2, 1, 3, 4, 18
#: v1.17 loitered where the X500 was from the switch to Mission until the mission's item 0.
MISSION_HOLD_S = 438.274 - 437.865
#: What SITL must never get from a real vehicle, one example per rule (the log's names).
NEVER_COPIED = {
    "CAL_ACC0_ID": "calibration of the real sensor chips",
    "TC_A_ENABLE": "calibration of the real sensor chips",
    "SYS_AUTOSTART": "airframe 10016",
    "SENS_BOARD_ROT": "board's mounting",
    "MAV_2_UDP_PRT": "MAVLink link of the real board",
    "GPS_1_PROTOCOL": "serial port",
    "IMU_GYRO_RATEMAX": "lockstep",
    "IMU_INTEG_RATE": "lockstep",
    "MAV_SYS_ID": "SITL instance",
    "SDLOG_MODE": "boot to shutdown",
    "COM_RC_IN_MODE": "MANUAL_CONTROL",
    "COM_CPU_MAX": "no CPU load",
    "CBRK_SUPPLY_CHK": "no power module",
}


@pytest.fixture(scope="module")
def log_parameters() -> dict:
    return pyulog.ULog(str(X500), ["vehicle_status"]).initial_parameters


@pytest.fixture(scope="module")
def stand_in_build(tmp_path_factory, log_parameters) -> Path:
    """A folder shaped like a PX4 build whose parameter list holds every name of the log but
    ADC_ADS1115_EN, with PX4 v1.14's EKF2_GPS_CHECK (9 bits, max 511): enough to plan."""
    return _stand_in_build(tmp_path_factory.mktemp("px4_build"), log_parameters)


def _stand_in_build(root: Path, log_parameters: dict, tag: bytes = b"v1.14.0") -> Path:
    (root / "bin").mkdir(parents=True)
    (root / "bin/px4").write_bytes(b"#!/bin/sh\nexit 1\n# \0" + tag + b"\0\n")
    (root / "bin/px4").chmod(0o755)
    (root / "etc/init.d-posix").mkdir(parents=True)
    (root / "etc/init.d-posix/rcS").write_text(". px4-rc.params\n")
    (root / "etc/extras").mkdir()
    entries = [{"name": name, "type": "Int32" if float(value).is_integer() else "Float"}
               for name, value in log_parameters.items() if name != "ADC_ADS1115_EN"]  # fmt: skip
    for entry in entries:
        if entry["name"] == "EKF2_GPS_CHECK":
            entry |= {"min": 0, "max": 511, "bitmask": [{"index": i} for i in range(9)]}
    document = json.dumps({"parameters": entries}).encode()
    (root / "etc/extras/parameters.json.xz").write_bytes(lzma.compress(document))
    return root


@pytest.fixture(scope="module")
def plan(stand_in_build):
    return plan_replay(X500, ReplayOptions(autopilot="px4", px4_dir=stand_in_build))


# -- the plan ---------------------------------------------------------------------------------


def test_the_logs_parameters_go_to_px4_except_the_vehicles_hardware(plan, log_parameters):
    """Every parameter of the log that this PX4 has, as logged (float32 exact), but the real
    vehicle's calibrations, drivers, ports and outputs and what SITL and the rig need; each
    skipped one is listed with its reason in replay.json and the run's notes."""
    assert plan.parameters["MC_ROLLRATE_P"] == log_parameters["MC_ROLLRATE_P"]
    assert plan.parameters["CA_ROTOR0_PX"] == 1.0  # the log's geometry, not the rig's airframe
    assert plan.parameters["NAV_DLL_ACT"] == 2  # hence the rig's ground-station HEARTBEAT
    assert "MC_ROLLRATE_P=0.14000000059604645" in plan.autopilot_params
    assert "COM_RC_IN_MODE=1" in plan.autopilot_params  # the rig's joystick, not the log's 3
    reasons = {s.name: s.reason for s in plan.skipped}
    for name, reason in NEVER_COPIED.items():
        assert reason in reasons[name], name
        assert name not in plan.parameters
    assert reasons["ADC_ADS1115_EN"] == "not a parameter of this PX4 build"
    assert reasons["EKF2_GPS_CHECK"] == "above this build's maximum 511"  # v1.17's bits 9-10
    assert plan.unknown_parameter_count == 1
    assert len(plan.parameters) + len(plan.skipped) == len(log_parameters) == 1135
    summary = plan.summary()
    assert summary["autopilot"] == "px4"
    assert summary["log_firmware"] == "PX4 v1.17.0rc (git 0b6e4687) on PX4_FMU_V6XRT"
    assert {"name": "CAL_ACC0_ID", "value": 2949130.0,
            "reason": reasons["CAL_ACC0_ID"]} in summary["parameters_skipped"]  # fmt: skip
    rig_owned = summary["parameters_set_by_the_rig"]
    assert rig_owned["IMU_INTEG_RATE"] == rig_owned["IMU_GYRO_RATEMAX"] == 800
    assert (rig_owned["COM_RC_IN_MODE"], rig_owned["SYS_HITL"]) == (1, 0)
    notes = " ".join(text for _, text in plan.notes)
    assert f"PX4 v1.17.0rc (git 0b6e4687) on PX4_FMU_V6XRT; PX4 SITL gets {len(plan.parameters)} " \
           "of its 1135 parameters" in notes  # fmt: skip
    assert "skipped (lockstep: the rig sets it to its IMU rate): IMU_GYRO_RATEMAX, " in notes


#: Of the X500 log's 1135 parameters (its PX4 is v1.17.0rc): how many each release's SITL
#: takes, skips, and does not have at all, and which it skips for a value out of its range.
_TAKEN_BY_RELEASE = {
    (1, 14): ((682, 453, 325), {"BAT2_N_CELLS", "EKF2_GPS_CHECK", "LND_FLIGHT_T_LO"}),
    (1, 17): ((747, 388, 255), {"LND_FLIGHT_T_LO"}),
}


def test_the_real_px4_build_takes_most_of_the_logs_parameters(log_parameters):
    """v1.14 takes 682 (325 unknown to it, 3 out of its range); v1.17, the line that flew,
    747 (255 unknown: modules this SITL build leaves out and the real board's drivers, 1
    out of its range). The rest are the vehicle's hardware or the rig's."""
    build = find_px4()
    if build is None or build.release not in _TAKEN_BY_RELEASE:
        pytest.skip(f"no PX4 SITL build of {sorted(_TAKEN_BY_RELEASE)}: set {PX4_DIR_ENV}")
    plan = plan_replay(X500, ReplayOptions(autopilot="px4"))
    applied, skipped = sitl_parameters(log_parameters, build_parameters(build))
    assert applied == plan.parameters
    counts, out_of_range = _TAKEN_BY_RELEASE[build.release]
    assert (len(applied), len(skipped), plan.unknown_parameter_count) == counts
    assert {s.name for s in plan.skipped if "this build's" in s.reason} == out_of_range


def test_the_replay_follows_the_logs_events(plan):
    """PX4 boots PX4_BOOT_S before the log, so the arm and every mode switch go out at the
    log's times; failsafe mode changes are PX4's to repeat, never commanded."""
    described = [(round(e.time_s, 3), e.kind, e.nav_state, e.commanded) for e in plan.pilot.events]
    assert described == [
        (round(ARMED_S, 3), "arm", None, True),
        (round(ARMED_S, 3), "mode", POSCTL, True),  # the mode it armed in
        (MISSION_S, "mode", MISSION, True),  # DO_SET_MODE from the ground station
        (TAKEOVER_S, "mode", POSCTL, True),  # "Pilot took over using sticks"
        (474.362, "autopilot", ALTCTL, True),  # "Failsafe: blind land": position invalid
        (476.353, "autopilot", POSCTL, True),  # and back
        (LAND_S, "mode", LAND, True),
        (DISARMED_S, "disarm", None, True),  # "Disarmed by landing": sent, PX4 landed by then?
        (DISARMED_S, "mode", POSCTL, False),  # PX4's own after the disarm
    ]
    origin = FIRST_S - PX4_BOOT_S
    assert plan.lead_in_s == PX4_BOOT_S
    assert plan.arm_s == plan.real_arm_s == ARMED_S
    commands = [(type(c).__name__, round(c.at_s + origin, 3), getattr(c, "nav_state", None))
                for c in plan.commands]  # fmt: skip
    assert commands == [
        ("Track", round(origin, 3), None),  # the sticks, from PX4's boot on
        ("UploadMission", round(origin + PX4_SETUP_S, 3), None),
        ("SetMode", round(ARMED_S - ARM_MODE_LEAD_S, 3), POSCTL),
        ("Arm", round(ARMED_S, 3), None),
        ("SetHome", 411.979, None),  # where the real PX4 moved its home at the take-off
        ("SetHome", 412.221, None),
        ("SetMode", MISSION_S, HOLD),  # as the real navigator held, then its mission
        ("SetMode", round(MISSION_S + MISSION_HOLD_S, 3), MISSION),
        ("SetMode", TAKEOVER_S, POSCTL),
        ("SetMode", 474.362, ALTCTL),  # the pilot's sticks act in Altitude as they did
        ("SetMode", 476.353, POSCTL),
        ("SetMode", LAND_S, LAND),
        ("Disarm", DISARMED_S, None),
    ]
    assert plan.commands[-1].may_refuse  # PX4 refuses it until it has landed
    scenario = plan.scenario(Path("x500_v2"))
    assert scenario.start.clock_s == pytest.approx(origin)
    assert scenario.duration_s == pytest.approx(plan.end_s - FIRST_S + PX4_BOOT_S)
    assert scenario.rates.imu_hz == 800  # the log's IMU_GYRO_RATEMAX: its rate loop's rate
    assert {type(c) for c in scenario.tracks} == {Track, UploadMission, SetHome}
    assert SetMode in {type(c) for c in scenario.commands}  # a file's command too
    notes = [text for _, text in plan.notes]
    assert (
        "replay: log event 474.362 s PX4 switched to Altitude by itself (failsafe: commanded, "
        "so the sticks act in the mode the vehicle flew): commanded"
    ) in notes
    assert plan.pilot.mission_holds == ((pytest.approx(MISSION_S, abs=1e-3),
                                   pytest.approx(MISSION_HOLD_S, abs=1e-3)),)  # fmt: skip
    assert (
        "replay: after the switch to Mission at 437.862 s the real navigator held the vehicle "
        "where it was for 0.409 s (a loiter) before the mission's first item: flown as Hold, "
        "then Mission"
    ) in notes
    assert plan.summary()["mission_holds"] == [
        [pytest.approx(MISSION_S, abs=1e-3), pytest.approx(MISSION_HOLD_S, abs=1e-3)]
    ]


def test_the_mission_is_uploaded_as_it_was_flown(plan):
    """navigator_mission_item: items 0-3 (the climb the navigator put before item 0 is not
    one of them; the log's fifth item never flew, so it is not known), put where the real
    vehicle flew them: each at its distance and bearing from home (the uploader moved the
    home by whole degrees, not the mission), each height above the home the real PX4 held
    then, as logged (the replay moves its home where the real PX4 moved its own: 1.82 m up
    at the take-off), and item 0, which PX4 passed 50 ms after making it current, at the
    height the vehicle hovered at then."""
    assert [(i.frame, i.command) for i in plan.pilot.mission] == [
        (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink.MAV_CMD_NAV_WAYPOINT)
    ] * 4
    # home_position.alt 185.84 m from the take-off (412.2 s) on; the vehicle at 190.00 m
    # when item 0 (logged 5 m) was passed at 438.27 s
    assert [i.alt_m for i in plan.pilot.mission] == pytest.approx([4.16, 10.0, 5.0, 10.0], abs=0.01)
    home = plan.home
    offsets = [
        geodetic_to_ned(i.lat_deg, i.lon_deg, 0.0, home.lat_deg, home.lon_deg, 0.0)[:2]
        for i in plan.pilot.mission
    ]
    assert math.hypot(*offsets[0]) < 1.0  # the first waypoint is above the take-off point
    # the first leg, north-east: 0.000262° of longitude east of home at the real site's
    # 41.9° N is 21.7 m (at the moved home's 51.9° N it would be 18.0 m)
    assert offsets[1] == pytest.approx((8.95, 21.7), abs=0.1)
    assert max(math.hypot(*o) for o in offsets) < 50.0  # the mission's legs, ~40 m
    assert all(math.isnan(i.param4) and i.param2 == 0.0 for i in plan.pilot.mission)
    assert plan.pilot.mission_notes == (
        "the log's mission had 5 items; 4 became current and could be uploaded (the log holds "
        "no more)",
        "the mission items lie 10° N, 2° E from the log's home: whole degrees, the uploader's "
        "offset of the log's positions, taken out; each item keeps its distance and bearing "
        "from home (moved in degrees, the east-west legs would scale by 0.83)",
        "mission item 0 was current for 0.05 s: the real PX4 passed it where the vehicle "
        "stood, 4.2 m against its 5.0 m; uploaded at that height, so this PX4 passes it too "
        "instead of flying to it first",
    )
    assert plan.summary()["mission"][0]["param4"] is None


def test_the_home_moves_where_the_real_px4_moved_it(plan):
    """home_position: set at arming (184.01 m), again at the take-off detection (184.11 m,
    411.98 s) and 0.24 s later 1.73 m higher (185.84 m: EKF2 had just put its height up), and
    after the disarm at the real site (the uploader's offset missed it): the replay sets the
    two in flight with DO_SET_HOME at their times; Land descends and slows by the height
    above it."""
    moves = plan.pilot.home_moves
    assert [round(t, 3) for t, _ in moves] == [411.979, 412.221]
    assert [round(h.alt_amsl_m, 2) for _, h in moves] == [184.11, 185.84]
    for _, home in moves:  # the log's (moved) site, within centimetres of the first home
        north, east, _ = geodetic_to_ned(home.lat_deg, home.lon_deg, 0.0, plan.home.lat_deg,
                                         plan.home.lon_deg, 0.0)  # fmt: skip
        assert math.hypot(north, east) < 0.2
    origin = plan.start_s - plan.lead_in_s
    sets = [(c.at_s + origin, c.home) for c in plan.commands if isinstance(c, SetHome)]
    assert sets == [(pytest.approx(t), home) for t, home in moves]
    assert plan.summary()["home_moves"][1]["alt_amsl_m"] == pytest.approx(185.84, abs=0.01)
    assert any("moved its home at 412.221 s to 185.84 m AMSL" in text for _, text in plan.notes)


def _mission_log(sequence, times_s, commands=None):
    """A flight log holding only a mission flown at ``times_s`` (items 10 m apart, 5 m above
    a home at 100 m AMSL, the vehicle hovering at 106 m), waypoints unless ``commands``."""
    count = len(sequence)
    topics = {
        "navigator_mission_item": {
            "timestamp": np.array(times_s) * 1e6,
            "sequence_current": np.array(sequence),
            "frame": np.full(count, 6),
            "nav_cmd": np.array(commands) if commands else np.full(count, 16),
            "latitude": 47.0 + np.array(sequence) * 1e-4, "longitude": np.full(count, 8.0),
            "altitude": np.full(count, 5.0), "altitude_is_relative": np.ones(count, bool),
            "time_inside": np.zeros(count), "acceptance_radius": np.zeros(count),
            "loiter_radius": np.zeros(count), "yaw": np.zeros(count),
        },
        "vehicle_global_position": {"timestamp": np.array([0.0]), "alt": np.array([106.0])},
        "home_position": {"timestamp": np.array([0.0]), "alt": np.array([100.0])},
    }  # fmt: skip
    return ReplayLog("synthetic.ulg", topics, {})


def test_only_an_item_left_at_once_is_put_where_it_was_passed():
    """Item 0 left 0.1 s after it became current goes up at the vehicle's 6 m; a mission
    flown twice (the second item 0 held 5 s) does not count the first run's item 1 as
    following the second run's item 0."""
    home = GeoPoint(47.0, 8.0, 100.0)
    items, notes = _mission_log([0, 1, 2], [10.0, 10.1, 20.0]).flown_mission(home)
    assert [i.alt_m for i in items] == [6.0, 5.0, 5.0]
    assert any("mission item 0 was current for 0.10 s" in n for n in notes)
    items, notes = _mission_log([0, 1, 0, 1], [10.0, 20.0, 30.0, 35.0]).flown_mission(home)
    assert [i.alt_m for i in items] == [5.0, 5.0]
    assert not any("passed" in n for n in notes)


def test_only_a_loiter_the_navigator_replaced_by_the_mission_is_flown_as_hold():
    """A loiter (31) started at the switch and replaced by item 0 is a hold; an inserted
    climb (22, which PX4 v1.14 inserts itself), a mission whose item 0 is a loiter, and a
    first item long after the switch are not."""
    switch = FlightEvent(10.0, EventKind.MODE, MISSION, True, "test")
    other = FlightEvent(10.0, EventKind.MODE, POSCTL, True, "test")
    log = _mission_log([0, 0, 1], [10.01, 10.41, 10.46], [31, 16, 16])
    assert log.mission_start_holds([switch]) == ((10.0, pytest.approx(0.4)),)
    assert log.mission_start_holds([other]) == ()
    assert _mission_log([0, 0, 1], [10.01, 12.0, 15.0], [22, 16, 16]).mission_start_holds(
        [switch]) == ()  # fmt: skip
    assert _mission_log([0, 1], [10.01, 15.0], [17, 16]).mission_start_holds([switch]) == ()
    assert _mission_log([0, 0, 1], [11.0, 11.4, 12.0], [31, 16, 16]).mission_start_holds(
        [switch]) == ()  # fmt: skip


def test_the_pilots_sticks_are_the_logs(plan):
    sticks = plan.pilot.sticks
    assert sticks.kind == "manual"
    assert len(sticks.times_s) == 477  # 476 samples (5 Hz) and the one in force at the start
    values = np.array(sticks.values)
    assert np.abs(values).max() <= 1.0
    assert values[0, 3] == pytest.approx(0.121, abs=1e-3)  # throttle just above centre
    assert values[:, 3].min() < -0.7  # throttle pulled down on the landing


def test_px4_replay_options_fail_in_one_line(stand_in_build, tmp_path, monkeypatch):
    def error(**options) -> str:
        with pytest.raises(ReplayError) as raised:
            plan_replay(X500, ReplayOptions(autopilot="px4", **options))
        assert "\n" not in str(raised.value)
        return str(raised.value)

    assert error(px4_dir=stand_in_build, drive="rates", window_s=(455.0, 460.0)) == (
        "--drive and --window choose the reference autopilot's loop; PX4 flies the log as its "
        "pilot flew it (sticks, modes, mission)"
    )
    assert error(px4_dir=stand_in_build, imu_hz=2000).startswith(
        "--imu-hz 2000: rates.imu_hz = 2000: PX4 answers every lockstep frame only when"
    )
    monkeypatch.delenv(PX4_DIR_ENV, raising=False)
    assert error() == (
        "--autopilot px4 needs PX4's build (--px4 DIR or $PX4_DIR): its parameter list decides "
        "which of the log's parameters PX4 takes"
    )
    (stand_in_build / "etc/extras/parameters.json.xz").rename(tmp_path / "kept.xz")
    try:
        assert "cannot read the build's parameter metadata" in error(px4_dir=stand_in_build)
    finally:
        (tmp_path / "kept.xz").rename(stand_in_build / "etc/extras/parameters.json.xz")


def test_rig_replay_with_px4_says_in_one_line_what_it_needs(capsys, monkeypatch):
    monkeypatch.delenv(PX4_DIR_ENV, raising=False)
    assert main(["replay", str(X500), "--autopilot", "px4"]) == 1
    assert capsys.readouterr().err == (
        "rig: error: --autopilot px4 needs PX4's build (--px4 DIR or $PX4_DIR): its parameter "
        "list decides which of the log's parameters PX4 takes\n"
    )


# -- the sticks on the link ---------------------------------------------------------------


class StickGround:
    """The GroundLink calls the sticks make, as plain tuples."""

    def manual_control(self, roll, pitch, yaw, throttle):
        return ("sticks", round(roll, 6), round(pitch, 6), round(yaw, 6), round(throttle, 6))

    def heartbeat(self):
        return ("heartbeat",)

    def set_mode(self, nav_state):
        return ("mode", nav_state)

    def attempt(self, conversation):
        return conversation


def test_sticks_are_sent_every_20_ms_interpolated_with_a_heartbeat_each_second():
    track = SetpointTrack("manual", (0.0, 0.2, 0.4), ((0.0, 0.0, 0.0, -1.0),
                                                      (0.5, -0.5, 0.0, 0.0),
                                                      (0.5, -0.5, 0.0, 0.0)))  # fmt: skip
    commands = (Track(at_s=0.0, track=track), SetMode(at_s=0.1, name="Position"))
    script = CommandScript(commands, StickGround(), barrier=False)
    sent = []
    for time_us in range(0, 2_000_001, 4000):  # 250 Hz frames
        for action in script.due(time_us):
            sent += [(time_us, message) for message in action.unacknowledged]
            if action.conversation is not None:
                sent.append((time_us, action.conversation))
    sticks = [(t, m) for t, m in sent if m[0] == "sticks"]
    assert [t for t, _ in sticks] == list(range(0, 2_000_001, STICKS_PERIOD_US))
    assert dict(sticks)[100_000] == ("sticks", 0.25, -0.25, 0.0, -0.5)  # halfway
    assert dict(sticks)[1_000_000] == ("sticks", 0.5, -0.5, 0.0, 0.0)  # held after the last
    assert (100_000, ("mode", POSCTL)) in sent  # a mode switch does not stop the sticks
    beats = [t for t, m in sent if m == ("heartbeat",)]
    assert beats == list(range(0, 2_000_001, HEARTBEAT_PERIOD_US))


def test_manual_control_carries_px4s_stick_convention(free_instance):
    """MANUAL_CONTROL x = pitch, y = roll, r = yaw (±1000), z = throttle 0..1000 (PX4
    reads z/500 − 1): PX4's own manual_control_setpoint comes back out."""
    ports = Ports(free_instance())
    ground = GroundLink(ports, home=None)
    try:
        message = ground.manual_control(roll=0.25, pitch=-0.5, yaw=1.5, throttle=-1.0)
        beat = ground.heartbeat()
    finally:
        ground.close()
    assert (message.x, message.y, message.z, message.r) == (-500, 250, 0, 1000)  # yaw at the stop
    assert message.target == ports.system_id
    assert (beat.type, beat.autopilot) == (mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID)


# -- PX4 flies it -------------------------------------------------------------------------------

#: The flight test's window: armed idle, the POSCTL take-off, the hover, the mission and the
#: pilot taking over with the sticks (about 40 s of wall time with PX4 on two cores).
WINDOW_END_S = 460.0


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    build = find_px4()
    if build is None:
        pytest.skip(f"no PX4 SITL build: set {PX4_DIR_ENV} (CI points it at ../shared/px4_sitl)")

    out = tmp_path_factory.mktemp("px4_replay")
    plan = plan_replay(X500, ReplayOptions(autopilot="px4", end_s=WINDOW_END_S, seed=3))
    timeouts = LinkTimeouts(connect_s=60, answer_s=30)
    result = run_replay(plan, RunOptions(instance=free_test_instance(), out_dir=out,
                                         timeouts=timeouts))  # fmt: skip
    return (out, pyulog.ULog(str(X500)), pyulog.ULog(str(result.autopilot_log)),
            pyulog.ULog(str(result.rig_log)))  # fmt: skip


def _armed_modes(log, until_s):
    """(time, nav_state) when armed and at each mode change while armed, before ``until_s``."""
    data = log.get_dataset("vehicle_status").data
    times_s, changes = data["timestamp"] / 1e6, []
    for k in np.nonzero((data["arming_state"] == 2) & (times_s < until_s))[0]:
        if not changes or changes[-1][1] != data["nav_state"][k]:
            changes.append((float(times_s[k]), int(data["nav_state"][k])))
    return changes


def _heading_deg(log, time_s):
    """The estimate's heading (°) at ``time_s``."""
    data = log.get_dataset("vehicle_attitude").data
    k = np.searchsorted(data["timestamp"] / 1e6, time_s)
    w, x, y, z = (data[f"q[{i}]"][k] for i in range(4))
    return math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def _height_gain_m(log, time_s, ground_s=411.0):
    """Climb since ``ground_s`` by the autopilot's estimate (its origin is not the ground)."""
    data = log.get_dataset("vehicle_local_position").data
    z = np.interp([ground_s, time_s], data["timestamp"] / 1e6, data["z"])
    return float(z[0] - z[1])


def _item_current_s(log: pyulog.ULog, sequence: int) -> float:
    """When the navigator first started mission item ``sequence``."""
    data = log.get_dataset("navigator_mission_item").data
    return float(data["timestamp"][data["sequence_current"] == sequence][0] / 1e6)


@pytest.mark.closed_loop
def test_px4_arms_switches_modes_and_climbs_as_the_real_flight(flown):
    """PX4 arms at the log's time (within 0.1 s), flies the log's modes in its order (each
    switch within 0.5 s of the log's, the Hold before the mission within 0.1 s; the
    take-over it makes itself, from the replayed sticks), takes off within 0.5 s of the real
    take-off and climbs like the real one (its estimate's height gain at 420 s within
    1.5 m, 430 s within 2 m)."""
    out, real, px4, _ = flown
    flown_changes, real_changes = _armed_modes(px4, WINDOW_END_S), _armed_modes(real, WINDOW_END_S)
    assert [mode for _, mode in real_changes] == [POSCTL, MISSION, POSCTL]
    # The real navigator's loiter before the mission's item 0 is flown as Hold, from the
    # log's switch to Mission (v1.14 and this v1.17 SITL both start a mission at once);
    # the mission's item 1 then becomes current at the real time.
    assert [mode for _, mode in flown_changes] == [POSCTL, HOLD, MISSION, POSCTL]
    assert flown_changes[1][0] == pytest.approx(real_changes[1][0], abs=0.1)
    assert flown_changes[2][0] == pytest.approx(real_changes[1][0] + MISSION_HOLD_S, abs=0.1)
    assert _item_current_s(px4, 1) == pytest.approx(_item_current_s(real, 1), abs=0.1)
    del flown_changes[1:3], real_changes[1]
    summary = json.loads((out / "replay.json").read_text())
    assert flown_changes[0][0] == pytest.approx(ARMED_S, abs=0.1)
    for flown_change, real_change in zip(flown_changes, real_changes, strict=True):
        assert flown_change[0] == pytest.approx(real_change[0], abs=0.5)
    messages = {m.message.strip(): m.timestamp / 1e6 for m in px4.logged_messages}
    assert messages["[commander] Takeoff detected"] == pytest.approx(411.97, abs=0.5)
    for time_s, bound_m in ((420.0, 1.5), (430.0, 2.0)):
        assert _height_gain_m(px4, time_s) == pytest.approx(_height_gain_m(real, time_s),
                                                             abs=bound_m)  # fmt: skip
    mission = px4.get_dataset("mission_result").data
    assert mission["seq_total"].max() == 4  # the flown mission, uploaded
    assert mission["seq_reached"].max() >= 1
    assert summary["autopilot"] == "px4"
    # Its mission turns follow the real planner's yaw rate (this build has no yaw
    # acceleration limit): the pilot takes over near the real heading (measured 4-8°: the
    # real heading turns at about 25°/s there, and v1.14 flies the last leg 0.9 s slower
    # than v1.17; 33° with the peak rate alone, 73° at v1.14's own 60°/s).
    assert _heading_deg(px4, TAKEOVER_S) == pytest.approx(_heading_deg(real, TAKEOVER_S), abs=12)
    # PX4 took the home where the real one moved its own (DO_SET_HOME at 412.22 s)
    home = px4.get_dataset("home_position").data
    after = home["timestamp"] / 1e6 > 412.3
    assert home["alt"][after] == pytest.approx(185.84, abs=0.01)


@pytest.mark.closed_loop
def test_px4_ran_with_the_logs_parameters_and_the_rigs_own(flown, log_parameters):
    _, _, px4, rig = flown
    flown_parameters = px4.initial_parameters
    for name in ("MC_ROLLRATE_P", "MC_PITCH_P", "MPC_XY_VEL_MAX", "CA_ROTOR0_PX", "EKF2_MAG_DECL"):
        assert flown_parameters[name] == pytest.approx(log_parameters[name], rel=1e-6), name
    assert flown_parameters["IMU_INTEG_RATE"] == flown_parameters["IMU_GYRO_RATEMAX"] == 800
    assert flown_parameters["COM_RC_IN_MODE"] == 1
    assert flown_parameters["CAL_ACC0_ID"] != log_parameters["CAL_ACC0_ID"]
    events = [m.message for m in rig.logged_messages]
    assert any(text.startswith("replay: the log was flown by PX4 v1.17.0rc") for text in events)
    assert "mission of 4 items uploaded" in events


# -- the 8S quad's Stabilized hover: armed before its log starts, a stick-throttle mode ------
QUAD4001 = LOGS / "px4_quad4001_v6c_stab_hover_2026-03-09.ulg"
#: The 8S quad's ULog header start_timestamp; its actuator_outputs holds a stale sample from
#: 0.6 s (published at boot, written when the logger started), which is not the flight.
QUAD_START_S = 104.889396
STABILIZED = 15


def test_the_8s_quad_is_armed_in_stabilized_at_its_logs_start(tmp_path):
    """The logger starts on arming, 5 ms after it here: the replay starts at the header's
    start, selects Stabilized 1 s before and arms at the start (20 s after PX4's boot). The
    SITL gets the log's stick → thrust map, which PX4 changed after v1.14: the centre stick
    at the log's hover-thrust estimate (its v1.16 with MPC_USE_HTE = 1; v1.14 takes
    MPC_THR_HOVER, 0.5 in the log) and the bottom at the log's thrust there, 0 (v1.14 holds
    MPC_MANTHR_MIN, 0.08 in the log, and idled the rotors through the log's rest)."""
    parameters = pyulog.ULog(str(QUAD4001), ["vehicle_status"]).initial_parameters
    build = _stand_in_build(tmp_path, parameters)
    options = ReplayOptions(autopilot="px4", px4_dir=build, vehicle="quad4001_8s")
    quad = plan_replay(QUAD4001, options)
    assert quad.start_s == QUAD_START_S
    assert [(e.kind, e.nav_state) for e in quad.pilot.events[:2]] == [
        ("mode", STABILIZED),
        ("arm", None),
    ]
    timed = [(type(c).__name__, c.at_s) for c in quad.commands if not isinstance(c, Track)]
    assert timed[:2] == [("SetMode", PX4_BOOT_S - ARM_MODE_LEAD_S), ("Arm", PX4_BOOT_S)]
    assert quad.learned["MPC_THR_HOVER"] == pytest.approx(0.657, abs=0.002)
    assert quad.learned["MPC_MANTHR_MIN"] == 0.0
    assert "MPC_THR_HOVER=0.65" in " ".join(quad.autopilot_params)
    assert quad.summary()["parameters_learned_in_the_flight"] == quad.learned


def test_a_climb_rate_flight_learns_nothing(plan):
    """The X500 flew POSCTL, ALTCTL, Mission and Land, where PX4 runs on its own estimate;
    this stand-in build has every parameter of the log, MPC_YAWRAUTO_ACC too."""
    assert plan.learned == {}
    assert plan.pilot.yaw_rate_limits == ()
    assert not any(isinstance(c, SetParam) for c in plan.commands)


def test_a_build_without_the_yaw_acceleration_limit_turns_as_the_real_planner_did(
    tmp_path, log_parameters
):
    """PX4 v1.14 has no MPC_YAWRAUTO_ACC (the X500's v1.17: 20°/s²) and turns in Mission at
    MPC_YAWRAUTO_MAX (60°/s) from the start: the replay sets that to the real vehicle's
    peak yaw rate in Mission, 33.6°/s (vehicle_angular_velocity, 437.9-455.4 s), and in
    flight to the yaw rate the real planner allowed itself."""
    without = {k: v for k, v in log_parameters.items() if k != "MPC_YAWRAUTO_ACC"}
    build = _stand_in_build(tmp_path, without)
    x500 = plan_replay(X500, ReplayOptions(autopilot="px4", px4_dir=build))
    assert x500.learned == {"MPC_YAWRAUTO_MAX": 33.6}
    assert "MPC_YAWRAUTO_MAX=33.6" in x500.autopilot_params
    assert x500.summary()["parameters_learned_in_the_flight"] == {"MPC_YAWRAUTO_MAX": 33.6}

    # In auto modes the limit follows the real planner's yaw rate (trajectory_setpoint,
    # 5 Hz): it ramps at MPC_YAWRAUTO_ACC (20°/s² = 4°/s a sample) through each turn.
    limits = x500.pilot.yaw_rate_limits
    times_s, values = np.array(limits).T
    assert times_s[0] == pytest.approx(MISSION_S, abs=1e-3)  # from the switch to Mission on
    assert values[0] == YAW_RATE_LIMIT_FLOOR_DEG_S  # not turning there
    assert np.all((times_s >= MISSION_S) & (times_s < TAKEOVER_S) | (times_s >= LAND_S))
    assert np.all(np.abs(np.diff(values)) >= 2.0)  # a PARAM_SET only for a change of 2°/s
    ramp = (times_s > 453.9) & (times_s < TAKEOVER_S)  # the last turn, cut by the take-over
    assert np.diff(values[ramp]) == pytest.approx(4.0, abs=0.3)
    assert values[ramp][-1] == pytest.approx(32.7, abs=0.1)  # its yawspeed at 455.2 s
    assert max(values) < 33.6  # the 5 Hz samples miss the peak between them
    sets = [c for c in x500.commands if isinstance(c, SetParam)]
    origin = x500.start_s - x500.lead_in_s
    assert [(c.name, c.at_s + origin, c.value) for c in sets] == [
        ("MPC_YAWRAUTO_MAX", pytest.approx(t), v) for t, v in limits
    ]
    assert x500.summary()["yaw_rate_limits"] == [list(limit) for limit in limits]


@pytest.mark.closed_loop
def test_px4_holds_the_8s_quads_rest_then_spins_up_on_its_sticks(tmp_path):
    """The first 10 s of the 8S quad's log through PX4 SITL: armed in Stabilized at the log's
    start, the rotors stand while the stick sits at the bottom (105-108.9 s: the log's rest,
    motors at 0), and turn from the pilot's spin-up on (the log's motors 0.2-0.3 at 112-114 s)."""
    build = find_px4()
    if build is None:
        pytest.skip(f"no PX4 SITL build: set {PX4_DIR_ENV} (CI points it at ../shared/px4_sitl)")
    options = ReplayOptions(autopilot="px4", vehicle="quad4001_8s", end_s=114.5, seed=3)
    timeouts = LinkTimeouts(connect_s=60, answer_s=30)
    result = run_replay(plan_replay(QUAD4001, options),
                        RunOptions(instance=free_test_instance(), out_dir=tmp_path,
                                   timeouts=timeouts))  # fmt: skip
    px4 = pyulog.ULog(str(result.autopilot_log), ["vehicle_status", "actuator_motors"])
    status = px4.get_dataset("vehicle_status").data
    armed = status["arming_state"] == 2
    assert status["timestamp"][armed][0] / 1e6 == pytest.approx(QUAD_START_S, abs=0.1)
    assert set(status["nav_state"][armed]) == {STABILIZED}
    truth = pyulog.ULog(str(result.rig_log), ["rig_propulsion_groundtruth"])
    rotors = truth.get_dataset("rig_propulsion_groundtruth").data
    time_s = rotors["timestamp"] / 1e6
    speed = np.column_stack([rotors[f"rotor_speed_radps[{k}]"] for k in range(4)])
    assert np.all(speed[(time_s > 105.0) & (time_s < 108.9)] == 0.0)
    assert np.all(speed[(time_s > 112.0) & (time_s < 114.0)] > 100.0)
