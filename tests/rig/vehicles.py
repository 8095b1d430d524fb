"""Vehicle files of six and eight rotors for the rig's tests, built from bundled quads:
the F450 on the six arms of PX4's hexa X (airframe 6001) and the X500 as PX4's coaxial
X8 (airframe 12001), each in that airframe's motor order and spins (spin +1: CCW, PX4's
KM > 0)."""

import dataclasses
import math
from pathlib import Path
from typing import Any

import tomli_w

from quad_model import load_vehicle

#: PX4 6001_hexa_x: rotor i's bearing from the nose (deg, towards the right) and spin.
HEXA_X = ((90, -1), (270, 1), (330, -1), (150, 1), (30, 1), (210, -1))
#: PX4 12001_octo_cox: rotor i's arm (front +, right +), upper (0-3) or lower (4-7), spin.
UPPER_Z_M, LOWER_Z_M = -0.08, -0.02
X8 = (((1, 1), UPPER_Z_M, 1), ((1, -1), UPPER_Z_M, -1), ((-1, -1), UPPER_Z_M, 1),
      ((-1, 1), UPPER_Z_M, -1), ((1, -1), LOWER_Z_M, 1), ((1, 1), LOWER_Z_M, -1),
      ((-1, 1), LOWER_Z_M, 1), ((-1, -1), LOWER_Z_M, -1))  # fmt: skip
#: The lower rotor of a coaxial pair in its upper's wake (as tests/quad_model's X8).
COAXIAL_THRUST_FACTOR, COAXIAL_TORQUE_FACTOR = 0.8, 0.9
#: The X8 carries four more motors and a larger pack than the X500: its mass and inertia
#: this many times the X500's (hover throttle about 0.4 instead of 0.13).
X8_MASS_RATIO = 1.75


def hexa_x(folder: Path) -> Path:
    """The F450 (high precision) with six of its rotors on arms of its own length."""
    base = load_vehicle("f450_high_precision")
    arm_m = math.hypot(*base.propulsion.position_frd_m[0][:2])
    hubs = [[round(arm_m * math.cos(math.radians(bearing)), 4) + 0.0,
             round(arm_m * math.sin(math.radians(bearing)), 4) + 0.0, 0.0]
            for bearing, _ in HEXA_X]  # fmt: skip
    return _write(base, folder / "hexa_x.toml", "F450 hexa X", hubs, [s for _, s in HEXA_X])


def x8(folder: Path) -> Path:
    """The X500 v2 with an upper and a lower rotor on each of its arms, 6 cm apart."""
    base = load_vehicle("x500_v2")
    body = base.body
    base = dataclasses.replace(base, body=dataclasses.replace(
        body, mass_kg=body.mass_kg * X8_MASS_RATIO,
        inertia_kgm2=tuple(tuple(X8_MASS_RATIO * i for i in row) for row in body.inertia_kgm2),
    ))  # fmt: skip
    arm_m = abs(base.propulsion.position_frd_m[0][0])
    hubs = [[arm_m * x, arm_m * y, z] for (x, y), z, _ in X8]
    return _write(base, folder / "x8.toml", "X500 coaxial X8", hubs, [s for *_, s in X8],
                  coaxial_thrust_factor=COAXIAL_THRUST_FACTOR,
                  coaxial_torque_factor=COAXIAL_TORQUE_FACTOR)  # fmt: skip


def _write(base: Any, path: Path, name: str, hubs: list[list[float]], spins: list[int],
           **propulsion: float) -> Path:  # fmt: skip
    document = _without_none(dataclasses.asdict(base))
    document["name"] = name
    document["propulsion"] |= {"position_frd_m": hubs, "spin_direction": spins} | propulsion
    path.write_text(tomli_w.dumps(document))
    return path


def _without_none(value: Any) -> Any:
    """A TOML file leaves an absent table or key out."""
    if isinstance(value, dict):
        return {k: _without_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, list | tuple):
        return [_without_none(v) for v in value]
    return value
