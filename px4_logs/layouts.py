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

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from px4_logs.outputs import motor_layout

Topics = dict[str, dict[str, NDArray]]


@dataclass(frozen=True)
class LogParts:
    """What a derivation reads: the first instance of each topic (with the topics derived
    before it), every instance in ``multi_id`` order, the parameters, the file (messages)."""

    topics: Topics
    instances: Mapping[str, Sequence[Mapping[str, NDArray]]]
    parameters: Mapping[str, float]
    source: str | Path


@dataclass(frozen=True)
class Derivation:
    """How to make ``topic`` from ``sources`` when a log lacks it (None: the log cannot)."""

    topic: str
    sources: tuple[str, ...]
    note: str
    derive: Callable[[LogParts], dict[str, NDArray] | None]


def _rates_from_gyro(log: LogParts) -> dict[str, NDArray]:
    gyro = log.topics["sensor_combined"]
    rates = {f"xyz[{i}]": gyro[f"gyro_rad[{i}]"] for i in range(3)}
    return {"timestamp": gyro["timestamp"], "timestamp_sample": gyro["timestamp"], **rates}


def _torque_from_controls(log: LogParts) -> dict[str, NDArray]:
    controls = log.topics["actuator_controls_0"]
    torque = {f"xyz[{i}]": controls[f"control[{i}]"] for i in range(3)}
    return {"timestamp": controls["timestamp"], **torque}


def _thrust_from_controls(log: LogParts) -> dict[str, NDArray]:
    controls = log.topics["actuator_controls_0"]
    zero = np.zeros_like(controls["control[3]"])
    # FRD body: thrust points up, along −z
    return {"timestamp": controls["timestamp"], "xyz[0]": zero, "xyz[1]": zero,
            "xyz[2]": -controls["control[3]"]}  # fmt: skip


def _motors_from_outputs(log: LogParts) -> dict[str, NDArray] | None:
    # the instance whose motor channels move with the thrust: another driver's may log zeros
    outputs = log.instances["actuator_outputs"]
    thrust, armed = log.topics.get("vehicle_thrust_setpoint"), log.topics.get("actuator_armed")
    layout = motor_layout(log.parameters, outputs, thrust, armed, log.source)
    if layout.instance is None:
        return None
    chosen = outputs[layout.instance]
    commands = layout.commands(chosen)
    motors = {"timestamp": np.asarray(chosen["timestamp"])}
    motors |= {f"control[{i}]": commands[:, i] for i in range(commands.shape[1])}
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
               "actuator_motors derived from the motor channels of actuator_outputs through "
               "their output range (the log predates PX4 1.13)", _motors_from_outputs),
)  # fmt: skip


def derive_missing(log: LogParts) -> tuple[str, ...]:
    """Add each topic the log lacks and can derive (``log.topics`` is changed in place);
    returns the notes of what was derived."""
    notes = []
    for derivation in DERIVATIONS:
        sources_present = all(source in log.topics for source in derivation.sources)
        if derivation.topic not in log.topics and sources_present:
            try:
                derived = derivation.derive(log)
            except KeyError:  # a source without the fields it needs (a damaged log)
                continue
            if derived is not None:
                log.topics[derivation.topic] = derived
                notes.append(derivation.note)
    return tuple(notes)
