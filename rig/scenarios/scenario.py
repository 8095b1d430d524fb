"""Scenario files (TOML): what one rig run flies, and under which conditions.

A scenario names its vehicle (a quad_model vehicle set), the test-bench constraint, the
environment (location, magnetic field, wind), the start pose, the command script, the
faults with their start/end times, the duration, the seed, the sensor layer and the rates.
The tables below are the file's schema (:mod:`hil_config`): every value is checked on
load and a bad file fails with one line naming the file, the key, the value and what was
expected (:class:`rig.errors.ScenarioError`). The bundled scenarios live in
``rig/scenarios/``; ``load_scenario("hover")`` finds them by name.

Times are simulated seconds from the start of the run. Units are in the key names. The
autopilot's clock (every message and log timestamp) reads ``clock_start_s`` at the start of
the run: ``start.clock_s``, 0 unless set; :mod:`rig.replay` starts it at the real log's
boot time.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, InstanceOf
from pydantic.json_schema import SkipJsonSchema

from fpga_hdl.chips.ublox.link import GpsFault
from fpga_hdl.cosim.harness import HARNESS_SYS_CLK_HZ
from hil_config import (
    FieldError,
    Integer,
    NonNegative,
    NonNegativeInteger,
    Number,
    Positive,
    PositiveInteger,
    Text,
    UnitInterval,
    Vector3,
    parse,
    read_toml,
    table,
)
from quad_model.environment import Environment, GeoPoint
from quad_model.vehicle import MAX_ROTORS
from rig.chips.layer import Chip
from rig.chips.pwm import DEFAULT_MOTOR_PWM_RANGE_US, PWM_TICK_HZ
from rig.errors import ScenarioError
from rig.mavlink.ground_link import PX4_MODES, MissionItem

SCENARIOS_DIR = Path(__file__).parent  # the bundled scenario files live beside this module
#: Coarsest capture tick: 10 µs is 1 % of the 1000-2000 µs throttle range.
MIN_PWM_TICK_HZ = 100_000
#: Finest capture tick: SensorTop needs a system clock of at least 4 ticks
#: (``fpga_hdl.top``), and the co-simulation's system clock runs at 10 MHz.
MAX_PWM_TICK_HZ = round(HARNESS_SYS_CLK_HZ) // 4
#: The paper's model rate; the default model rate is the least multiple of the IMU rate
#: at or above it (:func:`model_rate_for`).
PAPER_MODEL_HZ = 5000


class SensorLayer(StrEnum):
    """Where the chips run: ``tlm`` the Python register models, ``rtl`` the Verilog."""

    TLM = "tlm"
    RTL = "rtl"


class Constraint(StrEnum):
    """The test bench the airframe sits on (``free`` flies)."""

    FREE = "free"
    GIMBAL_PITCH = "gimbal_pitch"
    GIMBAL_ROLL = "gimbal_roll"
    THRUST_STAND = "thrust_stand"


class Sensor(StrEnum):
    ACCEL = "accel"
    GYRO = "gyro"
    MAG = "mag"
    BARO = "baro"


#: A motor of any vehicle the model flies; the run checks it against the vehicle flown.
Motor = Annotated[Integer, Field(ge=0, le=MAX_ROTORS - 1)]
BitMask = Annotated[Integer, Field(ge=1, le=255)]


def model_rate_for(imu_hz: int) -> int:
    """The model's default rate: the least whole multiple of the IMU rate at or above 5 kHz
    (the paper's model rate), so every frame holds whole physics steps (400 Hz → 5.2 kHz)."""
    return imu_hz * -(-PAPER_MODEL_HZ // imu_hz)


@table
class Rates:
    """Simulation and sensor rates (Hz); one lockstep frame is one IMU period.

    The GPS epochs come at the receiver's maximum navigation rate (``fix_rate_hz`` in the
    vehicle file, 10 Hz for the bundled ones), with its latency; the receiver reports
    those its CFG-RATE selects (PX4 configures 200 ms: 5 Hz). ``pwm_tick_hz`` is the PWM
    capture core's tick, the resolution of the measured pulse widths; in the RTL layer its
    clock runs all the time, one simulated cycle per tick, so a coarser tick trades
    resolution for speed.
    Without ``model_hz`` the model runs at :func:`model_rate_for` the IMU rate.
    """

    model_hz: PositiveInteger | None = None
    imu_hz: PositiveInteger = 1000
    mag_hz: PositiveInteger = 50  # PX4's IST8310 driver: read + next trigger every 20 ms
    baro_hz: PositiveInteger = 50
    pwm_hz: PositiveInteger = 400
    pwm_tick_hz: PositiveInteger = round(PWM_TICK_HZ)  # 1 µs, the unit PX4 uses for PWM widths

    def __post_init__(self) -> None:
        if 1_000_000 % self.imu_hz:
            raise FieldError("imu_hz", self.imu_hz, "must give a whole number of µs per frame")
        model_hz = model_rate_for(self.imu_hz) if self.model_hz is None else self.model_hz
        object.__setattr__(self, "model_hz", model_hz)
        if model_hz % self.imu_hz:
            raise FieldError("imu_hz", self.imu_hz, f"must divide model_hz ({model_hz})")
        for name in ("mag_hz", "baro_hz"):
            if getattr(self, name) > self.imu_hz:
                raise FieldError(name, getattr(self, name), f"exceeds imu_hz ({self.imu_hz})")
        self._check_pwm_tick()

    @property
    def frame_us(self) -> int:
        """One lockstep frame: one IMU period."""
        return 1_000_000 // self.imu_hz

    def _check_pwm_tick(self) -> None:
        """The capture tick must fit the gateware and hold the PWM period in whole ticks."""
        tick_hz = self.pwm_tick_hz
        if not MIN_PWM_TICK_HZ <= tick_hz <= MAX_PWM_TICK_HZ:
            raise FieldError(
                "pwm_tick_hz", tick_hz,
                f"must be within {MIN_PWM_TICK_HZ}..{MAX_PWM_TICK_HZ} Hz (10 µs to 0.4 µs ticks)",
            )  # fmt: skip
        # Whole system-clock cycles per tick keep the co-simulation's PWM clock edges off
        # the system clock's (fpga_hdl.cosim.harness).
        if round(HARNESS_SYS_CLK_HZ) % tick_hz:
            raise FieldError(
                "pwm_tick_hz", tick_hz,
                f"must divide {round(HARNESS_SYS_CLK_HZ)} Hz (a whole number of 0.1 µs cycles)",
            )  # fmt: skip
        period_us = round(1e6 / self.pwm_hz)
        if period_us * tick_hz % 1_000_000:
            raise FieldError(
                "pwm_tick_hz", tick_hz,
                f"the PWM period ({period_us} µs at pwm_hz = {self.pwm_hz}) is not a whole "
                f"number of ticks ({1e6 / tick_hz:g} µs)",
            )  # fmt: skip


@table
class StartPose:
    """Where and how the run starts."""

    position_ned_m: Vector3 = (0.0, 0.0, 0.0)
    yaw_deg: Number = 0.0
    #: The autopilot's clock at the start of the run (s); a replay sets the log's.
    clock_s: NonNegative = 0.0
    #: The pack's open-circuit voltage at the start; None: full.
    battery_voltage_v: Positive | None = None

    def __post_init__(self) -> None:
        if self.position_ned_m[2] > 0:
            raise FieldError(
                "position_ned_m", self.position_ned_m, "starts below the ground (down > 0)"
            )


# -- commands: one table per action, told apart by ``action`` ------------------------------


@table(kw_only=True)
class _Timed:
    #: Run seconds at which the command is sent.
    at_s: NonNegative


@table(kw_only=True)
class Arm(_Timed):
    action: Literal["arm"] = "arm"


@table(kw_only=True)
class Disarm(_Timed):
    action: Literal["disarm"] = "disarm"
    #: A refusal (the autopilot still flying) is logged, not an error (a replay's disarm
    #: follows the real flight's).
    may_refuse: Annotated[bool, Field(strict=True)] = False


@table(kw_only=True)
class Takeoff(_Timed):
    action: Literal["takeoff"] = "takeoff"
    altitude_m: Positive


@table(kw_only=True)
class Land(_Timed):
    action: Literal["land"] = "land"


@table(kw_only=True)
class Hold(_Timed):
    """PX4's Hold mode (loiter where it is); the mode to arm in again after a landing."""

    action: Literal["hold"] = "hold"


@table(kw_only=True)
class Goto(_Timed):
    """Offboard position setpoint, re-sent every 0.1 s until the next mode command."""

    action: Literal["goto"] = "goto"
    position_ned_m: Vector3
    yaw_deg: Number | None = None


@table(kw_only=True)
class Mission(_Timed):
    action: Literal["mission"] = "mission"
    waypoints_ned_m: Annotated[tuple[Vector3, ...], Field(min_length=1)]


@table(kw_only=True)
class PitchSweep(_Timed):
    """Offboard attitude setpoints: a pitch chirp at constant thrust (the paper's bench)."""

    action: Literal["pitch_sweep"] = "pitch_sweep"
    duration_s: Positive
    amplitude_deg: Positive
    f_min_radps: Positive
    f_max_radps: Positive
    thrust: UnitInterval
    rate_hz: Positive = 50.0

    def __post_init__(self) -> None:
        if self.f_min_radps >= self.f_max_radps:
            raise FieldError("f_max_radps", self.f_max_radps, "must exceed f_min_radps")


@table(kw_only=True)
class MotorTest(_Timed):
    action: Literal["motor_test"] = "motor_test"
    motor: Motor
    throttle: UnitInterval
    duration_s: Positive


@table(kw_only=True)
class SetParam(_Timed):
    action: Literal["set_param"] = "set_param"
    name: Text
    value: Number


@table(kw_only=True)
class SetMode(_Timed):
    """Switch PX4 to the flight mode of this QGroundControl ``name`` (``"Position"``,
    ``"Altitude"``, ``"Hold"``, ...: :data:`~rig.mavlink.ground_link.PX4_MODES`), as a ground
    station's mode menu does. A refusal is logged and the run goes on (a PX4 replay flies
    the log's mode switches, and the pilot's flight went on)."""

    name: Text
    action: Literal["mode"] = "mode"

    def __post_init__(self) -> None:
        if self.name.lower() not in _NAV_STATES:
            names = ", ".join(name for _, _, name in PX4_MODES.values())
            raise FieldError("name", self.name, f"not a PX4 mode to select ({names})")

    @property
    def nav_state(self) -> int:
        """PX4's ``vehicle_status.nav_state`` of the mode."""
        return _NAV_STATES[self.name.lower()]


_NAV_STATES = {name.lower(): nav_state for nav_state, (_, _, name) in PX4_MODES.items()}
#: A stick's deflection, -1..1.
Stick = Annotated[Number, Field(ge=-1, le=1)]


@table(kw_only=True)
class Sticks(_Timed):
    """A pilot's sticks from now on, held until the next ``sticks``: MANUAL_CONTROL every
    20 ms as a joystick through QGroundControl sends it, PX4's convention (-1..1; the
    throttle -1 at idle, 0 centred, which in Position and Altitude modes holds the height;
    pitch -1 forward)."""

    action: Literal["sticks"] = "sticks"
    roll: Stick = 0.0
    pitch: Stick = 0.0
    yaw: Stick = 0.0
    throttle: Stick = 0.0


_FileCommand = (
    Arm | Disarm | Takeoff | Land | Hold | SetMode | Sticks | Goto | Mission | PitchSweep
    | MotorTest | SetParam
)  # fmt: skip
#: A command of a scenario file: its ``action`` picks the table.
Command = Annotated[_FileCommand, Field(discriminator="action")]

#: What one sample of a :class:`SetpointTrack` holds, per kind.
TRACK_KINDS = {
    "velocity": "vn, ve, vd (m/s, NED) and yaw (rad; NaN: not controlled)",
    "attitude": "q w, x, y, z (body to NED) and collective thrust 0..1",
    "rates": "roll, pitch, yaw rate (rad/s, FRD) and collective thrust 0..1",
    "manual": "a pilot's sticks: roll, pitch, yaw, throttle, −1..1 (PX4's "
    "manual_control_setpoint; throttle −1 at idle)",
}


@table
class SetpointTrack:
    """Offboard setpoints recorded at known times (e.g. a real flight's), in run seconds.

    A :class:`Track` streams it from its own time on: each sample goes out at the first
    frame at or after its time, and the latest one is held (zero-order hold) in between. A
    ``manual`` track is a pilot's sticks instead, interpolated between its samples.
    """

    kind: str
    times_s: tuple[float, ...]
    values: tuple[tuple[float, ...], ...]

    def __post_init__(self) -> None:
        if self.kind not in TRACK_KINDS:
            raise ValueError(f"track kind {self.kind!r} is not one of {', '.join(TRACK_KINDS)}")
        if not self.times_s or len(self.times_s) != len(self.values):
            raise ValueError("a track needs one value per time, and at least one")


@table(kw_only=True)
class Track(_Timed):
    """Stream a recorded :class:`SetpointTrack`: set by code (a replay), not by a file."""

    track: SetpointTrack
    action: Literal["track"] = "track"


@table(kw_only=True)
class UploadMission(_Timed):
    """Upload a mission as flown (a replay's, from the log), without starting it: set by
    code; a mode switch to Mission starts it."""

    items: tuple[InstanceOf[MissionItem], ...]
    action: Literal["upload_mission"] = "upload_mission"


@table(kw_only=True)
class SetHome(_Timed):
    """Set PX4's home position (DO_SET_HOME): set by code (a PX4 replay moves it where
    the real PX4 moved its own in flight)."""

    home: InstanceOf[GeoPoint]
    action: Literal["set_home"] = "set_home"


#: A command that only code sets (a replay): recorded streams, mode switches, a flown
#: mission, a home moved in flight.
CodeCommand = Track | UploadMission | SetHome
#: What a command script walks: the file's commands and the code's.
ScriptCommand = _FileCommand | CodeCommand


# -- faults: one table per kind, told apart by ``kind`` -----------------------------------


@table(kw_only=True)
class _Fault:
    """Active from ``start_s`` until ``end_s`` (None: until the end)."""

    start_s: NonNegative
    end_s: Positive | None = None

    def __post_init__(self) -> None:
        if self.end_s is not None and self.end_s <= self.start_s:
            raise FieldError("end_s", self.end_s, f"must be after start_s ({self.start_s})")

    def active(self, time_s: float) -> bool:
        return self.start_s <= time_s and (self.end_s is None or time_s < self.end_s)

    @property
    def parameters(self) -> dict[str, Any]:
        """What the fault acts on and how hard: every key but kind and the times."""
        return {
            name: getattr(self, name)
            for name in self.__dataclass_fields__
            if name not in ("kind", "start_s", "end_s")
        }


@table(kw_only=True)
class MotorLoss(_Fault):
    kind: Literal["motor_loss"] = "motor_loss"
    motor: Motor


@table(kw_only=True)
class MotorDegradation(_Fault):
    kind: Literal["motor_degradation"] = "motor_degradation"
    motor: Motor
    #: Thrust left, 0..1: the severity a campaign sweeps.
    efficiency: UnitInterval


@table(kw_only=True)
class SensorStuck(_Fault):
    kind: Literal["sensor_stuck"] = "sensor_stuck"
    sensor: Sensor


@table(kw_only=True)
class SensorBias(_Fault):
    """Added to the sensor's axes (three numbers), or to the baro's pressure (Pa)."""

    kind: Literal["sensor_bias"] = "sensor_bias"
    sensor: Sensor
    bias: Number | Vector3

    def __post_init__(self) -> None:
        super().__post_init__()
        scalar = self.sensor == Sensor.BARO
        if scalar != isinstance(self.bias, float):
            shape = "one number (Pa)" if scalar else "three numbers (sensor axes)"
            raise FieldError("bias", self.bias, f"the {self.sensor} bias takes {shape}")


@table(kw_only=True)
class NoiseBurst(_Fault):
    kind: Literal["noise_burst"] = "noise_burst"
    sensor: Sensor
    std: Positive


@table(kw_only=True)
class BusBitFlip(_Fault):
    """Every byte the chip sends is XORed with ``mask`` on the bus."""

    kind: Literal["bus_bit_flip"] = "bus_bit_flip"
    chip: Chip
    mask: BitMask


@table(kw_only=True)
class ChipMute(_Fault):
    kind: Literal["chip_mute"] = "chip_mute"
    chip: Chip


@table(kw_only=True)
class GpsLoss(_Fault):
    kind: Literal["gps_loss"] = "gps_loss"


@table(kw_only=True)
class GpsReceiverFault(_Fault):
    """A fault of the u-blox receiver or its UART, at the chip layer (``tlm``, ``rtl``):
    ``loss_of_fix`` (fix type 0), ``jammed`` (2D from 3 satellites, 20x worse accuracy),
    ``bad_checksum`` (each frame corrupted on the line: PX4 drops it)."""

    kind: Literal["gps_receiver"] = "gps_receiver"
    fault: GpsFault


@table(kw_only=True)
class FlowChipFault(_Fault):
    """A fault of the PMW3901 optical-flow chip itself (``fpga_hdl.chips.pmw3901``):
    ``stuck`` (its image freezes: no motion, SQUAL held), ``zero_quality`` (SQUAL reads 0),
    ``drop_frames`` (it takes no new frames: no motion, MOT clear). The scenario must fly
    the camera (``optical_flow = true``)."""

    kind: Literal["flow_chip"] = "flow_chip"
    mode: Literal["stuck", "zero_quality", "drop_frames"]


@table(kw_only=True)
class PwmDropout(_Fault):
    """A PWM line goes quiet; no channel: every motor's."""

    kind: Literal["pwm_dropout"] = "pwm_dropout"
    channel: Motor | None = None


FaultSpec = Annotated[
    MotorLoss | MotorDegradation | SensorStuck | SensorBias | NoiseBurst | BusBitFlip
    | ChipMute | GpsLoss | GpsReceiverFault | FlowChipFault | PwmDropout,
    Field(discriminator="kind"),
]  # fmt: skip


@table
class Scenario:
    name: Text
    vehicle: Text
    duration_s: Positive
    #: Seed of every random source: the same seed gives the same rig.ulg.
    seed: NonNegativeInteger
    description: str = ""
    constraint: Constraint = Constraint.FREE
    environment: Environment = Environment()
    start: StartPose = StartPose()
    sensor_layer: SensorLayer = SensorLayer.TLM
    rates: Rates = Rates()
    #: Fly the vehicle's ``[rangefinder]`` (a LIDAR-Lite v3 on I2C, read at PX4's 20 Hz
    #: driver rate) and send its readings as DISTANCE_SENSOR.
    rangefinder: Annotated[bool, Field(strict=True)] = False
    #: Fly the vehicle's ``[optical_flow]`` (a PixArt PMW3901 on SPI, read as PX4's pmw3901
    #: driver does) and send its reports as HIL_OPTICAL_FLOW.
    optical_flow: Annotated[bool, Field(strict=True)] = False
    #: False: the vehicle flies without a GNSS receiver: no HIL_GPS is sent, and PX4 is told
    #: (``SYS_HAS_GPS`` 0, ``EKF2_GPS_CTRL`` 0).
    gps: Annotated[bool, Field(strict=True)] = True
    #: Pulse widths (µs) for motor command 0 and 1 (PX4's PWM_*_MIN/MAXn).
    motor_pwm_range_us: tuple[Positive, Positive] = DEFAULT_MOTOR_PWM_RANGE_US
    commands: tuple[Command, ...] = ()
    faults: tuple[FaultSpec, ...] = ()
    #: Commands set by code (a replay: recorded setpoint and stick streams, a PX4 replay's
    #: mode switches, mission and home moves); a file cannot give them.
    tracks: SkipJsonSchema[
        tuple[
            InstanceOf[Track]
            | InstanceOf[SetMode]
            | InstanceOf[UploadMission]
            | InstanceOf[SetHome],
            ...,
        ]
    ] = ()
    #: Where the scenario came from (its file); set by the loader.
    source: SkipJsonSchema[str] = "<code>"

    def __post_init__(self) -> None:
        frame_s = self.rates.frame_us / 1e6
        if self.duration_s < frame_s:
            raise FieldError(
                "duration_s", self.duration_s, f"shorter than one IMU frame ({frame_s} s)"
            )
        if self.motor_pwm_range_us[0] >= self.motor_pwm_range_us[1]:
            raise FieldError(
                "motor_pwm_range_us", self.motor_pwm_range_us, "must rise from command 0 to 1"
            )
        for key, items, time in (("commands", self.commands, "at_s"),
                                 ("faults", self.faults, "start_s")):  # fmt: skip
            for index, item in enumerate(items):
                if getattr(item, time) >= self.duration_s:
                    raise FieldError(
                        f"{key}[{index}].{time}",
                        getattr(item, time),
                        f"not before the end of the run (duration_s = {self.duration_s})",
                    )
        for index, fault in enumerate(self.faults):
            if fault.kind == "flow_chip" and not self.optical_flow:
                raise FieldError(
                    f"faults[{index}].kind", fault.kind, "no optical-flow camera is flown"
                )
        # Commands run in time order whatever the file's order (a stable sort keeps the
        # file's order among commands due at the same time).
        object.__setattr__(self, "commands", tuple(sorted(self.commands, key=_at)))

    def script(self) -> tuple[ScriptCommand, ...]:
        """The commands and the setpoint tracks, in time order."""
        return tuple(sorted((*self.commands, *self.tracks), key=_at))


def _at(command: _Timed) -> float:
    return command.at_s


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a bundled scenario by name (``"hover"``) or any scenario file by path."""
    document, path = read_toml(name_or_path, SCENARIOS_DIR, kind="scenario", error=ScenarioError)
    return scenario_from_dict(document, str(path))


def scenario_from_dict(document: Mapping[str, Any], source: str = "<dict>") -> Scenario:
    """Check and convert a parsed scenario document (a TOML table); raises
    :class:`ScenarioError`."""
    if "source" in document:  # the loader's key, not the file's
        raise ScenarioError(f"{source}: key 'source' = {document['source']!r}: unknown key")
    return parse(Scenario, {**document, "source": source}, source, ScenarioError)
