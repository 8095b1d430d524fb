"""``rig replay REAL.ulg``: fly a real PX4 flight's own commands through the rig.

:func:`plan_replay` reads the log and configures the run from it, without flying: the
vehicle from ``SYS_AUTOSTART`` (``--vehicle`` wins), the battery's cell count, every
parameter the reference autopilot knows, the start heading, the home position, the real
arm/disarm times and the setpoint tracks of the chosen drive, the motor outputs' PWM
range (so the armed motors idle at command 0 as the real ones did) and the battery's
resting voltage at the start (the pack is rarely full, and the ESC speed follows it).
:func:`run_replay` flies the plan and leaves ``rig.ulg``, ``autopilot.ulg``, the derived
``vehicle.toml`` and ``replay.json`` (what was applied, skipped and assumed) in the run folder.

The autopilot's clock starts at the real log's first timestamp, so the replayed logs share
the real log's time axis (ULog boot seconds) and one credibility plan scores both.

Drives (the reference autopilot's matching loop takes the log's own setpoints):

- ``velocity``: ``vehicle_local_position_setpoint`` vx, vy, vz (+ yaw when finite) as
  offboard velocity setpoints; it flies the whole flight, take-off and landing included.
- ``attitude``: ``vehicle_attitude_setpoint`` q_d and thrust, inside ``--window``.
- ``rates``: ``vehicle_rates_setpoint`` body rates and thrust, inside ``--window``.

Attitude and rates are open loop on position, so the velocity drive flies the vehicle to
the window and takes over again after it.

``--autopilot px4`` flies PX4 SITL instead, with the firmware's own parameters from the log
(:func:`rig.autopilots.px4.sitl_parameters` decides which ones SITL takes) and as the pilot
flew it: the log's sticks (``manual_control_setpoint``) as MANUAL_CONTROL, its arm, mode
switches and disarm at their times (``vehicle_status``), its mission uploaded as it was
flown (``navigator_mission_item``) and, in Offboard, its velocity setpoints. PX4 boots
PX4_BOOT_S before the log's start, so it is ready when the log arms.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import tomli_w
from numpy.typing import NDArray

from credibility.errors import CredibilityError
from credibility.layouts import legacy_pwm_range
from credibility.logs import read_ulog
from credibility.provenance import firmware_name
from hil_config import FieldError, read_toml
from quad_model.environment import (
    DRY_AIR_GAS_CONSTANT,
    PX4_DEFAULT_HOME,
    Environment,
    GeoPoint,
    MagneticField,
    Wind,
    isa_pressure_pa,
    isa_temperature_k,
)
from quad_model.frames import geodetic_to_ned, ned_to_geodetic
from quad_model.model import ModelInputError, charge_used_for_voltage_c
from quad_model.vehicle import VEHICLES_DIR, BatteryParams, VehicleFileError, vehicle_from_dict

if TYPE_CHECKING:
    from rig.apps.wind import WindEstimate
from rig.autopilots.px4 import (
    RIG_PARAMETERS,
    STICK_PARAMETERS,
    Px4NotFound,
    build_parameters,
    check_imu_rate,
    find_px4,
    lockstep_parameters,
    sitl_parameters,
)
from rig.autopilots.reference.params import PARAMETERS, ParameterError, Parameters
from rig.chips.pwm import DEFAULT_MOTOR_PWM_RANGE_US, PwmOutput
from rig.errors import RigError
from rig.lockstep.loop import (
    AUTOPILOTS,
    RUNS_DIR,
    Progress,
    RunOptions,
    RunResult,
    claim_run_dir,
    run_scenario,
)
from rig.mavlink.ground_link import PX4_MODES, MissionItem
from rig.mavlink.px4_api import mavlink
from rig.scenarios.scenario import (
    Arm,
    CodeCommand,
    Disarm,
    Rates,
    Scenario,
    ScriptCommand,
    SensorLayer,
    SetHome,
    SetMode,
    SetParam,
    SetpointTrack,
    StartPose,
    Takeoff,
    Track,
    UploadMission,
)

DRIVES = ("velocity", "attitude", "rates")
#: PX4 SYS_AUTOSTART → bundled vehicle (PX4-Autopilot ROMFS/px4fmu_common/init.d/airframes).
AIRFRAMES = {4019: "x500_v2"}
#: The rig's autopilot boots at the clock start; the real one had been up for minutes. Its
#: GPS fix, attitude and position estimates need this long before it can arm (the bundled
#: scenarios arm after 1 s too), so an earlier real arming is flown this late.
AUTOPILOT_READY_S = 1.0
#: A log that starts in the air is flown after a lead-in, since no autopilot (PX4 SITL
#: included) boots flying: take off to the log's height at --start, climbing at PX4's
#: MPC_TKO_SPEED default, and settle this long; the track then starts on the log's clock.
TAKEOFF_CLIMB_MPS = 1.5
LEAD_IN_SETTLE_S = 5.0
#: Parameters the rig sets itself: MAV_SYS_ID follows the SITL instance.
RIG_OWNED_PARAMETERS = frozenset({"MAV_SYS_ID"})
#: The autopilot looks declination up in the WMM at this epoch (flight_controller), so the
#: simulated field is taken at the same one: the two then agree on north.
WMM_EPOCH_YEAR = 2026.0
#: PX4 output functions Motor 1..4, the values of ``PWM_MAIN_FUNCn`` / ``PWM_AUX_FUNCn``
#: (PX4-Autopilot src/lib/mixer_module/output_functions.yaml: Motor start 101).
MOTOR_OUTPUT_FUNCTIONS = (101, 102, 103, 104)
#: PX4 vehicle_status.arming_state ARMED (msg/VehicleStatus.msg).
ARMING_STATE_ARMED = 2
#: PX4 SITL boots this long (simulated s) before the log's start, so that its pre-flight
#: checks (EKF2 aligned, GPS healthy for EKF2_REQ_GPS_H) have passed when the log arms, and
#: the arm, every mode switch and the landing happen at the log's own times.
PX4_BOOT_S = 20.0
#: Seconds after PX4's boot at which the log's mission is uploaded.
PX4_SETUP_S = 1.0
#: The mode the log armed in is selected this long before the arm (PX4 switches modes freely
#: while disarmed; the arm is then checked in that mode).
ARM_MODE_LEAD_S = 1.0
#: A PX4 replay's IMU (= lockstep) rate unless --imu-hz says otherwise is the log's
#: IMU_GYRO_RATEMAX, the rate its rate controller ran at (800 Hz on the X500), where PX4 can
#: keep lockstep at it; else this. At 250 Hz the rig's IMU (vibration sampled without the
#: real chips' 8 kHz filtering) left EKF2's vertical velocity 1-2 m/s off and the altitude
#: hold swinging ±2.5 m where the real one held; at 800 and 1000 Hz it follows the real flight.
PX4_IMU_HZ = Rates().imu_hz
#: ``vehicle_status.latest_disarming_reason`` of a pilot's or ground station's disarm (stick
#: gesture, RC switch, external command: the same numbers in every PX4 since 1.13). Any other
#: disarm (landing, pre-flight timeout, failsafe) was PX4's own. Either way a PX4 replay sends
#: a disarm at the log's time, so the disarmed stretch after landing is the log's; PX4 takes
#: it only once it has landed, and otherwise disarms by itself later.
PILOT_DISARM_REASONS = frozenset({1, 2, 4})
#: nav_states flown on the pilot's sticks: PX4 needs manual control input in them.
STICK_MODES = frozenset({0, 1, 2, 10, 15})
NAV_STATE_MISSION, NAV_STATE_LOITER, NAV_STATE_OFFBOARD = 3, 4, 14
#: Loiter commands (MAV_CMD_NAV_LOITER_UNLIM, _TIME, _TO_ALT): a navigator that started one
#: of these at the switch to Mission, then replaced it by the mission's first item, held
#: the vehicle where it was meanwhile (``_FlightLog.mission_start_holds``).
LOITER_COMMANDS = frozenset({17, 19, 31})
#: The navigator starts a mission item this soon after the switch to Mission (it runs at
#: 20 Hz); a later first record belongs to something else.
MISSION_START_S = 0.5
#: nav_states whose heading PX4's auto planner sets (MPC_YAWRAUTO_*): Mission, Loiter,
#: Return, Takeoff, Land, Precision land.
AUTO_YAW_MODES = frozenset({3, 4, 5, 17, 18, 20})
#: The least yaw rate (°/s) a replay's schedule of MPC_YAWRAUTO_MAX allows, so that a
#: heading that differs from the real one at a turn's start can still converge.
YAW_RATE_LIMIT_FLOOR_DEG_S = 5.0
#: A schedule's new MPC_YAWRAUTO_MAX is sent when it differs from the last by this much (°/s).
YAW_RATE_LIMIT_STEP_DEG_S = 2.0
#: nav_states whose throttle is the pilot's stick, not a climb rate: Manual, Acro, Stabilized.
MANUAL_THRUST_MODES = frozenset({0, 10, 15})
#: What a PX4 replay takes from the flight where PX4 changed between versions, and why
#: (:func:`_learned_parameters`).
_STICK_THRUST = "this SITL's stick → thrust map as the log's PX4 had it"
LEARNED = {
    "MPC_THR_HOVER": f"its hover_thrust_estimate, the centre stick's thrust in its PX4: "
    f"{_STICK_THRUST}",
    "MPC_MANTHR_MIN": f"its thrust set-point with the throttle stick at the bottom: "
    f"{_STICK_THRUST}",
    "MPC_YAWRAUTO_MAX": "its peak yaw rate in Mission, where its PX4 limited the yaw "
    "acceleration (MPC_YAWRAUTO_ACC, not in this build); in auto modes it then follows the "
    "yaw rate the real planner allowed itself (yaw_rate_limits in replay.json), so this "
    "SITL's turns start and end as the real ones did",
}
#: A mission item the real PX4 left within this long of making it current was passed where
#: the vehicle stood, not flown to: the X500's first waypoint, 0.8 m above the hovering
#: vehicle, was current for 50 ms in its v1.17. PX4 v1.14 SITL, given it as logged (on the
#: home at arming: 1.1 m below), descended to it first and ran the mission 1.9 s late;
#: given no such item, it climbed to the next one's height before leaving (its in-air
#: take-off step), 3.3 s late. Uploaded at the height it was passed, it is passed too.
#: No multicopter reaches a waypoint outside its acceptance radius this fast.
PASSED_AT_ONCE_S = 0.25
#: A home_position sample this far (m, any axis) from the one before is a home moved.
HOME_MOVED_M = 0.05
#: navigator_mission_item frames with a global position (MAV_FRAME GLOBAL*, PX4 stores 0).
GLOBAL_FRAMES = frozenset({0, 3, 5, 6})
#: Each drive's topic and fields, in SetpointTrack order (thrust is −thrust_body[2]).
#: What a mission item needs to go up (``Flight.flown_mission``).
_MISSION_ITEM_FIELDS = (
    "sequence_current", "frame", "latitude", "longitude", "altitude", "altitude_is_relative",
    "nav_cmd", "time_inside", "acceptance_radius", "loiter_radius", "yaw",
)  # fmt: skip
_DRIVE_FIELDS = {
    "velocity": ("vehicle_local_position_setpoint", ("vx", "vy", "vz", "yaw")),
    "attitude": ("vehicle_attitude_setpoint",
                 ("q_d[0]", "q_d[1]", "q_d[2]", "q_d[3]", "thrust_body[2]")),
    "rates": ("vehicle_rates_setpoint", ("roll", "pitch", "yaw", "thrust_body[2]")),
}  # fmt: skip


class ReplayError(RigError):
    """A flight log or replay option that cannot be flown: names the file, field and value."""


@dataclass(frozen=True)
class ReplayOptions:
    """What to replay and how (times are the log's boot seconds)."""

    drive: str = "velocity"
    window_s: tuple[float, float] | None = None
    start_s: float | None = None  # None: the log's first timestamp
    end_s: float | None = None  # None: the log's last timestamp
    vehicle: str | None = None  # None: from SYS_AUTOSTART
    seed: int = 0
    sensor_layer: SensorLayer = SensorLayer.TLM
    imu_hz: int | None = None  # None: Rates' default (1000 Hz); with PX4 see PX4_IMU_HZ
    autopilot: str = AUTOPILOTS[0]
    px4_dir: Path | None = None  # PX4's build (--px4); None: $PX4_DIR


@dataclass(frozen=True)
class SkippedParameter:
    name: str
    value: float
    reason: str


@dataclass(frozen=True)
class FlightEvent:
    """Something the pilot, a ground station or PX4 did in the real flight (log seconds):
    ``kind`` arm, disarm, mode (the pilot's mode, ``nav_state_user_intention``) or autopilot
    (PX4 changed mode by itself: a failsafe). ``commanded``: a PX4 replay sends it. A
    failsafe's mode (and the one it returns to) is commanded when a ground station can
    select it: the replay does not recreate the failsafe's cause (the X500's estimator lost
    its position for 2 s), and the pilot's sticks mean something else in another mode."""

    time_s: float
    kind: str
    nav_state: int | None
    commanded: bool
    detail: str

    def describe(self) -> str:
        what = {"arm": "armed", "disarm": "disarmed"}.get(self.kind) or (
            f"mode {_mode_name(self.nav_state)}"
            if self.kind == "mode"
            else f"PX4 switched to {_mode_name(self.nav_state)} by itself"
        )
        action = "commanded" if self.commanded else "not commanded"
        return f"{self.time_s:.3f} s {what} ({self.detail}): {action}"


@dataclass(frozen=True)
class Replay:
    """The replay's configuration, read from the log (:func:`plan_replay`).

    Times ``*_s`` are the log's boot seconds; the tracks and commands count run seconds
    from ``start_s``, as every scenario does.
    """

    log_path: Path
    drive: str
    start_s: float
    end_s: float
    window_s: tuple[float, float] | None
    vehicle: str  # bundled name or path
    vehicle_reason: str
    vehicle_document: dict[str, Any]
    cell_count: int | None
    motor_pwm_range_us: tuple[float, float]  # pulse at motor command 0 and 1
    initial_battery_voltage_v: float | None  # open-circuit at the start; None: full
    parameters: dict[str, float | int]  # applied, as the log has them
    skipped: tuple[SkippedParameter, ...]
    unknown_parameter_count: int
    #: The heading flown from the start: the log's at --start plus every estimator reset
    #: after it (``heading_resets``), so the vehicle points where the real one did once its
    #: estimator had corrected itself. Sticks are body-frame: a wrong heading turns them.
    yaw_rad: float
    home: GeoPoint | None
    real_arm_s: float | None
    arm_s: float | None  # as flown: the real time, at least AUTOPILOT_READY_S after start
    disarm_s: float | None
    tracks: dict[str, SetpointTrack]
    options: ReplayOptions
    log_warnings: tuple[str, ...] = ()  # what pyulog reported (a damaged message skipped)
    #: Airborne at --start: the height (m) taken off to first.
    start_height_m: float = 0.0
    #: Run seconds flown before the log's start: PX4's boot, an airborne start's take-off.
    lead_in_s: float = 0.0
    #: A PX4 replay's: the log's events, its mission as flown, the pilot's sticks.
    events: tuple[FlightEvent, ...] = ()
    mission: tuple[MissionItem, ...] = ()
    mission_notes: tuple[str, ...] = ()
    #: Per switch to Mission (log seconds): how long the real navigator held the vehicle
    #: where it was before the mission's first item; flown as Hold (``mission_start_holds``).
    mission_holds: tuple[tuple[float, float], ...] = ()
    sticks: SetpointTrack | None = None
    firmware: str = ""  # the log's PX4, as its header says
    #: The wind flown: the log's hover tilt through the vehicle's drag (rig.apps.wind);
    #: None, with the reason in ``wind_note``, when the log gives none.
    wind: WindEstimate | None = None
    wind_note: str = ""
    #: The day's temperature offset from ISA that gives the log's air density at home
    #: (vehicle_air_data.rho): thrust ∝ ρ, so the rotors turn as fast as the real ones.
    temperature_offset_k: float = 0.0
    air_density_kgpm3: float | None = None
    #: A PX4 replay's parameters the log's firmware learned in flight rather than read from
    #: its parameters (:func:`_learned_parameters`), set after the log's own.
    learned: dict[str, float] = field(default_factory=dict)
    #: (log s, °/s): MPC_YAWRAUTO_MAX set in flight, the real planner's yaw rate in auto
    #: modes (:func:`_yaw_rate_limits`); empty where the log's PX4 had no acceleration limit.
    yaw_rate_limits: tuple[tuple[float, float], ...] = ()
    #: (log s, home): where and when the real PX4 moved its home while armed
    #: (:meth:`_FlightLog.home_moves`); a PX4 replay sets each with DO_SET_HOME.
    home_moves: tuple[tuple[float, GeoPoint], ...] = ()
    #: (log s, rad): the log's estimator heading resets after --start
    #: (:meth:`_FlightLog.heading_resets`), taken into the start heading.
    heading_resets: tuple[tuple[float, float], ...] = ()

    @property
    def px4(self) -> bool:
        return self.options.autopilot == "px4"

    @property
    def ready_s(self) -> float:
        """Run seconds after which the autopilot can arm (an airborne start's lead-in)."""
        return PX4_BOOT_S if self.px4 else AUTOPILOT_READY_S

    @property
    def commands(self) -> tuple[ScriptCommand, ...]:
        """Arm, stream the velocity track (the drive's inside the window), disarm; run seconds.

        A log that starts airborne is preceded by the lead-in: arm, take off to its height,
        then the track from ``lead_in_s`` on. PX4 flies :meth:`_pilots_commands` instead."""
        if self.arm_s is None:
            return ()
        if self.px4:
            return self._pilots_commands()
        origin = self.start_s - self.lead_in_s  # log second of run second 0
        tracks = {kind: _delayed(track, self.lead_in_s) for kind, track in self.tracks.items()}
        commands: list[ScriptCommand] = [Arm(at_s=self.arm_s - origin)]
        if self.start_height_m:
            commands.append(Takeoff(at_s=self.ready_s + 0.1, altitude_m=self.start_height_m))
        commands.append(Track(at_s=max(self.arm_s - origin, self.lead_in_s),
                              track=tracks["velocity"]))  # fmt: skip
        if self.window_s is not None and self.drive != "velocity":
            a, b = self.window_s
            commands += [
                Track(at_s=a - origin, track=tracks[self.drive]),
                Track(at_s=b - origin, track=tracks["velocity"]),
            ]
        if self.disarm_s is not None:
            commands.append(Disarm(at_s=self.disarm_s - origin, may_refuse=True))
        return tuple(sorted(commands, key=lambda c: c.at_s))

    def _pilots_commands(self) -> tuple[ScriptCommand, ...]:
        """The flight as its pilot and ground station flew it (PX4): the sticks from PX4's
        boot on, the mission uploaded while PX4 boots, the mode it armed in just before the
        arm, then every commanded event at its log time (an airborne start: after the
        lead-in's arm and take-off, the mode in force at --start)."""
        origin = self.start_s - self.lead_in_s
        commands: list[ScriptCommand] = []
        if self.sticks is not None:
            commands.append(Track(at_s=0.0, track=self._lead_in_sticks()))
        if self.mission:
            commands.append(UploadMission(at_s=PX4_SETUP_S, items=self.mission))
        if self.start_height_m:
            takeoff = Takeoff(at_s=self.ready_s + 0.1, altitude_m=self.start_height_m)
            commands += [Arm(at_s=self.ready_s), takeoff]
        arms = {event.time_s for event in self.events if event.kind == "arm"}
        holds = dict(self.mission_holds)
        for event in self.events:
            if not event.commanded:
                continue
            at_s = event.time_s - origin
            if event.kind == "arm":
                if not self.start_height_m:  # an airborne start's lead-in armed already
                    commands.append(Arm(at_s=at_s))
            elif event.kind == "disarm":
                commands.append(Disarm(at_s=at_s, may_refuse=True))
            elif event.nav_state == NAV_STATE_OFFBOARD:
                velocity = _delayed(self.tracks["velocity"], self.lead_in_s)
                commands.append(Track(at_s=at_s, track=velocity))
            else:  # the mode it armed in is selected before the arm
                armed_in_it = event.time_s in arms
                at_s -= ARM_MODE_LEAD_S if armed_in_it else 0.0
                hold_s = holds.get(event.time_s) if event.nav_state == NAV_STATE_MISSION else None
                if hold_s is not None and not armed_in_it:  # a hold is in the air
                    commands.append(SetMode(at_s=at_s, nav_state=NAV_STATE_LOITER))
                    at_s += hold_s
                commands.append(SetMode(at_s=at_s, nav_state=event.nav_state))
        commands += [
            SetParam(at_s=time_s - origin, name="MPC_YAWRAUTO_MAX", value=limit)
            for time_s, limit in self.yaw_rate_limits
        ]
        commands += [SetHome(at_s=time_s - origin, home=home) for time_s, home in self.home_moves]
        return tuple(sorted(commands, key=lambda c: c.at_s))

    def _lead_in_sticks(self) -> SetpointTrack:
        """The sticks on the run's clock: before the log's start the first sample is held,
        except in an airborne start's lead-in, where they rest centred until --start."""
        assert self.sticks is not None
        track = _delayed(self.sticks, self.lead_in_s)
        if not self.start_height_m:
            return track
        centred = (0.0, 0.0, 0.0, 0.0)
        return SetpointTrack("manual", (0.0, self.lead_in_s - 1e-3, *track.times_s),
                             (centred, centred, *track.values))  # fmt: skip

    @property
    def autopilot_params(self) -> tuple[str, ...]:
        """The applied parameters as ``--param NAME=VALUE`` (repr: the exact float); PX4 also
        gets the rig's own stick input mode (:data:`STICK_PARAMETERS`)."""
        applied = self.parameters | self.learned | (STICK_PARAMETERS if self.px4 else {})
        return tuple(f"{name}={value!r}" for name, value in applied.items())

    @property
    def rig_parameters(self) -> dict[str, float]:
        """What the rig sets in PX4 whatever the log says (lockstep, SITL, the sticks)."""
        if not self.px4:
            return {}
        assert self.options.imu_hz is not None
        return RIG_PARAMETERS | lockstep_parameters(self.options.imu_hz) | STICK_PARAMETERS

    @property
    def notes(self) -> tuple[tuple[str, str], ...]:
        """Warnings for the run's log: what the replay could not take from the real flight."""
        notes = [("warn", f"replay: {warning}") for warning in self.log_warnings]
        if self.px4:
            notes += self._px4_notes()
        else:
            notes += [
                ("warn", f"replay: parameter {s.name} = {s.value:g} skipped ({s.reason})")
                for s in self.skipped
            ]
        if self.start_height_m:
            notes.append((
                "warn",
                f"replay: the log starts airborne at {self.start_s:.3f} s; the rig takes off to "
                f"its height ({self.start_height_m:.1f} m) in a {self.lead_in_s:.1f} s lead-in "
                f"and flies the log's setpoints from {self.start_s:.3f} s on its clock",
            ))  # fmt: skip
        elif self.arm_s is not None and self.arm_s != self.real_arm_s:
            notes.append(
                (
                    "warn",
                    f"replay: armed at {self.arm_s:.3f} s instead of "
                    f"{self.real_arm_s:.3f} s (the autopilot's start-up)",
                )
            )
        notes += [
            ("info", f"replay: the log's estimator reset its heading by "
                     f"{math.degrees(delta):+.1f}° at {time_s:.3f} s (a correction, not a turn)")
            for time_s, delta in self.heading_resets
        ]  # fmt: skip
        if self.heading_resets:
            notes.append((
                "info",
                f"replay: the vehicle starts at heading {math.degrees(self.yaw_rad):.1f}°, "
                "the log's at --start plus its estimator's resets",
            ))  # fmt: skip
        if self.initial_battery_voltage_v is None:
            notes.append(("warn", "replay: the battery starts full (no battery_status in the log)"))
        if self.air_density_kgpm3 is None:
            notes.append(("warn", "replay: ISA air (the log has no vehicle_air_data.rho)"))
        else:
            notes.append((
                "info",
                f"replay: air density {self.air_density_kgpm3:.3f} kg/m³ as logged (ISA "
                f"{self.temperature_offset_k:+.1f} K at home)",
            ))  # fmt: skip
        if self.wind is None:
            notes.append(("warn", f"replay: wind is zero ({self.wind_note})"))
        else:
            notes.append((
                "info",
                f"replay: wind {self.wind.describe()}, flown as a steady wind with Dryden "
                f"turbulence of W20 = {self.wind.speed_mps:.1f} m/s",
            ))  # fmt: skip
        return tuple(notes)

    def _px4_notes(self) -> list[tuple[str, str]]:
        """The firmware and where its parameters came from, skipped ones grouped by reason,
        PX4's boot before the log, and the log's events with what the replay does of each."""
        total = len(self.parameters) + len(self.skipped)
        notes = [("info", f"replay: the log was flown by {self.firmware}; PX4 SITL gets "
                          f"{len(self.parameters)} of its {total} parameters (replay.json lists "
                          "each one applied or skipped)")]  # fmt: skip
        by_reason: dict[str, list[str]] = {}
        for skipped in self.skipped:
            by_reason.setdefault(skipped.reason, []).append(skipped.name)
        notes += [
            ("warn", f"replay: skipped ({reason}): {', '.join(names)}")
            for reason, names in by_reason.items()
        ]
        notes += [
            ("info", f"replay: {name} = {value:.3f}, from the flight ({LEARNED[name]})")
            for name, value in self.learned.items()
        ]  # fmt: skip
        logged = {s.name: f"{s.value:g}" for s in self.skipped}
        notes.append((
            "info",
            f"replay: PX4 runs in lockstep at {self.options.imu_hz} Hz: IMU_GYRO_RATEMAX = "
            f"IMU_INTEG_RATE = {self.options.imu_hz} (the log's: "
            f"{logged.get('IMU_GYRO_RATEMAX', 'none')} and {logged.get('IMU_INTEG_RATE', 'none')})",
        ))  # fmt: skip
        notes.append((
            "info",
            f"replay: PX4 boots {PX4_BOOT_S:g} s before the log's start "
            f"({self.start_s - self.lead_in_s:.3f} s on the log's clock) to be ready to arm",
        ))  # fmt: skip
        notes += [("info", f"replay: {note}") for note in self.mission_notes]
        notes += [
            ("info", f"replay: after the switch to Mission at {time_s:.3f} s the real "
                     f"navigator held the vehicle where it was for {hold_s:.3f} s (a loiter) "
                     "before the mission's first item: flown as Hold, then Mission")
            for time_s, hold_s in self.mission_holds
        ]  # fmt: skip
        notes += [
            ("info", f"replay: the real PX4 moved its home at {time_s:.3f} s to "
                     f"{home.alt_amsl_m:.2f} m AMSL: set then with DO_SET_HOME")
            for time_s, home in self.home_moves
        ]  # fmt: skip
        notes += [("info", f"replay: log event {event.describe()}") for event in self.events]
        return notes

    def scenario(self, vehicle_path: Path) -> Scenario:
        """The scenario this replay flies, with its vehicle file at ``vehicle_path``."""
        environment = Environment()
        if self.home is not None:
            environment = Environment(
                home=self.home, magnetic_field=MagneticField.from_wmm(self.home, WMM_EPOCH_YEAR)
            )
        if self.wind is not None:
            # W20 (the Dryden intensity) is by definition the mean wind speed at 6 m
            wind = Wind(steady_ned_mps=self.wind.steady_ned_mps, wind_at_6m_mps=self.wind.speed_mps)
            environment = replace(environment, wind=wind)
        environment = replace(environment, temperature_offset_k=self.temperature_offset_k)
        try:
            rates = Rates(imu_hz=self.options.imu_hz or Rates().imu_hz)
        except FieldError as error:  # an IMU rate the model cannot step
            reason = f"--imu-hz = {error.value}: {error.reason}"
            raise ReplayError(f"{self.log_path}: {reason}") from None
        return Scenario(
            name=f"replay-{self.log_path.stem}",
            description=f"replay of {self.log_path.name} "
            f"({'as its pilot flew it' if self.px4 else f'{self.drive} drive'}), "
            f"{self.start_s:.3f}-{self.end_s:.3f} s",
            vehicle=str(vehicle_path),
            duration_s=self.end_s - self.start_s + self.lead_in_s,
            seed=self.options.seed,
            sensor_layer=self.options.sensor_layer,
            rates=rates,
            environment=environment,
            start=StartPose(
                yaw_deg=math.degrees(self.yaw_rad),
                clock_s=self.start_s - self.lead_in_s,
                battery_voltage_v=self.initial_battery_voltage_v,
            ),
            motor_pwm_range_us=self.motor_pwm_range_us,
            commands=tuple(c for c in self.commands if not isinstance(c, CodeCommand)),
            tracks=tuple(c for c in self.commands if isinstance(c, CodeCommand)),
            source=str(self.log_path),
        )

    def summary(self) -> dict[str, Any]:
        """``replay.json``: everything the replay took from the log, skipped or assumed."""
        return {
            "log": str(self.log_path),
            "drive": self.drive,
            "start_s": self.start_s,
            "end_s": self.end_s,
            "window_s": list(self.window_s) if self.window_s else None,
            "vehicle": self.vehicle,
            "vehicle_reason": self.vehicle_reason,
            "cell_count": self.cell_count,
            "motor_pwm_range_us": list(self.motor_pwm_range_us),
            "initial_battery_voltage_v": self.initial_battery_voltage_v,
            "autopilot": self.options.autopilot,
            "log_firmware": self.firmware,
            "parameters_applied": self.parameters,
            "parameters_skipped": [
                {"name": s.name, "value": s.value, "reason": s.reason} for s in self.skipped
            ],
            "parameters_unknown_count": self.unknown_parameter_count,
            "parameters_set_by_the_rig": self.rig_parameters,
            "parameters_learned_in_the_flight": self.learned,
            "yaw_rate_limits": [list(pair) for pair in self.yaw_rate_limits],
            "home_moves": [
                {
                    "time_s": time_s,
                    "lat_deg": home.lat_deg,
                    "lon_deg": home.lon_deg,
                    "alt_amsl_m": home.alt_amsl_m,
                }
                for time_s, home in self.home_moves
            ],
            "log_warnings": list(self.log_warnings),
            "start_yaw_deg": math.degrees(self.yaw_rad),
            "heading_resets": [
                {"time_s": time_s, "delta_deg": math.degrees(delta)}
                for time_s, delta in self.heading_resets
            ],
            "home": None
            if self.home is None
            else {
                "lat_deg": self.home.lat_deg,
                "lon_deg": self.home.lon_deg,
                "alt_amsl_m": self.home.alt_amsl_m,
            },
            "wind": self.wind.summary() if self.wind else f"zero: {self.wind_note}",
            "air_density_kgpm3": self.air_density_kgpm3,
            "temperature_offset_k": self.temperature_offset_k,
            "real_arm_s": self.real_arm_s,
            "arm_s": self.arm_s,
            "disarm_s": self.disarm_s,
            "lead_in_s": self.lead_in_s,
            "events": [asdict(event) for event in self.events],
            "mission": [  # yaw NaN (the autopilot's choice) as null: JSON has no NaN
                asdict(item) | {"param4": None if math.isnan(item.param4) else item.param4}
                for item in self.mission
            ],
            "mission_notes": list(self.mission_notes),
            "mission_holds": [list(hold) for hold in self.mission_holds],
            "seed": self.options.seed,
            "sensor_layer": self.options.sensor_layer,
            "imu_hz": self.options.imu_hz,
        }


def plan_replay(log_path: str | Path, options: ReplayOptions = ReplayOptions()) -> Replay:
    """Configure a replay of ``log_path`` (no flying); raises :class:`ReplayError`."""
    path = Path(log_path)
    options = _checked(options)
    px4 = options.autopilot == "px4"
    log = _FlightLog(path)
    start_s = log.first_s if options.start_s is None else options.start_s
    end_s = log.last_s if options.end_s is None else options.end_s
    for flag, value in (("--start", start_s), ("--end", end_s)):
        if not log.first_s <= value <= log.last_s:
            raise ReplayError(
                f"{path}: {flag} {value:g} s is outside the log "
                f"({log.first_s:.3f}-{log.last_s:.3f} s)"
            )
    if end_s <= start_s + AUTOPILOT_READY_S:
        raise ReplayError(
            f"{path}: --end {end_s:g} s must come more than "
            f"{AUTOPILOT_READY_S:g} s after --start {start_s:g} s"
        )
    window = _window(path, options, start_s, end_s)
    if px4:
        options = _with_px4_imu_rate(options, log.parameters)
    ready_s = PX4_BOOT_S if px4 else AUTOPILOT_READY_S
    start_height_m, lead_in_s = 0.0, (PX4_BOOT_S if px4 else 0.0)
    if not log.landed_at(start_s):
        start_height_m = log.height_at(start_s)
        lead_in_s = ready_s + start_height_m / TAKEOFF_CLIMB_MPS + LEAD_IN_SETTLE_S
    vehicle, reason = _vehicle_choice(path, log, options.vehicle)
    vehicle_document, cell_count, battery = _vehicle_document(vehicle, log)
    pwm_range_us = motor_pwm_range(log.parameters, path)
    try:
        PwmOutput(1, 400, pwm_range_us)  # the rig's outputs span what the ESC input does
    except ValueError as error:
        raise ReplayError(f"{path}: motor outputs' PWM_*_MIN/MAXn: {error}") from None
    battery_voltage_v = log.battery_voltage_v(start_s)
    if battery_voltage_v is not None:
        try:
            charge_used_for_voltage_c(battery, battery_voltage_v)
        except ModelInputError as error:
            raise ReplayError(
                f"{path}: battery_status.voltage_v at --start {start_s:g} s: {error}"
            ) from None
    if px4:
        parameters, skipped, unknown = _px4_parameters(log.parameters, options)
    else:
        parameters, skipped, unknown = _parameters(log.parameters)
    real_arm_s, disarm_s = log.arming(start_s, end_s)
    if start_height_m:  # armed in the air: the lead-in arms as soon as the autopilot is ready
        real_arm_s = arm_s = start_s - lead_in_s + ready_s
    elif px4:  # PX4 booted early enough to arm at the log's time
        arm_s = real_arm_s
    else:
        arm_s = None if real_arm_s is None else max(real_arm_s, start_s + AUTOPILOT_READY_S)
    if window is not None and (arm_s is None or window[0] <= arm_s):
        raise ReplayError(
            f"{path}: --window starts at {window[0]:g} s, before the vehicle is "
            f"armed ({'never' if arm_s is None else f'{arm_s:.3f} s'})"
        )
    events = log.timeline(start_s, end_s) if px4 else ()
    offboard = any(e.commanded and e.nav_state == NAV_STATE_OFFBOARD for e in events)
    tracks = {"velocity": log.track("velocity", start_s, end_s)} if not px4 or offboard else {}
    if options.drive != "velocity":
        tracks[options.drive] = log.track(options.drive, start_s, end_s)
    home = log.home()
    mission: tuple[MissionItem, ...] = ()
    mission_notes: tuple[str, ...] = ()
    mission_holds: tuple[tuple[float, float], ...] = ()
    home_moves = log.home_moves(home, real_arm_s, disarm_s or end_s) if px4 else ()
    if any(e.commanded and e.nav_state == NAV_STATE_MISSION for e in events):
        mission, mission_notes = log.flown_mission(home, bool(home_moves))
        mission_holds = log.mission_start_holds(events)
    heading_resets = log.heading_resets(start_s, end_s)
    sticks = None
    if px4:
        sticks = log.sticks(start_s, end_s)
        manual = sorted({e.nav_state for e in events if e.commanded} & STICK_MODES)
        if sticks is None and manual:
            raise ReplayError(
                f"{path}: topic manual_control_setpoint (the pilot's sticks, which PX4 needs "
                f"in mode {_mode_name(manual[0])}) is not in the log"
            )
    replay = Replay(
        log_path=path,
        drive=options.drive,
        start_s=start_s,
        end_s=end_s,
        window_s=window,
        vehicle=vehicle,
        vehicle_reason=reason,
        vehicle_document=vehicle_document,
        cell_count=cell_count,
        motor_pwm_range_us=pwm_range_us,
        initial_battery_voltage_v=battery_voltage_v,
        parameters=parameters,
        skipped=skipped,
        unknown_parameter_count=unknown,
        yaw_rad=math.remainder(
            log.heading_at(start_s) + sum(delta for _, delta in heading_resets), math.tau
        ),
        heading_resets=heading_resets,
        home=home,
        real_arm_s=real_arm_s,
        arm_s=arm_s,
        disarm_s=disarm_s,
        tracks=tracks,
        options=options,
        log_warnings=log.warnings,
        start_height_m=start_height_m,
        lead_in_s=lead_in_s,
        events=events,
        mission=mission,
        mission_notes=mission_notes,
        mission_holds=mission_holds,
        sticks=sticks,
        firmware=log.firmware,
        learned=_learned_parameters(log, parameters, events),
        yaw_rate_limits=_yaw_rate_limits(log, parameters, start_s, end_s) if px4 else (),
        home_moves=home_moves,
        **_wind(path, vehicle_document, vehicle),
        **_air(log, home, start_s, end_s),
    )
    replay.scenario(Path(vehicle))  # a bad rate fails here, before a run folder exists
    return replay


def _learned_parameters(
    log: _FlightLog, applied: Mapping[str, float], events: tuple[FlightEvent, ...]
) -> dict[str, float]:
    """The parameters that give this SITL the log's own behaviour where PX4 changed it
    between versions (the 8S quad's v1.16 and the X500's v1.17 against the v1.14 SITL).

    Where the replay flew a stick-throttle mode, the log's stick → thrust map:

    - MPC_THR_HOVER = the log's hover-thrust estimate when its PX4 ran on it (MPC_USE_HTE):
      v1.16 puts the centre stick there in Stabilized (0.655 in hover; its MPC_THR_HOVER is
      0.5), v1.14 at MPC_THR_HOVER; without it the centred stick gives the SITL 0.50 where
      the real one gave 0.66, and it never lifts. The estimate converges in the first seconds
      airborne, so its median over the flight is taken.
    - MPC_MANTHR_MIN = the log's thrust set-point with the stick at the bottom (0 there:
      armed, the motors stopped), which v1.14 holds at MPC_MANTHR_MIN (0.08: the SITL's
      rotors idled through the log's rest).

    In the climb-rate modes PX4 flies on its own estimate, so nothing is set there.

    Where it flew Mission and its PX4 limited the yaw acceleration in auto modes
    (MPC_YAWRAUTO_ACC, 20°/s² in the X500's v1.17) but this build has no such limit:

    - MPC_YAWRAUTO_MAX = the peak yaw rate the real vehicle reached in Mission (the X500's
      33.6°/s against its MPC_YAWRAUTO_MAX of 60). v1.14 turns at MPC_YAWRAUTO_MAX from
      the turn's start: it handed the X500's pilot a heading 73° from the real one at the
      take-over, 33° with the real peak rate as its limit."""
    learned = {}
    if any(e.commanded and e.nav_state in MANUAL_THRUST_MODES for e in events):
        estimate = log.hover_thrust()
        if (
            "MPC_THR_HOVER" in applied
            and log.parameters.get("MPC_USE_HTE")
            and estimate is not None
        ):
            learned["MPC_THR_HOVER"] = estimate
        bottom = log.thrust_at_bottom_stick()
        if "MPC_MANTHR_MIN" in applied and bottom is not None:
            learned["MPC_MANTHR_MIN"] = bottom
    if _yaw_acceleration_limited(log, applied):
        peak = log.peak_yaw_rate_deg_s(NAV_STATE_MISSION)
        if peak is not None and 0.0 < peak < applied["MPC_YAWRAUTO_MAX"]:
            learned["MPC_YAWRAUTO_MAX"] = round(peak, 1)
    return learned


def _yaw_acceleration_limited(log: _FlightLog, applied: Mapping[str, float]) -> bool:
    """The log's PX4 limited the yaw acceleration in auto modes, this SITL cannot."""
    return (
        "MPC_YAWRAUTO_ACC" in log.parameters
        and "MPC_YAWRAUTO_ACC" not in applied
        and "MPC_YAWRAUTO_MAX" in applied
    )


def _yaw_rate_limits(
    log: _FlightLog, applied: Mapping[str, float], start_s: float, end_s: float
) -> tuple[tuple[float, float], ...]:
    """MPC_YAWRAUTO_MAX over the flight (log s, °/s) for a SITL without the log's yaw
    acceleration limit: in auto modes, the rate the real planner allowed itself.

    The log's PX4 (v1.17 on the X500) ramps a turn's yaw rate at MPC_YAWRAUTO_ACC (20°/s²);
    v1.14 turns at MPC_YAWRAUTO_MAX from the turn's first step. Its limit set to the real
    ``trajectory_setpoint.yawspeed`` (the larger of each sample and the next, so it never
    lags the real ramp) gives it the real turn. The real rate is followed only down to
    :data:`YAW_RATE_LIMIT_FLOOR_DEG_S`, and a new value is sent when it moved by
    :data:`YAW_RATE_LIMIT_STEP_DEG_S` (each is a PARAM_SET conversation)."""
    if not _yaw_acceleration_limited(log, applied):
        return ()
    limits: list[tuple[float, float]] = []
    for time_s, rates in log.auto_yaw_rates_deg_s(AUTO_YAW_MODES, start_s, end_s):
        envelope = np.maximum(rates, np.append(rates[1:], rates[-1]))
        for k, (sample_s, rate) in enumerate(zip(time_s, envelope, strict=True)):
            limit = round(max(float(rate), YAW_RATE_LIMIT_FLOOR_DEG_S), 1)
            if k == 0 or abs(limit - limits[-1][1]) >= YAW_RATE_LIMIT_STEP_DEG_S:
                limits.append((float(sample_s), limit))
    return tuple(limits)


def _wind(path: Path, vehicle_document: dict[str, Any], vehicle: str) -> dict[str, Any]:
    """``wind`` and ``wind_note`` of the replay: the log's hover tilt through the vehicle's
    drag, or none, with the reason (no hover, no attitude)."""
    from rig.apps.wind import WindEstimateError, estimate_wind  # wind → identify → replay

    try:
        return {"wind": estimate_wind(path, vehicle_from_dict(vehicle_document, vehicle))}
    except WindEstimateError as error:
        return {"wind": None, "wind_note": f"no estimate: {error}"}


def _air(log: _FlightLog, home: GeoPoint | None, start_s: float, end_s: float) -> dict[str, Any]:
    """The log's mean air density and the ISA temperature offset that gives it at home (the
    model has ISA pressure; density is what thrust and drag feel)."""
    density = log.air_density(start_s, end_s)
    if density is None:
        return {}
    altitude = (home or PX4_DEFAULT_HOME).alt_amsl_m
    temperature_k = isa_pressure_pa(altitude) / (DRY_AIR_GAS_CONSTANT * density)
    return {
        "air_density_kgpm3": density,
        "temperature_offset_k": temperature_k - isa_temperature_k(altitude),
    }


def _checked(options: ReplayOptions) -> ReplayOptions:
    """The options with the IMU rate resolved; a bad one fails in one line naming its flag."""
    if options.drive not in DRIVES:
        raise ReplayError(f"--drive {options.drive!r}: expected one of {', '.join(DRIVES)}")
    if options.sensor_layer not in list(SensorLayer):
        raise ReplayError(
            f"--sensor-layer {options.sensor_layer!r}: expected one of {', '.join(SensorLayer)}"
        )
    if options.autopilot not in AUTOPILOTS:
        raise ReplayError(
            f"--autopilot {options.autopilot!r}: expected one of {', '.join(AUTOPILOTS)}"
        )
    if options.autopilot != "px4":
        return replace(options, imu_hz=options.imu_hz or Rates().imu_hz)
    if options.drive != "velocity" or options.window_s is not None:
        raise ReplayError(
            "--drive and --window choose the reference autopilot's loop; PX4 flies the log "
            "as its pilot flew it (sticks, modes, mission)"
        )
    if options.imu_hz is not None:
        try:
            check_imu_rate(options.imu_hz)
        except RigError as error:
            raise ReplayError(f"--imu-hz {options.imu_hz}: {error}") from None
    return options


def _with_px4_imu_rate(options: ReplayOptions, logged: Mapping[str, float]) -> ReplayOptions:
    """Without --imu-hz, PX4 runs its rate loop at the log's IMU_GYRO_RATEMAX when it can
    keep lockstep there (PX4_IMU_HZ otherwise)."""
    if options.imu_hz is not None:
        return options
    rate = int(logged.get("IMU_GYRO_RATEMAX", 0))
    try:
        check_imu_rate(rate)
        Rates(imu_hz=rate)
    except (RigError, FieldError):
        rate = PX4_IMU_HZ
    return replace(options, imu_hz=rate)


def _px4_parameters(
    logged: dict[str, float | int], options: ReplayOptions
) -> tuple[dict[str, float | int], tuple[SkippedParameter, ...], int]:
    """The log's parameters PX4 SITL takes, the skipped ones with why, and how many this
    build does not have; the build (--px4, $PX4_DIR) is needed for its parameter list."""
    try:
        build = find_px4(options.px4_dir)
        known = None if build is None else build_parameters(build)
    except Px4NotFound as error:
        raise ReplayError(str(error)) from None
    if known is None:
        raise ReplayError(
            "--autopilot px4 needs PX4's build (--px4 DIR or $PX4_DIR): its parameter list "
            "decides which of the log's parameters PX4 takes"
        )
    applied, skipped = sitl_parameters(logged, known)
    return (
        {name: logged[name] for name in applied},
        tuple(SkippedParameter(*entry) for entry in skipped),
        sum(1 for name in logged if name not in known),
    )


def run_replay(
    replay: Replay,
    run_options: RunOptions | None = None,
    progress: Callable[[Progress], None] | None = None,
) -> RunResult:
    """Fly a planned replay; the run folder also gets ``vehicle.toml`` and ``replay.json``.

    ``run_options`` says where and how (instance, folder, timeouts); its ``--param`` values
    are applied after the log's, so they win. The autopilot and PX4's build are the plan's.
    """
    run_options = run_options or RunOptions()
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    default_dir = RUNS_DIR / f"replay-{replay.log_path.stem}-{stamp}"
    run_dir = claim_run_dir(run_options.out_dir or default_dir, run_options.force)
    vehicle_path = (run_dir / "vehicle.toml").resolve()
    vehicle_path.write_text(tomli_w.dumps(replay.vehicle_document))
    (run_dir / "replay.json").write_text(json.dumps(replay.summary(), indent=2) + "\n")
    scenario = replay.scenario(vehicle_path)
    flown = replace(
        run_options,
        autopilot=replay.options.autopilot,
        px4_dir=replay.options.px4_dir or run_options.px4_dir,
        out_dir=run_dir,
        sensor_layer=replay.options.sensor_layer,
        autopilot_params=(*replay.autopilot_params, *run_options.autopilot_params),
        notes=(*replay.notes, *run_options.notes),
    )
    return run_scenario(scenario, flown, progress)


# -- the log ---------------------------------------------------------------------------------


class _FlightLog:
    """The parts of a real ULog a replay reads, with one-line errors naming file and field."""

    def __init__(self, path: Path) -> None:
        self.path = path
        if not path.is_file():
            raise ReplayError(f"{path}: flight log not found")
        try:
            ulog, self.warnings = read_ulog(path)  # pyulog's warnings become the run's notes
        except CredibilityError as error:
            raise ReplayError(str(error)) from None
        self.topics = {d.name: d.data for d in ulog.data_list if d.multi_id == 0}
        if not self.topics:
            raise ReplayError(f"{path}: the ULog holds no logged data")
        self.parameters: dict[str, float | int] = dict(ulog.initial_parameters)
        self.firmware = firmware_name(ulog.msg_info_dict)
        # A topic's first sample may be its last one before the logger started (published
        # at boot: the 8S quad's actuator_outputs at 0.6 s, logging from 104.9 s); the
        # header's start time bounds the logged span (0 in some logs, the X500's).
        first_us = min(float(d.data["timestamp"][0]) for d in ulog.data_list)
        self.first_s = max(first_us, float(ulog.start_timestamp)) / 1e6
        self.last_s = max(float(d.data["timestamp"][-1]) for d in ulog.data_list) / 1e6

    def topic(self, name: str, why: str, fields: tuple[str, ...] = ()) -> dict[str, NDArray[Any]]:
        """Topic ``name`` holding ``fields``; a log without them is one line saying ``why``
        they were needed (a damaged or older log)."""
        if name not in self.topics:
            raise ReplayError(f"{self.path}: topic {name} ({why}) is not in the log")
        data = self.topics[name]
        missing = [field for field in fields if field not in data]
        if missing:
            raise ReplayError(f"{self.path}: topic {name} has no field {missing[0]} ({why})")
        return data

    def _at(self, name: str, field: str, time_s: float, why: str) -> float:
        """The field's value in force at ``time_s`` (the first sample's before the topic starts)."""
        data = self.topic(name, why, (field,))
        index = max(int(np.searchsorted(data["timestamp"] / 1e6, time_s, "right")) - 1, 0)
        return float(data[field][index])

    def landed_at(self, time_s: float) -> bool:
        return bool(self._at("vehicle_land_detected", "landed", time_s, "landed at --start"))

    def height_at(self, time_s: float) -> float:
        """Height above the estimator's origin (where it booted, on the ground) at ``time_s``."""
        height = -self._at("vehicle_local_position", "z", time_s, "the height at an airborne start")
        if not math.isfinite(height) or height <= 0:
            raise ReplayError(
                f"{self.path}: vehicle_local_position.z = {-height:g} m at {time_s:g} s: no "
                "height to take off to for an airborne start"
            )
        return height

    def altitude_at(self, time_s: float) -> float | None:
        """The vehicle's altitude AMSL in force at ``time_s`` (None: not logged)."""
        return self._logged_at("vehicle_global_position", "alt", time_s)

    def home_altitude_at(self, time_s: float) -> float | None:
        """The real PX4's home altitude AMSL in force at ``time_s`` (None: not logged)."""
        return self._logged_at("home_position", "alt", time_s)

    def _logged_at(self, name: str, field: str, time_s: float) -> float | None:
        """:meth:`_at` for what a replay can do without: None when the topic, the field or
        a finite value is missing."""
        data = self.topics.get(name)
        if data is None or field not in data or not len(data["timestamp"]):
            return None
        index = max(int(np.searchsorted(data["timestamp"] / 1e6, time_s, "right")) - 1, 0)
        value = float(data[field][index])
        return value if math.isfinite(value) else None

    def battery_voltage_v(self, time_s: float) -> float | None:
        """The pack's voltage at ``time_s`` (None: no battery_status). The replay starts
        landed and disarmed, where only the avionics load the pack: ≈ its open-circuit
        voltage (R·I is mV)."""
        if "battery_status" not in self.topics:
            return None
        return self._at("battery_status", "voltage_v", time_s, "the starting battery voltage")

    def heading_at(self, time_s: float) -> float:
        heading = self._at("vehicle_local_position", "heading", time_s, "the start heading")
        if not math.isfinite(heading):
            raise ReplayError(
                f"{self.path}: vehicle_local_position.heading is {heading} at "
                f"{time_s:g} s (the start heading)"
            )
        return heading

    def heading_resets(self, start_s: float, end_s: float) -> tuple[tuple[float, float], ...]:
        """(log s, rad): each jump the estimator made in its heading after ``start_s``.

        A reset is the estimator correcting itself (EKF2's in-flight magnetometer alignment
        once airborne, away from the ground's iron; a switch of estimator instance), not the
        vehicle turning: the X500's heading jumps 8.9° at 415.1 s, 2 s after take-off. Empty
        where the log predates ``heading_reset_counter``.
        """
        data = self.topics.get("vehicle_local_position", {})
        if "heading_reset_counter" not in data or "delta_heading" not in data:
            return ()
        time_s = data["timestamp"] / 1e6
        jumps = np.flatnonzero(np.diff(data["heading_reset_counter"]) != 0) + 1
        return tuple(
            (float(time_s[i]), float(data["delta_heading"][i]))
            for i in jumps
            if start_s < time_s[i] <= end_s and math.isfinite(data["delta_heading"][i])
        )

    def air_density(self, start_s: float, end_s: float) -> float | None:
        """Mean vehicle_air_data.rho over the replay (None: not logged or not plausible)."""
        data = self.topics.get("vehicle_air_data")
        if data is None or "rho" not in data:
            return None
        time_s = data["timestamp"] / 1e6
        rho = data["rho"][(time_s >= start_s) & (time_s <= end_s)]
        rho = rho[np.isfinite(rho) & (rho > 0.5) & (rho < 1.5)]  # air from sea level to 5 km
        return float(rho.mean()) if rho.size else None

    def peak_yaw_rate_deg_s(self, nav_state: int) -> float | None:
        """The largest |body z rate| (°/s, ``vehicle_angular_velocity``) while PX4 flew
        ``nav_state`` (``vehicle_status``); None without either topic or such a stretch."""
        status = self.topics.get("vehicle_status")
        rates = self.topics.get("vehicle_angular_velocity")
        if status is None or rates is None or "nav_state" not in status or "xyz[2]" not in rates:
            return None
        index = np.searchsorted(status["timestamp"], rates["timestamp"], "right") - 1
        flown = (index >= 0) & (status["nav_state"][np.clip(index, 0, None)] == nav_state)
        yaw_rate = np.abs(rates["xyz[2]"][flown].astype(float))
        yaw_rate = yaw_rate[np.isfinite(yaw_rate)]
        return float(np.degrees(yaw_rate.max())) if yaw_rate.size else None

    def auto_yaw_rates_deg_s(
        self, nav_states: frozenset[int], start_s: float, end_s: float
    ) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Per stretch flown in ``nav_states`` inside ``[start_s, end_s)``: the log
        seconds and |``trajectory_setpoint.yawspeed``| (°/s, NaN as 0: no yaw rate set),
        the first sample moved back to the mode switch; none without either topic."""
        status = self.topics.get("vehicle_status")
        setpoints = self.topics.get("trajectory_setpoint")
        if status is None or setpoints is None or "yawspeed" not in setpoints:
            return []
        nav = status["nav_state"]
        switched = np.maximum.accumulate(np.where(np.diff(nav, prepend=-1) != 0,
                                                  np.arange(len(nav)), 0))  # fmt: skip
        index = np.clip(np.searchsorted(status["timestamp"], setpoints["timestamp"], "right") - 1,
                        0, None)  # fmt: skip
        time_s = setpoints["timestamp"] / 1e6
        inside = np.isin(nav[index], list(nav_states)) & (time_s >= start_s) & (time_s < end_s)
        rates = np.nan_to_num(np.degrees(np.abs(setpoints["yawspeed"].astype(float))))
        edges = np.flatnonzero(np.diff(np.r_[0, inside.astype(int), 0]))
        stretches = []
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            times = time_s[a:b].copy()
            times[0] = max(status["timestamp"][switched[index[a]]] / 1e6, start_s)
            stretches.append((times, rates[a:b]))
        return stretches

    def hover_thrust(self) -> float | None:
        """Median of the valid hover_thrust_estimate.hover_thrust (None: none logged)."""
        data = self.topics.get("hover_thrust_estimate")
        if data is None or "hover_thrust" not in data:
            return None
        thrust = data["hover_thrust"][_valid(data)]
        thrust = thrust[np.isfinite(thrust) & (thrust > 0) & (thrust < 1)]
        return float(np.median(thrust)) if thrust.size else None

    def thrust_at_bottom_stick(self) -> float | None:
        """Median collective thrust set-point while the throttle stick sat at its bottom
        (within 1 %), None without such samples or either topic."""
        sticks = self.topics.get("manual_control_setpoint")
        thrust = self.topics.get("vehicle_thrust_setpoint")
        if sticks is None or thrust is None or "throttle" not in sticks or "xyz[2]" not in thrust:
            return None
        index = np.searchsorted(sticks["timestamp"], thrust["timestamp"], "right") - 1
        held = sticks["throttle"][np.clip(index, 0, None)]
        bottom = (index >= 0) & (held <= -0.99)
        return float(np.median(-thrust["xyz[2]"][bottom])) if bottom.any() else None

    def home(self) -> GeoPoint | None:
        """The first valid home position (the flying site), None without one."""
        data = self.topics.get("home_position")
        if data is None or not len(data["timestamp"]):
            return None
        lat, lon, alt = (float(data[k][0]) for k in ("lat", "lon", "alt"))
        if not (math.isfinite(lat + lon + alt) and -90 <= lat <= 90 and -180 <= lon <= 180):
            return None
        return GeoPoint(lat, lon, alt)

    def home_moves(
        self, home: GeoPoint | None, armed_s: float | None, disarmed_s: float
    ) -> tuple[tuple[float, GeoPoint], ...]:
        """Where and when the real PX4 moved its home while armed (``armed_s`` to
        ``disarmed_s``, log seconds): PX4 sets it again at take-off, on its estimate then
        (the X500's EKF2 had just put its height 1.7 m up: home 1.82 m above the one it
        armed at), and Land and Return descend, slow down and land by the height above it.
        Moves of less than :data:`HOME_MOVED_M` are left out."""
        data = self.topics.get("home_position")
        if home is None or armed_s is None or data is None:
            return ()
        moves: list[tuple[float, GeoPoint]] = []
        previous = home
        for k in range(1, len(data["timestamp"])):
            time_s = float(data["timestamp"][k]) / 1e6
            point = GeoPoint(*(float(data[f][k]) for f in ("lat", "lon", "alt")))
            if not (armed_s < time_s < disarmed_s and math.isfinite(point.alt_amsl_m)):
                continue
            north, east, down = geodetic_to_ned(point.lat_deg, point.lon_deg, point.alt_amsl_m,
                                                previous.lat_deg, previous.lon_deg,
                                                previous.alt_amsl_m)  # fmt: skip
            if max(abs(north), abs(east), abs(down)) >= HOME_MOVED_M:
                moves.append((time_s, point))
                previous = point
        return tuple(moves)

    def arming(self, start_s: float, end_s: float) -> tuple[float | None, float | None]:
        """The real arm and disarm times clipped to ``[start_s, end_s)`` (None: not in it).

        The arm time is ``vehicle_status.armed_time`` of the first armed sample: the logger
        starts on arming, so the first sample comes after it.
        """
        status = self.topic("vehicle_status", "arming times", ("arming_state",))
        times_s = status["timestamp"] / 1e6
        armed = status["arming_state"] == ARMING_STATE_ARMED
        if not armed.any():
            return None, None
        first = int(np.argmax(armed))
        arm_s = _arm_time_s(status, first)
        disarmed_after = np.nonzero(~armed[first:])[0]
        disarm_s = float(times_s[first + disarmed_after[0]]) if len(disarmed_after) else None
        arm_s = max(arm_s, start_s) if arm_s < end_s else None
        if disarm_s is not None and not start_s < disarm_s < end_s:
            disarm_s = None
        return arm_s, disarm_s

    def timeline(self, start_s: float, end_s: float) -> tuple[FlightEvent, ...]:
        """The flight's arm, disarm and mode switches in ``[start_s, end_s)``, and what PX4
        did by itself, from ``vehicle_status``; the mode in force at ``start_s`` comes first.

        The pilot's mode is ``nav_state_user_intention`` (``nav_state`` in a PX4 before
        1.14): a replay commands it while armed (and the mode armed in), never a mode PX4
        chose itself in a failsafe, nor the mode it returns to after an automatic disarm.
        """
        status = self.topic(
            "vehicle_status", "the flight's arm, disarm and mode switches",
            ("nav_state", "arming_state"),
        )  # fmt: skip
        times_s = status["timestamp"] / 1e6
        nav = status["nav_state"].astype(int)
        intended = status.get("nav_state_user_intention", status["nav_state"]).astype(int)
        armed = status["arming_state"] == ARMING_STATE_ARMED
        reasons = status.get("latest_disarming_reason")
        failsafe = status.get("failsafe", np.zeros(len(nav)))
        events: list[FlightEvent] = []
        flown = False
        for k in range(len(times_s)):
            time_s, mode = float(times_s[k]), int(intended[k])
            if armed[k] != (armed[k - 1] if k else False):
                events.append(self._arming_event(status, k, armed[k], reasons))
                time_s = events[-1].time_s  # the mode it armed in, or left to after a disarm
            flown = flown or bool(armed[k])
            if not k or mode != intended[k - 1]:
                if mode not in PX4_MODES:
                    commanded, detail = False, "not a mode a ground station selects"
                elif armed[k] or not flown:
                    commanded, detail = True, "the pilot's"
                else:
                    commanded, detail = False, "after the disarm: PX4's own"
                events.append(FlightEvent(time_s, "mode", mode, commanded, detail))
            elif nav[k] != nav[k - 1]:
                cause = "failsafe" if failsafe[k] else "back from a failsafe"
                flown_mode = int(nav[k]) in PX4_MODES and bool(armed[k])
                detail = (f"{cause}: commanded, so the sticks act in the mode the vehicle flew"
                          if flown_mode else f"{cause}: PX4 decides again")  # fmt: skip
                events.append(FlightEvent(float(times_s[k]), "autopilot", int(nav[k]),
                                          flown_mode, detail))  # fmt: skip
        return _clipped(events, start_s, end_s)

    def _arming_event(
        self, status: dict[str, NDArray[Any]], k: int, armed: bool, reasons: NDArray[Any] | None
    ) -> FlightEvent:
        if armed:  # the logger starts on arming: the arm comes before the first sample
            return FlightEvent(_arm_time_s(status, k), "arm", None, True, "the pilot's")
        reason = None if reasons is None else int(reasons[k])
        whose = ("the pilot's" if reason is None or reason in PILOT_DISARM_REASONS else
                 f"PX4's own, reason {reason}")  # fmt: skip
        detail = f"{whose}; refused unless PX4 has landed"
        return FlightEvent(float(status["timestamp"][k]) / 1e6, "disarm", None, True, detail)

    def sticks(self, start_s: float, end_s: float) -> SetpointTrack | None:
        """The pilot's sticks (``manual_control_setpoint`` roll, pitch, yaw, throttle, PX4's
        −1..1) in run seconds from ``start_s``, first the ones in force then; None without."""
        data = self.topics.get("manual_control_setpoint")
        fields = ("roll", "pitch", "yaw", "throttle")
        if data is None or any(f not in data for f in fields):
            return None
        valid = _valid(data)
        if not valid.any():
            return None
        times_s = data["timestamp"][valid] / 1e6
        values = _hold_last_finite(np.column_stack([data[f][valid].astype(float) for f in fields]))
        inside = (times_s > start_s) & (times_s < end_s)
        before = np.nonzero(times_s <= start_s)[0]
        first = values[before[-1]] if len(before) else values[0]
        return SetpointTrack(
            "manual",
            (0.0, *(float(t) - start_s for t in times_s[inside])),
            tuple(tuple(float(v) for v in row) for row in (first, *values[inside])),
        )

    def flown_mission(
        self, home: GeoPoint | None, home_replayed: bool = False
    ) -> tuple[tuple[MissionItem, ...], tuple[str, ...]]:
        """The mission as PX4 flew it, uploadable as MISSION_ITEM_INT, and what the log
        could not say about it. ``navigator_mission_item`` holds for each sequence number
        the last item logged with it (one the navigator inserted, such as a climb before the
        first waypoint, is logged before it); positions and heights are put where the real
        vehicle flew them (:func:`_mission_positions`, :meth:`_mission_altitudes`)."""
        data = self.topics.get("navigator_mission_item")
        if data is None or not len(data["timestamp"]):
            return (), ("the log flew Mission mode but holds no navigator_mission_item: no "
                        "mission to upload",)  # fmt: skip
        missing = [field for field in _MISSION_ITEM_FIELDS if field not in data]
        if missing:
            return (), (f"navigator_mission_item has no field {missing[0]}: no mission to "
                        "upload",)  # fmt: skip
        last = _last_row_per_item(data)
        flown = 0
        while flown in last:
            flown += 1
        notes = []
        if flown < len(last):
            notes.append(
                f"mission items {sorted(set(last) - set(range(flown)))} follow a gap "
                f"(item {flown} never became current): only items 0-{flown - 1} go up"
            )
        results = self.topics.get("mission_result")
        total = (
            int(results["seq_total"].max())
            if results is not None and "seq_total" in results
            else flown
        )
        if total > flown:
            notes.append(
                f"the log's mission had {total} items; {flown} became current and "
                f"could be uploaded (the log holds no more)"
            )
        rows = [last[seq] for seq in range(flown)]
        frames = {int(data["frame"][k]) for k in rows}
        if not frames <= GLOBAL_FRAMES:
            return (), (
                *notes,
                f"mission frame(s) {sorted(frames - GLOBAL_FRAMES)} are not "
                "global positions: no mission to upload",
            )
        positions, position_notes = _mission_positions(data, rows, home)
        altitudes, altitude_notes = self._mission_altitudes(data, rows, home, home_replayed)
        notes += [*position_notes, *altitude_notes]
        items = tuple(
            MissionItem(
                frame=(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT if data["altitude_is_relative"][k]
                       else mavlink.MAV_FRAME_GLOBAL_INT),
                command=int(data["nav_cmd"][k]),
                lat_deg=lat, lon_deg=lon, alt_m=altitude,
                param1=float(data["time_inside"][k]), param2=float(data["acceptance_radius"][k]),
                param3=float(data["loiter_radius"][k]), param4=math.degrees(float(data["yaw"][k])),
            )
            for k, (lat, lon), altitude in zip(rows, positions, altitudes, strict=True)
        )  # fmt: skip
        return items, tuple(notes)

    def mission_start_holds(self, events: Sequence[FlightEvent]) -> tuple[tuple[float, float], ...]:
        """Per commanded switch to Mission, the time the real navigator held the vehicle
        before the mission's first item: (switch, hold) in log seconds, where it first
        started a loiter it then replaced by the item logged last with the same sequence
        number (the one the replay uploads, :meth:`flown_mission`).

        Why: PX4 v1.17 (the X500's) loiters at the vehicle's position for 0.41 s after the
        switch, then starts the mission; PX4 v1.14 SITL starts it at once, and ran the
        whole mission and the POSCTL flying after it 0.4 s ahead of the log.
        """
        data = self.topics.get("navigator_mission_item")
        if data is None or not {"sequence_current", "nav_cmd"} <= data.keys():
            return ()
        times_s = data["timestamp"] / 1e6
        sequence = data["sequence_current"].astype(int)
        last = _last_row_per_item(data)
        holds = []
        for event in events:
            if not (event.commanded and event.nav_state == NAV_STATE_MISSION):
                continue
            first = int(np.searchsorted(times_s, event.time_s))
            if first == len(times_s) or times_s[first] > event.time_s + MISSION_START_S:
                continue
            flown = last[int(sequence[first])]
            if (
                flown > first
                and int(data["nav_cmd"][first]) in LOITER_COMMANDS
                and (sequence[first:flown] == sequence[first]).all()
            ):
                holds.append((event.time_s, float(times_s[flown] - times_s[first])))
        return tuple(holds)

    def _mission_altitudes(
        self,
        data: dict[str, NDArray[Any]],
        rows: list[int],
        home: GeoPoint | None,
        home_replayed: bool,
    ) -> tuple[list[float], list[str]]:
        """Each item's altitude for this replay. A relative one is above the home the real
        PX4 held when it flew the item (PX4 sets home again at take-off, on its estimate
        then): as logged where the replay moves its home as the real one did
        (``home_replayed``), else moved onto this replay's home, the log's first. One passed
        at once (:data:`PASSED_AT_ONCE_S`) is put where the vehicle passed it."""
        times_s = data["timestamp"] / 1e6
        sequence = data["sequence_current"].astype(int)
        altitudes, notes = [float(data["altitude"][k]) for k in rows], []
        if home is None:
            return altitudes, notes
        relative = [bool(data["altitude_is_relative"][k]) for k in rows]
        homes_then = {k: self.home_altitude_at(times_s[k]) for k in rows}
        homes_then = {k: home.alt_amsl_m if h is None else h for k, h in homes_then.items()}
        references = homes_then if home_replayed else dict.fromkeys(rows, home.alt_amsl_m)
        moves_m = {
            k: homes_then[k] - references[k]
            for k, is_relative in zip(rows, relative, strict=True)
            if is_relative
        }
        moved = sorted({round(m, 2) for m in moves_m.values() if abs(m) >= 0.01})
        if moved:
            notes.append(
                f"relative mission altitudes moved by {', '.join(f'{m:+g}' for m in moved)} m: "
                f"the real PX4 flew them above a home it set again at take-off, not the log's "
                f"first ({home.alt_amsl_m:.2f} m), this replay's"
            )
        for index, k in enumerate(rows):
            altitudes[index] += moves_m.get(k, 0.0)
            following = k + 1 + np.nonzero(sequence[k + 1 :] > sequence[k])[0]
            if index == len(rows) - 1 or not len(following):
                continue
            current_s = float(times_s[following[0]] - times_s[k])
            standing = self.altitude_at(float(times_s[k]))
            if current_s >= PASSED_AT_ONCE_S or standing is None:
                continue
            passed_at = standing - (references[k] if relative[index] else 0.0)
            notes.append(
                f"mission item {sequence[k]} was current for {current_s:.2f} s: the real PX4 "
                f"passed it where the vehicle stood, {passed_at:.1f} m against its "
                f"{altitudes[index]:.1f} m; uploaded at that height, so this PX4 passes it "
                "too instead of flying to it first"
            )
            altitudes[index] = passed_at
        return altitudes, notes

    def track(self, drive: str, start_s: float, end_s: float) -> SetpointTrack:
        """The drive's setpoints in run seconds from ``start_s``, first the one in force then.

        NaN components hold the last finite value: PX4 logs NaN for an axis its mode does
        not control (vx, vy, vz before take-off, thrust in some modes), and the replay must
        still command something there; before any finite value a velocity is 0 (the vehicle
        is landed at the start) and a rate or thrust is 0. Yaw stays NaN (not controlled).
        Set-points logged before an estimator heading reset are turned by the resets after
        them, into the frame the replay starts in (:meth:`heading_resets`).
        """
        name, fields = _DRIVE_FIELDS[drive]
        data = self.topic(name, f"needed by --drive {drive}", fields)
        times_s = data["timestamp"] / 1e6
        values = np.column_stack([data[f].astype(float) for f in fields])
        resets = self.heading_resets(start_s, end_s)
        turn = np.zeros_like(times_s)
        for reset_s, delta in resets:
            turn[times_s < reset_s] += delta
        if drive == "velocity":
            cos, sin = np.cos(turn), np.sin(turn)
            values[:, 0], values[:, 1] = (
                cos * values[:, 0] - sin * values[:, 1],
                sin * values[:, 0] + cos * values[:, 1],
            )
            values[:, 3] = np.remainder(values[:, 3] + turn + np.pi, 2 * np.pi) - np.pi
        elif drive == "attitude":  # q_d ← (a turn about NED down) ⊗ q_d, for every sample
            # at once (quad_model.frames.quat_multiply takes one pair)
            w, x, y, z = values[:, :4].T
            c, s = np.cos(turn / 2), np.sin(turn / 2)
            values[:, :4] = np.column_stack(
                (c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w)
            )
        if drive != "velocity":
            values[:, -1] = -values[:, -1]  # thrust = −thrust_body[2] (PX4 FRD, 0..1)
        held = values.shape[1] - 1 if drive == "velocity" else values.shape[1]
        values[:, :held] = _hold_last_finite(values[:, :held])
        inside = (times_s > start_s) & (times_s < end_s)
        before = np.nonzero(times_s <= start_s)[0]
        first = values[before[-1]] if len(before) else _initial(drive, values[0])
        track_times = (0.0, *(float(t) - start_s for t in times_s[inside]))
        rows = (first, *values[inside])
        return SetpointTrack(drive, track_times, tuple(tuple(float(v) for v in r) for r in rows))


def _last_row_per_item(data: Mapping[str, NDArray[Any]]) -> dict[int, int]:
    """navigator_mission_item's last row for each sequence number: the item as flown (one
    the navigator started first in its place, a climb or a loiter, is logged before it)."""
    return {int(seq): k for k, seq in enumerate(data["sequence_current"])}


def _mission_positions(
    data: dict[str, NDArray[Any]], rows: list[int], home: GeoPoint | None
) -> tuple[list[tuple[float, float]], list[str]]:
    """Each mission item's latitude and longitude for this replay. A log whose positions
    were moved by whole degrees to hide the site (its home, not its mission) has each item
    put at its distance and bearing from the home moved back: a shift in degrees would
    scale the east-west legs by the ratio of the two latitudes' cosines."""
    lat = np.array([float(data["latitude"][k]) for k in rows])
    lon = np.array([float(data["longitude"][k]) for k in rows])
    positions = [(float(a), float(o)) for a, o in zip(lat, lon, strict=True)]
    if home is None:
        return positions, []
    shift = tuple(
        float(np.round(h - np.median(v))) for h, v in ((home.lat_deg, lat), (home.lon_deg, lon))
    )
    if shift == (0.0, 0.0):
        return positions, []
    site_lat, site_lon = home.lat_deg - shift[0], home.lon_deg - shift[1]
    moved = []
    for item_lat, item_lon in positions:
        north, east, _ = geodetic_to_ned(item_lat, item_lon, 0.0, site_lat, site_lon, 0.0)
        moved.append(ned_to_geodetic((north, east, 0.0), home.lat_deg, home.lon_deg, 0.0)[:2])
    scale = math.cos(math.radians(home.lat_deg)) / math.cos(math.radians(site_lat))
    note = (
        f"the mission items lie {shift[0]:g}° N, {shift[1]:g}° E from the log's home: whole "
        "degrees, the uploader's offset of the log's positions, taken out; each item keeps "
        f"its distance and bearing from home (moved in degrees, the east-west legs would "
        f"scale by {scale:.2f})"
    )
    return moved, [note]


def _clipped(events: list[FlightEvent], start_s: float, end_s: float) -> tuple[FlightEvent, ...]:
    """The events in ``[start_s, end_s)``; the pilot's mode in force at ``start_s`` (if the
    flight was armed then) comes first, moved to ``start_s``, and the arm with it when it
    came before ``start_s`` (the logger starts on arming: the 8S quad's arm is 5 ms before
    its log's start)."""
    before = [e for e in events if e.time_s < start_s]
    inside = [e for e in events if start_s <= e.time_s < end_s]
    modes = [e for e in before if e.kind == "mode"]
    armed = [e for e in before if e.kind in ("arm", "disarm")]
    if modes and armed and armed[-1].kind == "arm":
        inside[:0] = [
            replace(modes[-1], time_s=start_s, commanded=True, detail="in force at --start"),
            replace(armed[-1], time_s=start_s, detail=f"{armed[-1].detail}, before --start"),
        ]
    return tuple(inside)


def _mode_name(nav_state: int | None) -> str:
    mode = PX4_MODES.get(nav_state) if nav_state is not None else None
    return mode[2] if mode is not None else f"nav_state {nav_state}"


def _delayed(track: SetpointTrack, delay_s: float) -> SetpointTrack:
    """The track ``delay_s`` later (after an airborne start's lead-in)."""
    if not delay_s:
        return track
    return SetpointTrack(track.kind, tuple(t + delay_s for t in track.times_s), track.values)


def _initial(drive: str, first: NDArray[np.float64]) -> NDArray[np.float64]:
    """The setpoint before the topic's first sample: at rest on the ground."""
    if drive == "velocity":
        return np.array([0.0, 0.0, 0.0, first[3]])
    if drive == "attitude":
        return np.array([*first[:4], 0.0])
    return np.zeros(4)


def _valid(data: dict[str, NDArray[Any]]) -> NDArray[np.bool_]:
    """A topic's ``valid`` flags (every sample valid in a topic without them)."""
    if "valid" in data:
        return data["valid"].astype(bool)
    return np.ones(len(data["timestamp"]), bool)


def _arm_time_s(status: dict[str, NDArray[Any]], k: int) -> float:
    """When the vehicle armed, for armed sample ``k``: ``armed_time`` (the logger starts on
    arming, so the first armed sample comes after it), or the sample's time in a log
    without it (or with 0 there)."""
    armed_us = float(status["armed_time"][k]) if "armed_time" in status else 0.0
    return (armed_us or float(status["timestamp"][k])) / 1e6


def _hold_last_finite(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Replace each NaN by the last finite value above it in its column (0 before any)."""
    held = values.copy()
    last = np.zeros(values.shape[1])
    for row in held:
        finite = np.isfinite(row)
        last[finite] = row[finite]
        row[~finite] = last[~finite]
    return held


def _window(
    path: Path, options: ReplayOptions, start_s: float, end_s: float
) -> tuple[float, float] | None:
    if options.drive == "velocity":
        if options.window_s is not None:
            raise ReplayError(
                "--window applies to --drive attitude|rates only (the velocity "
                "drive flies the whole replay)"
            )
        return None
    if options.window_s is None:
        raise ReplayError(
            f"--drive {options.drive} needs --window START END (boot seconds): "
            "it is open loop on position, the velocity drive flies outside it"
        )
    a, b = options.window_s
    if not start_s + AUTOPILOT_READY_S < a < b < end_s:
        raise ReplayError(
            f"{path}: --window {a:g} {b:g} must lie inside the replay "
            f"({start_s + AUTOPILOT_READY_S:.3f}-{end_s:.3f} s) with START < END"
        )
    return a, b


def _vehicle_choice(path: Path, log: _FlightLog, vehicle: str | None) -> tuple[str, str]:
    if vehicle is not None:
        return vehicle, "--vehicle"
    autostart = log.parameters.get("SYS_AUTOSTART")
    if autostart is None:
        raise ReplayError(
            f"{path}: parameter SYS_AUTOSTART is not in the log; give --vehicle NAME|PATH"
        )
    if int(autostart) not in AIRFRAMES:
        raise ReplayError(
            f"{path}: parameter SYS_AUTOSTART = {int(autostart)} is an airframe "
            f"without a bundled vehicle (known: "
            f"{', '.join(f'{k} {v}' for k, v in AIRFRAMES.items())}); "
            "--vehicle NAME|PATH overrides it"
        )
    return AIRFRAMES[int(autostart)], f"SYS_AUTOSTART = {int(autostart)}"


def _vehicle_document(
    vehicle: str, log: _FlightLog
) -> tuple[dict[str, Any], int | None, BatteryParams]:
    """The vehicle file with the log's battery cell count (BAT1_N_CELLS, else BAT_N_CELLS),
    the count and the resulting battery."""
    try:
        document, source = read_toml(vehicle, VEHICLES_DIR, kind="vehicle", error=VehicleFileError)
    except VehicleFileError as error:
        raise ReplayError(f"--vehicle: {error}") from None
    cells = log.parameters.get("BAT1_N_CELLS", log.parameters.get("BAT_N_CELLS"))
    if cells is not None and int(cells) > 0 and isinstance(document.get("battery"), dict):
        document["battery"]["cell_count"] = int(cells)
    try:
        battery = vehicle_from_dict(document, str(source)).battery
    except VehicleFileError as error:
        raise ReplayError(f"--vehicle: {error}") from None
    return document, None if cells is None else int(cells), battery


def motor_pwm_range(params: Mapping[str, float], source: str | Path) -> tuple[float, float]:
    """PWM (µs) at motor command 0 and 1: the log's ``PWM_*_MINn/MAXn`` of the outputs
    assigned to Motor 1..4 (an older PX4's ``PWM_MAIN_MIN/MAX``), PX4's defaults 1000/2000
    when the log has none (PX4 SITL, the rig's autopilot)."""
    ranges = set()
    for key, function in params.items():
        if key.startswith(("PWM_MAIN_FUNC", "PWM_AUX_FUNC")) and function in MOTOR_OUTPUT_FUNCTIONS:
            prefix, channel = key.split("_FUNC")
            limits = (f"{prefix}_MIN{channel}", f"{prefix}_MAX{channel}")
            for name in limits:
                if name not in params:
                    raise ReplayError(
                        f"{source}: parameter {name} is not in the log "
                        f"({key} = {int(function)} is a motor output)"
                    )
            ranges.add((float(params[limits[0]]), float(params[limits[1]])))
    if not ranges:  # a PX4 before 1.13 has one range for all, or none (SITL, our autopilot)
        return legacy_pwm_range(params) or DEFAULT_MOTOR_PWM_RANGE_US
    if len(ranges) > 1:
        raise ReplayError(f"{source}: the motor outputs have different PWM ranges {sorted(ranges)}")
    return ranges.pop()


def _parameters(
    logged: dict[str, float | int],
) -> tuple[dict[str, float | int], tuple[SkippedParameter, ...], int]:
    """Split the log's parameters: applied (known and in range), skipped, unknown count."""
    known = {spec.name for spec in PARAMETERS} - RIG_OWNED_PARAMETERS
    check = Parameters()
    applied: dict[str, float | int] = {}
    skipped = []
    for name in sorted(logged):
        if name not in known:
            continue
        try:
            check.set(name, logged[name])
        except ParameterError as error:  # outside our range: reported, never clamped
            skipped.append(SkippedParameter(name, float(logged[name]), str(error)))
            continue
        applied[name] = logged[name]
    unknown = sum(1 for name in logged if name not in known and name not in RIG_OWNED_PARAMETERS)
    return applied, tuple(skipped), unknown
