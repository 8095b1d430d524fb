"""PX4's topics across versions: the newer topics a reader wants, derived from what a log of
an older layout holds.

PX4 1.13 split the mixer into control allocation: ``vehicle_torque_setpoint``,
``vehicle_thrust_setpoint`` and ``actuator_motors`` replaced ``actuator_controls_0`` (roll,
pitch, yaw torque and thrust, −1..1 / 0..1) and the normalised motor commands were only in
``actuator_outputs`` (PWM µs). ``vehicle_angular_velocity`` appeared in 1.10; before it the
body rates were ``sensor_combined.gyro_rad``. A derived topic is an approximation of the one
it stands for, so each says how in a note the reader shows.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Topics = dict[str, dict[str, NDArray]]
#: PX4's PWM at motor command 0 and 1 (µs) when a log sets no range.
DEFAULT_PWM_RANGE_US = (1000.0, 2000.0)


def legacy_pwm_range(parameters: Mapping[str, float]) -> tuple[float, float] | None:
    """``PWM_MAIN_MIN``/``PWM_MAIN_MAX`` of a log before PX4 1.13 (one range for every main
    output), None when the log has not both."""
    if "PWM_MAIN_MIN" in parameters and "PWM_MAIN_MAX" in parameters:
        return float(parameters["PWM_MAIN_MIN"]), float(parameters["PWM_MAIN_MAX"])
    return None


@dataclass(frozen=True)
class Derivation:
    """How to make ``topic`` from ``sources`` when a log lacks it."""

    topic: str
    sources: tuple[str, ...]
    note: str
    derive: Callable[[Topics, Mapping[str, float]], dict[str, NDArray]]


def _rates_from_gyro(topics: Topics, _: Mapping[str, float]) -> dict[str, NDArray]:
    gyro = topics["sensor_combined"]
    rates = {f"xyz[{i}]": gyro[f"gyro_rad[{i}]"] for i in range(3)}
    return {"timestamp": gyro["timestamp"], "timestamp_sample": gyro["timestamp"], **rates}


def _torque_from_controls(topics: Topics, _: Mapping[str, float]) -> dict[str, NDArray]:
    controls = topics["actuator_controls_0"]
    torque = {f"xyz[{i}]": controls[f"control[{i}]"] for i in range(3)}
    return {"timestamp": controls["timestamp"], **torque}


def _thrust_from_controls(topics: Topics, _: Mapping[str, float]) -> dict[str, NDArray]:
    controls = topics["actuator_controls_0"]
    zero = np.zeros_like(controls["control[3]"])
    # FRD body: thrust points up, along −z
    return {"timestamp": controls["timestamp"], "xyz[0]": zero, "xyz[1]": zero,
            "xyz[2]": -controls["control[3]"]}  # fmt: skip


def _motors_from_outputs(topics: Topics, parameters: Mapping[str, float]) -> dict[str, NDArray]:
    outputs = topics["actuator_outputs"]
    low, high = legacy_pwm_range(parameters) or DEFAULT_PWM_RANGE_US
    motors = {"timestamp": outputs["timestamp"]}
    for i in range(8):
        field = f"output[{i}]"
        if field in outputs:
            motors[f"control[{i}]"] = np.clip((outputs[field] - low) / (high - low), 0.0, 1.0)
    return motors


DERIVATIONS = (
    Derivation("vehicle_angular_velocity", ("sensor_combined",),
               "vehicle_angular_velocity derived from sensor_combined.gyro_rad (the log predates "
               "PX4 1.10: raw gyro, not bias-corrected or filtered)", _rates_from_gyro),
    Derivation("vehicle_torque_setpoint", ("actuator_controls_0",),
               "vehicle_torque_setpoint derived from actuator_controls_0 (the log predates PX4 "
               "1.13)", _torque_from_controls),
    Derivation("vehicle_thrust_setpoint", ("actuator_controls_0",),
               "vehicle_thrust_setpoint derived from actuator_controls_0 (the log predates PX4 "
               "1.13)", _thrust_from_controls),
    Derivation("actuator_motors", ("actuator_outputs",),
               "actuator_motors derived from actuator_outputs with PWM_MAIN_MIN/MAX (the log "
               "predates PX4 1.13)", _motors_from_outputs),
)  # fmt: skip


def derive_missing(topics: Topics, parameters: Mapping[str, float]) -> tuple[str, ...]:
    """Add each topic the log lacks and can derive (``topics`` is changed in place);
    returns the notes of what was derived."""
    notes = []
    for derivation in DERIVATIONS:
        sources_present = all(source in topics for source in derivation.sources)
        if derivation.topic not in topics and sources_present:
            try:
                topics[derivation.topic] = derivation.derive(topics, parameters)
            except KeyError:  # a source without the fields it needs (a damaged log) gives none
                continue
            notes.append(derivation.note)
    return tuple(notes)
