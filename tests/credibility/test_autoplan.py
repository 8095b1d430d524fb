"""The automatic test plan: the segments found in the real X500 flight against the hand
plan's (x500_validation.toml), a synthetic log's known step, and what a log lacks."""

from pathlib import Path

import numpy as np
import pytest

from credibility import autoplan
from credibility.autoplan import draft, noise, plan_file, responses, setpoints
from credibility.cli import main
from credibility.plan import load_plan
from px4_logs import FlightLog

X500_LOG = Path(__file__).resolve().parents[2] / "data/flight_logs"
X500_LOG /= "px4_x500v2_v6xrt_flight_2026-03-20.ulg"


@pytest.fixture(scope="module")
def x500_draft() -> draft.Draft:
    return autoplan.draft_plan(FlightLog.read(X500_LOG))


def _segments(draft: draft.Draft) -> dict[str, tuple[float, float]]:
    return {test.name: test.keys["segment_s"] for test in draft.tests}


def test_x500_segments_match_the_hand_plan(x500_draft):
    """Each automatic segment against the hand plan's choice of the same event, within
    the stated tolerance (the hand plan's times are rounded to 0.5 s or one sample)."""
    found = _segments(x500_draft)
    hand = {
        # armed at idle 409.0-411.0 (spin-up at 411.2): within one motor sample (0.1 s)
        "gyro_x_sigma_idle": ((409.0, 411.0), 0.2),
        # the pitch doublet 474.3-477.3: within two attitude samples
        "pitch_doublet_474s": ((474.3, 477.3), 0.1),
        # the pilot's inputs 455-481.5 (the pilot took over at 455.43, AUTO_LAND at 481.57)
        "roll_rate_response": ((455.0, 481.5), 0.5),
        # the roll ramp-step from 455.5
        "roll_ramp_step_455s": ((455.5, 457.0), 0.35),
    }
    for name, ((start, end), tolerance) in hand.items():
        assert found[name][0] == pytest.approx(start, abs=tolerance), name
        assert found[name][1] == pytest.approx(end, abs=tolerance), name
    # the step responses start where the hand plan's do, within the 0.5 s lead
    for name, start in (("level_flight_v_right_460s", 460.0), ("landing_descent_vz", 482.0),
                        ("level_flight_vy_439s", 438.5)):  # fmt: skip
        assert found[name][0] == pytest.approx(start, abs=1.0), name
    # the hover lies inside the hand plan's 420-436 s hover give or take its first 2 s
    assert 418.0 <= found["gyro_x_sigma_hover"][0] < found["gyro_x_sigma_hover"][1] <= 436.0


def test_x500_rest_starts_after_the_props_stopped(x500_draft):
    """The hand plan's 503.2-504.0 s starts 0.13 s after the disarm (503.07 s), while the
    props still coast: its accelerometer σ (0.108 m/s² in x) is three times the floor the
    log shows from 503.6 s on. The automatic segment must be at that floor."""
    start, end = _segments(x500_draft)["accel_x_sigma_rest"]
    assert start >= 503.07 + noise.DISARM_COAST_S
    log = FlightLog.read(X500_LOG)
    time_s = log.time_s("sensor_combined")
    accel = log.topics["sensor_combined"]["accelerometer_m_s2[0]"]
    assert accel[(time_s >= start) & (time_s <= end)].std() < 0.04
    assert accel[(time_s >= 503.2) & (time_s <= 504.0)].std() > 0.1


def test_x500_comments_give_the_numbers(x500_draft):
    doublet = next(t for t in x500_draft.tests if t.name == "pitch_doublet_474s")
    assert "+0 → +13.4 ° in 0.10 s at 474.34 s" in doublet.found
    sideways = next(t for t in x500_draft.tests if t.name == "level_flight_v_right_460s")
    assert sideways.keys["signal"] == "vehicle_local_position.v_right"  # Position mode: heading


def test_x500_plan_loads_back_and_names_the_log(x500_draft, tmp_path):
    sim = tmp_path / "runs" / "sim.ulg"
    text = autoplan.plan_toml(x500_draft, X500_LOG, sim, tmp_path)
    (tmp_path / "plan.toml").write_text(text, encoding="utf-8")
    plan = load_plan(tmp_path / "plan.toml")
    assert plan.logs["real"] == X500_LOG.resolve()
    assert plan.logs["sim"] == sim.resolve()
    assert len(plan.tests) == len(x500_draft.tests)
    assert dict(plan.weights) == {"performance": 0.3, "time": 0.3, "frequency": 0.4}
    assert "2026-03-20" in plan.description
    assert "airframe 4019" in plan.name
    assert {item.name for item in plan.not_scorable} >= {"rotor_speeds"}
    # without --sim: a placeholder that `credibility report` names as missing
    placeholder = autoplan.plan_toml(x500_draft, X500_LOG, None, tmp_path)
    assert f'sim = "{plan_file.SIM_PLACEHOLDER}"' in placeholder


def _synthetic(with_velocity_setpoint: bool, flies: bool = True) -> FlightLog:
    """100 s at 20 Hz, airborne from 10 to 90 s (``flies``, else never) in Position mode,
    the pitch set-point stepping 0 → 15° at 50.0 s."""
    time_s = np.arange(0.0, 100.0, 0.05)
    stamps = (time_s * 1e6).astype(np.int64)
    pitch = np.radians(np.where(time_s >= 50.0, 15.0, 0.0))
    topics = {
        "vehicle_attitude_setpoint": {
            "timestamp": stamps,
            "q_d[0]": np.cos(pitch / 2), "q_d[1]": np.zeros_like(pitch),
            "q_d[2]": np.sin(pitch / 2), "q_d[3]": np.zeros_like(pitch),
        },
        "vehicle_land_detected": {"timestamp": stamps,
                                  "landed": ((time_s < 10) | (time_s > 90) | (not flies))
                                  .astype(float)},
        "vehicle_status": {"timestamp": stamps, "nav_state": np.full(time_s.size, 2),
                           "arming_state": np.full(time_s.size, 2)},
        "actuator_armed": {"timestamp": stamps, "armed": np.ones(time_s.size)},
    }  # fmt: skip
    if with_velocity_setpoint:
        zero = np.zeros(time_s.size)
        topics["vehicle_local_position_setpoint"] = {"timestamp": stamps, "vx": zero,
                                                     "vy": zero, "vz": zero}  # fmt: skip
    return FlightLog("synthetic.ulg", topics, {})


def test_a_known_step_gives_its_segment():
    tests, _ = setpoints.step_tests(_synthetic(with_velocity_setpoint=True))
    (step,) = [test for test in tests if test.kind == "time"]
    assert step.name == "pitch_step_50s"
    lead, settle = setpoints.ATTITUDE_STEP.lead_s, setpoints.ATTITUDE_STEP.settle_s
    # the step lies between the last sample at 0° (49.95 s) and the first at 15° (50.0 s)
    assert step.keys["segment_s"] == pytest.approx((49.95 - lead, 50.0 + settle), abs=0.011)
    assert "+0 → +15 ° in 0.05 s at 49.95 s" in step.found


def test_a_missing_topic_is_listed_with_the_reason():
    _, skipped = setpoints.step_tests(_synthetic(with_velocity_setpoint=False))
    (velocity,) = [item for item in skipped if item.name == "velocity_steps"]
    assert "vehicle_local_position_setpoint" in velocity.reason
    assert velocity.kind == "time"


def test_a_log_never_airborne_plans_no_flight_dynamics():
    tests, skipped = setpoints.step_tests(_synthetic(with_velocity_setpoint=True, flies=False))
    assert tests == []
    assert "never left the ground" in skipped[0].reason


def test_cli_bad_input_is_one_line(tmp_path, capsys):
    assert main(["plan", str(tmp_path / "missing.ulg")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "missing.ulg: flight log not found" in err


def test_a_velocity_ramp_between_holds_is_one_step():
    """0 m/s until 10 s, a ramp to 3 m/s over 2 s, then held: one step from the last
    sample of the first level (10.0 s) to the first of the second (12.0 s)."""
    time_s = np.arange(0.0, 20.0, 0.1)
    values = np.clip((time_s - 10.0) * 1.5, 0.0, 3.0)
    (step,) = setpoints.steps(time_s, values, setpoints.VELOCITY_STEP)
    # each level's band (0.4 m/s) reaches 0.4/1.5 = 0.27 s into the ramp
    assert step.start_s == pytest.approx(10.2, abs=0.051)
    assert step.end_s == pytest.approx(11.8, abs=0.051)
    assert step.change == pytest.approx(3.0 - 2 * 0.3, abs=0.16)


def test_a_slow_drift_is_not_a_step():
    time_s = np.arange(0.0, 20.0, 0.1)
    assert setpoints.steps(time_s, 0.2 * time_s, setpoints.VELOCITY_STEP) == []


def test_the_coherent_band_spans_a_dip_but_not_a_gap():
    freqs = np.geomspace(0.1, 10.0, 61)  # 30 points a decade
    coherence = np.where((freqs >= 0.5) & (freqs <= 5.0), 0.9, 0.2)
    coherence[np.argmin(np.abs(freqs - 1.0))] = 0.4  # one incoherent point inside
    band = responses.coherent_band(freqs, coherence, 0.6)
    assert band == pytest.approx((freqs[freqs >= 0.5][0], freqs[freqs <= 5.0][-1]))
    # less than an octave is no band
    narrow = np.where((freqs >= 1.0) & (freqs <= 1.8), 0.9, 0.2)
    assert responses.coherent_band(freqs, narrow, 0.6) is None


def test_cli_writes_a_plan_that_loads(tmp_path, capsys):
    out = tmp_path / "plans" / "x500.toml"
    assert main(["plan", str(X500_LOG), "--out", str(out)]) == 0
    assert f"→ {out}" in capsys.readouterr().out
    plan = load_plan(out)
    assert plan.logs["sim"] == (out.parent / plan_file.SIM_PLACEHOLDER).resolve()
    assert any(test.name == "pitch_doublet_474s" for test in plan.tests)


def test_without_an_arming_state_rest_and_idle_are_not_planned():
    """The X8's high-rate log has neither actuator_armed nor vehicle_status: its motors at
    0 may be stopped or idling, so neither state is planned, and the reason says so."""
    time_s = np.arange(0.0, 10.0, 0.005)
    stamps = (time_s * 1e6).astype(np.int64)
    imu = {f"gyro_rad[{i}]": np.zeros(time_s.size) for i in range(3)}
    log = FlightLog("bench.ulg", {"sensor_combined": {"timestamp": stamps, **imu}}, {})
    tests, skipped = noise.noise_tests(log)
    assert tests == []
    reasons = {item.name: item.reason for item in skipped}
    for state in ("rest", "idle"):
        assert "no arming state in the log" in reasons[f"imu_sigma_{state}"]


def test_a_position_step_is_scored_on_the_velocity_along_its_axis():
    """A goto handed to the position loop unsmoothed: x set-point 0 → 5 m at 20.0 s, in the
    air from 5 to 55 s; the segment from POSITION_STEP's lead before the last sample at 0 m
    to its settling time after the first at 5 m."""
    time_s = np.arange(0.0, 60.0, 0.05)
    stamps = (time_s * 1e6).astype(np.int64)
    zero = np.zeros(time_s.size)
    log = FlightLog("goto.ulg", {
        "vehicle_local_position_setpoint": {"timestamp": stamps, "x": np.where(time_s >= 20.0,
                                            5.0, 0.0), "y": zero, "z": zero - 4.0},
        "vehicle_land_detected": {"timestamp": stamps,
                                  "landed": ((time_s < 5) | (time_s > 55)).astype(float)},
    }, {})  # fmt: skip
    (test,) = setpoints.position_steps(log, log.airborne_span())
    assert test.name == "position_step_x_20s"
    assert test.keys["signal"] == "vehicle_local_position.vx"
    shape = setpoints.POSITION_STEP
    assert test.keys["segment_s"] == pytest.approx((19.95 - shape.lead_s, 20.0 + shape.settle_s),
                                                   abs=0.011)  # fmt: skip
    assert "+0 → +5 m in 0.05 s at 19.95 s" in test.found
