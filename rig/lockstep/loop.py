"""The closed loop: model → sensor chips → autopilot → PWM → model, in lockstep, logged.

One frame is one IMU period (1 ms by default):

1. the model advances one frame holding the motor throttles the PWM capture measured;
2. sensor physics samples the truth (IMU every frame, mag/baro/GPS on their schedules) and
   the sensor-layer faults are applied;
3. the samples are loaded into the chips and PX4's drivers read them over SPI/I2C, and a
   GPS epoch's solution goes into the u-blox receiver, whose NAV-PVT PX4's driver decodes
   from its UART once the last byte is in (``sensor_layer``: Python register models, or
   the RTL as Verilator-compiled code);
4. due scenario commands go to the autopilot on its onboard link (acknowledged first with the
   reference autopilot, so each acts at a known frame);
5. HIL_SENSOR (+ HIL_GPS, + HIL_STATE_QUATERNION at the asked interval) goes out and, once
   lockstep is established, the autopilot's HIL_ACTUATOR_CONTROLS for this very frame is
   awaited under the watchdog;
6. the controls become PWM pulses whose captured widths set the throttles of the next frame.

The next frame's throttles are the widths captured up to this frame, so steps 1–2 of the
next frame and this frame's logging do not need the autopilot's answer: the rig does them
between sending the frame and awaiting the answer, while the autopilot computes (on another
core when one is free). Lockstep is unchanged: PX4 never sees a frame before it answered
the previous one, and every number is the same as in strict order (a golden test).

Two clocks: the rig's own parts (model, chips, PWM, faults, scenario commands) count run
time from 0; everything that leaves the rig (every message to the autopilot, every log
timestamp) is stamped on the autopilot's boot clock, ``Scenario.start.clock_s`` later. A
replay starts that clock at the real log's first timestamp, so both logs share one time
axis, while the RTL never simulates the hundreds of seconds before it.

Everything lands in ``rig.ulg``. Any failure (a stalled or dead autopilot, a refused
command, Ctrl-C) ends the run cleanly: the reason is logged, the log is closed readable,
and the error propagates as one line.
"""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fpga_hdl.chips.ist8310.driver import sample_from_field_gauss
from fpga_hdl.chips.lidarlite.driver import PX4_CYCLE_US, PX4_MAX_DISTANCE_M, sample_from_range
from fpga_hdl.chips.lidarlite.regs import MIN_RANGE_M
from fpga_hdl.chips.mpu6000.regs import Mpu6000Sample
from fpga_hdl.chips.ms5611.model import raw_from_si
from fpga_hdl.chips.pmw3901.driver import CameraCounts
from fpga_hdl.chips.ublox.link import receiver_solution
from quad_model import QuadModel, SensorSuite, load_vehicle
from quad_model.frames import ned_to_geodetic, yaw_quat
from quad_model.model import Mount, VehicleTruth
from quad_model.sensors import SensorReadings
from quad_model.vehicle import VehicleFileError
from rig.autopilots import Autopilot
from rig.autopilots.px4 import check_imu_rate, find_px4, sensor_parameters
from rig.chips.layer import (
    BypassSensorLayer,
    ChipFrame,
    ChipReadout,
    SensorLayer,
    TlmSensorLayer,
    gps_fix,
)
from rig.chips.pwm import Pulse, PwmOutput, throttle_from_capture
from rig.errors import AutopilotStalled, RigError, ScenarioError
from rig.lockstep.autopilots import autopilot_run
from rig.lockstep.pacing import Pacer
from rig.logs.rig_log import RigLog
from rig.mavlink.ground_link import GroundLink
from rig.mavlink.px4_api import Ports, mavlink
from rig.mavlink.sim_messages import (
    distance_sensor,
    hil_gps,
    hil_optical_flow,
    hil_sensor_frame,
    hil_state_quaternion_frame,
)
from rig.mavlink.simulator_link import LinkStats, LinkTimeouts, SimulatorLink
from rig.scenarios.faults import FaultInjector, check_motors, describe
from rig.scenarios.scenario import Rates, Scenario
from rig.scenarios.script import Action, CommandScript

if TYPE_CHECKING:  # the compiled harness's module: imported when the rtl layer starts
    from fpga_hdl.cosim.native import CallCost

#: ``RunOptions.sensor_layer`` that skips the chips (benchmarks only, not a scenario's).
BYPASS = "bypass"
#: Where runs land unless ``--out`` says otherwise (ignored by git).
RUNS_DIR = Path("runs")
#: The rangefinder physics is sampled once per cycle of PX4's LIDAR-Lite driver (20 Hz),
#: just before it: the chip measures the scene at the cycle's acquire command.
RANGEFINDER_RATE_HZ = 1e6 / PX4_CYCLE_US
#: What PX4's driver publishes as the LIDAR-Lite v3's range (the layers' start-up checks
#: that PX4's probe takes the chip for a v1/v3).
RANGEFINDER_LIMITS_M = (MIN_RANGE_M, PX4_MAX_DISTANCE_M)
#: Ground truth is logged at this rate (PX4 SITL logs its groundtruth topics at ~100 Hz).
TRUTH_LOG_HZ = 250
#: Starts of an autopilot that stalls in its start-up (PX4's races, :func:`run_scenario`).
AUTOPILOT_STARTS = 3
_MOUNTS = {
    "free": Mount.FREE,
    "gimbal_pitch": Mount.GIMBAL_PITCH,
    "gimbal_roll": Mount.GIMBAL_ROLL,
    "thrust_stand": Mount.THRUST_STAND,
}


@dataclass(frozen=True)
class RunOptions:
    """How to run a scenario (everything the scenario file does not say)."""

    autopilot: Autopilot = Autopilot.REFERENCE
    instance: int = 0
    out_dir: Path | None = None
    sensor_layer: str | None = None  # None: the scenario's
    duration_s: float | None = None  # None: the scenario's
    timeouts: LinkTimeouts = field(default_factory=LinkTimeouts)
    #: Autopilot parameters ``NAME=VALUE`` (``--param``), for either autopilot.
    autopilot_params: tuple[str, ...] = ()
    #: PX4 SITL build (``--px4``); None: ``$PX4_DIR``, else the user starts PX4 by hand.
    px4_dir: Path | None = None
    #: Told the command to run when the rig waits for a PX4 started by hand.
    on_waiting: Callable[[str], None] | None = None
    #: Command that starts the autopilot instead of ``python -m rig.autopilots.reference`` (tests).
    autopilot_argv: tuple[str, ...] | None = None
    #: ``(level, text)`` events for the start of ``rig.ulg`` (e.g. what a replay skipped).
    notes: tuple[tuple[str, str], ...] = ()
    #: At most this many simulated seconds per wall second (inf: as fast as possible).
    speed: float = math.inf
    #: Overwrite the logs of a run already in ``out_dir`` (``--force``); else refused.
    force: bool = False

    def __post_init__(self) -> None:
        if self.autopilot not in list(Autopilot):
            raise RigError(
                f"autopilot must be one of {', '.join(Autopilot)}, not {self.autopilot!r}"
            )
        object.__setattr__(self, "autopilot", Autopilot(self.autopilot))  # a name given as text


@dataclass(frozen=True)
class Progress:
    """What a progress display (the status line, the live view) shows, once per simulated
    tenth of a second: the truth, the motors and what the autopilot reported."""

    time_s: float
    duration_s: float
    real_time_factor: float
    altitude_m: float
    armed: bool
    last_event: str
    #: Ground truth: attitude body→NED (w, x, y, z), position and velocity NED.
    attitude_quat: tuple[float, ...]
    position_ned_m: tuple[float, ...]
    velocity_ned_mps: tuple[float, ...]
    #: The IMU as the autopilot gets it (sensor models, faults, chips), FRD.
    accel_mps2: tuple[float, ...]
    gyro_radps: tuple[float, ...]
    #: Motor throttles 0..1 from the captured PWM: what the motors run at.
    motor_throttles: tuple[float, ...]
    #: The autopilot's latest HEARTBEAT ``custom_mode`` (PX4's encoding); None before one.
    custom_mode: int | None
    #: The scenario's faults acting now, as the log names them.
    active_faults: tuple[str, ...]


@dataclass(frozen=True)
class FrameBudget:
    """Mean wall time of one frame, split by part of the loop (µs per frame).

    Measured every run (a clock read per part costs well under 1 µs) so a slow run shows
    where its time went. The lockstep is sequential, so the autopilot's compute shows up
    here too: in ``autopilot_wait_us`` (blocked on its answer, beyond the work the rig
    overlaps with it) and in ``socket_send_us`` (the send wakes the autopilot, which often
    runs on the sender's core before the send returns).
    """

    model_us: float  # motor faults, the 5 kHz model over one frame, its truth
    sensor_physics_us: float  # sensor models and sensor faults
    chips_us: float  # chip words, register models + PX4's drivers (or the RTL), PWM capture
    mavlink_us: float  # HIL_* encoding and packing, parsing the autopilot's messages
    socket_send_us: float
    autopilot_wait_us: float
    logging_us: float  # rig.ulg
    other_us: float  # ground link, scenario commands, loop bookkeeping

    @property
    def total_us(self) -> float:
        return sum(getattr(self, f.name) for f in fields(self))


@dataclass(frozen=True)
class RunResult:
    run_dir: Path
    rig_log: Path
    autopilot_log: Path | None
    simulated_s: float
    wall_s: float
    frames: int
    link: LinkStats
    budget: FrameBudget
    #: The autopilot flown: ``PX4 v1.17.0 (DIR; parameters through …)``, a hand-started
    #: PX4, or the reference autopilot.
    autopilot: str = "the reference autopilot"
    #: What each kind of call into the compiled chips cost over the frames (``rtl`` only):
    #: the chips' part of the budget, by bus transaction and clock.
    chip_costs: tuple[CallCost, ...] = ()
    #: How many times the autopilot was started: more than once after a stall in its
    #: start-up (:func:`run_scenario`; ``rig.ulg`` says why).
    autopilot_starts: int = 1

    @property
    def real_time_factor(self) -> float:
        return self.simulated_s / self.wall_s if self.wall_s > 0 else math.inf


def default_run_dir(scenario: Scenario) -> Path:
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    return RUNS_DIR / f"{scenario.name}-{stamp}"


#: The autopilot's log in a run folder, by autopilot: PX4's, the reference autopilot's.
AUTOPILOT_LOGS = ("px4.ulg", "autopilot.ulg")
#: Files whose presence means a folder already holds a run.
RUN_LOGS = ("rig.ulg", "autopilot.ulg", "px4.ulg")


def claim_run_dir(run_dir: Path, force: bool) -> Path:
    """Create the run folder; one that holds a run's logs is refused unless ``force``
    (then they are overwritten), so a finished run is never lost to a reused ``--out``."""
    held = [name for name in RUN_LOGS if (run_dir / name).exists()]
    if held and not force:
        raise RigError(
            f"{run_dir}: already holds a run ({', '.join(held)}); choose another --out, "
            "or pass --force to overwrite it"
        )
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def run_scenario(
    scenario: Scenario,
    options: RunOptions = RunOptions(),
    progress: Callable[[Progress], None] | None = None,
) -> RunResult:
    """Fly ``scenario`` closed-loop; returns where the logs are, raises :class:`RigError`."""
    if options.autopilot is Autopilot.PX4:  # before anything starts: no PX4, a rate it refuses
        check_imu_rate(scenario.rates.imu_hz, find_px4(options.px4_dir))
    run_dir = claim_run_dir(options.out_dir or default_run_dir(scenario), options.force)
    for start in range(1, AUTOPILOT_STARTS + 1):
        loop = _Loop(scenario, options, run_dir, progress)
        try:
            return replace(_fly(loop), autopilot_starts=start)
        except AutopilotStalled as error:
            # PX4's lockstep start-up races now and then (a module's start waits for
            # simulated time that waits for it): a flight that has not begun is started
            # over, a stall in flight is reported.
            set_aside = None
            if start < AUTOPILOT_STARTS and not loop.scenario_began:
                set_aside = loop.autopilot.set_aside_start(start)
            if set_aside is None:
                if start == 1:
                    raise
                raise AutopilotStalled(f"{error} (start {start}: the earlier ones stalled in "
                                       "their start-up, rig.ulg says how)") from None  # fmt: skip
            note = (f"the autopilot stalled in its start-up, before the scenario sent it "
                    f"anything, and was started again (its console then: {set_aside.name}): "
                    f"{error}")  # fmt: skip
            options = replace(options, notes=(*options.notes, ("warn", note)))
    raise AssertionError("the last start returns or raises")


def _fly(loop: _Loop) -> RunResult:
    """Run the loop to its end; the error that ended it goes into its log too."""
    try:
        loop.run()
    except RigError as error:
        loop.log.event(loop.time_us, f"run ended: {error}", "err")
        raise
    except KeyboardInterrupt:
        loop.log.event(loop.time_us, "run interrupted by the user (Ctrl-C)", "warn")
        raise
    finally:
        loop.close()
    return loop.result()


def next_slot_us(due_us: int | None, now_us: int, interval_us: int) -> int:
    """The slot after a message sent at ``now_us`` (due at ``due_us``; None: the first) of a
    stream at ``interval_us``: on a grid from the first message, so an interval the frames
    do not divide keeps its rate on average (PX4's 5000 µs of ground truth at 250 Hz
    frames: four frames in five, not every second one); slots already past are skipped."""
    anchor_us = now_us if due_us is None else due_us
    return anchor_us + ((now_us - anchor_us) // interval_us + 1) * interval_us


class _Loop:
    """One run's state; :func:`run_scenario` is its only user."""

    def __init__(
        self,
        scenario: Scenario,
        options: RunOptions,
        run_dir: Path,
        progress: Callable[[Progress], None] | None,
    ) -> None:
        self.scenario = scenario
        self.options = options
        self.run_dir = run_dir
        self.progress = progress
        self.duration_s = options.duration_s or scenario.duration_s
        self.sensor_layer_name = options.sensor_layer or scenario.sensor_layer
        self.rates = scenario.rates
        self.frame_us = self.rates.frame_us
        #: The autopilot's clock at frame 0 (µs); ``time_us`` is that clock, ``run_us`` the run's.
        self.clock_start_us = round(scenario.start.clock_s * 1e6)
        self.run_us = 0
        self.time_us = self.clock_start_us
        self.frames = 0
        self.armed = False
        self.last_event = ""
        self._wall_start = time.monotonic()
        self._wall_end: float | None = None
        self._chip_costs: tuple[CallCost, ...] = ()
        self._closers: list[Callable[[], None]] = []
        #: Wall time of each part of the frames so far (s), for :class:`FrameBudget`.
        self._spent_s = dict.fromkeys(("model", "sensor physics", "chips", "messages", "logging"),
                                      0.0)  # fmt: skip

        try:
            vehicle = load_vehicle(scenario.vehicle)
        except VehicleFileError as error:
            raise ScenarioError(f"{scenario.source}: key 'vehicle': {error}") from None
        if scenario.rangefinder and vehicle.rangefinder is None:
            raise ScenarioError(f"{scenario.source}: key 'rangefinder': vehicle "
                                f"{vehicle.name!r} has no [rangefinder] table")  # fmt: skip
        if scenario.optical_flow and vehicle.optical_flow is None:
            raise ScenarioError(f"{scenario.source}: key 'optical_flow': vehicle "
                                f"{vehicle.name!r} has no [optical_flow] table")  # fmt: skip
        #: One PWM output, capture channel and HIL_ACTUATOR_CONTROLS entry per rotor.
        self.motors = motors = vehicle.propulsion.rotor_count
        check_motors(scenario.faults, motors, scenario.source, vehicle.name)
        environment = scenario.environment
        home = environment.home
        self.log = RigLog(
            run_dir / "rig.ulg",
            info={
                "sys_name": "hil-rig",
                "ver_hw": f"RIG_{self.sensor_layer_name.upper()}",
                "scenario": scenario.name,
                "scenario_source": Path(scenario.source).name,
                "vehicle": vehicle.name,
                "autopilot": options.autopilot,
            },
            parameters={
                "RIG_SEED": scenario.seed,
                "RIG_IMU_HZ": self.rates.imu_hz,
                "RIG_PWM_HZ": self.rates.pwm_hz,
                "SYS_HITL": 0,
            },
            home_lat_deg=home.lat_deg,
            home_lon_deg=home.lon_deg,
            home_alt_m=home.alt_amsl_m,
        )
        self._closers.append(self.log.close)
        for level, text in options.notes:
            self.log.event(self.time_us, text, level)

        model_rng, sensor_rng, fault_rng = np.random.default_rng(scenario.seed).spawn(3)
        assert self.rates.model_hz is not None, "Rates fills it from imu_hz"
        self.model = QuadModel(
            vehicle, model_rng, environment, _MOUNTS[scenario.constraint], self.rates.model_hz
        )
        start = scenario.start
        self.model.reset(
            position_ned_m=start.position_ned_m,
            attitude_quat=yaw_quat(math.radians(start.yaw_deg)),
            battery_voltage_v=scenario.start.battery_voltage_v,
        )
        #: The flow chip's counts of the camera's frames (the fraction carried frame to frame).
        self._camera_counts = CameraCounts()
        camera = vehicle.optical_flow
        self._camera_frame_rate_hz = 0.0 if camera is None else camera.frame_rate_hz
        self.sensors = SensorSuite(
            vehicle, environment, sensor_rng, self.rates.imu_hz, self.rates.mag_hz,
            self.rates.baro_hz, RANGEFINDER_RATE_HZ if scenario.rangefinder else None,
            optical_flow=scenario.optical_flow, gps=scenario.gps,
        )  # fmt: skip
        self.faults = FaultInjector(scenario.faults, fault_rng, self._fault_event, motors)
        self.layer = _make_sensor_layer(self.sensor_layer_name, self.rates, motors)
        self._closers.append(self.layer.close)
        self.pwm = PwmOutput(motors, self.rates.pwm_hz, scenario.motor_pwm_range_us)
        self.throttle = np.zeros(motors)
        self._capture: tuple[tuple[float, ...], tuple[bool, ...]] | None = None
        self._delivered: ChipReadout  # the latest chip readout, for the progress report
        self.ports = Ports(options.instance)
        self.autopilot = autopilot_run(
            options.autopilot,
            vehicle=vehicle,
            hover_throttle=self.model.hover_throttle(),
            imu_hz=self.rates.imu_hz,
            user_parameters=options.autopilot_params,
            sensor_parameters=sensor_parameters(
                vehicle,
                gps=scenario.gps,
                optical_flow=scenario.optical_flow,
            ),
            px4_dir=options.px4_dir,
            run_dir=run_dir,
            ports=self.ports,
            argv=options.autopilot_argv,
            event=lambda text, level: self.log.event(self.time_us, text, level),
            on_waiting=options.on_waiting,
        )

    @property
    def scenario_began(self) -> bool:
        """Whether anything of the scenario has reached the autopilot (a command, a
        set-point, a stick): before that, a run started over is the same run."""
        ground = getattr(self, "ground", None)  # None: the run stopped before its link
        return ground is not None and ground.messages_sent > 0

    # -- run ---------------------------------------------------------------------------

    def run(self) -> None:
        self.layer.start()
        link = SimulatorLink(self.ports, self.options.timeouts, motors=self.motors,
                             peer_exit=self.autopilot.exit_description)  # fmt: skip
        self._closers.append(link.close)
        self.link = link
        ground = GroundLink(self.ports, self.scenario.environment.home)
        self._closers.append(ground.close)
        self.ground = ground
        barrier = self.autopilot.barrier
        script = CommandScript(self.scenario.script(), ground, barrier=barrier,
                               clock_start_s=self.scenario.start.clock_s)  # fmt: skip
        self._closers.append(self.autopilot.close)
        self.autopilot.connect(link)
        self.log.event(self.time_us, f"autopilot connected on {link.endpoint}")
        frames_total = round(self.duration_s * 1e6) // self.frame_us
        costs_before = {cost.what: cost for cost in self.layer.costs()}
        # The first frame's model step and sensor reads come before the clock starts: on a
        # fresh clone they compile the model's numba kernels (seconds), which a paced run
        # would otherwise spend behind the wall clock.
        truth, readings = self._advance(1)
        self._sense(1, readings)
        # The start-up (imports, the autopilot's connection, the chips) leaves thousands of
        # new long-lived objects, so the collector's next full pass would fall in the first
        # seconds of the run: 70-180 ms in which no frame moves, a stall a paced run shows.
        # Collected now, the next full pass is many minutes of frames away.
        gc.collect()
        self._wall_start = time.monotonic()  # the RTF counts the frames, not the start-up
        self._spent_s = dict.fromkeys(self._spent_s, 0.0)  # and so does the budget
        pacer = Pacer(self.options.speed)
        state_next_us: int | None = None  # the next ground-truth slot, once asked for
        truth_every = max(1, self.rates.imu_hz // TRUTH_LOG_HZ)
        poll_every = max(1, self.rates.imu_hz // 100)
        settled = False
        pending: list[Action] = []
        clock = time.perf_counter
        for frame in range(1, frames_total + 1):
            started = clock()
            self.run_us = frame * self.frame_us
            self.time_us = self.clock_start_us + self.run_us
            time_s = self.run_us / 1e6
            pulses, out = self._finish()
            read = clock()
            messages = self._sensor_messages(out)
            interval_us = link.state_interval_us
            if interval_us and (state_next_us is None or self.time_us >= state_next_us):
                state_next_us = next_slot_us(state_next_us, self.time_us, interval_us)
                messages.append(self._state_message(truth))
            self._spent_s["chips"] += read - started
            self._spent_s["messages"] += clock() - read
            # Read the onboard link every 10 ms (every frame while PX4 owes an answer): its
            # telemetry would otherwise fill the socket buffer and the kernel would drop
            # the next COMMAND_ACK.
            if ground.busy or frame % poll_every == 0:
                result = ground.poll(time_s)
                if result is not None:
                    self._event(result)
                settled = settled or self.autopilot.settle()
            if link.lockstep:  # commands only once the autopilot keeps pace (determinism)
                pending.extend(script.due(self.run_us))
                pending = self._run_actions(pending, time_s, barrier)
            link.send_frame(self.time_us, messages)
            # While the autopilot computes its answer, do what does not depend on it: log
            # this frame, step the model to the next one (its throttle is the PWM captured
            # up to now), sample its sensors and read them through the chips. The answer
            # only sets the PWM widths that the next frame's pulses carry, and the sensor
            # transfers never touch the PWM capture, so the result is the same as in
            # strict order.
            logging = clock()
            self._log_readings(readings, pulses, out)
            if frame % truth_every == 0:
                self.log.truth(self.time_us, truth)
            self._spent_s["logging"] += clock() - logging
            this_truth = truth
            if frame < frames_total:
                truth, readings = self._advance(frame + 1)
                self._sense(frame + 1, readings)
            controls = link.answer(self.time_us)
            if controls is not None:
                answered = clock()
                self.armed = controls.armed
                self.pwm.command(controls.motors, controls.armed)
                commanded = clock()
                self.log.motors(self.time_us, controls.time_us, controls.motors)
                self._spent_s["chips"] += commanded - answered
                self._spent_s["logging"] += clock() - commanded
            self.frames = frame
            if self.progress is not None and frame % max(1, self.rates.imu_hz // 10) == 0:
                self._report(self.progress, this_truth)
            pacer.wait(self.run_us / 1e6)
        self._wall_end = time.monotonic()
        self._chip_costs = tuple(cost.since(costs_before.get(cost.what))
                                 for cost in self.layer.costs())  # fmt: skip
        self.log.event(self.time_us, f"run completed: {self.frames} frames")

    def _advance(self, frame: int) -> tuple[VehicleTruth, SensorReadings]:
        """Step the model to the end of ``frame`` and sample its sensors (faults applied)."""
        started = time.perf_counter()
        self.faults.update(frame * self.frame_us, self.model)
        self.model.advance(self.throttle, self.frame_us / 1e6)
        truth = self.model.truth
        modelled = time.perf_counter()
        readings = self.faults.samples(self.sensors.sample(truth))
        self._spent_s["model"] += modelled - started
        self._spent_s["sensor physics"] += time.perf_counter() - modelled
        return truth, readings

    def _sense(self, frame: int, readings: SensorReadings) -> None:
        """Load ``frame``'s samples into the chips and read them as PX4's drivers do; the
        PWM capture waits for :meth:`_finish`."""
        started = time.perf_counter()
        imu, mag, baro, flow = readings.imu, readings.mag, readings.baro, readings.flow
        assert imu is not None, "the IMU is due every frame"
        chip_frame = ChipFrame(
            now_us=frame * self.frame_us,
            imu=Mpu6000Sample.from_si(imu.accel_mps2, imu.gyro_radps, imu.temperature_degc),
            mag=None if mag is None else sample_from_field_gauss(mag.field_gauss),
            baro_d1_d2=None
            if baro is None
            else raw_from_si(baro.pressure_pa, baro.temperature_degc),
            read_mag=mag is not None,
            faults=self.faults.chip_faults(),
            si=readings,
            gps=None if readings.gps is None else receiver_solution(
                gps_fix(readings.gps), readings.gps.epoch_us, self.faults.gps_fault()),
            range=None if readings.range is None else sample_from_range(readings.range.distance_m),
            flow=None if flow is None else self._camera_counts.sample(
                flow.flow_xy_rad, flow.squal, flow.exposure_s * self._camera_frame_rate_hz),
        )  # fmt: skip
        self.layer.sense(chip_frame)
        self._spent_s["chips"] += time.perf_counter() - started

    def _finish(self) -> tuple[tuple[Pulse, ...], ChipReadout]:
        """Feed the pulses the autopilot's last answer started and capture the PWM: the
        sensed frame's readout, and the pulses."""
        pulses = tuple(self.pwm.pulses(self.run_us + 1, self.faults.pwm_dropped()))
        out = self.layer.finish(pulses)
        self._delivered = out
        for chip, error in out.bus_errors:
            self.log.bus_error(chip)
            self._event(f"bus error: {chip}: {error}", "warn")
        capture = (out.pwm_widths_us, out.pwm_timed_out)
        if capture != self._capture:  # it changes only at pulse ends and timeouts
            self._capture = capture
            self.throttle = throttle_from_capture(*capture)
        return pulses, out

    def _log_readings(self, readings: SensorReadings, pulses: tuple[Pulse, ...],
                      out: ChipReadout) -> None:  # fmt: skip
        if pulses:
            self.log.pwm(self.time_us, out.pwm_widths_us)
        self.log.imu(self.time_us, self.frame_us, out.accel_mps2, out.gyro_radps)
        if out.mag_gauss is not None:
            self.log.mag(self.time_us, out.mag_gauss, out.imu_temperature_degc)
        if out.baro_pa_degc is not None:
            self.log.baro(self.time_us, out.baro_pa_degc)
        for received in out.gps:
            self.log.gps(self.time_us, self.clock_start_us + received.sent_us, received.fix)
        if out.range is not None:
            self.log.rangefinder(self.time_us, out.range.distance_m, out.range.signal_quality,
                                 RANGEFINDER_LIMITS_M)  # fmt: skip
        if out.flow is not None:
            self.log.optical_flow(self.time_us, out.flow.pixel_flow_rad,
                                  out.flow.integration_timespan_us, out.flow.quality)  # fmt: skip

    def _sensor_messages(self, out: ChipReadout) -> list[mavlink.MAVLink_message | bytes]:
        """What the drivers read this frame, as PX4's simulator messages (HIL_SENSOR, in
        every frame, packed at once)."""
        messages: list[mavlink.MAVLink_message | bytes] = [
            hil_sensor_frame(
                self.link.mav, self.time_us, accel_mps2=out.accel_mps2, gyro_radps=out.gyro_radps,
                mag_gauss=out.mag_gauss, baro=out.baro_pa_degc,
            )
        ]  # fmt: skip
        for received in out.gps:  # as PX4's u-blox driver decoded them (bypass: the model's)
            fix = received.fix
            messages.append(
                hil_gps(
                    self.link.mav, self.time_us, lat_deg=fix.latitude_deg,
                    lon_deg=fix.longitude_deg, alt_amsl_m=fix.altitude_msl_m,
                    vel_ned_mps=(fix.vel_n_m_s, fix.vel_e_m_s, fix.vel_d_m_s), eph_m=fix.eph,
                    epv_m=fix.epv, fix_type=fix.fix_type, satellites_visible=fix.satellites_used,
                )
            )  # fmt: skip
        if out.range is not None:
            messages.append(
                distance_sensor(
                    self.link.mav, self.time_us, distance_m=out.range.distance_m,
                    signal_quality=out.range.signal_quality, min_m=RANGEFINDER_LIMITS_M[0],
                    max_m=RANGEFINDER_LIMITS_M[1],
                )
            )  # fmt: skip
        if out.flow is not None:
            messages.append(
                hil_optical_flow(
                    self.link.mav, self.time_us, pixel_flow_rad=out.flow.pixel_flow_rad,
                    integration_timespan_us=out.flow.integration_timespan_us,
                    quality=out.flow.quality,
                )
            )  # fmt: skip
        return messages

    def _state_message(self, truth: VehicleTruth) -> bytes:
        home = self.scenario.environment.home
        lat, lon, alt = ned_to_geodetic(
            truth.position_ned_m, home.lat_deg, home.lon_deg, home.alt_amsl_m
        )
        return hil_state_quaternion_frame(
            self.link.mav, self.time_us, q_body_to_ned=truth.attitude_quat,
            rates_frd_radps=truth.angular_rate_frd_radps, lat_deg=lat, lon_deg=lon,
            alt_amsl_m=alt, vel_ned_mps=truth.velocity_ned_mps,
            specific_force_frd_mps2=truth.specific_force_frd_mps2,
        )  # fmt: skip

    def _run_actions(self, actions: list[Action], time_s: float, barrier: bool) -> list[Action]:
        """Run due actions; returns those still waiting (without the barrier, PX4: one
        conversation at a time)."""
        ground = self.ground
        waiting: list[Action] = []
        for action in actions:
            if action.conversation is None:
                ground.send_unacknowledged(action.unacknowledged)
            elif barrier:
                result = ground.converse_now(action.name, action.conversation)
                if action.logged:
                    self._event(result)
            elif ground.busy or waiting:
                waiting.append(action)
            else:
                done = ground.start(action.name, action.conversation, time_s)
                self._event(f"{action.name}: {done}")
        return waiting

    # -- reporting -------------------------------------------------------------------------

    def _fault_event(self, run_us: int, text: str) -> None:
        self.log.event(self.clock_start_us + run_us, text, "warn")
        self.last_event = text

    def _event(self, text: str, level: str = "info") -> None:
        self.log.event(self.time_us, text, level)
        self.last_event = text

    def _report(self, progress: Callable[[Progress], None], truth: VehicleTruth) -> None:
        wall = time.monotonic() - self._wall_start
        time_s = self.run_us / 1e6
        progress(
            Progress(
                time_s=time_s,
                duration_s=self.duration_s,
                real_time_factor=time_s / wall if wall > 0 else math.inf,
                altitude_m=-float(truth.position_ned_m[2]),
                armed=self.armed,
                last_event=self.last_event,
                attitude_quat=tuple(truth.attitude_quat.tolist()),
                position_ned_m=tuple(truth.position_ned_m.tolist()),
                velocity_ned_mps=tuple(truth.velocity_ned_mps.tolist()),
                accel_mps2=self._delivered.accel_mps2,
                gyro_radps=self._delivered.gyro_radps,
                motor_throttles=tuple(self.throttle.tolist()),
                custom_mode=self.ground.custom_mode,
                active_faults=tuple(describe(f) for f in self.faults.faults if f.active(time_s)),
            )
        )

    def close(self) -> None:
        for close in reversed(self._closers):
            close()

    def result(self) -> RunResult:
        wall_end = self._wall_end or time.monotonic()
        autopilot_log = self.autopilot.log_path
        return RunResult(
            run_dir=self.run_dir,
            rig_log=self.log.path,
            autopilot_log=autopilot_log if autopilot_log.is_file() else None,
            simulated_s=self.run_us / 1e6,
            wall_s=wall_end - self._wall_start,
            frames=self.frames,
            link=self.link.stats,
            budget=self._budget(wall_end - self._wall_start),
            autopilot=self.autopilot.description(),
            chip_costs=self._chip_costs,
        )

    def _budget(self, wall_s: float) -> FrameBudget:
        frames = max(self.frames, 1)
        spent, link = self._spent_s, self.link.stats
        parts_s = (spent["model"], spent["sensor physics"], spent["chips"],
                   spent["messages"] + link.encode_s + link.decode_s, link.send_s, link.wait_s,
                   spent["logging"])  # fmt: skip
        other_s = wall_s - sum(parts_s)
        return FrameBudget(*(part_s / frames * 1e6 for part_s in (*parts_s, other_s)))


def _make_sensor_layer(name: str, rates: Rates, motors: int) -> SensorLayer:
    if name == "tlm":
        return TlmSensorLayer(motors=motors, pwm_tick_hz=rates.pwm_tick_hz)
    if name == BYPASS:
        return BypassSensorLayer(motors=motors)
    # Imported on demand: each builds its simulator once (cached under build/) and starts it.
    from rig.chips.native import NativeSensorLayer
    from rig.chips.rtl import COCOTB_LAYER, RtlSensorLayer

    if name == COCOTB_LAYER:  # the same RTL under cocotb (benchmarks and comparisons)
        return RtlSensorLayer(motors=motors, pwm_hz=rates.pwm_hz, pwm_tick_hz=rates.pwm_tick_hz)
    return NativeSensorLayer(motors=motors, pwm_hz=rates.pwm_hz, pwm_tick_hz=rates.pwm_tick_hz)
