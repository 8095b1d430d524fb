"""Which of a PX4 log's outputs drive the motors, and their PWM range."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from px4_logs.errors import LogError
from px4_logs.layouts import DEFAULT_PWM_RANGE_US, legacy_pwm_range

#: PX4's output functions Motor 1..4 (``PWM_MAIN_FUNCn``/``PWM_AUX_FUNCn``, PX4 1.13 on).
MOTOR_OUTPUT_FUNCTIONS = (101, 102, 103, 104)


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
                    raise LogError(
                        f"{source}: parameter {name} is not in the log "
                        f"({key} = {int(function)} is a motor output)"
                    )
            ranges.add((float(params[limits[0]]), float(params[limits[1]])))
    if not ranges:  # a PX4 before 1.13 has one range for all, or none (SITL, our autopilot)
        return legacy_pwm_range(params) or DEFAULT_PWM_RANGE_US
    if len(ranges) > 1:
        raise LogError(f"{source}: the motor outputs have different PWM ranges {sorted(ranges)}")
    return ranges.pop()
