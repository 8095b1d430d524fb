"""Which of a PX4 log's outputs drive the motors: the output driver (PWM, DShot, UAVCAN ESCs),
its range in its own unit and as ESC throttle, and the ``actuator_outputs`` instance and
channels that carry motor 1..N.

PX4 1.13 on assigns a function to each output of each driver by ``<PREFIX>_FUNCn`` (Motor m
is function 100 + m) with the range ``<PREFIX>_MINn/MAXn`` in the driver's unit
(``src/lib/mixer_module``); each driver publishes its own ``actuator_outputs`` instance, in
the order the drivers started, so which instance is which is read from the data. An older
PX4 had one range for all main outputs (``PWM_MAIN_MIN/MAX``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from px4_logs.errors import LogError

if TYPE_CHECKING:  # the reader imports this module to derive an older layout's motors
    from px4_logs.flight_log import FlightLog

Topic = Mapping[str, NDArray[Any]]

#: The model's ESC convention: PWM (µs) at throttle 0 and 1; PX4's range when a log sets none.
DEFAULT_PWM_RANGE_US = (1000.0, 2000.0)
#: PX4's output functions Motor 1..12.
MOTOR_FUNCTIONS = tuple(range(101, 113))
#: ``<PREFIX>_TIMn`` values that make PX4's dshot driver take the prefix's outputs
#: (DShot150, DShot300, DShot600); its other timers are then left out.
DSHOT_TIMER_VALUES = (-5.0, -4.0, -3.0)
#: The dshot driver's output values at full throttle, and its floor (0 is "disarmed").
DSHOT_FULL_SCALE = 1999.0
DSHOT_MIN_VALUE = 1.0


class OutputProtocol(StrEnum):
    PWM = "pwm"
    DSHOT = "dshot"
    CAN = "can"


@dataclass(frozen=True)
class _Driver:
    prefix: str
    protocol: OutputProtocol
    unit: str
    #: The driver's values at ESC throttle 0 and 1.
    full_scale: tuple[float, float]


#: PX4's output drivers configured by ``<PREFIX>_FUNCn`` that run ESCs (module.yaml of
#: pwm_out, px4io, pca9685_pwm_out, uavcan). PWM_MAIN/AUX turn DShot by their timers.
DRIVERS = (
    _Driver("PWM_MAIN", OutputProtocol.PWM, "µs", DEFAULT_PWM_RANGE_US),
    _Driver("PWM_AUX", OutputProtocol.PWM, "µs", DEFAULT_PWM_RANGE_US),
    _Driver("PCA9685", OutputProtocol.PWM, "µs", DEFAULT_PWM_RANGE_US),
    # UAVCAN's esc.RawCommand: 0..8191 is the ESC's full throttle
    _Driver("UAVCAN_EC", OutputProtocol.CAN, "CAN raw", (0.0, 8191.0)),
)


@dataclass(frozen=True)
class MotorOutputs:
    """How a log's motor commands (``actuator_motors``, 0..1) reached the ESCs."""

    protocol: OutputProtocol
    #: ``CA_ROTOR_COUNT``, else the motor functions found.
    rotor_count: int
    #: ESC throttle (the model's convention: PWM 1000..2000 µs → 0..1; DShot and CAN their
    #: full digital range → 0..1) at motor command 0 and 1; outside 0..1 where the driver's
    #: range passes the ESC's (a PWM minimum below 1000 µs), which the ESC clips.
    throttle_range: tuple[float, float]
    #: The same in the driver's own unit (``unit``).
    output_range: tuple[float, float]
    unit: str
    #: The ``actuator_outputs`` instance that carries the motors (None: not logged).
    instance: int | None
    #: Its channel index (0-based) of motor 1..N.
    channels: tuple[int, ...]
    #: One line: how this was decided (parameters, which instance moved), for notes.
    reason: str

    @property
    def pwm_range_us(self) -> tuple[float, float]:
        """The PWM (µs) giving the same ESC throttle at command 0 and 1 on the model's
        1000-2000 µs convention: what the rig's PWM outputs and the vehicle model take."""
        low, span = DEFAULT_PWM_RANGE_US[0], DEFAULT_PWM_RANGE_US[1] - DEFAULT_PWM_RANGE_US[0]
        return low + span * self.throttle_range[0], low + span * self.throttle_range[1]

    def commands(self, outputs: Topic) -> NDArray[np.float64]:
        """The motor commands (rows × motors, 0..1) an ``actuator_outputs`` sample of this
        instance stands for: its motor channels mapped back through ``output_range``."""
        low, high = self.output_range
        values = np.column_stack(
            [np.asarray(outputs[f"output[{c}]"], float) for c in self.channels]
        )
        return np.clip((values - low) / (high - low), 0.0, 1.0)


def motor_outputs(log: FlightLog) -> MotorOutputs:
    """The motor outputs of ``log``: the driver whose ``<PREFIX>_FUNCn`` hold the motors, its
    range, and the ``actuator_outputs`` instance whose motor channels move with the thrust."""
    return motor_layout(
        log.parameters,
        log.instances("actuator_outputs"),
        log.topics.get("vehicle_thrust_setpoint"),
        log.topics.get("actuator_armed"),
        log.path,
    )


def motor_layout(
    parameters: Mapping[str, float],
    outputs: Sequence[Topic],
    thrust: Topic | None,
    armed: Topic | None,
    source: str | Path,
) -> MotorOutputs:
    """:func:`motor_outputs` from the log's parts (the reader calls it before it is built):
    ``outputs`` are the ``actuator_outputs`` instances, each sorted by time."""
    found = _motor_channels(parameters, source)
    if found is None:  # an older PX4 (one PWM_MAIN range) or none set (SITL, the rig)
        legacy = "PWM_MAIN_MIN" in parameters and "PWM_MAIN_MAX" in parameters
        output_range = (
            (float(parameters["PWM_MAIN_MIN"]), float(parameters["PWM_MAIN_MAX"]))
            if legacy
            else DEFAULT_PWM_RANGE_US
        )
        count = int(parameters.get("CA_ROTOR_COUNT", 0)) or _output_count(outputs)
        driver, channels = DRIVERS[0], tuple(range(count))
        decided = (
            "PWM_MAIN_MIN/MAX (PX4 before 1.13)"
            if legacy
            else "no motor output parameters: PX4's default PWM 1000-2000 µs"
        )
    else:
        driver, channels, output_range, range_from = found
        count = int(parameters.get("CA_ROTOR_COUNT", 0)) or len(channels)
        decided = f"{driver.prefix or 'PWM'}_FUNCn hold motors 1-{len(channels)} ({range_from})"
    instance, moved = _moving_instance(outputs, channels, thrust, armed)
    low, high = driver.full_scale
    return MotorOutputs(
        protocol=driver.protocol,
        rotor_count=count,
        throttle_range=(
            (output_range[0] - low) / (high - low),
            (output_range[1] - low) / (high - low),
        ),
        output_range=output_range,
        unit=driver.unit,
        instance=instance,
        channels=channels,
        reason=f"{driver.protocol.value} {output_range[0]:g}-{output_range[1]:g} {driver.unit}: "
        f"{decided}; {moved}",
    )


def _motor_channels(
    parameters: Mapping[str, float], source: str | Path
) -> tuple[_Driver, tuple[int, ...], tuple[float, float], str] | None:
    """The driver holding the motor functions, the channel of each motor, their range and
    where the range came from; None when no ``<PREFIX>_FUNCn`` is a motor (a PX4 before
    1.13)."""
    holders: dict[str, dict[int, int]] = {}  # prefix → motor → 0-based channel
    for key, function in parameters.items():
        prefix, _, channel = key.rpartition("_FUNC")
        known = any(prefix == driver.prefix for driver in DRIVERS)
        if function in MOTOR_FUNCTIONS and channel.isdigit() and known:
            holders.setdefault(prefix, {})[int(function) - 100] = int(channel) - 1
    if not holders:
        return None
    if len(holders) > 1:
        raise LogError(
            f"{source}: the motors are spread over the output drivers {sorted(holders)}: "
            "one driver's range and instance per vehicle is supported"
        )
    ((prefix, motors),) = holders.items()
    missing = [m for m in range(1, max(motors) + 1) if m not in motors]
    if missing:
        raise LogError(
            f"{source}: no {prefix}_FUNCn is Motor {missing[0]} (motors {sorted(motors)})"
        )
    channels = tuple(motors[m] for m in sorted(motors))
    driver = next(d for d in DRIVERS if d.prefix == prefix)
    timers = [v for k, v in parameters.items() if k.startswith(f"{prefix}_TIM")]
    if driver.protocol is OutputProtocol.PWM and any(v in DSHOT_TIMER_VALUES for v in timers):
        # the dshot driver ignores the PWM limits: DSHOT_MIN × full scale up to full scale
        floor = max(
            DSHOT_MIN_VALUE, float(int(parameters.get("DSHOT_MIN", 0.0) * DSHOT_FULL_SCALE))
        )
        dshot = _Driver(prefix, OutputProtocol.DSHOT, "DShot", (0.0, DSHOT_FULL_SCALE))
        return dshot, channels, (floor, DSHOT_FULL_SCALE), "DSHOT_MIN"
    limits_of = [(f"{prefix}_MIN{c + 1}", f"{prefix}_MAX{c + 1}") for c in channels]
    if driver.protocol is OutputProtocol.PWM and not any(
        name in parameters for pair in limits_of for name in pair
    ):
        # PX4 SITL's simulated PWM outputs have the functions but no limits to set
        return driver, channels, DEFAULT_PWM_RANGE_US, f"no {prefix}_MIN/MAXn: PX4's default"
    ranges = set()
    for motor, output in enumerate((c + 1 for c in channels), start=1):
        limits = (f"{prefix}_MIN{output}", f"{prefix}_MAX{output}")
        for name in limits:
            if name not in parameters:
                raise LogError(
                    f"{source}: parameter {name} is not in the log "
                    f"({prefix}_FUNC{output} = {100 + motor} is a motor output)"
                )
        ranges.add((float(parameters[limits[0]]), float(parameters[limits[1]])))
    if len(ranges) > 1:
        raise LogError(f"{source}: the motor outputs have different ranges {sorted(ranges)}")
    return driver, channels, ranges.pop(), f"{prefix}_MIN/MAXn"


def _output_count(outputs: Sequence[Topic]) -> int:
    """The outputs in use of an older layout (its motors are the first ones): the largest
    ``noutputs`` any instance logged, else its ``output[i]`` columns."""
    counts = [
        int(np.max(data["noutputs"])) if "noutputs" in data and len(data["noutputs"])
        else sum(1 for field in data if field.startswith("output["))
        for data in outputs
    ]  # fmt: skip
    return max(counts, default=0)


def _moving_instance(
    outputs: Sequence[Topic], channels: tuple[int, ...], thrust: Topic | None, armed: Topic | None
) -> tuple[int | None, str]:
    """The instance whose motor channels follow the collective thrust set-point most closely
    while armed (Pearson r of their mean with it); an instance whose motor channels never
    change (a driver with no ESC on it logs zeros) cannot win. Without a thrust set-point,
    the first that moves."""
    if not outputs:
        return None, "actuator_outputs not logged"
    best, best_score, scores = None, -np.inf, []
    for index, data in enumerate(outputs):
        if not channels or any(f"output[{c}]" not in data for c in channels):
            scores.append(f"{index}: lacks the motor channels")
            continue
        stamps = np.asarray(data["timestamp"], dtype=float)
        motors = np.mean([np.asarray(data[f"output[{c}]"], float) for c in channels], axis=0)
        if armed is not None and "armed" in armed:
            state = np.asarray(armed["armed"], dtype=float)
            at = np.searchsorted(np.asarray(armed["timestamp"], float), stamps, "right") - 1
            on = state[np.clip(at, 0, None)] > 0.5
            if on.sum() >= 2:
                stamps, motors = stamps[on], motors[on]
        if motors.size < 2 or np.ptp(motors) == 0.0:
            scores.append(f"{index}: constant")
            continue
        score = 0.0
        if thrust is not None and "xyz[2]" in thrust:
            lift = -np.interp(stamps, np.asarray(thrust["timestamp"], float), thrust["xyz[2]"])
            score = float(np.corrcoef(motors, lift)[0, 1]) if np.ptp(lift) > 0 else 0.0
            scores.append(f"{index}: r = {score:.2f} with the thrust")
        else:
            scores.append(f"{index}: moves")
        if score > best_score:
            best, best_score = index, score
    if best is None:
        return None, "no actuator_outputs instance moves its motor channels (" + "; ".join(
            scores
        ) + ")"
    return best, f"actuator_outputs instance {best} carries them ({'; '.join(scores)})"
