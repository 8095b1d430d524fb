"""The loop's per-frame shortcuts change nothing, and its time budget adds up.

Each shortcut skips work only between the events that can change its result: the PWM
capture between a pulse's (re-timed) fall and a timeout, the fault inputs between a
fault's start and end, the sensor faults on a healthy frame. Each is checked against the
unshortened reference: fpga_hdl's capture model over the whole pulse history, the
injector's own outputs, the very readings object.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from fpga_hdl.chips.pwm_capture.model import PwmCaptureModel
from fpga_hdl.top import PWM_RESULT_LATENCY_TICKS as HOST_LATENCY
from quad_model.sensors import ImuSample, SensorReadings
from rig.chips.layer import ChipFault
from rig.chips.pwm import PWM_TIMEOUT_S, PwmCapture, PwmOutput
from rig.errors import AutopilotProtocolError
from rig.lockstep.loop import RunOptions, run_scenario
from rig.mavlink.px4_api import ActuatorMode, Ports, mavlink
from rig.mavlink.sim_messages import decode_actuator_controls
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.faults import FaultInjector
from rig.scenarios.scenario import ChipMute, PwmDropout, SensorBias, scenario_from_dict

DOUBLE = Path(__file__).with_name("autopilot_double.py")


def test_capture_every_microsecond_around_the_falls_equals_the_whole_history():
    """Results are asked at every µs near each fall, so skipping the recompute until the
    host can read the fall (3 ticks) would show if it skipped one tick too many."""
    model = PwmCaptureModel(tick_hz=1e6, timeout_s=PWM_TIMEOUT_S, latency_ticks=HOST_LATENCY)
    out, capture, history = PwmOutput(1, 400), PwmCapture(1), []
    now_us = 0
    for period in range(40):
        out.command([(period % 5) / 4], armed=True)
        dropped = {0} if 20 <= period < 30 else set()  # a dropout long enough to time out
        start_us = period * out.period_us
        pulses = out.pulses(start_us + 1, dropped)
        history += [(p.start_us / 1e6, (p.start_us + p.width_us) / 1e6) for p in pulses]
        fall_us = start_us + 1000 + 250 * (period % 5)
        probes = [*range(fall_us - 2, fall_us + 5), start_us + 2499]
        for probe_us in sorted(p for p in probes if p >= now_us):
            now_us = probe_us
            widths, timed_out = capture.capture(pulses, now_us)
            pulses = []
            full = model.capture(history, at_s=now_us / 1e6)
            assert (widths[0], timed_out[0]) == (full.width_ticks, full.timeout), now_us


def test_pwm_output_latches_only_the_latest_command_at_each_period():
    out = PwmOutput(2, 400)
    out.command([0.1, 0.2], armed=True)
    out.command([0.3, 0.4], armed=True)  # replaces the first before any period starts
    assert [p.width_us for p in out.pulses(1)] == [1300, 1400]
    out.command([0.5, 0.6], armed=False)
    assert [p.width_us for p in out.pulses(2501)] == [1000, 1000]  # disarmed: PWM_MAIN_DIS
    assert [p.width_us for p in out.pulses(5001)] == [1000, 1000]  # held without a command


def test_healthy_frames_pass_the_readings_through_untouched():
    injector = FaultInjector(
        [SensorBias(start_s=1.0, end_s=2.0, sensor="accel", bias=(1.0, 0.0, 0.0))],
        np.random.default_rng(0),
        lambda time_us, text: None,
        motors=4,
    )
    readings = SensorReadings(ImuSample(0.5, np.zeros(3), np.zeros(3), 25.0), None, None, None)

    class Model:
        def set_motor_health(self, motor, thrust_fraction):
            raise AssertionError("no motor fault here")

    injector.update(500_000, Model())
    assert injector.samples(readings) is readings
    injector.update(1_000_000, Model())
    assert injector.samples(readings).imu.accel_mps2.tolist() == [1.0, 0.0, 0.0]


def test_fault_inputs_change_only_when_a_fault_starts_or_ends():
    injector = FaultInjector(
        [ChipMute(start_s=1.0, end_s=2.0, chip="ms5611"),
         PwmDropout(start_s=1.5, channel=1)],
        np.random.default_rng(0),
        lambda time_us, text: None,
        motors=4,
    )  # fmt: skip
    seen = []
    for time_us in range(0, 3_000_000, 250_000):
        injector.update(time_us, None)
        seen.append((time_us, dict(injector.chip_faults()), set(injector.pwm_dropped())))
    mute = {"ms5611": ChipFault(mute=True)}
    assert [(t, f, d) for t, f, d in seen if t in (750_000, 1_000_000, 1_750_000, 2_000_000)] == [
        (750_000, {}, set()), (1_000_000, mute, set()), (1_750_000, mute, {1}),
        (2_000_000, {}, {1}),
    ]  # fmt: skip
    with pytest.raises(TypeError):
        injector.chip_faults()["mpu6000"] = ChipFault(mute=True)  # read-only: shared by frames


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
def test_actuator_controls_any_non_finite_motor_is_rejected(bad):
    mav = mavlink.MAVLink(None, 1, 1)
    armed = int(ActuatorMode.SAFETY_ARMED)
    message = mav.hil_actuator_controls_encode(7000, [0.5, 0.5, bad, 0.5] + [0.0] * 12, armed, 1)
    with pytest.raises(AutopilotProtocolError, match=r"^HIL_ACTUATOR_CONTROLS at time_usec=7000 "):
        decode_actuator_controls(message, 4)


@pytest.mark.closed_loop
def test_frame_budget_parts_are_positive_and_add_up_to_the_wall_time(tmp_path, free_instance):
    instance = free_instance()
    argv = (sys.executable, str(DOUBLE), "--port", str(Ports(instance).simulator_tcp),
            "--behaviour", "px4", "--throttle", "0.6")  # fmt: skip
    document = {"name": "budget", "vehicle": "f450_high_precision", "duration_s": 0.3, "seed": 1}
    options = RunOptions(instance=instance, out_dir=tmp_path, autopilot_argv=argv,
                         timeouts=LinkTimeouts(connect_s=20, answer_s=5))  # fmt: skip
    result = run_scenario(scenario_from_dict(document), options)
    budget = result.budget
    parts = [budget.model_us, budget.sensor_physics_us, budget.chips_us, budget.mavlink_us,
             budget.socket_send_us, budget.autopilot_wait_us, budget.logging_us]  # fmt: skip
    assert all(part > 0 for part in parts), budget
    assert budget.other_us >= 0, budget  # the parts never overlap
    assert budget.total_us * result.frames == pytest.approx(result.wall_s * 1e6, rel=1e-9)
