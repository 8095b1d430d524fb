"""A replay planned from its log without flying: the vehicle, the start, the parameters,
the tracks or the pilot's commands, the wind and the air (:func:`plan_replay`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from hil_config import FieldError, read_toml
from px4_logs import FlightLog, motor_outputs
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
from quad_model.model import ModelInputError, charge_used_for_voltage_c
from quad_model.vehicle import (
    VEHICLES_DIR,
    BatteryParams,
    VehicleFileError,
    vehicle_for_airframe,
    vehicle_from_dict,
)
from rig.autopilots import Autopilot
from rig.autopilots.px4 import (
    RIG_PARAMETERS,
    STICK_PARAMETERS,
    check_imu_rate,
    lockstep_parameters,
)
from rig.chips.pwm import PwmOutput
from rig.errors import RigError
from rig.identify.wind import WindEstimate, WindEstimateError, estimate_wind
from rig.mavlink.ground_link import PX4_MODES, MissionItem
from rig.replay.options import Drive, ReplayError, ReplayOptions
from rig.replay.parameters import (
    LEARNED,
    SkippedParameter,
    learned_parameters,
    px4_parameters,
    reference_parameters,
    with_px4_imu_rate,
    yaw_rate_limits,
)
from rig.replay.timeline import (
    ARM_MODE_LEAD_S,
    NAV_STATE_LOITER,
    NAV_STATE_MISSION,
    NAV_STATE_OFFBOARD,
    STICK_MODES,
    EventKind,
    FlightEvent,
    ReplayLog,
    delayed,
    mode_name,
)
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

#: The rig's autopilot boots at the clock start; the real one had been up for minutes. Its
#: GPS fix, attitude and position estimates need this long before it can arm (the bundled
#: scenarios arm after 1 s too), so an earlier real arming is flown this late.
AUTOPILOT_READY_S = 1.0


#: A log that starts in the air is flown after a lead-in, since no autopilot (PX4 SITL
#: included) boots flying: take off to the log's height at --start, climbing at PX4's
#: MPC_TKO_SPEED default, and settle this long; the track then starts on the log's clock.
TAKEOFF_CLIMB_MPS = 1.5


LEAD_IN_SETTLE_S = 5.0


#: The autopilot looks declination up in the WMM at this epoch (flight_controller), so the
#: simulated field is taken at the same one: the two then agree on north.
WMM_EPOCH_YEAR = 2026.0
#: PX4 SITL boots this long (simulated s) before the log's start, so that its pre-flight
#: checks (EKF2 aligned, GPS healthy for EKF2_REQ_GPS_H) have passed when the log arms, and
#: the arm, every mode switch and the landing happen at the log's own times.
PX4_BOOT_S = 20.0
#: Seconds after PX4's boot at which the log's mission is uploaded.
PX4_SETUP_S = 1.0


@dataclass(frozen=True)
class PilotInputs:
    """What a PX4 replay flies as the log's pilot and ground station did (the reference
    autopilot flies the log's set-point tracks instead, :attr:`Replay.tracks`)."""

    #: The log's arm, mode switches and disarm (:meth:`ReplayLog.timeline`).
    events: tuple[FlightEvent, ...]
    #: The pilot's sticks (``manual_control_setpoint``); None: the log has none.
    sticks: SetpointTrack | None
    #: The mission as flown, and what the replay did to it.
    mission: tuple[MissionItem, ...] = ()
    mission_notes: tuple[str, ...] = ()
    #: Per switch to Mission (log seconds): how long the real navigator held the vehicle
    #: where it was before the mission's first item; flown as Hold (``mission_start_holds``).
    mission_holds: tuple[tuple[float, float], ...] = ()
    #: (log s, °/s): MPC_YAWRAUTO_MAX set in flight, the real planner's yaw rate in auto
    #: modes (:func:`yaw_rate_limits`); empty where the log's PX4 had no acceleration limit.
    yaw_rate_limits: tuple[tuple[float, float], ...] = ()
    #: (log s, home): where and when the real PX4 moved its home while armed
    #: (:meth:`ReplayLog.home_moves`); each is set with DO_SET_HOME.
    home_moves: tuple[tuple[float, GeoPoint], ...] = ()


#: Run seconds after which each autopilot can arm: PX4 boots before the log's start.
READY_S = {Autopilot.REFERENCE: AUTOPILOT_READY_S, Autopilot.PX4: PX4_BOOT_S}


@dataclass(frozen=True)
class Replay:
    """The replay's configuration, read from the log (:func:`plan_replay`).

    Times ``*_s`` are the log's boot seconds; the tracks and commands count run seconds
    from ``start_s``, as every scenario does.
    """

    log_path: Path
    drive: Drive
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
    tracks: dict[Drive, SetpointTrack]
    options: ReplayOptions
    log_warnings: tuple[str, ...] = ()  # what pyulog reported (a damaged message skipped)
    #: Airborne at --start: the height (m) taken off to first.
    start_height_m: float = 0.0
    #: Run seconds flown before the log's start: PX4's boot, an airborne start's take-off.
    lead_in_s: float = 0.0
    #: A PX4 replay's pilot inputs; None: the reference autopilot flies the tracks.
    pilot: PilotInputs | None = None
    firmware: str = ""  # the log's PX4, as its header says
    #: The wind flown: the log's hover tilt through the vehicle's drag (rig.identify.wind);
    #: None, with the reason in ``wind_note``, when the log gives none.
    wind: WindEstimate | None = None
    wind_note: str = ""
    #: The day's temperature offset from ISA that gives the log's air density at home
    #: (vehicle_air_data.rho): thrust ∝ ρ, so the rotors turn as fast as the real ones.
    temperature_offset_k: float = 0.0
    air_density_kgpm3: float | None = None
    #: A PX4 replay's parameters the log's firmware learned in flight rather than read from
    #: its parameters (:func:`learned_parameters`), set after the log's own.
    learned: dict[str, float] = field(default_factory=dict)
    #: (log s, rad): the log's estimator heading resets after --start
    #: (:meth:`ReplayLog.heading_resets`), taken into the start heading.
    heading_resets: tuple[tuple[float, float], ...] = ()

    @property
    def px4(self) -> bool:
        return self.pilot is not None

    @property
    def ready_s(self) -> float:
        """Run seconds after which the autopilot can arm (an airborne start's lead-in)."""
        return READY_S[self.options.autopilot]

    @property
    def commands(self) -> tuple[ScriptCommand, ...]:
        """Arm, stream the velocity track (the drive's inside the window), disarm; run seconds.

        A log that starts airborne is preceded by the lead-in: arm, take off to its height,
        then the track from ``lead_in_s`` on. PX4 flies :meth:`_pilots_commands` instead."""
        if self.arm_s is None:
            return ()
        if self.pilot is not None:
            return self._pilots_commands(self.pilot)
        origin = self.start_s - self.lead_in_s  # log second of run second 0
        tracks = {kind: delayed(track, self.lead_in_s) for kind, track in self.tracks.items()}
        commands: list[ScriptCommand] = [Arm(at_s=self.arm_s - origin)]
        if self.start_height_m:
            commands.append(Takeoff(at_s=self.ready_s + 0.1, altitude_m=self.start_height_m))
        commands.append(Track(at_s=max(self.arm_s - origin, self.lead_in_s),
                              track=tracks[Drive.VELOCITY]))  # fmt: skip
        if self.window_s is not None and self.drive is not Drive.VELOCITY:
            a, b = self.window_s
            commands += [
                Track(at_s=a - origin, track=tracks[self.drive]),
                Track(at_s=b - origin, track=tracks[Drive.VELOCITY]),
            ]
        if self.disarm_s is not None:
            commands.append(Disarm(at_s=self.disarm_s - origin, may_refuse=True))
        return tuple(sorted(commands, key=lambda c: c.at_s))

    def _pilots_commands(self, pilot: PilotInputs) -> tuple[ScriptCommand, ...]:
        """The flight as its pilot and ground station flew it (PX4): the sticks from PX4's
        boot on, the mission uploaded while PX4 boots, the mode it armed in just before the
        arm, then every commanded event at its log time (an airborne start: after the
        lead-in's arm and take-off, the mode in force at --start)."""
        origin = self.start_s - self.lead_in_s
        commands: list[ScriptCommand] = []
        if pilot.sticks is not None:
            commands.append(Track(at_s=0.0, track=self._lead_in(pilot.sticks)))
        if pilot.mission:
            commands.append(UploadMission(at_s=PX4_SETUP_S, items=pilot.mission))
        if self.start_height_m:
            takeoff = Takeoff(at_s=self.ready_s + 0.1, altitude_m=self.start_height_m)
            commands += [Arm(at_s=self.ready_s), takeoff]
        arms = {event.time_s for event in pilot.events if event.kind is EventKind.ARM}
        holds = dict(pilot.mission_holds)
        for event in pilot.events:
            if not event.commanded:
                continue
            at_s = event.time_s - origin
            if event.kind is EventKind.ARM:
                if not self.start_height_m:  # an airborne start's lead-in armed already
                    commands.append(Arm(at_s=at_s))
            elif event.kind is EventKind.DISARM:
                commands.append(Disarm(at_s=at_s, may_refuse=True))
            elif event.nav_state == NAV_STATE_OFFBOARD:
                velocity = delayed(self.tracks[Drive.VELOCITY], self.lead_in_s)
                commands.append(Track(at_s=at_s, track=velocity))
            else:  # the mode it armed in is selected before the arm
                armed_in_it = event.time_s in arms
                at_s -= ARM_MODE_LEAD_S if armed_in_it else 0.0
                hold_s = holds.get(event.time_s) if event.nav_state == NAV_STATE_MISSION else None
                if hold_s is not None and not armed_in_it:  # a hold is in the air
                    commands.append(SetMode(at_s=at_s, name=PX4_MODES[NAV_STATE_LOITER][2]))
                    at_s += hold_s
                assert event.nav_state is not None  # only an arm or a disarm has no mode
                commands.append(SetMode(at_s=at_s, name=PX4_MODES[event.nav_state][2]))
        commands += [
            SetParam(at_s=time_s - origin, name="MPC_YAWRAUTO_MAX", value=limit)
            for time_s, limit in pilot.yaw_rate_limits
        ]
        commands += [SetHome(at_s=time_s - origin, home=home) for time_s, home in pilot.home_moves]
        return tuple(sorted(commands, key=lambda c: c.at_s))

    def _lead_in(self, sticks: SetpointTrack) -> SetpointTrack:
        """The sticks on the run's clock: before the log's start the first sample is held,
        except in an airborne start's lead-in, where they rest centred until --start."""
        track = delayed(sticks, self.lead_in_s)
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
        if self.pilot is not None:
            notes += self._px4_notes(self.pilot)
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

    def _px4_notes(self, pilot: PilotInputs) -> list[tuple[str, str]]:
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
        notes += [("info", f"replay: {note}") for note in pilot.mission_notes]
        notes += [
            ("info", f"replay: after the switch to Mission at {time_s:.3f} s the real "
                     f"navigator held the vehicle where it was for {hold_s:.3f} s (a loiter) "
                     "before the mission's first item: flown as Hold, then Mission")
            for time_s, hold_s in pilot.mission_holds
        ]  # fmt: skip
        notes += [
            ("info", f"replay: the real PX4 moved its home at {time_s:.3f} s to "
                     f"{home.alt_amsl_m:.2f} m AMSL: set then with DO_SET_HOME")
            for time_s, home in pilot.home_moves
        ]  # fmt: skip
        notes += [("info", f"replay: log event {event.describe()}") for event in pilot.events]
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
        pilot = self.pilot or PilotInputs(events=(), sticks=None)
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
            "yaw_rate_limits": [list(pair) for pair in pilot.yaw_rate_limits],
            "home_moves": [
                {
                    "time_s": time_s,
                    "lat_deg": home.lat_deg,
                    "lon_deg": home.lon_deg,
                    "alt_amsl_m": home.alt_amsl_m,
                }
                for time_s, home in pilot.home_moves
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
            "events": [asdict(event) for event in pilot.events],
            "mission": [  # yaw NaN (the autopilot's choice) as null: JSON has no NaN
                asdict(item) | {"param4": None if math.isnan(item.param4) else item.param4}
                for item in pilot.mission
            ],
            "mission_notes": list(pilot.mission_notes),
            "mission_holds": [list(hold) for hold in pilot.mission_holds],
            "seed": self.options.seed,
            "sensor_layer": self.options.sensor_layer,
            "imu_hz": self.options.imu_hz,
        }


def plan_replay(log_path: str | Path, options: ReplayOptions | None = None) -> Replay:
    """Configure a replay of ``log_path`` (no flying); raises :class:`ReplayError`."""
    path = Path(log_path)
    options = _checked(options or ReplayOptions())
    px4 = options.autopilot is Autopilot.PX4
    log = ReplayLog.read(path)
    start_s = log.first_s if options.start_s is None else options.start_s
    if options.start_s is None and px4:
        # PX4 boots PX4_BOOT_S before the start, and a ULog's clock starts at 0: a log from
        # PX4's boot (PX4 SITL's, the rig's) is replayed from the first second PX4 can reach
        start_s = max(start_s, PX4_BOOT_S)
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
        options = with_px4_imu_rate(options, log.parameters)
    ready_s = READY_S[options.autopilot]
    start_height_m, lead_in_s = 0.0, (ready_s if px4 else 0.0)
    if not log.landed_at(start_s):
        start_height_m = log.height_at(start_s)
        lead_in_s = ready_s + start_height_m / TAKEOFF_CLIMB_MPS + LEAD_IN_SETTLE_S
    if start_s - lead_in_s < 0.0:  # a ULog's clock is unsigned: no run second before 0
        raise ReplayError(
            f"{path}: --start {start_s:g} s is too early on the log's clock: the "
            f"{options.autopilot} replay starts {lead_in_s:g} s before it (PX4 boots first), "
            "and the clock cannot go below 0: give a later --start"
        )
    vehicle, reason = _vehicle_choice(log, options.vehicle)
    vehicle_document, cell_count, battery = _vehicle_document(vehicle, log)
    outputs = motor_outputs(log)
    pwm_range_us = outputs.pwm_range_us  # the same ESC throttle whatever the log's protocol
    try:
        PwmOutput(1, 400, pwm_range_us)  # the rig's outputs span what the ESC input does
    except ValueError as error:
        raise ReplayError(f"{path}: the motor outputs' range ({outputs.reason}): {error}") from None
    battery_voltage_v = log.battery_voltage_v(start_s)
    if battery_voltage_v is not None:
        try:
            charge_used_for_voltage_c(battery, battery_voltage_v)
        except ModelInputError as error:
            raise ReplayError(
                f"{path}: battery_status.voltage_v at --start {start_s:g} s: {error}"
            ) from None
    if px4:
        parameters, skipped, unknown = px4_parameters(log.parameters, options)
    else:
        parameters, skipped, unknown = reference_parameters(log.parameters)
    real_arm_s, disarm_s = log.arming(start_s, end_s)
    arm_s: float | None
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
    home = log.home()
    pilot = (
        _pilot_inputs(log, parameters, start_s, end_s, real_arm_s, disarm_s, home) if px4 else None
    )
    events = pilot.events if pilot is not None else ()
    offboard = any(e.commanded and e.nav_state == NAV_STATE_OFFBOARD for e in events)
    velocity = not px4 or offboard
    tracks = {Drive.VELOCITY: log.track(Drive.VELOCITY, start_s, end_s)} if velocity else {}
    if options.drive is not Drive.VELOCITY:
        tracks[options.drive] = log.track(options.drive, start_s, end_s)
    heading_resets = log.heading_resets(start_s, end_s)
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
        pilot=pilot,
        firmware=log.firmware,
        learned=learned_parameters(log, parameters, events),
        **_wind(log, vehicle_document, vehicle),
        **_air(log, home, start_s, end_s),
    )
    replay.scenario(Path(vehicle))  # a bad rate fails here, before a run folder exists
    return replay


def _pilot_inputs(
    log: ReplayLog,
    parameters: Mapping[str, float],
    start_s: float,
    end_s: float,
    real_arm_s: float | None,
    disarm_s: float | None,
    home: GeoPoint | None,
) -> PilotInputs:
    """What PX4 flies from the log: its events, the sticks where a mode needs them, the
    mission where one was flown, the yaw-rate limits and the home moves."""
    events = log.timeline(start_s, end_s)
    sticks = log.sticks(start_s, end_s)
    manual = sorted({e.nav_state for e in events if e.commanded and e.nav_state in STICK_MODES})
    if sticks is None and manual:
        raise ReplayError(
            f"{log.path}: topic manual_control_setpoint (the pilot's sticks, which PX4 needs "
            f"in mode {mode_name(manual[0])}) is not in the log"
        )
    home_moves = log.home_moves(home, real_arm_s, disarm_s or end_s)
    mission: tuple[MissionItem, ...] = ()
    mission_notes: tuple[str, ...] = ()
    mission_holds: tuple[tuple[float, float], ...] = ()
    if any(e.commanded and e.nav_state == NAV_STATE_MISSION for e in events):
        mission, mission_notes = log.flown_mission(home, bool(home_moves))
        mission_holds = log.mission_start_holds(events)
    return PilotInputs(
        events=events,
        sticks=sticks,
        mission=mission,
        mission_notes=mission_notes,
        mission_holds=mission_holds,
        yaw_rate_limits=yaw_rate_limits(log, parameters, start_s, end_s),
        home_moves=home_moves,
    )


def _wind(log: FlightLog, vehicle_document: dict[str, Any], vehicle: str) -> dict[str, Any]:
    """``wind`` and ``wind_note`` of the replay: the log's hover tilt through the vehicle's
    drag, or none, with the reason (no hover, no attitude)."""
    try:
        return {"wind": estimate_wind(log, vehicle_from_dict(vehicle_document, vehicle))}
    except WindEstimateError as error:
        return {"wind": None, "wind_note": f"no estimate: {error}"}


def _air(log: ReplayLog, home: GeoPoint | None, start_s: float, end_s: float) -> dict[str, Any]:
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
    if options.drive not in list(Drive):
        raise ReplayError(f"--drive {options.drive!r}: expected one of {', '.join(Drive)}")
    options = replace(options, drive=Drive(options.drive))  # a name given as text
    if options.sensor_layer not in list(SensorLayer):
        raise ReplayError(
            f"--sensor-layer {options.sensor_layer!r}: expected one of {', '.join(SensorLayer)}"
        )
    if options.autopilot not in list(Autopilot):
        raise ReplayError(
            f"--autopilot {options.autopilot!r}: expected one of {', '.join(Autopilot)}"
        )
    options = replace(options, autopilot=Autopilot(options.autopilot))  # a name given as text
    if options.autopilot is Autopilot.REFERENCE:
        return replace(options, imu_hz=options.imu_hz or Rates().imu_hz)
    if options.drive is not Drive.VELOCITY or options.window_s is not None:
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


def _window(
    path: Path, options: ReplayOptions, start_s: float, end_s: float
) -> tuple[float, float] | None:
    if options.drive is Drive.VELOCITY:
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


def _vehicle_choice(log: ReplayLog, vehicle: str | None) -> tuple[str, str]:
    if vehicle is not None:
        return vehicle, "--vehicle"
    try:
        name = vehicle_for_airframe(log.parameters, log.path)
    except VehicleFileError as error:
        raise ReplayError(str(error)) from None
    return name, f"SYS_AUTOSTART = {int(log.parameters['SYS_AUTOSTART'])}"


def _vehicle_document(
    vehicle: str, log: ReplayLog
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
