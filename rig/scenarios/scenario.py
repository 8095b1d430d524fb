"""Scenario files (TOML): what one rig run flies, and under which conditions.

A scenario names its vehicle (a quad_model vehicle set), the test-bench constraint, the
environment (location, magnetic field, wind), the start pose, the command script, the
faults with their start/end times, the duration, the seed, the sensor layer and the rates.
Every value is checked on load; a bad file fails with one line naming the file, the key
and the value (:class:`rig.errors.ScenarioError`). The bundled scenarios live in
``rig/scenarios/``; ``load_scenario("hover")`` finds them by name.

Times are simulated seconds from the start of the run. Units are in the key names. The
autopilot's clock (every message and log timestamp) reads ``clock_start_s`` at the start of
the run: 0 for a scenario file; :mod:`rig.apps.replay` starts it at the real log's boot time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fpga_hdl.cosim.harness import HARNESS_SYS_CLK_HZ
from quad_model.environment import Environment, GeoPoint, MagneticField, Wind
from quad_model.toml_file import read_toml_file
from rig.chips.pwm import DEFAULT_MOTOR_PWM_RANGE_US, PWM_TICK_HZ
from rig.errors import ScenarioError

SCENARIOS_DIR = Path(__file__).parent  # the bundled scenario files live beside this module
SENSOR_LAYERS = ("tlm", "rtl")
CONSTRAINTS = ("free", "gimbal_pitch", "gimbal_roll", "thrust_stand")
SENSORS = ("accel", "gyro", "mag", "baro")
CHIPS = ("mpu6000", "ms5611", "ist8310")
#: Coarsest capture tick: 10 µs is 1 % of the 1000-2000 µs throttle range.
MIN_PWM_TICK_HZ = 100_000
#: Finest capture tick: SensorTop needs a system clock of at least 4 ticks
#: (``fpga_hdl.top``), and the co-simulation's system clock runs at 10 MHz.
MAX_PWM_TICK_HZ = round(HARNESS_SYS_CLK_HZ) // 4

#: Command actions and their parameters: ``name → (kind, required)``. Kinds are checked
#: by :func:`_typed`; the ground-station client (``rig.mavlink.ground_link``) turns each
#: into MAVLink.
ACTIONS: dict[str, dict[str, tuple[str, bool]]] = {
    "arm": {},
    "disarm": {},
    "takeoff": {"altitude_m": ("positive", True)},
    "land": {},
    "goto": {"position_ned_m": ("vector3", True), "yaw_deg": ("number", False)},
    "mission": {"waypoints_ned_m": ("vector3_list", True)},
    "pitch_sweep": {
        "duration_s": ("positive", True),
        "amplitude_deg": ("positive", True),
        "f_min_radps": ("positive", True),
        "f_max_radps": ("positive", True),
        "thrust": ("unit", True),
        "rate_hz": ("positive", False),
    },
    "motor_test": {
        "motor": ("motor", True),
        "throttle": ("unit", True),
        "duration_s": ("positive", True),
    },
    "set_param": {"name": ("string", True), "value": ("number", True)},
}

#: Fault kinds and their parameters (the layer each acts on is in ``rig.scenarios.faults``).
FAULT_KINDS: dict[str, dict[str, tuple[str, bool]]] = {
    "motor_loss": {"motor": ("motor", True)},
    "motor_degradation": {"motor": ("motor", True), "efficiency": ("unit", True)},
    "sensor_stuck": {"sensor": ("sensor", True)},
    "sensor_bias": {"sensor": ("sensor", True), "bias": ("bias", True)},
    "noise_burst": {"sensor": ("sensor", True), "std": ("positive", True)},
    "bus_bit_flip": {"chip": ("chip", True), "mask": ("byte", True)},
    "chip_mute": {"chip": ("chip", True)},
    "gps_loss": {},
    "pwm_dropout": {"channel": ("motor", False)},
}


@dataclass(frozen=True)
class Rates:
    """Simulation and sensor rates (Hz); one lockstep frame is one IMU period.

    The GPS rate is the receiver's (``fix_rate_hz`` in the vehicle file, 10 Hz for the
    bundled ones), with its latency. ``pwm_tick_hz`` is the PWM capture core's tick, the
    resolution of the measured pulse widths; in the RTL layer its clock runs all the
    time, one simulated cycle per tick, so a coarser tick trades resolution for speed.
    A file without ``model_hz`` gets :func:`model_rate_for` its IMU rate.
    """

    model_hz: int = 5000
    imu_hz: int = 1000
    mag_hz: int = 100
    baro_hz: int = 50
    pwm_hz: int = 400
    pwm_tick_hz: int = round(PWM_TICK_HZ)  # 1 µs, the unit PX4 uses for PWM widths

    @property
    def frame_us(self) -> int:
        """One lockstep frame: one IMU period."""
        return 1_000_000 // self.imu_hz


@dataclass(frozen=True)
class StartPose:
    position_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class Command:
    """One scripted ground-station action at ``at_s``."""

    at_s: float
    action: str
    params: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class FaultSpec:
    """One fault, active from ``start_s`` until ``end_s`` (None: until the end)."""

    kind: str
    start_s: float
    end_s: float | None = None
    params: Mapping[str, Any] = field(default_factory=dict)

    def active(self, time_s: float) -> bool:
        return self.start_s <= time_s and (self.end_s is None or time_s < self.end_s)


@dataclass(frozen=True)
class Scenario:
    name: str
    source: str
    description: str
    vehicle: str
    constraint: str
    environment: Environment
    start: StartPose
    duration_s: float
    seed: int
    sensor_layer: str
    rates: Rates
    commands: tuple[Command, ...]
    faults: tuple[FaultSpec, ...]
    #: The autopilot's clock at the start of the run (s); set by code, not by the file.
    clock_start_s: float = 0.0
    #: Pulse widths (µs) for motor command 0 and 1 (PWM_*_MIN/MAXn); set by code (a replay).
    motor_pwm_range_us: tuple[float, float] = DEFAULT_MOTOR_PWM_RANGE_US
    #: The pack's open-circuit voltage at the start, None: full; set by code (a replay).
    initial_battery_voltage_v: float | None = None


_TOP_KEYS = {
    "name", "description", "vehicle", "constraint", "duration_s", "seed", "sensor_layer",
    "environment", "start", "rates", "commands", "faults",
}  # fmt: skip


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a bundled scenario by name (``"hover"``) or any scenario file by path."""
    document, path = read_toml_file(
        name_or_path, SCENARIOS_DIR, kind="scenario", error=ScenarioError
    )
    return scenario_from_dict(document, str(path))


def scenario_from_dict(document: Mapping[str, Any], source: str = "<dict>") -> Scenario:
    """Check and convert a parsed scenario document; raises :class:`ScenarioError`."""
    where = _Where(source)
    where.no_unknown_keys(document, _TOP_KEYS, "")
    duration_s = where.get(document, "duration_s", "positive")
    rates = _rates(document.get("rates", {}), where)
    frame_s = rates.frame_us / 1e6
    commands = tuple(
        _command(item, f"commands[{i}]", where, duration_s)
        for i, item in enumerate(where.get(document, "commands", "table_list", default=[]))
    )
    faults = tuple(
        _fault(item, f"faults[{i}]", where, duration_s)
        for i, item in enumerate(where.get(document, "faults", "table_list", default=[]))
    )
    if duration_s < frame_s:
        where.fail("duration_s", duration_s, f"shorter than one IMU frame ({frame_s} s)")
    return Scenario(
        name=where.get(document, "name", "string"),
        source=source,
        description=where.get(document, "description", "string", default=""),
        vehicle=where.get(document, "vehicle", "string"),
        constraint=where.get(document, "constraint", "string", default="free", choices=CONSTRAINTS),
        environment=_environment(document.get("environment", {}), where),
        start=_start(document.get("start", {}), where),
        duration_s=duration_s,
        seed=where.get(document, "seed", "seed"),
        sensor_layer=where.get(
            document, "sensor_layer", "string", default="tlm", choices=SENSOR_LAYERS
        ),
        rates=rates,
        commands=tuple(sorted(commands, key=lambda c: c.at_s)),
        faults=faults,
    )


class _Where:
    """Builds the one-line messages: ``file: key 'a.b' = value: reason``."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, value: Any, reason: str) -> None:
        raise ScenarioError(f"{self.source}: key {key!r} = {value!r}: {reason}")

    def no_unknown_keys(self, table: Mapping[str, Any], known: set[str], prefix: str) -> None:
        if not isinstance(table, Mapping):
            raise ScenarioError(f"{self.source}: {prefix.rstrip('.') or 'file'} is not a table")
        for key in table:
            if key not in known:
                self.fail(
                    f"{prefix}{key}", table[key], f"unknown key (known: {', '.join(sorted(known))})"
                )

    def get(
        self,
        table: Mapping[str, Any],
        key: str,
        kind: str,
        *,
        default: Any = ...,
        prefix: str = "",
        choices: tuple[str, ...] = (),
    ) -> Any:
        if key not in table:
            if default is ...:
                raise ScenarioError(f"{self.source}: key {prefix + key!r} is missing")
            return default
        value = _typed(table[key], kind)
        if value is _BAD:
            self.fail(prefix + key, table[key], f"expected {_KIND_TEXT[kind]}")
        if choices and value not in choices:
            self.fail(prefix + key, value, f"expected one of {', '.join(choices)}")
        return value


_BAD = object()
_KIND_TEXT = {
    "number": "a number",
    "positive": "a positive number",
    "non_negative": "a number >= 0",
    "unit": "a number in 0..1",
    "string": "a string",
    "seed": "an integer >= 0",
    "rate": "a positive integer (Hz)",
    "motor": "a motor index 0..3",
    "byte": "an integer bit mask 1..255",
    "vector3": "three numbers",
    "vector3_list": "a non-empty list of three-number lists",
    "table_list": "an array of tables",
    "sensor": f"one of {', '.join(SENSORS)}",
    "chip": f"one of {', '.join(CHIPS)}",
    "bias": "a number or three numbers",
}


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    return float(value)


def _typed(value: Any, kind: str) -> Any:
    number = _number(value)
    integer = value if isinstance(value, int) and not isinstance(value, bool) else None
    checks = {
        "number": number,
        "positive": number if number is not None and number > 0 else None,
        "non_negative": number if number is not None and number >= 0 else None,
        "unit": number if number is not None and 0 <= number <= 1 else None,
        "string": value if isinstance(value, str) and value else None,
        "seed": integer if integer is not None and integer >= 0 else None,
        "rate": integer if integer is not None and integer > 0 else None,
        "motor": integer if integer is not None and 0 <= integer <= 3 else None,
        "byte": integer if integer is not None and 1 <= integer <= 255 else None,
        "sensor": value if value in SENSORS else None,
        "chip": value if value in CHIPS else None,
    }
    if kind in checks:
        result = checks[kind]
        return _BAD if result is None else result
    if kind == "vector3":
        return _vector3(value)
    if kind == "bias":
        return number if number is not None else _vector3(value)
    if kind == "vector3_list":
        if not isinstance(value, list) or not value:
            return _BAD
        vectors = [_vector3(v) for v in value]
        return _BAD if any(v is _BAD for v in vectors) else tuple(vectors)
    if kind == "table_list":
        return (
            value if isinstance(value, list) and all(isinstance(v, dict) for v in value) else _BAD
        )
    raise AssertionError(f"unknown kind {kind}")


def _vector3(value: Any) -> Any:
    if not isinstance(value, list) or len(value) != 3:
        return _BAD
    numbers = [_number(v) for v in value]
    return _BAD if None in numbers else tuple(numbers)


def model_rate_for(imu_hz: int) -> int:
    """The model's default rate: the least whole multiple of the IMU rate at or above 5 kHz
    (the paper's model rate), so every frame holds whole physics steps (400 Hz → 5.2 kHz)."""
    return imu_hz * -(-Rates.model_hz // imu_hz)


def _rates(table: Mapping[str, Any], where: _Where) -> Rates:
    names = ("model_hz", "imu_hz", "mag_hz", "baro_hz", "pwm_hz", "pwm_tick_hz")
    where.no_unknown_keys(table, set(names), "rates.")
    defaults = Rates()
    values = {
        n: where.get(table, n, "rate", default=getattr(defaults, n), prefix="rates.") for n in names
    }
    if "model_hz" not in table:
        values["model_hz"] = model_rate_for(values["imu_hz"])
    rates = Rates(**values)
    if 1_000_000 % rates.imu_hz:
        where.fail("rates.imu_hz", rates.imu_hz, "must give a whole number of µs per frame")
    if rates.model_hz % rates.imu_hz:
        where.fail("rates.imu_hz", rates.imu_hz, f"must divide rates.model_hz ({rates.model_hz})")
    for name in ("mag_hz", "baro_hz"):
        if getattr(rates, name) > rates.imu_hz:
            where.fail(
                f"rates.{name}", getattr(rates, name), f"exceeds rates.imu_hz ({rates.imu_hz})"
            )
    _check_pwm_tick(rates, where)
    return rates


def _check_pwm_tick(rates: Rates, where: _Where) -> None:
    """The capture tick must fit the gateware and hold the PWM period in whole ticks."""
    tick_hz = rates.pwm_tick_hz
    if not MIN_PWM_TICK_HZ <= tick_hz <= MAX_PWM_TICK_HZ:
        where.fail(
            "rates.pwm_tick_hz", tick_hz,
            f"must be within {MIN_PWM_TICK_HZ}..{MAX_PWM_TICK_HZ} Hz (10 µs to 0.4 µs ticks)",
        )  # fmt: skip
    # Whole system-clock cycles per tick keep the co-simulation's PWM clock edges off
    # the system clock's (fpga_hdl.cosim.harness).
    if round(HARNESS_SYS_CLK_HZ) % tick_hz:
        where.fail(
            "rates.pwm_tick_hz", tick_hz,
            f"must divide {round(HARNESS_SYS_CLK_HZ)} Hz (a whole number of 0.1 µs cycles)",
        )  # fmt: skip
    period_us = round(1e6 / rates.pwm_hz)
    if period_us * tick_hz % 1_000_000:
        where.fail(
            "rates.pwm_tick_hz", tick_hz,
            f"the PWM period ({period_us} µs at rates.pwm_hz = {rates.pwm_hz}) is not a whole "
            f"number of ticks ({1e6 / tick_hz:g} µs)",
        )  # fmt: skip


def _environment(table: Mapping[str, Any], where: _Where) -> Environment:
    keys = {
        "home",
        "magnetic_field",
        "wind_steady_ned_mps",
        "wind_at_6m_mps",
        "temperature_offset_k",
    }
    where.no_unknown_keys(table, keys, "environment.")
    default = Environment()
    home = default.home
    if "home" in table:
        t = table["home"]
        where.no_unknown_keys(t, {"lat_deg", "lon_deg", "alt_amsl_m"}, "environment.home.")
        home = GeoPoint(*(where.get(t, k, "number", prefix="environment.home.")
                          for k in ("lat_deg", "lon_deg", "alt_amsl_m")))  # fmt: skip
        if not (-90 <= home.lat_deg <= 90 and -180 <= home.lon_deg <= 180):
            where.fail("environment.home", t, "latitude must be in ±90° and longitude in ±180°")
    field_ = default.magnetic_field
    if "magnetic_field" in table:
        t = table["magnetic_field"]
        names = ("declination_deg", "inclination_deg", "intensity_gauss")
        where.no_unknown_keys(t, set(names), "environment.magnetic_field.")
        values = [where.get(t, k, "number", prefix="environment.magnetic_field.") for k in names]
        field_ = _quad_model_value(where, "environment.magnetic_field", t, MagneticField, *values)
    wind = Wind(
        steady_ned_mps=where.get(
            table, "wind_steady_ned_mps", "vector3", default=(0.0, 0.0, 0.0), prefix="environment."
        ),
        wind_at_6m_mps=where.get(
            table, "wind_at_6m_mps", "non_negative", default=0.0, prefix="environment."
        ),
    )
    offset = where.get(table, "temperature_offset_k", "number", default=0.0, prefix="environment.")
    return _quad_model_value(
        where, "environment.home", table.get("home"), Environment, home, field_, wind, offset
    )


def _quad_model_value(where: _Where, key: str, raw: Any, cls: type, *args: Any) -> Any:
    """Build a quad_model value; its own range checks become scenario errors on ``key``."""
    try:
        return cls(*args)
    except ValueError as error:
        where.fail(key, raw, str(error))


def _start(table: Mapping[str, Any], where: _Where) -> StartPose:
    where.no_unknown_keys(table, {"position_ned_m", "yaw_deg"}, "start.")
    position = where.get(
        table, "position_ned_m", "vector3", default=(0.0, 0.0, 0.0), prefix="start."
    )
    if position[2] > 0:
        where.fail("start.position_ned_m", list(position), "starts below the ground (down > 0)")
    return StartPose(position, where.get(table, "yaw_deg", "number", default=0.0, prefix="start."))


def _params(
    item: Mapping[str, Any], spec: dict[str, tuple[str, bool]], prefix: str, where: _Where
) -> dict[str, Any]:
    params = {}
    for name, (kind, required) in spec.items():
        value = where.get(item, name, kind, default=... if required else None, prefix=prefix)
        if value is not None:
            params[name] = value
    return params


def _command(item: Mapping[str, Any], key: str, where: _Where, duration_s: float) -> Command:
    prefix = f"{key}."
    action = where.get(item, "action", "string", prefix=prefix, choices=tuple(ACTIONS))
    spec = ACTIONS[action]
    where.no_unknown_keys(item, {"at_s", "action", *spec}, prefix)
    at_s = where.get(item, "at_s", "non_negative", prefix=prefix)
    if at_s >= duration_s:
        where.fail(
            prefix + "at_s", at_s, f"not before the end of the run (duration_s = {duration_s})"
        )
    params = _params(item, spec, prefix, where)
    if action == "pitch_sweep" and params["f_min_radps"] >= params["f_max_radps"]:
        where.fail(prefix + "f_max_radps", params["f_max_radps"], "must exceed f_min_radps")
    return Command(at_s=at_s, action=action, params=params)


def _fault(item: Mapping[str, Any], key: str, where: _Where, duration_s: float) -> FaultSpec:
    prefix = f"{key}."
    kind = where.get(item, "kind", "string", prefix=prefix, choices=tuple(FAULT_KINDS))
    spec = FAULT_KINDS[kind]
    where.no_unknown_keys(item, {"kind", "start_s", "end_s", *spec}, prefix)
    start_s = where.get(item, "start_s", "non_negative", prefix=prefix)
    end_s = where.get(item, "end_s", "positive", default=None, prefix=prefix)
    if start_s >= duration_s:
        where.fail(
            prefix + "start_s",
            start_s,
            f"not before the end of the run (duration_s = {duration_s})",
        )
    if end_s is not None and end_s <= start_s:
        where.fail(prefix + "end_s", end_s, f"must be after start_s ({start_s})")
    params = _params(item, spec, prefix, where)
    if kind == "sensor_bias":
        scalar = params["sensor"] == "baro"
        if scalar != isinstance(params["bias"], float):
            shape = "one number (Pa)" if scalar else "three numbers (sensor axes)"
            where.fail(prefix + "bias", item["bias"], f"the {params['sensor']} bias takes {shape}")
    return FaultSpec(kind=kind, start_s=start_s, end_s=end_s, params=params)
