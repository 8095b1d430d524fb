"""The identification of a vehicle from one flight log: each method in turn, on the log read
once."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from px4_logs import FlightLog, MotorOutputs, OutputProtocol, motor_outputs
from quad_model.vehicle import Vehicle
from rig.identify.battery import identify_battery
from rig.identify.bounds import QUAD_ROTORS
from rig.identify.hover import identify_hover
from rig.identify.rate_plant import (
    ALIASING_BIAS,
    ALIASING_RATE_HZ,
    identify_axis,
    torque_per_unit_nm,
)
from rig.identify.results import AxisIdentification, Identification, IdentificationError


def identify_vehicle(
    log: FlightLog,
    vehicle: Vehicle,
    excitation_window_s: tuple[float, float] | None = None,
) -> Identification:
    """Identify hover, roll/pitch plant and inertia of ``vehicle`` from one flight log.

    ``excitation_window_s`` is the span for the rate-loop fit (default: the whole airborne
    span); the whole airborne span is always fitted too, as a cross-check.
    """
    sample_rate_hz = _sample_rate_hz(log)
    gyro_cutoff_hz = float(log.parameters.get("IMU_GYRO_CUTOFF", 0.0))
    outputs = motor_outputs(log)
    # the fits' mixer, hover and thrust stand are a quad's; a PX4 before 1.13 logs no count
    if "CA_ROTOR_COUNT" in log.parameters and outputs.rotor_count != QUAD_ROTORS:
        raise IdentificationError(
            f"{log.path}: {outputs.rotor_count} rotors ({outputs.reason}); the identification "
            f"handles {QUAD_ROTORS}"
        )
    pwm_range = outputs.pwm_range_us
    airborne = log.airborne_span()
    window = excitation_window_s or airborne
    if not (airborne[0] <= window[0] < window[1] <= airborne[1]):
        raise IdentificationError(
            f"{log.path}: excitation window {window[0]:g}-{window[1]:g} s is not inside the "
            f"airborne span {airborne[0]:.1f}-{airborne[1]:.1f} s"
        )
    hover = identify_hover(log, vehicle, outputs)
    identified_vehicle = replace(
        vehicle,
        propulsion=replace(
            vehicle.propulsion,
            speed_offset_radps=hover.speed_offset_radps.value,
            speed_slope_radps=hover.speed_slope_radps,
        ),
    )
    torque_per_unit = torque_per_unit_nm(
        identified_vehicle,
        log.parameters,
        float(np.mean(hover.motor_command)),
        pwm_range,
        hover.battery_voltage_v,
        hover.air_density_kgpm3,
    )
    axes = [
        identify_axis(
            log, axis, window, airborne, sample_rate_hz, gyro_cutoff_hz, torque_per_unit[axis]
        )
        for axis in range(2)
    ]
    if hover.throttle.refused:  # the torque per unit is the mixer's at the hover command
        axes = [_without_hover(axis, hover.throttle.refused) for axis in axes]
    axes.append(
        AxisIdentification(
            "yaw",
            identified=False,
            reason="not identifiable: the yaw reaction torque (rotor drag + spin-up) is not "
            "the B/(s(τs+1)) plant and flight excites it little; I_zz kept from the vehicle",
        )
    )
    battery, battery_reason = identify_battery(log, hover, vehicle)
    return Identification(
        log=log.path,
        vehicle_name=vehicle.name,
        sample_rate_hz=sample_rate_hz,
        gyro_cutoff_hz=gyro_cutoff_hz,
        pwm_range_us=pwm_range,
        hover=hover,
        axes=tuple(axes),
        notes=(*log.derived, *_output_notes(log, outputs), *_notes(sample_rate_hz, log.parameters)),
        battery=battery,
        battery_reason=battery_reason,
    )


def _without_hover(axis: AxisIdentification, why: str) -> AxisIdentification:
    inertia = axis.inertia_kgm2
    if inertia is None:
        return axis
    refused = f"the hover throttle is refused ({why})"
    inertia = replace(inertia, refused=inertia.refused or refused)
    return replace(axis, inertia_kgm2=inertia, cross_check_inertia_kgm2=None)


def _output_notes(log: FlightLog, outputs: MotorOutputs) -> tuple[str, ...]:
    """How the motors reached the ESCs, where it is not the plain one PWM output."""
    if outputs.protocol is OutputProtocol.PWM and len(log.instances("actuator_outputs")) <= 1:
        return ()
    return (f"motor outputs: {outputs.reason}",)


def _notes(sample_rate_hz: float, params: Mapping[str, float]) -> tuple[str, ...]:
    notes = []
    if sample_rate_hz < ALIASING_RATE_HZ:
        notes.append(
            f"log rate {sample_rate_hz:.0f} Hz: the torque set-point's noise above "
            f"{sample_rate_hz / 2:.0f} Hz (rate D-term) folds into the band, so B reads low and "
            f"I high (≤ {ALIASING_BIAS:.0%}, in the uncertainty); log the rate topics at "
            "≥ 200 Hz (SDLOG_PROFILE high rate) for a clean estimate"
        )
    if params.get("THR_MDL_FAC", 0.0) != 0.0:
        # the mixer here allocates with a thrust linear in the motor command, as PX4 with
        # THR_MDL_FAC = 0; a non-linear thrust model changes the torque per unit command
        notes.append(
            f"THR_MDL_FAC = {params['THR_MDL_FAC']:g}: the torque per unit assumes PX4's linear "
            "thrust model (THR_MDL_FAC = 0), so I carries that error too"
        )
    return tuple(notes)


def _sample_rate_hz(log: FlightLog) -> float:
    time_s, _ = log.series("vehicle_angular_velocity", "xyz[0]", "body rates for the rate fit")
    if time_s.size < 100:
        raise IdentificationError(
            f"{log.path}: vehicle_angular_velocity has only {time_s.size} samples"
        )
    return float((time_s.size - 1) / (time_s[-1] - time_s[0]))
