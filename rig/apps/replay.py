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
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from numpy.typing import NDArray

from credibility.errors import CredibilityError
from credibility.layouts import legacy_pwm_range
from credibility.logs import read_ulog
from hil_config import FieldError, read_toml
from quad_model.environment import Environment, GeoPoint, MagneticField
from quad_model.model import ModelInputError, charge_used_for_voltage_c
from quad_model.vehicle import VEHICLES_DIR, BatteryParams, VehicleFileError, vehicle_from_dict
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
from rig.scenarios.scenario import (
    Arm,
    Disarm,
    Rates,
    Scenario,
    ScriptCommand,
    SensorLayer,
    SetpointTrack,
    StartPose,
    Takeoff,
    Track,
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
#: Each drive's topic and fields, in SetpointTrack order (thrust is −thrust_body[2]).
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
    imu_hz: int = Rates().imu_hz


@dataclass(frozen=True)
class SkippedParameter:
    name: str
    value: float
    reason: str


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
    yaw_rad: float
    home: GeoPoint | None
    real_arm_s: float | None
    arm_s: float | None  # as flown: the real time, at least AUTOPILOT_READY_S after start
    disarm_s: float | None
    tracks: dict[str, SetpointTrack]
    options: ReplayOptions
    log_warnings: tuple[str, ...] = ()  # what pyulog reported (a damaged message skipped)
    #: Airborne at --start: the height (m) taken off to first, and how long that takes (s).
    start_height_m: float = 0.0
    lead_in_s: float = 0.0

    @property
    def commands(self) -> tuple[ScriptCommand, ...]:
        """Arm, stream the velocity track (the drive's inside the window), disarm; run seconds.

        A log that starts airborne is preceded by the lead-in: arm, take off to its height,
        then the track from ``lead_in_s`` on."""
        if self.arm_s is None:
            return ()
        origin = self.start_s - self.lead_in_s  # log second of run second 0
        tracks = {kind: _delayed(track, self.lead_in_s) for kind, track in self.tracks.items()}
        commands: list[ScriptCommand] = [Arm(at_s=self.arm_s - origin)]
        if self.lead_in_s:
            commands.append(Takeoff(at_s=AUTOPILOT_READY_S + 0.1, altitude_m=self.start_height_m))
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

    @property
    def autopilot_params(self) -> tuple[str, ...]:
        """The applied parameters as ``--param NAME=VALUE`` (repr: the exact float)."""
        return tuple(f"{name}={value!r}" for name, value in self.parameters.items())

    @property
    def notes(self) -> tuple[tuple[str, str], ...]:
        """Warnings for the run's log: what the replay could not take from the real flight."""
        notes = [("warn", f"replay: {warning}") for warning in self.log_warnings]
        notes += [
            ("warn", f"replay: parameter {s.name} = {s.value:g} skipped ({s.reason})")
            for s in self.skipped
        ]
        if self.lead_in_s:
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
        if self.initial_battery_voltage_v is None:
            notes.append(("warn", "replay: the battery starts full (no battery_status in the log)"))
        notes.append(("info", "replay: wind is zero (the real wind is unknown)"))
        return tuple(notes)

    def scenario(self, vehicle_path: Path) -> Scenario:
        """The scenario this replay flies, with its vehicle file at ``vehicle_path``."""
        environment = Environment()
        if self.home is not None:
            environment = Environment(
                home=self.home, magnetic_field=MagneticField.from_wmm(self.home, WMM_EPOCH_YEAR)
            )
        try:
            rates = Rates(imu_hz=self.options.imu_hz)
        except FieldError as error:  # an IMU rate the model cannot step
            reason = f"--imu-hz = {error.value}: {error.reason}"
            raise ReplayError(f"{self.log_path}: {reason}") from None
        return Scenario(
            name=f"replay-{self.log_path.stem}",
            description=f"replay of {self.log_path.name} ({self.drive} drive), "
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
            commands=tuple(c for c in self.commands if not isinstance(c, Track)),
            tracks=tuple(c for c in self.commands if isinstance(c, Track)),
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
            "parameters_applied": self.parameters,
            "parameters_skipped_out_of_range": [
                {"name": s.name, "value": s.value, "reason": s.reason} for s in self.skipped
            ],
            "parameters_unknown_count": self.unknown_parameter_count,
            "log_warnings": list(self.log_warnings),
            "start_yaw_deg": math.degrees(self.yaw_rad),
            "home": None
            if self.home is None
            else {
                "lat_deg": self.home.lat_deg,
                "lon_deg": self.home.lon_deg,
                "alt_amsl_m": self.home.alt_amsl_m,
            },
            "wind": "zero: the real wind is unknown",
            "real_arm_s": self.real_arm_s,
            "arm_s": self.arm_s,
            "disarm_s": self.disarm_s,
            "seed": self.options.seed,
            "sensor_layer": self.options.sensor_layer,
            "imu_hz": self.options.imu_hz,
        }


def plan_replay(log_path: str | Path, options: ReplayOptions = ReplayOptions()) -> Replay:
    """Configure a replay of ``log_path`` (no flying); raises :class:`ReplayError`."""
    path = Path(log_path)
    if options.drive not in DRIVES:
        raise ReplayError(f"--drive {options.drive!r}: expected one of {', '.join(DRIVES)}")
    if options.sensor_layer not in list(SensorLayer):
        raise ReplayError(
            f"--sensor-layer {options.sensor_layer!r}: expected one of {', '.join(SensorLayer)}"
        )
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
    start_height_m = lead_in_s = 0.0
    if not log.landed_at(start_s):
        start_height_m = log.height_at(start_s)
        lead_in_s = AUTOPILOT_READY_S + start_height_m / TAKEOFF_CLIMB_MPS + LEAD_IN_SETTLE_S
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
    parameters, skipped, unknown = _parameters(log.parameters)
    real_arm_s, disarm_s = log.arming(start_s, end_s)
    if lead_in_s:  # armed in the air: the lead-in arms as soon as the autopilot is ready
        real_arm_s = arm_s = start_s - lead_in_s + AUTOPILOT_READY_S
    else:
        arm_s = None if real_arm_s is None else max(real_arm_s, start_s + AUTOPILOT_READY_S)
    if window is not None and (arm_s is None or window[0] <= arm_s):
        raise ReplayError(
            f"{path}: --window starts at {window[0]:g} s, before the vehicle is "
            f"armed ({'never' if arm_s is None else f'{arm_s:.3f} s'})"
        )
    tracks = {"velocity": log.track("velocity", start_s, end_s)}
    if options.drive != "velocity":
        tracks[options.drive] = log.track(options.drive, start_s, end_s)
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
        yaw_rad=log.heading_at(start_s),
        home=log.home(),
        real_arm_s=real_arm_s,
        arm_s=arm_s,
        disarm_s=disarm_s,
        tracks=tracks,
        options=options,
        log_warnings=log.warnings,
        start_height_m=start_height_m,
        lead_in_s=lead_in_s,
    )
    replay.scenario(Path(vehicle))  # a bad rate fails here, before a run folder exists
    return replay


def run_replay(
    replay: Replay,
    run_options: RunOptions | None = None,
    progress: Callable[[Progress], None] | None = None,
) -> RunResult:
    """Fly a planned replay; the run folder also gets ``vehicle.toml`` and ``replay.json``.

    ``run_options`` says where and how (instance, folder, timeouts); its ``--param`` values
    are applied after the log's, so they win.
    """
    run_options = run_options or RunOptions()
    if run_options.autopilot != AUTOPILOTS[0]:
        raise ReplayError(
            "replay flies the reference autopilot only (its setpoints are "
            "acknowledged so a replay is deterministic)"
        )
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    default_dir = RUNS_DIR / f"replay-{replay.log_path.stem}-{stamp}"
    run_dir = claim_run_dir(run_options.out_dir or default_dir, run_options.force)
    vehicle_path = (run_dir / "vehicle.toml").resolve()
    vehicle_path.write_text(tomli_w.dumps(replay.vehicle_document))
    (run_dir / "replay.json").write_text(json.dumps(replay.summary(), indent=2) + "\n")
    scenario = replay.scenario(vehicle_path)
    flown = replace(
        run_options,
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
        self.first_s = min(float(d.data["timestamp"][0]) for d in ulog.data_list) / 1e6
        self.last_s = max(float(d.data["timestamp"][-1]) for d in ulog.data_list) / 1e6

    def topic(self, name: str, why: str) -> dict[str, NDArray[Any]]:
        if name not in self.topics:
            raise ReplayError(f"{self.path}: topic {name} ({why}) is not in the log")
        return self.topics[name]

    def _at(self, name: str, field: str, time_s: float, why: str) -> float:
        """The field's value in force at ``time_s`` (the first sample's before the topic starts)."""
        data = self.topic(name, why)
        if field not in data:
            raise ReplayError(f"{self.path}: topic {name} has no field {field} ({why})")
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

    def home(self) -> GeoPoint | None:
        """The first valid home position (the flying site), None without one."""
        data = self.topics.get("home_position")
        if data is None or not len(data["timestamp"]):
            return None
        lat, lon, alt = (float(data[k][0]) for k in ("lat", "lon", "alt"))
        if not (math.isfinite(lat + lon + alt) and -90 <= lat <= 90 and -180 <= lon <= 180):
            return None
        return GeoPoint(lat, lon, alt)

    def arming(self, start_s: float, end_s: float) -> tuple[float | None, float | None]:
        """The real arm and disarm times clipped to ``[start_s, end_s)`` (None: not in it).

        The arm time is ``vehicle_status.armed_time`` of the first armed sample: the logger
        starts on arming, so the first sample comes after it.
        """
        status = self.topic("vehicle_status", "arming times")
        times_s = status["timestamp"] / 1e6
        armed = status["arming_state"] == ARMING_STATE_ARMED
        if not armed.any():
            return None, None
        first = int(np.argmax(armed))
        arm_s = float(status["armed_time"][first]) / 1e6 or float(times_s[first])
        disarmed_after = np.nonzero(~armed[first:])[0]
        disarm_s = float(times_s[first + disarmed_after[0]]) if len(disarmed_after) else None
        arm_s = max(arm_s, start_s) if arm_s < end_s else None
        if disarm_s is not None and not start_s < disarm_s < end_s:
            disarm_s = None
        return arm_s, disarm_s

    def track(self, drive: str, start_s: float, end_s: float) -> SetpointTrack:
        """The drive's setpoints in run seconds from ``start_s``, first the one in force then.

        NaN components hold the last finite value: PX4 logs NaN for an axis its mode does
        not control (vx, vy, vz before take-off, thrust in some modes), and the replay must
        still command something there; before any finite value a velocity is 0 (the vehicle
        is landed at the start) and a rate or thrust is 0. Yaw stays NaN (not controlled).
        """
        name, fields = _DRIVE_FIELDS[drive]
        data = self.topic(name, f"needed by --drive {drive}")
        missing = [f for f in fields if f not in data]
        if missing:
            raise ReplayError(
                f"{self.path}: topic {name} has no field {missing[0]} (needed by --drive {drive})"
            )
        times_s = data["timestamp"] / 1e6
        values = np.column_stack([data[f].astype(float) for f in fields])
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
