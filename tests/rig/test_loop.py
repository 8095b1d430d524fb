"""The closed loop with the TLM chips against the test-double autopilot process.

The double speaks PX4's side of the link for real (see autopilot_double.py), so these
runs exercise everything but the flight controller: model, sensor physics, chips and
drivers, HIL encoding, lockstep, PWM capture, faults and rig.ulg. Flights with the
reference autopilot are in test_closed_loop.py.
"""

import gc
import json
import math
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import pyulog

from rig.errors import AutopilotStalled, ScenarioError
from rig.lockstep.autopilots import AUTOPILOT_STOP_GRACE_S
from rig.lockstep.loop import RunOptions, next_slot_us, run_scenario
from rig.mavlink.px4_api import HilSensorFields, Ports, mavlink
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import scenario_from_dict

DOUBLE = Path(__file__).with_name("autopilot_double.py")
F450_HOVER_THROTTLE = 0.55  # quad_model's hover_throttle() for the F450 at 488 m, rounded


def fly(
    tmp_path, free_instance, *double_args, duration_s=1.0, faults=(), seed=1, name="run",
    progress=None, **scenario,
):  # fmt: skip
    instance = free_instance()
    record = tmp_path / f"{name}-received.jsonl"
    argv = (
        sys.executable, str(DOUBLE), "--port", str(Ports(instance).simulator_tcp),
        "--record", str(record), *double_args,
    )  # fmt: skip
    document = {"name": "t", "vehicle": "f450_high_precision", "duration_s": duration_s,
                "seed": seed, "faults": list(faults), **scenario}  # fmt: skip
    options = RunOptions(
        instance=instance,
        out_dir=tmp_path / name,
        timeouts=LinkTimeouts(connect_s=20, answer_s=5),
        autopilot_argv=argv,
    )
    result = run_scenario(scenario_from_dict(document), options, progress)
    received = [json.loads(line) for line in record.read_text().splitlines()]
    return result, pyulog.ULog(str(result.rig_log)), received


def data(log, topic):
    return log.get_dataset(topic).data


def test_vehicle_at_rest_sensors_reach_the_autopilot_at_their_rates(tmp_path, free_instance):
    result, log, received = fly(tmp_path, free_instance, "--behaviour", "px4", duration_s=1.0)
    assert result.frames == 1000
    sensors = [m for m in received if m["mavpackettype"] == "HIL_SENSOR"]
    assert [m["time_usec"] for m in sensors] == list(range(1000, 1_000_001, 1000))
    masks = np.array([m["fields_updated"] for m in sensors])
    imu = HilSensorFields.ACCEL | HilSensorFields.GYRO
    assert np.all(masks & imu == imu)  # every frame: accel and gyro (lockstep needs gyro)
    assert np.sum(masks & HilSensorFields.MAG == HilSensorFields.MAG) == 50  # PX4's IST8310
    # MS5611 at 50 Hz: D2 then D1, 10 ms each (PX4's cycle), the first pressure at 21 ms.
    baro_times = [m["time_usec"] for m in sensors if m["fields_updated"] & HilSensorFields.BARO]
    assert baro_times == list(range(21_000, 1_000_001, 20_000))
    gps = [m for m in received if m["mavpackettype"] == "HIL_GPS"]
    # PX4's CFG-RATE (200 ms) makes the receiver report every other of the vehicle's 10 Hz
    # epochs: those at 0, 200, ... 800 ms, out 110 ms later (the receiver's latency) and
    # 8.7 ms on the line; the one at 1000 ms is not out within the second.
    assert len(gps) == 5
    # Ground truth at the 5000 µs the double asked for; the stream starts when the rig has
    # read the request, which depends on wall-clock timing, so check its spacing.
    state_times = [m["time_usec"] for m in received if m["mavpackettype"] == "HIL_STATE_QUATERNION"]
    assert len(state_times) >= 150
    assert set(np.diff(state_times)) == {5000}

    # At rest, level, on the ground: what PX4 would read, through the chips' quantization.
    accel = np.array([[m["xacc"], m["yacc"], m["zacc"]] for m in sensors])
    # The F450 file's residual IMU errors after calibration: bias σ 0.05 m/s², scale σ 0.5 %,
    # misalignment σ 0.01 rad (≈ 0.1 m/s² on x/y at 1 g): bounds at about 3σ.
    mean = accel.mean(axis=0)
    assert np.linalg.norm(mean) == pytest.approx(9.80665, abs=0.2)
    assert np.abs(mean[:2]).max() < 0.35
    assert mean[2] < -9.5
    baro = [m for m in sensors if m["fields_updated"] & HilSensorFields.BARO]
    # ISA troposphere p = p0·(1 − L·h/T0)^(g/(R·L)) at 488 m AMSL: 955.98 hPa (ICAO tables
    # give 954.61 hPa at 500 m); the bound covers the F450's baro offset and noise.
    isa_hpa = 1013.25 * (1 - 0.0065 * 488 / 288.15) ** 5.25588
    assert isa_hpa == pytest.approx(955.98, abs=0.01)
    assert np.mean([m["abs_pressure"] for m in baro]) == pytest.approx(isa_hpa, abs=0.5)
    mag = [m for m in sensors if m["fields_updated"] & HilSensorFields.MAG]
    field = np.mean([[m["xmag"], m["ymag"], m["zmag"]] for m in mag], axis=0)
    assert field == pytest.approx([0.215, 0.013, 0.433], abs=0.02)  # WMM at PX4's home
    assert gps[0]["lat"] == pytest.approx(473977420, abs=50)
    assert gps[0]["fix_type"] >= 3
    assert gps[0]["satellites_visible"] >= 6

    # rig.ulg holds the same data under PX4's names, plus the truth.
    logged = data(log, "sensor_combined")
    assert len(logged["timestamp"]) == 1000
    assert logged["accelerometer_m_s2[2]"] == pytest.approx(accel[:, 2], abs=1e-5)
    truth = data(log, "vehicle_local_position_groundtruth")
    assert np.max(np.abs(truth["z"])) < 1e-3  # resting on the ground
    outputs = data(log, "actuator_outputs")
    assert outputs["output[0]"][0] == 0.0  # the first pulse is still high at 1 ms
    assert np.all(outputs["output[0]"][1:] == 1000.0)  # disarmed: PWM_MAIN_DIS
    messages = [m.message for m in log.logged_messages]
    assert messages[-1] == "run completed: 1000 frames"
    assert log.initial_parameters["RIG_SEED"] == 1
    assert log.msg_info_dict["scenario"] == "t"


def test_rangefinder_reaches_the_autopilot_as_distance_sensor_one_cycle_late(
    tmp_path, free_instance
):
    """The LIDAR-Lite at PX4's 50 ms driver cycle: each DISTANCE_SENSOR carries the
    acquisition started one cycle earlier, so it reads the truth of 50 ms before: the
    sensor's 0.10 m above the landing point plus the climb, within 4σ of the datasheet's
    2.5 cm noise and the 1 cm resolution."""
    _, log, received = fly(
        tmp_path, free_instance, "--behaviour", "px4", "--throttle", "0.7", duration_s=1.5,
        rangefinder=True,
    )  # fmt: skip
    ranges = [m for m in received if m["mavpackettype"] == "DISTANCE_SENSOR"]
    times_us = [m["time_boot_ms"] * 1000 for m in ranges]
    assert times_us == list(range(50_000, 1_500_001, 50_000))  # the first cycle only measures
    assert {(m["min_distance"], m["max_distance"], m["orientation"], m["signal_quality"])
            for m in ranges} == {(5, 2500, mavlink.MAV_SENSOR_ROTATION_PITCH_270, 100)}  # fmt: skip
    truth = data(log, "vehicle_local_position_groundtruth")
    measured_at_s = np.array(times_us) / 1e6 - 0.05
    height = -np.interp(measured_at_s, truth["timestamp"] / 1e6, truth["z"])
    assert height[-1] > 0.5  # it climbed: the ranges are not all the resting 0.10 m
    distances = np.array([m["current_distance"] for m in ranges]) / 100
    assert np.abs(distances - (height + 0.10)).max() < 4 * 0.025 + 0.005
    logged = data(log, "distance_sensor")
    assert logged["current_distance"] == pytest.approx(distances, abs=1e-6)


def test_a_rangefinder_on_a_vehicle_without_one_is_one_line_naming_the_key(tmp_path):
    document = {"name": "t", "vehicle": "f450_low_precision", "duration_s": 1.0, "seed": 1,
                "rangefinder": True}  # fmt: skip
    with pytest.raises(ScenarioError) as error:
        run_scenario(scenario_from_dict(document), RunOptions(out_dir=tmp_path / "run"))
    assert str(error.value) == (
        "<dict>: key 'rangefinder': vehicle 'F450 low precision' has no [rangefinder] table"
    )


def test_optical_flow_reaches_the_autopilot_as_px4s_driver_reports_it_without_gps(
    tmp_path, free_instance
):
    """The PMW3901 read as PX4's driver does: a HIL_OPTICAL_FLOW every 20 ms (a report every
    second 10 ms cycle) with the window's time, no gyro and no distance; its flow is the
    truth's image motion over the window (climbing level and still, ~0 but for the noise
    and the counts); with ``gps = false`` no HIL_GPS at all and no sensor_gps in rig.ulg."""
    _, log, received = fly(
        tmp_path, free_instance, "--behaviour", "px4", "--throttle", "0.7", duration_s=1.5,
        optical_flow=True, gps=False,
    )  # fmt: skip
    assert not [m for m in received if m["mavpackettype"] == "HIL_GPS"]
    assert "sensor_gps" not in {d.name for d in log.data_list}
    flows = [m for m in received if m["mavpackettype"] == "HIL_OPTICAL_FLOW"]
    times_us = [m["time_usec"] for m in flows]
    assert times_us == list(range(20_000, 1_500_001, 20_000))
    assert {m["integration_time_us"] for m in flows} == {20_000}
    assert all(math.isnan(m["integrated_xgyro"]) and m["distance"] == -1.0 for m in flows)
    # F450 camera on a textured (0.8) floor in daylight: SQUAL 230 × 0.8, the driver's mean.
    assert {m["quality"] for m in flows} == {184}
    motion = np.array([(m["integrated_x"], m["integrated_y"]) for m in flows])
    assert np.abs(motion).max() < 4 / 385  # a few counts of noise and rounding, no motion
    logged = data(log, "sensor_optical_flow")
    assert logged["pixel_flow[0]"] == pytest.approx(motion[:, 0], abs=1e-7)
    assert list(logged["integration_timespan_us"]) == [20_000] * len(flows)


def test_an_x8_gets_a_pwm_channel_per_motor_and_a_dropout_stops_motor_8(tmp_path, free_instance):
    """Eight motors from HIL_ACTUATOR_CONTROLS through eight PWM lines and capture
    channels to the model's eight rotors; motor 8's line goes quiet at 0.5 s, its capture
    times out 0.1 s after its last pulse and its rotor spins down, the others run on."""
    from tests.rig.vehicles import x8

    dropout = {"kind": "pwm_dropout", "channel": 7, "start_s": 0.5}
    _, log, _ = fly(tmp_path, free_instance, "--behaviour", "px4", "--throttle", "0.7",
                    "--motors", "8", duration_s=1.0, vehicle=str(x8(tmp_path)),
                    faults=[dropout])  # fmt: skip
    outputs = data(log, "actuator_outputs")
    t = outputs["timestamp"] / 1e6
    assert set(outputs["noutputs"]) == {8}
    running = (t > 0.1) & (t < 0.5)
    for motor in range(8):
        assert set(outputs[f"output[{motor}]"][running]) == {1700.0}  # 1000 + 0.7 × 1000 µs
    rotors = data(log, "rig_propulsion_groundtruth")
    thrust = np.array([rotors[f"thrust_n[{k}]"][-1] for k in range(8)])
    assert thrust[7] < 0.1 * thrust[:7].min()


def test_a_fault_on_a_motor_the_vehicle_lacks_is_one_line_naming_the_key(tmp_path):
    document = {"name": "t", "vehicle": "f450_high_precision", "duration_s": 1.0, "seed": 1,
                "faults": [{"kind": "motor_loss", "motor": 5, "start_s": 0.5}]}  # fmt: skip
    with pytest.raises(ScenarioError) as error:
        run_scenario(scenario_from_dict(document), RunOptions(out_dir=tmp_path / "run"))
    assert str(error.value) == (
        "<dict>: key 'faults[0].motor' = 5: vehicle 'F450 high precision' has motors 0..3"
    )


def test_pwm_carries_the_commanded_throttle_and_the_vehicle_climbs(tmp_path, free_instance):
    _, log, _ = fly(
        tmp_path, free_instance, "--behaviour", "px4", "--throttle", "0.7", duration_s=1.5
    )
    outputs = data(log, "actuator_outputs")
    assert outputs["output[0]"][-1] == pytest.approx(1700.0)  # 1000 + 0.7 × 1000 µs
    assert np.diff(outputs["timestamp"]).min() >= 2000  # 400 Hz pulses: a new width ≤ every 2.5 ms
    motors = data(log, "actuator_motors")
    assert motors["control[0]"][-1] == pytest.approx(0.7)
    truth = data(log, "vehicle_local_position_groundtruth")
    assert truth["z"][-1] < -1.0  # 0.7 > hover throttle (≈ 0.55): it climbs (NED z < 0)
    assert truth["vz"][-1] < -1.0


def test_same_seed_gives_identical_rig_log(tmp_path, free_instance):
    spin = ("--behaviour", "px4", "--throttle", "0.6", "--arm-after", "100")
    _, first, _ = fly(tmp_path, free_instance, *spin, name="a", seed=7)
    _, second, _ = fly(tmp_path, free_instance, *spin, name="b", seed=7)
    _, other, _ = fly(tmp_path, free_instance, *spin, name="c", seed=8)
    for topic in ("sensor_combined", "vehicle_local_position_groundtruth", "sensor_baro"):
        a, b = data(first, topic), data(second, topic)
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=f"{topic}.{key}")
    assert not np.array_equal(
        data(first, "sensor_combined")["gyro_rad[0]"], data(other, "sensor_combined")["gyro_rad[0]"]
    )


@pytest.mark.parametrize(("frame_us", "interval_us", "per_second"),
                         [(1000, 5000, 200), (4000, 5000, 200), (2500, 5000, 200),
                          (4000, 3000, 250), (1000, 300, 1000)])  # fmt: skip
def test_a_stream_keeps_its_rate_on_average_at_any_frame_rate(frame_us, interval_us, per_second):
    """A message goes with the first frame at or after its slot, the slots a fixed grid from
    the first message: the asked rate on average, capped at one a frame."""
    sent, due = [], None
    for time_us in range(37_000, 37_000 + 2_000_000, frame_us):  # the first at any frame
        if due is None or time_us >= due:
            slot = time_us if due is None else due
            due = next_slot_us(due, time_us, interval_us)
            sent.append(time_us)
            assert slot <= time_us < slot + max(frame_us, interval_us)  # with its slot's frame
    assert len(sent) == 2 * per_second


def test_ground_truth_at_250_hz_frames_comes_at_the_200_hz_px4_asks_for(tmp_path, free_instance):
    """5000 µs asked at 4000 µs frames: four frames in five carry HIL_STATE_QUATERNION."""
    _, _, received = fly(tmp_path, free_instance, duration_s=2.0, rates={"imu_hz": 250})
    state_times = [m["time_usec"] for m in received if m["mavpackettype"] == "HIL_STATE_QUATERNION"]
    assert set(np.diff(state_times)) == {4000, 8000}
    span_s = (state_times[-1] - state_times[0]) / 1e6
    assert len(state_times) - 1 == pytest.approx(200 * span_s, abs=1)


@pytest.mark.parametrize("interval_us", [-1, 0])
def test_no_ground_truth_when_the_autopilot_stops_it_or_names_no_rate(
    tmp_path, free_instance, interval_us
):
    _, _, received = fly(tmp_path, free_instance, "--state-interval-us", str(interval_us))
    assert {m["mavpackettype"] for m in received} >= {"HIL_SENSOR"}
    assert not [m for m in received if m["mavpackettype"] == "HIL_STATE_QUATERNION"]


def test_reading_the_sensors_while_the_autopilot_computes_changes_nothing(
    tmp_path, free_instance, monkeypatch
):
    """The loop senses frame k+1 before the answer to frame k, with frame k+1's samples:
    the same log as a layer that does each whole frame at once, after the answer (the
    strict order)."""
    import rig.lockstep.loop as loop
    from rig.chips.layer import TlmSensorLayer, run_now

    class StrictOrder(TlmSensorLayer):
        def sense(self, frame):
            assert frame.si.imu.time_us == frame.now_us, "the frame's own samples"
            self._frame = frame

        def finish(self, pulses):
            return run_now(self.engine.frame(self._frame._replace(pulses=pulses)))

    spin = ("--behaviour", "px4", "--throttle", "0.6", "--arm-after", "100")
    _, overlapped, _ = fly(tmp_path, free_instance, *spin, name="overlapped", seed=7)
    monkeypatch.setattr(loop, "TlmSensorLayer", StrictOrder)
    _, strict, _ = fly(tmp_path, free_instance, *spin, name="strict", seed=7)
    for topic in ("sensor_combined", "sensor_mag", "sensor_baro", "actuator_outputs",
                  "vehicle_local_position_groundtruth"):  # fmt: skip
        a, b = data(overlapped, topic), data(strict, topic)
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=f"{topic}.{key}")


def test_a_run_collects_its_garbage_before_its_clock_and_none_in_its_frames(
    tmp_path, free_instance
):
    """A full collection among the frames stalls them all for 70-180 ms; the run does it
    before its clock starts, and the next is minutes of frames away.

    Here the start-up leaves as many new objects as the process had, kept through the run,
    with no collection during it; from the first progress report on, the collector runs
    every 50 net allocations and tries a full pass every ninth time, which it makes once
    new long-lived objects are a quarter of all: in the frames, unless the run collected
    them first."""
    full: list[list[float]] = []  # each full collection's start and end (monotonic)

    def on_collection(phase, info):
        if info["generation"] == 2:
            if phase == "start":
                full.append([time.monotonic(), math.inf])
            else:
                full[-1][1] = time.monotonic()

    clock_starts = []  # the run's clock start, as each progress report implies it

    def progress(report):
        clock_starts.append(time.monotonic() - report.time_s / report.real_time_factor)
        gc.set_threshold(50, 2, 2)

    thresholds = gc.get_threshold()
    gc.set_threshold(10**9, 10, 10)
    start_up = [[] for _ in range(len(gc.get_objects()))]  # noqa: F841 - kept through the run
    gc.callbacks.append(on_collection)
    try:
        result, _, _ = fly(tmp_path, free_instance, progress=progress)
    finally:
        gc.callbacks.remove(on_collection)
        gc.set_threshold(*thresholds)
    clock_start = clock_starts[0]
    assert any(end <= clock_start for _, end in full)
    assert not [start for start, _ in full
                if clock_start < start < clock_start + result.wall_s]  # fmt: skip


def test_killed_autopilot_ends_the_run_with_a_clear_message_and_a_readable_log(
    tmp_path, free_instance
):
    with pytest.raises(AutopilotStalled) as error:
        fly(tmp_path, free_instance, "--behaviour", "close", "--after", "300", duration_s=2.0)
    assert "the autopilot closed the simulator link" in str(error.value)
    assert "PX4 never reconnects" in str(error.value)
    log = pyulog.ULog(str(tmp_path / "run" / "rig.ulg"))
    assert len(data(log, "sensor_combined")["timestamp"]) >= 299
    assert log.logged_messages[-1].message.startswith("run ended: the autopilot closed")


def test_an_autopilot_that_ignores_sigint_is_killed_and_the_kill_is_logged(tmp_path, free_instance):
    """Its own log may then miss its last buffer: the rig's log says so."""
    _, log, _ = fly(tmp_path, free_instance, "--ignore-sigint", duration_s=0.2)
    warning = log.logged_messages[-1]
    assert warning.log_level_str() == "WARNING"
    assert warning.message == (f"the autopilot did not stop within {AUTOPILOT_STOP_GRACE_S:g} "
                               "s of SIGINT and was killed: its log may miss its last half "
                               "second")  # fmt: skip


def test_pwm_dropout_times_out_the_capture_and_the_motors_stop(tmp_path, free_instance):
    dropout = {"kind": "pwm_dropout", "start_s": 1.0}
    spin = ("--behaviour", "px4", "--throttle", "0.7")
    _, log, _ = fly(tmp_path, free_instance, *spin, duration_s=1.6, faults=[dropout])
    truth = data(log, "rig_propulsion_groundtruth")
    t = truth["timestamp"] / 1e6
    speed_before = truth["rotor_speed_radps[0]"][np.searchsorted(t, 0.99)]
    speed_after = truth["rotor_speed_radps[0]"][-1]
    assert speed_before > 500  # spinning at 0.7 throttle
    assert speed_after < 0.2 * speed_before  # capture timed out (10 ms) → ESC stops
    events = [m.message for m in log.logged_messages]
    assert "fault pwm_dropout started" in events


def test_bus_faults_reach_the_autopilot_through_the_chips(tmp_path, free_instance):
    faults = [
        {"kind": "bus_bit_flip", "chip": "mpu6000", "mask": 0x80, "start_s": 0.5, "end_s": 0.6},
        {"kind": "chip_mute", "chip": "ist8310", "start_s": 0.5},
    ]
    _, log, received = fly(
        tmp_path, free_instance, "--behaviour", "px4", duration_s=0.8, faults=faults
    )
    sensors = [m for m in received if m["mavpackettype"] == "HIL_SENSOR"]
    zacc = {m["time_usec"]: m["zacc"] for m in sensors}
    assert zacc[400_000] == pytest.approx(-9.81, abs=0.1)
    # Flipping bit 7 of every byte turns −9.81 m/s² (0xF8xx at ±16 g) into a positive value.
    assert zacc[550_000] > 0
    assert zacc[700_000] == pytest.approx(-9.81, abs=0.1)  # the flip ended
    mag_times = [m["time_usec"] for m in sensors if m["fields_updated"] & HilSensorFields.MAG]
    assert max(mag_times) < 500_000  # a muted IST8310 NACKs: no mag reaches the autopilot
    events = [m.message for m in log.logged_messages]
    assert "fault chip_mute (chip=ist8310) started" in events
    assert any(
        e.startswith("bus error: ist8310: I2C target 0x0E did not acknowledge") for e in events
    )


def test_sensor_faults_and_gps_loss(tmp_path, free_instance):
    faults = [
        {"kind": "sensor_stuck", "sensor": "gyro", "start_s": 0.3, "end_s": 0.5},
        {"kind": "sensor_bias", "sensor": "baro", "bias": 500.0, "start_s": 0.3},
        {"kind": "gps_loss", "start_s": 0.45},
    ]
    _, log, received = fly(
        tmp_path, free_instance, "--behaviour", "px4", duration_s=0.7, faults=faults
    )
    sensors = [m for m in received if m["mavpackettype"] == "HIL_SENSOR"]
    gyro = {m["time_usec"]: (m["xgyro"], m["ygyro"], m["zgyro"]) for m in sensors}
    stuck = {gyro[t] for t in range(300_000, 500_000, 1000)}
    assert len(stuck) == 1  # frozen: the same sample for 200 frames
    assert len({gyro[t] for t in range(100_000, 300_000, 1000)}) > 50  # noisy before
    baro = [(m["time_usec"], m["abs_pressure"]) for m in sensors if m["fields_updated"] & 0x200]
    before = np.mean([p for t, p in baro if t < 290_000])
    after = np.mean([p for t, p in baro if t > 340_000])  # after the MS5611 cycle latency
    assert after - before == pytest.approx(5.0, abs=0.3)  # +500 Pa = +5 hPa
    gps_times = [m["time_usec"] for m in received if m["mavpackettype"] == "HIL_GPS"]
    assert max(gps_times) < 450_000
    assert math.isclose(len(data(log, "sensor_gps")["timestamp"]), len(gps_times))


def test_gps_receiver_faults_reach_the_autopilot_through_the_ublox_uart(tmp_path, free_instance):
    """Every fix reaches HIL_GPS through the u-blox twin and PX4's decoder: 8.7 ms after the
    receiver output it (a 100-byte NAV-PVT at 115200 baud), so at the second-next 1 ms
    frame. Loss of fix arrives as fix type 0, jamming as a 2D fix from 3 satellites, and
    the epochs sent with a bad checksum never arrive."""
    faults = [
        {"kind": "gps_receiver", "fault": "loss_of_fix", "start_s": 0.3, "end_s": 0.5},
        {"kind": "gps_receiver", "fault": "jammed", "start_s": 0.5, "end_s": 0.7},
        {"kind": "gps_receiver", "fault": "bad_checksum", "start_s": 0.7, "end_s": 0.9},
    ]
    _, log, received = fly(
        tmp_path, free_instance, "--behaviour", "px4", duration_s=1.2, faults=faults
    )
    gps = [m for m in received if m["mavpackettype"] == "HIL_GPS"]
    logged = data(log, "sensor_gps")
    assert [m["time_usec"] for m in gps] == logged["timestamp"].tolist()
    assert set(logged["timestamp"] - logged["timestamp_sample"]) == {9000}
    by_sent = dict(zip(logged["timestamp_sample"].tolist(), gps, strict=True))
    # 5 Hz (PX4's CFG-RATE): epochs every 200 ms out 110 ms later, at 110, 310, ... 1110
    # ms, less the one at 710 ms sent with a bad checksum.
    assert sorted(by_sent) == [110_000, 310_000, 510_000, 910_000, 1_110_000]
    for sent_us, message in by_sent.items():
        state = (message["fix_type"], message["satellites_visible"])
        if sent_us < 300_000 or sent_us >= 900_000:
            assert state[0] == 3
            assert state[1] >= 6
        elif sent_us < 500_000:
            assert state == (0, 0)
        elif sent_us < 700_000:
            assert state == (2, 3)
            assert message["eph"] == 20 * gps[0]["eph"]
        else:
            raise AssertionError(f"the fix sent at {sent_us} µs had a bad checksum")
    assert any(300_000 <= t < 500_000 for t in by_sent)
    assert any(500_000 <= t < 700_000 for t in by_sent)
    assert any(t >= 900_000 for t in by_sent)
    events = [m.message for m in log.logged_messages]
    assert "fault gps_receiver (fault=bad_checksum) started" in events


def test_px4_mode_waits_for_the_connection_and_steps_until_the_ack(
    tmp_path, free_instance, monkeypatch
):
    """``--autopilot px4`` with no PX4 build given: the rig prepares PX4's work dir and
    parameters, says how to start PX4, and waits for its connection; a
    command is sent and the rig keeps stepping (PX4 acts only as its clock advances)
    until the COMMAND_ACK arrives. PX4 itself cannot be installed here: the peer is the
    PX4-side test double (boot delay, one answer per frame) plus a UDP thread that sends
    HEARTBEATs and ACKs commands on the API link the way PX4's mavlink module does, 50 ms
    late."""
    monkeypatch.delenv("PX4_DIR", raising=False)
    instance = free_instance()
    ports = Ports(instance)
    api = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    api.bind(("127.0.0.1", ports.onboard_local_udp))
    api.settimeout(0.1)
    acked = []

    def px4_api():
        mav = mavlink.MAVLink(None, ports.system_id, 1)
        beat = mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0)
        for _ in range(100):  # 10 s: PX4 beats at 1 Hz; faster here, the rig may bind late
            api.sendto(beat.pack(mav), ("127.0.0.1", ports.onboard_remote_udp))
            try:
                data, sender = api.recvfrom(65536)
                break
            except TimeoutError:
                continue
        else:
            return
        (command,) = mavlink.MAVLink(None, 0, 0).parse_buffer(data)
        time.sleep(0.05)
        api.sendto(mav.command_ack_encode(command.command, 0).pack(mav), sender)
        acked.append(command.command)

    thread = threading.Thread(target=px4_api, daemon=True)
    thread.start()
    double = subprocess.Popen([sys.executable, str(DOUBLE), "--port", str(ports.simulator_tcp),
                               "--behaviour", "px4", "--after", "60"])  # fmt: skip
    try:
        document = {"name": "px4", "vehicle": "f450_high_precision", "duration_s": 1.0,
                    "seed": 1, "commands": [{"at_s": 0.2, "action": "arm"}]}  # fmt: skip
        options = RunOptions(autopilot="px4", instance=instance, out_dir=tmp_path / "px4",
                             timeouts=LinkTimeouts(connect_s=20, answer_s=5))  # fmt: skip
        result = run_scenario(scenario_from_dict(document), options)
    finally:
        double.kill()
        double.wait()
        thread.join()
        api.close()
    assert acked == [mavlink.MAV_CMD_COMPONENT_ARM_DISARM]
    assert result.link.freewheel_frames >= 60  # PX4 "booted" for 60 frames
    events = [(m.timestamp, m.message) for m in pyulog.ULog(str(result.rig_log)).logged_messages]
    texts = [text for _, text in events]
    assert texts[0].startswith("waiting for PX4 SITL on TCP 127.0.0.1:")
    assert (
        f"PX4_SYS_AUTOSTART=10016 $PX4_DIR/build/px4_sitl_default/bin/px4 -d -i {instance}"
        in texts[0]
    )
    assert "param set IMU_INTEG_RATE 1000" in (tmp_path / "px4/px4/bin/px4-rc.params").read_text()
    # "sent", or "held until the autopilot's first HEARTBEAT" on a machine slow to start it
    (sent_at,) = [t for t, text in events if text.startswith("arm at t=0.2 s: ")]
    (acked_at,) = [t for t, text in events if text == "arm: accepted"]
    assert acked_at > sent_at  # the rig kept stepping while PX4 had not answered
