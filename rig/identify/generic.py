"""The generic multicopter: every vehicle-file value for a quad of a given mass (arm length
and cell count), the starting point of ``rig vehicle`` for the values a log cannot give.

Each rule below is sized on the bundled vehicles (the F450's bench-measured set, the X500's
Gazebo and identified values) and common frame classes, and each value comes with how far
the bundled vehicles lie from it (``GenericVehicle.notes``: the ± a vehicle file carries).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from quad_model.environment import isa_density_kgpm3
from quad_model.frames import STANDARD_GRAVITY_MPS2
from quad_model.vehicle import (
    BatteryParams,
    BodyParams,
    PropulsionParams,
    Vehicle,
    load_vehicle,
)

#: Frame classes (mass kg, prop diameter m, centre-to-hub arm m), log-log interpolated and,
#: beyond the ends, at constant disc loading (D and arm ∝ √m): a 250 mm racer-class quad
#: (0.6 kg, 5-inch props), the F450 (1.4 kg, 9.4-inch DJI 9450, 0.225 m: its bench set),
#: the X500 V2 (2.0 kg, 10-inch, 0.246 m: Holybro's frame), a 650 mm frame for 15-inch props
#: (4 kg, 0.325 m: the Tarot 650 class the 8S quad's file assumes).
FRAME_CLASSES = (
    (0.6, 0.127, 0.125),
    (1.4, 0.239, 0.225),
    (2.0, 0.254, 0.246),
    (4.0, 0.381, 0.325),
)
#: Static thrust and power coefficients (n in rev/s: T = C_T·ρ·n²·D⁴, P = C_P·ρ·n³·D⁵) of a
#: typical multirotor prop: C_T ≈ 0.10 (the UIUC propeller data's 10-inch props, 0.10-0.11),
#: C_P/C_T = 0.40, the ratio of PX4's Gazebo x500 (momentConstant 0.016 m on a 10-inch prop:
#: 2π·0.016/0.254) and of the F450's bench k_Q/k_T (0.42).
THRUST_COEFFICIENT = 0.10
POWER_COEFFICIENT = 0.04
ISA_DENSITY_KGPM3 = isa_density_kgpm3(0.0)
#: The frame the scale rules below start from: the X500's 10-inch prop and 0.246 m arm.
REFERENCE_PROP_M = 0.254
REFERENCE_ARM_M = 0.246
#: Thrust to weight at full throttle: a common multicopter's 2 (the X500's curve).
FULL_THROTTLE_THRUST_TO_WEIGHT = 2.0
#: The generic hover throttle on the speed curve (before a log's hover moves it).
HOVER_THROTTLE = 0.5
#: Mass in the four motor pods (motor, prop, ESC, outer arm) as point masses at the hubs; the
#: rest a uniform box 0.6·arm square and 0.4·arm tall at the centre (battery, FMU, hub).
POD_MASS_FRACTION = 0.3
#: Rotor plane above the centre of mass, per metre of arm (X500 0.04 m at 0.246 m; 8S 0.05).
ROTOR_PLANE_PER_ARM = 0.15
#: A LiPo pack: 30 % of the mass at 150 Wh/kg; 0.06 Ω·Ah per cell (the X500's identified
#: 0.048 Ω for 4S 5 Ah).
PACK_MASS_FRACTION = 0.3
PACK_WH_PER_KG = 150.0
CELL_RESISTANCE_OHM_AH = 0.06
CELL_NOMINAL_V = 3.7
#: Where the sensors come from: the bundled X500 (a Pixhawk 6X-class board).
SENSOR_SOURCE = "x500_v2"


@dataclass(frozen=True)
class GenericVehicle:
    """A complete :class:`Vehicle` and, per ``table.key``, how it was sized (with its ±)."""

    vehicle: Vehicle
    notes: dict[str, str]


def frame_class(mass_kg: float) -> tuple[float, float]:
    """(prop diameter, arm) in metres for ``mass_kg``, from :data:`FRAME_CLASSES`."""
    masses, diameters, arms = (np.log(np.array(c)) for c in zip(*FRAME_CLASSES, strict=True))
    log_mass = math.log(mass_kg)

    def size(values: np.ndarray) -> float:
        if log_mass <= masses[0]:
            return float(np.exp(values[0] + (log_mass - masses[0]) / 2))
        if log_mass >= masses[-1]:
            return float(np.exp(values[-1] + (log_mass - masses[-1]) / 2))
        return float(np.exp(np.interp(log_mass, masses, values)))

    return size(diameters), size(arms)


def generic_vehicle(mass_kg: float, cell_count: int, arm_m: float | None = None) -> GenericVehicle:
    """The generic quad X of ``mass_kg`` on ``cell_count`` LiPo cells; ``arm_m`` (centre to
    hub) overrides the frame class's arm."""
    diameter, class_arm = frame_class(mass_kg)
    arm = class_arm if arm_m is None else arm_m
    arm_source = "given" if arm_m is not None else f"frame class of {mass_kg:g} kg"
    radius = diameter / 2
    k_t = THRUST_COEFFICIENT * ISA_DENSITY_KGPM3 * diameter**4 / (4 * math.pi**2)
    k_q = POWER_COEFFICIENT * ISA_DENSITY_KGPM3 * diameter**5 / (8 * math.pi**3)
    weight = mass_kg * STANDARD_GRAVITY_MPS2
    hover_speed = math.sqrt(weight / (4 * k_t))
    full_speed = math.sqrt(FULL_THROTTLE_THRUST_TO_WEIGHT) * hover_speed
    slope = (full_speed - hover_speed) / (1 - HOVER_THROTTLE)
    # Axial inflow by blade element and momentum theory at hover (x500_v2.toml's reasoning):
    # dT/dV = -2ρA·v_h·σa/(σa + 16λ_h) = -k·ω_h, σa = 0.55 for two 7.5 %-chord blades.
    disc = math.pi * radius**2
    induced = math.sqrt(weight / 4 / (2 * ISA_DENSITY_KGPM3 * disc))
    inflow = induced / (hover_speed * radius)
    solidity_lift = 0.55
    axial = (2 * ISA_DENSITY_KGPM3 * disc * induced * solidity_lift
             / (solidity_lift + 16 * inflow) / hover_speed)  # fmt: skip
    pod = POD_MASS_FRACTION * mass_kg / 4
    hub = (1 - POD_MASS_FRACTION) * mass_kg
    side, height = 0.6 * arm, 0.4 * arm
    i_xx = 4 * pod * arm**2 / 2 + hub * (side**2 + height**2) / 12
    i_zz = 4 * pod * arm**2 + hub * 2 * side**2 / 12
    h = arm / math.sqrt(2)
    plane = -ROTOR_PLANE_PER_ARM * arm
    capacity = PACK_MASS_FRACTION * mass_kg * PACK_WH_PER_KG / (cell_count * CELL_NOMINAL_V)
    sensors = load_vehicle(SENSOR_SOURCE)
    scale = diameter / REFERENCE_PROP_M
    vehicle = Vehicle(
        name=f"generic {mass_kg:g} kg quad X",
        body=BodyParams(
            mass_kg=mass_kg,
            inertia_kgm2=((i_xx, 0.0, 0.0), (0.0, i_xx, 0.0), (0.0, 0.0, i_zz)),
            drag_area_m2=(arm**2, arm**2, 2 * arm**2),
            angular_drag_nms2=(0.004 * (arm / REFERENCE_ARM_M) ** 4,) * 3,
        ),
        propulsion=PropulsionParams(
            position_frd_m=((h, h, plane), (-h, -h, plane), (h, -h, plane), (-h, h, plane)),
            spin_direction=(1, 1, -1, -1),
            thrust_coefficient_n_per_radps2=k_t,
            torque_coefficient_nm_per_radps2=k_q,
            reference_air_density_kgpm3=ISA_DENSITY_KGPM3,
            rotor_inertia_kgm2=6.8e-5 * scale**5,
            motor_time_constant_s=0.02 * scale**2,
            speed_slope_radps=slope,
            speed_offset_radps=full_speed - slope,
            min_throttle=0.05,
            speed_curve_voltage_v=cell_count * CELL_NOMINAL_V,
            rotor_drag_coefficient_ns_per_m_rad=8.06e-5 * scale**2,
            blade_count=2,
            axial_inflow_coefficient_ns_per_m_rad=axial,
        ),
        battery=BatteryParams(
            cell_count=cell_count,
            capacity_ah=capacity,
            cell_full_v=4.2,
            cell_empty_v=3.5,
            internal_resistance_ohm=cell_count * CELL_RESISTANCE_OHM_AH / capacity,
            propulsion_efficiency=0.7,
            avionics_power_w=5.0,
        ),
        imu=sensors.imu,
        vibration=replace(
            sensors.vibration,
            reference_rotor_speed_radps=hover_speed,
            level_rotor_speed_radps=(),
            accel_tone_level=(),
            accel_broadband_level=(),
            gyro_tone_level=(),
            gyro_broadband_level=(),
        ),
        baro=sensors.baro,
        mag=sensors.mag,
        gps=sensors.gps,
    )
    prop = f"{diameter / 0.0254:.1f}-inch prop (frame class of {mass_kg:g} kg)"
    notes = {
        "body.inertia_kgm2": f"ASSUMED: pods {POD_MASS_FRACTION:.0%} of the mass at the hubs, "
        f"the rest a box at the centre, arm {arm:.3f} m ({arm_source}); ± 50 % (the F450's "
        "bench inertia is 1.7× this, the X500's Gazebo one 1.0×)",
        "body.drag_area_m2": "C_D·A ≈ arm² sideways, twice from below; × 2 (X500 0.8×, F450 1.8×)",
        "body.angular_drag_nms2": "the X500's 0.004 × (arm/0.246 m)⁴; × 2 (F450 1.3×)",
        "propulsion.position_frd_m": f"quad X, arm {arm:.3f} m ({arm_source}), rotor plane "
        f"{-plane:.3f} m above the centre of mass (0.15·arm); ± 20 %",
        "propulsion.spin_direction": "PX4's quad X: 0, 1 CCW; 2, 3 CW",
        "propulsion.thrust_coefficient_n_per_radps2": f"C_T {THRUST_COEFFICIENT} of a {prop}: "
        "C_T·ρD⁴/4π²; ± 30 % (X500 1.15×, F450 1.1×)",
        "propulsion.torque_coefficient_nm_per_radps2": f"C_P {POWER_COEFFICIENT} of a {prop}: "
        "C_P·ρD⁵/8π³; ± 50 % (X500's Gazebo value 0.65×, F450 1.15×)",
        "propulsion.reference_air_density_kgpm3": "ISA sea level, where C_T and C_P hold",
        "propulsion.rotor_inertia_kgm2": "6.8e-5 kg·m² × (D/10 inch)⁵ (prop mass ∝ D³); × 3 "
        "(X500's Gazebo value 0.4×, F450 bench 2.6×)",
        "propulsion.motor_time_constant_s": "0.02 s (the F450's bench value) × (D/10 inch)²; × 2",
        "propulsion.speed_slope_radps": f"ω(1) = √{FULL_THROTTLE_THRUST_TO_WEIGHT:g}·ω_h "
        f"(thrust to weight {FULL_THROTTLE_THRUST_TO_WEIGHT:g} at full throttle); ± 30 %",
        "propulsion.speed_offset_radps": f"the hover at throttle {HOVER_THROTTLE}; ± 30 %",
        "propulsion.min_throttle": "a common ESC's start-up threshold (throttle 0-1 is PWM "
        "1000-2000 µs); ± 0.05",
        "propulsion.speed_curve_voltage_v": f"{CELL_NOMINAL_V} V per cell, loaded",
        "propulsion.rotor_drag_coefficient_ns_per_m_rad": "PX4 Gazebo x500's 8.06e-5 × prop "
        "area; × 2 (F450 1.5×)",
        "propulsion.blade_count": "two-blade props, the common multicopter prop",
        "propulsion.axial_inflow_coefficient_ns_per_m_rad": "blade element + momentum theory at "
        "the generic hover (σa = 0.55); ± 50 %",
        "propulsion.coaxial_thrust_factor": "1: a quad X has no coaxial pair",
        "propulsion.coaxial_torque_factor": "1: a quad X has no coaxial pair",
        "battery.capacity_ah": f"a LiPo of {PACK_MASS_FRACTION:.0%} of the mass at "
        f"{PACK_WH_PER_KG:g} Wh/kg; ± 50 %",
        "battery.cell_full_v": "LiPo charge voltage",
        "battery.cell_empty_v": "a loaded LiPo's cut-off; ± 0.1 V",
        "battery.internal_resistance_ohm": f"{CELL_RESISTANCE_OHM_AH} Ω·Ah per cell over the "
        "capacity (the X500's identified pack); × 2",
        "battery.propulsion_efficiency": "motor × ESC; ± 0.15 (X500 0.60, 8S quad 0.78)",
        "battery.avionics_power_w": "FMU, GNSS, receiver, telemetry; ± 3 W",
    }
    for table in ("imu", "baro", "mag", "gps"):
        for key in getattr(vehicle, table).__dataclass_fields__:
            notes[f"{table}.{key}"] = (
                f"the bundled {SENSOR_SOURCE}'s (a Pixhawk 6X-class board), unchecked on this one"
            )
    for key in vehicle.vibration.__dataclass_fields__:
        notes[f"vibration.{key}"] = f"the bundled {SENSOR_SOURCE}'s spectrum shape"
    notes["vibration.reference_rotor_speed_radps"] = "the generic hover rotor speed"
    notes["vibration.level_rotor_speed_radps"] = "none: the levels follow ω² from the shape"
    for key in ("accel_tone_level", "accel_broadband_level", "gyro_tone_level",
                "gyro_broadband_level"):  # fmt: skip
        notes[f"vibration.{key}"] = "none (ω² law)"
    return GenericVehicle(vehicle, notes)
