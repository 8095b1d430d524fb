"""The scenario ground station against a scripted autopilot on the API link (real UDP).

The peer binds 14580+i as PX4 SITL does and answers as PX4's mavlink module does; every
message the rig sends is parsed by pymavlink (CRC from the definitions) and checked.
"""

import math
import socket
import threading
import time

import pytest

from quad_model.environment import PX4_DEFAULT_HOME, GeoPoint
from quad_model.frames import euler_from_quat, geodetic_to_ned
from rig.errors import GroundLinkError
from rig.mavlink.ground_link import PX4_MAIN_MODE_OFFBOARD, GroundLink, sweep_pitch_rad
from rig.mavlink.px4_api import Ports, mavlink
from tests.instances import worker_instances


class ScriptedAutopilot(threading.Thread):
    """Answers COMMAND_LONG, the mission protocol and PARAM_SET like PX4; records all. Its
    onboard link announces itself with a HEARTBEAT as it starts, as PX4's does (unless
    ``heartbeat`` is False: a link not started yet)."""

    def __init__(self, ports, refuse=(), statustext="", announce_late=False, heartbeat=True):
        super().__init__(daemon=True)
        self.ports = ports
        self.heartbeat = heartbeat
        self.announce_late = announce_late  # PX4's second PARAM_VALUE of a change, late
        self.announced = {}
        self.refuse = set(refuse)
        self.statustext = statustext
        self.received = []
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind(("127.0.0.1", ports.onboard_local_udp))
        except OSError:
            self.sock.close()
            raise
        self.sock.settimeout(0.2)
        self.stopped = threading.Event()
        self.mav = mavlink.MAVLink(None, ports.system_id, 1)
        self.mission_count = 0

    def reply(self, *messages, to):
        for message in messages:
            self.sock.sendto(message.pack(self.mav), to)

    def beat(self):
        """PX4's HEARTBEAT, to the port its onboard link sends to (the rig's)."""
        beat = self.mav.heartbeat_encode(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4,
            mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0, 0,
        )  # fmt: skip
        self.reply(beat, to=("127.0.0.1", self.ports.onboard_remote_udp))

    def run(self):
        parser = mavlink.MAVLink(None, 0, 0)
        if self.heartbeat:
            self.beat()
        while not self.stopped.is_set():
            try:
                data, sender = self.sock.recvfrom(65536)
            except TimeoutError:
                continue
            for m in parser.parse_buffer(data) or ():
                self.received.append(m)
                self.handle(m, sender)

    def handle(self, m, sender):
        kind = m.get_type()
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            refused = m.command in self.refuse
            if refused and self.statustext:
                self.reply(self.mav.statustext_encode(3, self.statustext.encode()), to=sender)
            result = mavlink.MAV_RESULT_DENIED if refused else mavlink.MAV_RESULT_ACCEPTED
            self.reply(self.mav.command_ack_encode(m.command, result), to=sender)
        elif kind == "MISSION_COUNT":
            self.mission_count = m.count
            self.reply(self.mav.mission_request_int_encode(245, 190, 0), to=sender)
        elif kind == "MISSION_ITEM_INT":
            if m.seq + 1 < self.mission_count:
                self.reply(self.mav.mission_request_int_encode(245, 190, m.seq + 1), to=sender)
            else:
                accepted = mavlink.MAV_MISSION_ACCEPTED
                self.reply(self.mav.mission_ack_encode(245, 190, accepted), to=sender)
        elif kind == "PARAM_SET":
            value = min(m.param_value, 10.0)  # a parameter with a maximum, as PX4 clamps
            if self.announce_late and m.param_id in self.announced:
                earlier = self.announced[m.param_id]
                announcement = self.mav.param_value_encode(
                    m.param_id.encode(), earlier, m.param_type, 100, 1
                )
                self.reply(announcement, to=sender)
            self.announced[m.param_id] = value
            self.reply(
                self.mav.param_value_encode(m.param_id.encode(), value, m.param_type, 100, 1),
                to=sender,
            )


@pytest.fixture
def pair():
    made = []

    def make(**peer_kw):
        for instance in worker_instances(60, 40):
            ports = Ports(instance)
            try:
                peer = ScriptedAutopilot(ports, **peer_kw)
            except OSError:
                continue
            try:
                link = GroundLink(ports, PX4_DEFAULT_HOME, ack_timeout_s=2.0)
            except GroundLinkError:
                peer.sock.close()
                continue
            peer.start()
            made.append((link, peer))
            return link, peer
        raise RuntimeError("no free API-link ports")

    yield make
    for link, peer in made:
        link.close()
        peer.stopped.set()
        peer.join()
        peer.sock.close()


def test_arm_sends_px4_arm_command_and_returns_on_ack(pair):
    link, peer = pair()
    assert link.converse_now("arm", link.arm()) == "arm: accepted"
    (command,) = peer.received
    assert command.get_type() == "COMMAND_LONG"
    assert command.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM
    assert command.param1 == 1.0
    assert (command.target_system, command.target_component) == (link.ports.system_id, 1)
    assert link.mav.srcSystem == 245


def test_takeoff_sets_mis_takeoff_alt_then_takes_off_to_it(pair):
    link, peer = pair()
    assert link.converse_now("takeoff", link.takeoff(5.0)) == "takeoff to 5 m: accepted"
    param, command = peer.received
    assert param.get_type() == "PARAM_SET"
    assert (param.param_id, param.param_value) == ("MIS_TAKEOFF_ALT", 5.0)
    assert command.command == mavlink.MAV_CMD_NAV_TAKEOFF
    assert math.isnan(command.param7)  # NaN: MIS_TAKEOFF_ALT above the autopilot's home
    assert math.isnan(command.param5)
    assert math.isnan(command.param6)  # NaN lat/lon: take off where you are


def test_refusal_quotes_the_autopilot_reason(pair):
    link, _ = pair(
        refuse={mavlink.MAV_CMD_COMPONENT_ARM_DISARM}, statustext="Arming denied: no GPS"
    )
    with pytest.raises(GroundLinkError) as error:
        link.converse_now("arm", link.arm())
    assert str(error.value) == (
        "the autopilot refused arm: MAV_RESULT_DENIED (2) (Arming denied: no GPS)"
    )


def test_missing_ack_is_a_bounded_wait_with_a_clear_error():
    for instance in worker_instances(60, 40):
        try:
            link = GroundLink(Ports(instance), PX4_DEFAULT_HOME, ack_timeout_s=0.2)
            break
        except GroundLinkError:
            continue
    try:
        with pytest.raises(
            GroundLinkError,
            match=r"^land: no COMMAND_ACK for MAV_CMD_NAV_LAND"
            r" \(21\) from the autopilot on UDP \d+ within 0\.2 s of wall time",
        ):
            link.converse_now("land", link.land())
    finally:
        link.close()


def test_offboard_setpoint_travels_before_the_mode_switch(pair):
    link, peer = pair()
    setpoint = link.position_setpoint((5.0, -1.0, -5.0), None, 12.5)
    link.converse_now("goto", link.offboard([setpoint], "goto"))
    first, second = peer.received
    assert first.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
    assert (first.x, first.y, first.z) == (5.0, -1.0, -5.0)
    assert first.coordinate_frame == mavlink.MAV_FRAME_LOCAL_NED
    assert first.time_boot_ms == 12500
    ignored = first.type_mask
    assert ignored & mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE == 0  # position used
    assert ignored & mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE  # velocity ignored
    assert ignored & mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE  # no yaw given
    assert second.command == mavlink.MAV_CMD_DO_SET_MODE
    assert (second.param1, second.param2) == (1.0, PX4_MAIN_MODE_OFFBOARD)


def test_attitude_setpoint_carries_the_pitch_as_a_quaternion():
    for instance in worker_instances(60, 40):
        try:
            link = GroundLink(Ports(instance), PX4_DEFAULT_HOME)
            break
        except GroundLinkError:
            continue
    message = link.attitude_setpoint(0.0, math.radians(5.0), 0.0, 0.3, 2.0)
    link.close()
    (parsed,) = mavlink.MAVLink(None, 1, 1).parse_buffer(message.pack(link.mav))
    assert euler_from_quat(parsed.q) == pytest.approx([0.0, math.radians(5.0), 0.0], abs=1e-7)
    assert parsed.thrust == pytest.approx(0.3)
    assert parsed.type_mask == 0b111  # body rates ignored, attitude and thrust used


def test_mission_upload_protocol_and_start(pair):
    link, peer = pair()
    waypoints = [(0, 0, -5), (10, 0, -5), (10, 10, -6)]
    result = link.converse_now("mission", link.mission(waypoints))
    assert result == "mission of 3 waypoints: accepted"
    kinds = [m.get_type() for m in peer.received]
    assert kinds == ["MISSION_COUNT", *["MISSION_ITEM_INT"] * 3, "COMMAND_LONG"]
    items = peer.received[1:4]
    for seq, (item, (north, east, down)) in enumerate(zip(items, waypoints, strict=True)):
        assert item.seq == seq
        assert item.frame == mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
        assert item.command == mavlink.MAV_CMD_NAV_WAYPOINT
        assert item.z == -down  # relative altitude, m
        back = geodetic_to_ned(item.x / 1e7, item.y / 1e7, 488.0, 47.397742, 8.545594, 488.0)
        assert back[:2] == pytest.approx([north, east], abs=0.02)  # degE7 ≈ 1.1 cm
    assert peer.received[-1].command == mavlink.MAV_CMD_MISSION_START


def test_param_set_checks_the_echoed_value(pair):
    link, _ = pair()
    assert link.converse_now("set_param", link.set_param("MPC_XY_VEL_MAX", 8.0)) == (
        "MPC_XY_VEL_MAX = 8"
    )
    with pytest.raises(GroundLinkError, match=r"kept MPC_XY_VEL_MAX = 10 instead of 12"):
        link.converse_now("set_param", link.set_param("MPC_XY_VEL_MAX", 12.0))


def test_param_set_passes_over_the_late_announcement_of_an_earlier_value(pair):
    """PX4 announces a changed parameter once more after its answer: a replay setting
    MPC_YAWRAUTO_MAX every 0.2 s read 29.9 while it set 26 and stopped the run."""
    link, _ = pair(announce_late=True)
    for value in (9.9, 2.6, 9.9):
        result = link.converse_now("set_param", link.set_param("MPC_YAWRAUTO_MAX", value))
        assert result == f"MPC_YAWRAUTO_MAX = {value:g}"
    with pytest.raises(GroundLinkError, match=r"kept MPC_YAWRAUTO_MAX = 10 instead of 12"):
        link.converse_now("set_param", link.set_param("MPC_YAWRAUTO_MAX", 12.0))


def test_set_home_sends_the_position_in_whole_dege7(pair):
    """DO_SET_HOME as a COMMAND_INT (MAV_FRAME_GLOBAL: AMSL altitude): a float32 param of a
    COMMAND_LONG holds 51.9° only to 4e-6° (0.4 m)."""
    link, peer = pair()
    home = GeoPoint(51.90101147, -85.70567538, 185.8384)
    assert link.converse_now("home", link.set_home(home)) == "home at 185.84 m AMSL: accepted"
    (command,) = peer.received
    assert command.get_type() == "COMMAND_INT"
    assert command.command == mavlink.MAV_CMD_DO_SET_HOME
    assert command.frame == mavlink.MAV_FRAME_GLOBAL
    assert command.param1 == 0.0  # the position given, not the vehicle's
    assert (command.x, command.y) == (519010115, -857056754)
    assert command.z == pytest.approx(185.8384, abs=1e-4)


def test_motor_test_uses_one_based_motor_and_percent(pair):
    link, peer = pair()
    link.converse_now("motor_test", link.motor_test(0, 0.5, 10.0))
    (command,) = peer.received
    assert command.command == mavlink.MAV_CMD_DO_MOTOR_TEST
    assert (command.param1, command.param2, command.param3, command.param4) == (
        1.0, mavlink.MOTOR_TEST_THROTTLE_PERCENT, 50.0, 10.0,
    )  # fmt: skip


def test_polling_driver_completes_when_the_ack_arrives(pair):
    link, _ = pair()
    link.start("arm", link.arm(), 1.0)
    result, deadline = None, time.monotonic() + 5.0  # a loaded machine may delay the peer
    while result is None and time.monotonic() < deadline:
        result = link.poll(1.0)
    assert result == "arm: accepted"
    assert not link.busy


def test_polling_driver_holds_its_first_message_until_the_autopilot_is_heard(pair):
    """PX4's onboard link starts from its start-up script while its lockstep clock runs: a
    MISSION_COUNT sent before it listens is lost, so the first message waits for PX4's
    HEARTBEAT, and then goes out."""
    link, peer = pair(heartbeat=False)
    assert link.start("arm", link.arm(), 1.0).startswith("held until the autopilot's first")
    for time_s in (1.1, 1.2, 20.0):  # a late start is no answer timeout
        assert link.poll(time_s) is None
    time.sleep(0.2)
    assert peer.received == []
    assert link.busy
    peer.beat()
    result, deadline = None, time.monotonic() + 5.0
    while result is None and time.monotonic() < deadline:
        result = link.poll(20.5)
    assert result == "arm: accepted"
    assert [m.get_type() for m in peer.received] == ["COMMAND_LONG"]


def test_an_autopilot_never_heard_is_named_in_one_line(pair):
    link, _ = pair(heartbeat=False)
    link.start("upload_mission", link.upload_mission([]), 1.0)
    assert link.poll(30.0) is None
    with pytest.raises(GroundLinkError, match=r"^upload_mission: no HEARTBEAT from the autopilot "
                       r"on UDP \d+ within 30 s of simulated time"):  # fmt: skip
        link.poll(31.5)


def test_log_chirp_frequency_runs_from_f_min_to_f_max():
    duration, f0, f1 = 60.0, 0.25, 40.0

    # The instantaneous frequency is the phase derivative: check it numerically at both ends.
    def phase_rate(t, h=1e-4):
        a = math.asin(sweep_pitch_rad(t, duration, 1.0, f0, f1))
        b = math.asin(sweep_pitch_rad(t + h, duration, 1.0, f0, f1))
        return abs(b - a) / h

    assert phase_rate(0.0) == pytest.approx(f0, rel=1e-3)
    assert sweep_pitch_rad(-1.0, duration, 1.0, f0, f1) == 0.0
    assert sweep_pitch_rad(61.0, duration, 1.0, f0, f1) == 0.0
    # Zero crossings are π/ω apart; near the end ω(t) = f0·(f1/f0)^(t/T) → 40 rad/s.
    times = [duration - 0.5 + k * 1e-5 for k in range(50000)]
    values = [sweep_pitch_rad(t, duration, 1.0, f0, f1) for t in times]
    crossings = [t for t, a, b in zip(times, values, values[1:], strict=False) if a * b < 0]
    spacing = (crossings[-1] - crossings[-3]) / 2
    omega_expected = f0 * (f1 / f0) ** (crossings[-2] / duration)
    assert math.pi / spacing == pytest.approx(omega_expected, rel=1e-3)
    assert omega_expected == pytest.approx(f1, rel=0.02)  # the last crossing, just before T


def test_a_tolerated_refusal_is_the_result_not_an_error(pair):
    """A replay's disarm follows the real flight's; a simulated vehicle still in the air is
    refused, and the run goes on with the refusal in its log."""
    link, _ = pair(
        refuse={mavlink.MAV_CMD_COMPONENT_ARM_DISARM}, statustext="Disarming denied: not landed"
    )
    assert link.converse_now("disarm", link.attempt(link.arm(False))) == (
        "the autopilot refused disarm: MAV_RESULT_DENIED (2) (Disarming denied: not landed); "
        "the run goes on"
    )


def test_velocity_rates_and_quaternion_setpoints_say_what_they_control():
    """PX4's type_mask semantics (MAVLink common.xml POSITION_TARGET_TYPEMASK,
    ATTITUDE_TARGET_TYPEMASK), checked after a round trip through pymavlink."""
    for instance in worker_instances(60, 40):
        try:
            link = GroundLink(Ports(instance), PX4_DEFAULT_HOME)
            break
        except GroundLinkError:
            continue
    parser = mavlink.MAVLink(None, 1, 1)
    messages = [
        link.velocity_setpoint((1.0, -2.0, -1.5), 1.7, 413.25),
        link.velocity_setpoint((1.0, -2.0, -1.5), None, 413.25),
        link.rates_setpoint((0.1, -0.2, 0.3), 0.55, 415.02),
        link.quaternion_setpoint((0.9, 0.1, 0.2, 0.3), 0.6, 415.02),
    ]
    link.close()
    velocity, no_yaw, rates, attitude = (parser.parse_buffer(m.pack(link.mav))[0] for m in messages)
    assert (velocity.vx, velocity.vy, velocity.vz) == (1.0, -2.0, -1.5)
    assert velocity.yaw == pytest.approx(1.7)
    assert velocity.time_boot_ms == 413250
    position_ignored = (mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE
                        | mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE
                        | mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE)  # fmt: skip
    assert velocity.type_mask & position_ignored == position_ignored
    assert velocity.type_mask & (mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE
                                 | mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE) == 0  # fmt: skip
    assert no_yaw.type_mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
    assert rates.type_mask == mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE  # rates used
    assert (rates.body_roll_rate, rates.body_pitch_rate, rates.body_yaw_rate) == pytest.approx(
        (0.1, -0.2, 0.3)
    )
    assert rates.thrust == pytest.approx(0.55)
    assert rates.time_boot_ms == 415020
    assert attitude.type_mask == 0b111  # body rates ignored, attitude and thrust used
    assert attitude.q == pytest.approx([0.9, 0.1, 0.2, 0.3])
