"""The physical bounds of identified values, in one place: an estimate outside them is refused
(the table and ``--toml`` show why, never the number) and the vehicle keeps its prior value.

Why: a fit always returns a number, and a log the method does not suit (motors on another
output, a doctored or damaged log) gives numbers no vehicle can have; printed as results they
would be pasted into a vehicle file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from rig.identify.results import Estimate

#: The rotor count the identification's fits are written for (a quad's mixer, hover and
#: thrust stand); the model flies more (quad_model.vehicle.ROTOR_COUNTS).
QUAD_ROTORS = 4


@dataclass(frozen=True)
class Bound:
    """``low < value < high`` (``closed``: ``low ≤ value ≤ high``), and why."""

    low: float
    high: float
    why: str
    closed: bool = False

    def holds(self, value: float) -> bool:
        if self.closed:
            return self.low <= value <= self.high
        return self.low < value < self.high


BOUNDS = {
    "hover throttle": Bound(0.0, 1.0, "at throttle 0 the rotors stand, at 1 nothing is left "
                            "to control with"),
    "motor command": Bound(0.0, 1.0, "a motor at command 0 (or saturated at 1) does not hold "
                           "a hover"),
    "speed offset": Bound(-math.inf, math.inf, "the speed curve is finite"),
    "rotor speed": Bound(0.0, math.inf, "a standing rotor lifts nothing"),
    "rotor line": Bound(0.0, math.inf, "a rotor line is at a positive frequency"),
    "thrust coefficient": Bound(0.0, math.inf, "a turning rotor lifts"),
    "control effectiveness": Bound(0.0, math.inf, "a positive torque speeds the body up"),
    "inertia": Bound(0.0, math.inf, "every body has a positive moment of inertia"),
    "motor time constant": Bound(0.0, math.inf, "a motor takes time to change speed"),
    "delay": Bound(0.0, math.inf, "the response cannot come before the command", closed=True),
    "internal resistance": Bound(0.0, math.inf, "a loaded battery's voltage sags"),
    "avionics power": Bound(0.0, math.inf, "the flight controller draws power"),
    # motor × ESC × propeller: hobby multicopters 0.4-0.8; below 0.2 the torque coefficient
    # or the rotor speed is off, above 1 the rotors would make energy
    "propulsion efficiency": Bound(0.2, 1.0, "multicopter propulsion converts 20-100 % of "
                                   "its electrical power to shaft power", closed=True),
}  # fmt: skip


def refusal(quantity: str, value: float, uncertainty: float = 0.0) -> str:
    """Why ``value`` ± ``uncertainty`` cannot be the ``quantity`` (a key of BOUNDS); "" when
    it can."""
    bound = BOUNDS[quantity]
    if not (math.isfinite(value) and bound.holds(value)):
        brackets = "[]" if bound.closed else "()"
        return (
            f"{quantity} {value:.4g} is outside {brackets[0]}{bound.low:g}, {bound.high:g}"
            f"{brackets[1]}: {bound.why}"
        )
    if not math.isfinite(uncertainty):
        return f"{quantity} {value:.4g} has an uncertainty that is not finite"
    return ""


def motor_refusal(commands: tuple[float, ...]) -> str:
    """Why the hover's mean motor commands cannot be a hover's ("" when they can): a motor at
    0 is a log whose commands are not the motors' (another output's zeros), and the mean of
    the others would pass for a throttle."""
    for motor, command in enumerate(commands, start=1):
        reason = refusal("motor command", command)
        if reason:
            return f"motor {motor}: {reason}"
    return ""


def bounded(quantity: str, estimate: Estimate) -> Estimate:
    """``estimate``, refused with the reason when it is outside its quantity's bound."""
    reason = estimate.refused or refusal(quantity, estimate.value, estimate.uncertainty)
    return replace(estimate, refused=reason)
