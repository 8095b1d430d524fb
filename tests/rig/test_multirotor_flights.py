"""A hexa and an X8 flown by the reference autopilot, and a hexa losing a motor.

The vehicles are tests/rig/vehicles.py's (PX4's hexa X and coaxial X8 motor orders, built
from the bundled F450 and X500). Every number checked comes from the rig's ground truth
(rig.ulg) or the autopilot's own log.
"""

import numpy as np
import pytest
import pyulog

from quad_model.frames import quat_to_dcm
from tests.rig.flights import fly
from tests.rig.vehicles import hexa_x, x8

pytestmark = pytest.mark.closed_loop

#: Take off to this height, hover, land (the rig's hil_sim demo's shape, shorter).
HOVER_M = 3.0
COMMANDS = [{"at_s": 0.5, "action": "arm"},
            {"at_s": 0.6, "action": "takeoff", "altitude_m": HOVER_M},
            {"at_s": 14.0, "action": "land"}]  # fmt: skip
#: The climb to the take-off height has ended (PX4's take-off completes 0.8 m short of
#: it, NAV_MC_ALT_RAD, and the hold closes the rest) from here to the land command.
HOVER_S = (9.0, 14.0)
#: The issue's bound on the hover: true height within this of the commanded one.
HOVER_BOUND_M = 0.15


def _truth(log):
    data = log.get_dataset("vehicle_local_position_groundtruth").data
    return data["timestamp"] / 1e6, -data["z"]


@pytest.mark.cosim
@pytest.mark.parametrize("vehicle", [hexa_x, x8], ids=["hexa_x", "x8"])
def test_a_hexa_and_an_x8_take_off_hover_and_land_through_the_rtl_chips(tmp_path, vehicle):
    """Through the RTL chips at IMU 1 kHz, every motor through its own PWM line and capture
    channel, the height from the LIDAR-Lite below 5 m (EKF2_RNG_CTRL 1): after the climb
    the true height stays within ±0.15 m of 3 m; the landing is detected and the vehicle
    disarms on the ground."""
    scenario = {"name": vehicle.__name__, "vehicle": str(vehicle(tmp_path)), "duration_s": 25.0,
                "seed": 3, "sensor_layer": "rtl", "rates": {"imu_hz": 1000},
                "rangefinder": True, "commands": COMMANDS}  # fmt: skip
    result = fly(scenario, tmp_path / "run")
    log = pyulog.ULog(str(result.rig_log))
    t, height = _truth(log)
    hover = (t >= HOVER_S[0]) & (t < HOVER_S[1])
    assert np.abs(height[hover] - HOVER_M).max() < HOVER_BOUND_M
    assert height[-1] < 0.05
    outputs = log.get_dataset("actuator_outputs").data
    motors = 6 if vehicle is hexa_x else 8
    assert set(outputs["noutputs"]) == {motors}
    messages = [m.message for m in pyulog.ULog(str(result.autopilot_log)).logged_messages]
    assert "Landing detected" in messages
    assert any(text.startswith("Disarmed") for text in messages)


def test_a_hexa_losing_a_motor_in_hover_comes_down_upright(tmp_path):
    """PX4 ignores a motor failure unless told otherwise (CA_FAILURE_MODE 0, its default;
    its failure detector only warns): the dead motor stays in the allocation, and so here.
    Motor 1 (right) stops in a 3 m hover: the rate loop asks the dead rotor for full
    thrust against the roll, and with airmode off the allocation lowers the collective
    until that command fits, so the hexa cannot hold its height. It stays upright (tilt
    under 25°: the opposite rotor slows to balance the roll) while it sinks to the ground
    within 3 s."""
    scenario = {"name": "hexa_motor_loss", "vehicle": str(hexa_x(tmp_path)), "duration_s": 13.5,
                "seed": 3, "rangefinder": True, "commands": COMMANDS[:2],
                "faults": [{"kind": "motor_loss", "motor": 0, "start_s": 10.0}]}  # fmt: skip
    log = pyulog.ULog(str(fly(scenario, tmp_path / "run").rig_log))
    t, height = _truth(log)
    assert abs(height[np.searchsorted(t, 10.0)] - HOVER_M) < HOVER_BOUND_M
    down = t[(t > 10.0) & (height < 0.05)]
    assert down.size > 0
    assert down[0] < 13.0
    attitude = log.get_dataset("vehicle_attitude_groundtruth").data
    after = attitude["timestamp"] / 1e6 > 10.0
    q = np.column_stack([attitude[f"q[{k}]"][after] for k in range(4)])
    tilt_deg = np.degrees([np.arccos(quat_to_dcm(row)[2, 2]) for row in q])
    assert tilt_deg.max() < 25.0
