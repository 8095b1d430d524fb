"""The autopilot as a separate process: PX4 SITL's links around the flight controller.

It connects to the rig on TCP 127.0.0.1:4560+i (retrying until accepted, like PX4's
``simulator_mavlink``), sends a HEARTBEAT and asks for HIL_STATE_QUATERNION, then answers
each HIL_SENSOR with ``id = 0`` with exactly one HIL_ACTUATOR_CONTROLS stamped with the same
``time_usec``. Ground-station messages are handled as soon as they arrive, between sensor
frames, in one ``select`` loop, so a command acknowledged before the next frame acts at a
known frame.
"""

from __future__ import annotations

import math
import os
import select
import signal
import socket
import sys
import time
from pathlib import Path
from types import FrameType, TracebackType

import numpy as np

from rig.autopilots.reference.flight_controller import FlightController
from rig.autopilots.reference.flight_log import open_flight_log
from rig.autopilots.reference.gcs import GroundStation, MavlinkLink
from rig.autopilots.reference.params import Parameters
from rig.autopilots.reference.sensors import (
    FlowReading,
    GpsFix,
    GroundTruth,
    RangeReading,
    SensorFrame,
)
from rig.mavlink.px4_api import (
    ACCEL_FIELDS,
    BARO_FIELDS,
    CUSTOM_MODE_ENABLED,
    DEFAULT_HOME_ALT_AMSL_M,
    DEFAULT_HOME_LAT_DEG,
    DEFAULT_HOME_LON_DEG,
    GYRO_FIELDS,
    LOCKSTEP_FLAG,
    MAG_FIELDS,
    SAFETY_ARMED,
    Ports,
    mavlink,
)
from rig.mavlink.sim_messages import autopilot_messages_from_read, frame_bytes

#: PX4 asks the simulator for ground truth every 5000 µs
#: (``SimulatorMavlink::request_hil_state_quaternion``).
GROUND_TRUTH_INTERVAL_US = 5000
#: Wall-clock pause between connection attempts (PX4 retries about every 0.5 ms; a little
#: slower here costs nothing and spares the CPU).
CONNECT_RETRY_S = 0.01
#: ``HIL_ACTUATOR_CONTROLS.controls``: PX4's 16 outputs, the motors first.
_ACTUATOR_OUTPUTS = 16
_ACTUATOR = mavlink.MAVLink_hil_actuator_controls_message
#: With the simulator quiet this long (wall time), heartbeats keep ground stations informed.
IDLE_HEARTBEAT_S = 1.0
#: In lockstep the autopilot's clock stands still while the simulator sends nothing, as
#: PX4's does; after this long (wall time) it says so once, naming the simulator as the
#: side that stopped, and goes on waiting (a rig paused in a debugger resumes).
SIM_SILENCE_NOTE_S = 5.0
#: While the simulator sends frames less than this apart (wall time), the autopilot polls
#: for the next one this long instead of sleeping in ``select``. On a virtual machine a
#: process asleep in ``select`` takes 50–150 µs to wake, and the simulator's send pays for
#: the wake-up. At IMU 1 kHz on a 2-core VM, in a spell of slow wake-ups, the RTL loop with
#: this autopilot ran 0.65× real time sleeping and 1.2× polling (at other times the two
#: were within the runs' spread). The cost is a core while frames come back to back; a
#: paced run at a lower rate, or a stopped simulator, gets the sleep. Polling yields the
#: CPU between polls: two TLM runs side by side on 2 CPUs flew 2.0× each polling without
#: yielding, 2.7–3.6× yielding and 3.0–3.8× sleeping.
FRAME_POLL_S = 0.002


def sensor_frame(
    message: mavlink.MAVLink_message,
    gps: GpsFix | None,
    ranged: RangeReading | None = None,
    flow: FlowReading | None = None,
) -> SensorFrame:
    """HIL_SENSOR (SI units after PX4's conversions: hPa → Pa) → :class:`SensorFrame`."""
    fields = message.fields_updated

    def has(group: int) -> bool:
        return fields & group == group

    pressure = message.abs_pressure * 100.0 if has(BARO_FIELDS) else None
    return SensorFrame(
        accel_mps2=np.array([message.xacc, message.yacc, message.zacc])
        if has(ACCEL_FIELDS) else None,
        gyro_radps=np.array([message.xgyro, message.ygyro, message.zgyro])
        if has(GYRO_FIELDS) else None,
        mag_gauss=np.array([message.xmag, message.ymag, message.zmag])
        if has(MAG_FIELDS) else None,
        baro_pressure_pa=pressure,
        baro_temperature_degc=message.temperature if pressure is not None else None,
        gps=gps,
        range=ranged,
        flow=flow,
    )  # fmt: skip


def range_reading(message: mavlink.MAVLink_message) -> RangeReading:
    """DISTANCE_SENSOR (cm; quality 0 unknown, else 1..100) as PX4's
    ``publish_distance_topic`` turns it into ``distance_sensor``."""
    quality = -1 if message.signal_quality == 0 else 100 * (message.signal_quality - 1) // 99
    return RangeReading(
        distance_m=message.current_distance * 0.01,
        signal_quality=quality,
        min_m=message.min_distance * 0.01,
        max_m=message.max_distance * 0.01,
    )


def flow_reading(message: mavlink.MAVLink_message, time_us: int) -> FlowReading:
    """HIL_OPTICAL_FLOW as PX4's ``simulator_mavlink`` turns it into ``sensor_optical_flow``:
    integrated x/y as ``pixel_flow`` (rad), the window and the quality as they are, stamped
    ``time_us``, the autopilot's clock at arrival (in lockstep the last HIL_SENSOR's time).

    Its integrated gyro and distance are left out: the rig's chip has neither (NaN, -1), so
    PX4 integrates its own gyro over the window and takes the height from DISTANCE_SENSOR.
    """
    return FlowReading(
        time_us=time_us,
        pixel_flow_rad=(message.integrated_x, message.integrated_y),
        integration_timespan_us=message.integration_time_us,
        quality=message.quality,
    )


def gps_fix(message: mavlink.MAVLink_message) -> GpsFix:
    """HIL_GPS (degE7, mm, cm/s, eph/epv in cm as PX4 reads them) → :class:`GpsFix`."""
    return GpsFix(
        lat_deg=message.lat * 1e-7,
        lon_deg=message.lon * 1e-7,
        alt_amsl_m=message.alt * 1e-3,
        velocity_ned_mps=(message.vn * 0.01, message.ve * 0.01, message.vd * 0.01),
        eph_m=message.eph * 0.01,
        epv_m=message.epv * 0.01,
        fix_type=message.fix_type,
        satellites_used=message.satellites_visible,
    )


def ground_truth(message: mavlink.MAVLink_message) -> GroundTruth:
    """HIL_STATE_QUATERNION → :class:`GroundTruth` (for the estimator-error log only)."""
    return GroundTruth(
        q=np.array(message.attitude_quaternion, dtype=float),
        lat_deg=message.lat * 1e-7,
        lon_deg=message.lon * 1e-7,
        alt_amsl_m=message.alt * 1e-3,
        velocity_ned_mps=np.array([message.vx, message.vy, message.vz]) * 0.01,
    )


def warm_up() -> None:
    """Compile the flight controller's numba kernels before talking to the simulator.

    PX4 boots before it connects; a cold numba cache costs seconds of compiling, which the
    rig would spend freewheeling frames unanswered, or (paced) behind the wall clock. A
    throwaway controller flies frames of a vehicle at rest: disarmed, then armed and told
    to take off, so every compiled path runs once.
    """
    params = Parameters()
    params.set("COM_SPOOLUP_TIME", 0.0)  # straight to the climb: the control paths run at once
    controller = FlightController(params)
    at_home = GpsFix(
        DEFAULT_HOME_LAT_DEG, DEFAULT_HOME_LON_DEG, DEFAULT_HOME_ALT_AMSL_M, (0.0, 0.0, 0.0),
        eph_m=0.5, epv_m=0.8, fix_type=3, satellites_used=10,
    )  # fmt: skip
    frame = SensorFrame(
        accel_mps2=np.array([0.0, 0.0, -9.81]), gyro_radps=np.zeros(3),
        mag_gauss=np.array([0.21, 0.01, 0.43]), baro_pressure_pa=95_460.0,
        baro_temperature_degc=15.0, gps=at_home,
    )  # fmt: skip
    for k in range(1, 60):
        if k == 30:
            controller.arm(force=True)
            controller.takeoff(math.nan)
        controller.update(frame, k * 4000)


def wait_readable(socks: list[socket.socket], poll_s: float, timeout_s: float
                  ) -> list[socket.socket]:  # fmt: skip
    """The sockets with something to read: polled for ``poll_s``, then waited for in
    ``select`` up to ``timeout_s`` (an empty list if nothing came).

    Between polls the process yields its CPU to any other that is ready to run: with more
    processes than CPUs (a campaign's parallel runs), the rig it waits for runs instead.
    """
    deadline = time.monotonic() + poll_s
    while time.monotonic() < deadline:
        readable, _, _ = select.select(socks, [], [], 0)
        if readable:
            return readable
        os.sched_yield()
    readable, _, _ = select.select(socks, [], [], timeout_s)
    return readable


class StopRequest:
    """SIGINT, the rig's way to stop its autopilot, taken between frames.

    The handler only notes the signal; Python's wake-up fd makes the serving loop's
    ``select`` return at once, and the loop stops at the top of its next turn. A
    KeyboardInterrupt could instead land inside the last frame's ``write_log`` (the rig
    sends SIGINT as soon as it has that frame's answer), and two runs of one seed would
    then differ in their last log rows.
    """

    def __init__(self) -> None:
        self.requested = False
        self.wake, self._wake_write = socket.socketpair()
        for end in (self.wake, self._wake_write):
            end.setblocking(False)

    def __enter__(self) -> StopRequest:
        self._previous_fd = signal.set_wakeup_fd(self._wake_write.fileno(),
                                                 warn_on_full_buffer=False)  # fmt: skip
        self._previous_handler = signal.signal(signal.SIGINT, self._note)
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:  # fmt: skip
        signal.signal(signal.SIGINT, self._previous_handler)
        signal.set_wakeup_fd(self._previous_fd)
        self.wake.close()
        self._wake_write.close()

    def _note(self, signum: int, frame: FrameType | None) -> None:
        self.requested = True


class Autopilot:
    """The process: the flight controller, the simulator link and the ground-station links."""

    def __init__(self, instance: int, params: Parameters, log_path: Path | None) -> None:
        self.ports = Ports(instance)
        params.set("MAV_SYS_ID", self.ports.system_id)
        self.log = open_flight_log(log_path, params.as_dict()) if log_path else None
        self.fc = FlightController(params, self.log)
        sysid = self.ports.system_id
        self.links = [
            MavlinkLink("gcs", self.ports.gcs_local_udp, self.ports.gcs_remote_udp, sysid),
            MavlinkLink("api", self.ports.api_local_udp, self.ports.api_remote_udp, sysid),
            MavlinkLink(
                "onboard", self.ports.onboard_local_udp, self.ports.onboard_remote_udp, sysid
            ),
        ]
        self.ground = GroundStation(self.fc, self.links)
        self.sim_mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=1)
        self.sim_mav.robust_parsing = True
        self.sim: socket.socket | None = None
        self.sim_malformed = 0
        self._gps: GpsFix | None = None
        self._range: RangeReading | None = None
        self._flow: FlowReading | None = None
        self._last_frame_wall_s = time.monotonic()
        self._frame_gap_s = math.inf  # wall time between the last two sensor frames
        self._silence_noted = False

    def connect(self) -> socket.socket:
        """Connect to the rig, retrying until it accepts; heartbeats meanwhile. Returns the
        connection (also ``sim``)."""
        last_heartbeat = 0.0
        while True:
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            try:
                sock.connect(("127.0.0.1", self.ports.simulator_tcp))
                break
            except OSError:
                sock.close()
            if time.monotonic() - last_heartbeat > IDLE_HEARTBEAT_S:
                last_heartbeat = time.monotonic()
                self.ground.heartbeat()
            time.sleep(CONNECT_RETRY_S)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sim = sock
        mav = self.sim_mav
        self._send_sim(mavlink.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0, 3))  # fmt: skip
        self._send_sim(mav.command_long_encode(
            0, 0, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
            mavlink.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, GROUND_TRUTH_INTERVAL_US, 0, 0, 0, 0, 0,
        ))  # fmt: skip
        return sock

    def run(self) -> str | None:
        """Serve until the simulator closes the link (returns why) or SIGINT comes (returns
        None once the frame in hand is answered and logged)."""
        warm_up()
        sim = self.connect()
        self._last_frame_wall_s = time.monotonic()
        with StopRequest() as stop:
            return self._serve(sim, stop)

    def _serve(self, sim: socket.socket, stop: StopRequest) -> str | None:
        socks = [sim, stop.wake, *(link.sock for link in self.links)]
        while not stop.requested:
            poll_s = FRAME_POLL_S if self._frame_gap_s < FRAME_POLL_S else 0.0
            readable = wait_readable(socks, poll_s, IDLE_HEARTBEAT_S)
            if stop.wake in readable:
                stop.wake.recv(64)  # the signal numbers Python wrote: the flag says enough
            if not readable:
                self.ground.heartbeat()
            if sim not in readable:
                self._note_silence()
            for link in self.links:
                if link.sock in readable:
                    for message, sender in link.receive():
                        self.ground.handle(link, message, sender)
            self.ground.retry_uploads()
            if sim in readable:
                data = sim.recv(65536)
                if not data:
                    return f"the simulator closed the link at t={self.fc.time_us / 1e6:.3f} s"
                fast = autopilot_messages_from_read(data) if self.sim_mav.buf_len() == 0 else None
                messages = fast if fast is not None else self.sim_mav.parse_buffer(data) or []
                for message in messages:
                    self._handle_sim(message)
        return None

    def close(self) -> None:
        if self.sim is not None:
            self.sim.close()
        for link in self.links:
            link.close()
        if self.log is not None:
            self.log.close()

    def _note_silence(self) -> None:
        silent_s = time.monotonic() - self._last_frame_wall_s
        if silent_s >= SIM_SILENCE_NOTE_S and not self._silence_noted:
            self._silence_noted = True
            print(f"rig.autopilots.reference: the simulator sent no sensor frame for "
                  f"{SIM_SILENCE_NOTE_S:g} s of wall time; the clock stands at "
                  f"t={self.fc.time_us / 1e6:.3f} s (lockstep), waiting",
                  file=sys.stderr, flush=True)  # fmt: skip

    def _handle_sim(self, message: mavlink.MAVLink_message) -> None:
        kind = message.get_type()
        if kind == "HIL_SENSOR":
            if message.id != 0:
                return  # only IMU 0 drives the lockstep clock, as in PX4
            now = time.monotonic()
            self._frame_gap_s = now - self._last_frame_wall_s
            self._last_frame_wall_s = now
            self._silence_noted = False
            frame = sensor_frame(message, self._gps, self._range, self._flow)
            self._gps = self._range = self._flow = None
            controls = self.fc.step(frame, message.time_usec)
            mode = CUSTOM_MODE_ENABLED | (SAFETY_ARMED if controls.armed else 0)
            outputs = [*controls.motors, *[0.0] * (_ACTUATOR_OUTPUTS - len(controls.motors))]
            assert self.sim is not None, "run() connects before any message arrives"
            self.sim.sendall(frame_bytes(self.sim_mav, _ACTUATOR, (  # wire order
                message.time_usec, LOCKSTEP_FLAG, *outputs, mode)))  # fmt: skip
            # Logged once the simulator has its answer: in lockstep it waits for nothing else.
            self.fc.write_log(message.time_usec)
            self.ground.stream(message.time_usec)
        elif kind == "HIL_GPS":
            self._gps = gps_fix(message)
        elif kind == "DISTANCE_SENSOR":
            self._range = range_reading(message)
        elif kind == "HIL_OPTICAL_FLOW":
            self._flow = flow_reading(message, self.fc.time_us)
        elif kind == "HIL_STATE_QUATERNION":
            self.fc.observe_truth(ground_truth(message))
        elif kind == "BAD_DATA":
            self.sim_malformed += 1

    def _send_sim(self, message: mavlink.MAVLink_message) -> None:
        assert self.sim is not None, "run() connects before any message arrives"
        self.sim.sendall(message.pack(self.sim_mav))
