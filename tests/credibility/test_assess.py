"""Plans end to end on synthetic logs whose indices are known in closed form."""

import json
import math

import control
import numpy as np
import pandas as pd
import pytest

from credibility.assess import assess
from credibility.cli import main
from credibility.errors import CredibilityError
from credibility.plan import load_plan
from credibility.signals import step_metrics

RATE_HZ = 100.0
LAG_S = 0.3  # the sim's clock runs 0.3 s behind the real one


def _plant_output(x: np.ndarray, gain: float) -> np.ndarray:
    s = control.tf("s")
    plant = control.sample_system(gain / (s / (2 * np.pi * 4.0) + 1), 1 / RATE_HZ, "tustin")
    return control.forced_response(plant, U=x).outputs


@pytest.fixture
def logs(tmp_path):
    """real.parquet and sim.csv / sim_low.csv with known differences."""
    rng = np.random.default_rng(42)
    t = np.arange(0.0, 60.0, 1 / RATE_HZ)
    sweep_in = rng.standard_normal(t.size)

    def table(curve_offset, lag_s, gain, level):
        wave = np.sin(2 * np.pi * 0.5 * (t - lag_s)) + curve_offset
        x = rng.standard_normal(t.size) if gain else sweep_in
        return pd.DataFrame(
            {
                "time_s": t,
                "vehicle.curve": wave,
                "vehicle.level": np.full(t.size, level),
                "vehicle.u": x,
                "vehicle.y": _plant_output(x, gain or 1.0),
            }
        )

    table(0.0, 0.0, 0.0, 10.0).to_parquet(tmp_path / "real.parquet")
    table(0.05, LAG_S, 1.0, 10.2).to_csv(tmp_path / "sim.csv", index=False)
    table(0.2, LAG_S, 1.5, 9.0).to_csv(tmp_path / "sim_low.csv", index=False)
    return tmp_path


PLAN = """
[plan]
name = "synthetic"
k_p = 0.05
eps_min = 0.5

[weights]
performance = 0.3
time = 0.3
frequency = 0.4

[logs]
real = "real.parquet"
sim = "sim.csv"
sim_low = "sim_low.csv"

[[tests]]
name = "level"
kind = "performance"
parameter = "mean"
signal = "vehicle.level"
segment_s = [10.0, 20.0]
compare = ["sim_low"]

[[tests]]
name = "curve"
kind = "time"
signal = "vehicle.curve"
segment_s = [10.0, 30.0]
compare = ["sim_low"]
align = { method = "xcorr", max_lag_s = 1.0 }

[[tests]]
name = "plant"
kind = "frequency"
input = "vehicle.u"
output = "vehicle.y"
segment_s = [0.0, 59.0]
band_hz = [0.5, 20.0]
n_points = 20
windows_s = [2.0, 4.0, 8.0]
compare = ["sim_low"]
"""


def _write_plan(directory, text=PLAN):
    path = directory / "plan.toml"
    path.write_text(text)
    return path


def _eta(e, eps):
    return 0.75 * eps / math.hypot(0.75 * eps, e)


def test_indices_of_known_errors(logs):
    result = assess(load_plan(_write_plan(logs)))
    level, curve, plant = result.results
    # η_p: p_e = 10, p_s = 10.2, ε_p = 0.05·10 = 0.5
    assert level.rows[0].eta == pytest.approx(_eta(0.2, 0.5), rel=1e-9)
    assert level.rows[1].eta == pytest.approx(_eta(1.0, 0.5), rel=1e-9)
    # η_t: the lag is found, the offset is the error, ε_t = 0.05 · range(sin) = 0.1
    assert curve.rows[0].alignment_shift_s == pytest.approx(LAG_S, abs=2e-3)
    assert curve.threshold == pytest.approx(0.1, rel=1e-3)
    assert curve.rows[0].error == pytest.approx(0.05, abs=2e-3)
    assert curve.rows[0].eta == pytest.approx(_eta(0.05, 0.1), abs=0.01)
    assert curve.rows[1].error == pytest.approx(0.2, abs=2e-3)
    assert curve.zero_output_error == pytest.approx(1 / math.sqrt(2), rel=1e-3)
    # η_f: same plant → e_mag, e_pha ≈ 0; a 1.5× gain is 20·log10(1.5) = 3.52 dB everywhere
    same, low = plant.rows
    assert same.e_mag_db < 0.1
    assert same.e_pha_deg < 1.0
    assert low.e_mag_db == pytest.approx(20 * math.log10(1.5), abs=0.1)
    assert low.e_pha_deg < 1.0
    assert same.included.all()
    mag_range = plant.real.magnitude_db.max() - plant.real.magnitude_db.min()
    assert low.eps_mag_db == pytest.approx(0.05 * mag_range, rel=1e-9)
    assert low.eta_mag == pytest.approx(_eta(low.e_mag_db, low.eps_mag_db), rel=1e-9)
    # Aggregates: only the assessed sim counts (the compare rows are references).
    etas = [level.eta, curve.eta, plant.eta]
    expected_all = math.sqrt(0.3 * etas[0] ** 2 + 0.3 * etas[1] ** 2 + 0.4 * etas[2] ** 2)
    assert result.eta_all == pytest.approx(expected_all, rel=1e-12)
    assert result.eta_min == min(etas)


def test_event_alignment_reports_the_lag(tmp_path):
    t = np.arange(0.0, 20.0, 0.01)
    step = np.clip((t - 5.0) / 0.5, 0.0, 1.0)
    pd.DataFrame({"time_s": t, "v.x": step}).to_csv(tmp_path / "real.csv", index=False)
    pd.DataFrame({"time_s": t + 100.0, "v.x": np.clip((t - 5.7) / 0.5, 0, 1)}).to_csv(
        tmp_path / "sim.csv", index=False
    )
    plan = """
[logs]
real = "real.csv"
sim = "sim.csv"
[[tests]]
name = "takeoff"
kind = "time"
signal = "v.x"
segment_s = [4.0, 10.0]
segment_sim_s = [104.0, 110.0]
align = { method = "event", threshold = 0.5, max_lag_s = 1.0 }
"""
    result = assess(load_plan(_write_plan(tmp_path, plan)))
    row = result.results[0].rows[0]
    assert row.alignment_shift_s == pytest.approx(0.7, abs=1e-9)
    assert row.error == pytest.approx(0.0, abs=1e-9)
    assert result.plan.weights == {"time": 1.0}


def test_step_metrics_of_closed_form_responses():
    t = np.linspace(0.0, 10.0, 100_001)
    tau = 0.5
    first_order = step_metrics(t, 1 - np.exp(-t / tau), 0.02, 1.0)
    assert first_order.rise_time_s == pytest.approx(tau * math.log(9), abs=1e-3)
    assert first_order.settling_time_s == pytest.approx(tau * math.log(50), abs=1e-3)
    assert first_order.overshoot_pct == pytest.approx(0.0, abs=1e-5)  # steady state is a mean
    zeta, wn = 0.3, 4.0
    wd = wn * math.sqrt(1 - zeta**2)
    y = 1 - np.exp(-zeta * wn * t) * (
        np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t)
    )
    second_order = step_metrics(t, y, 0.02, 1.0)
    expected = 100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
    assert second_order.overshoot_pct == pytest.approx(expected, abs=0.01)


def test_cli_report_writes_html_and_json_and_exit_code(logs, capsys):
    plan = _write_plan(logs)
    out = logs / "out"
    code = main(["report", str(plan), "--out", str(out)])
    summary = json.loads((out / "plan.json").read_text())
    assert code == (0 if summary["summary"]["eta_min"] >= 0.5 else 1)
    assert summary["summary"]["exit_code"] == code
    assert summary["plan"]["k_e"] == pytest.approx(0.75)
    assert {log["role"] for log in summary["logs"]} == {"real", "sim", "sim_low"}
    assert all(len(log["sha256"]) == 64 for log in summary["logs"])
    freq = summary["tests"][2]
    assert freq["windows_s"] == [2.0, 4.0, 8.0]
    assert freq["rows"][0]["excluded_hz"] == []
    assert "Tischler" in freq["cifer_w_gamma"]
    html = (out / "plan.html").read_text()
    assert html.count("data:image/png;base64,") == 2
    assert "http" not in html.replace("http-equiv", "")  # self-contained, no network
    # Same logs with a stricter ε_min: exit code 1.
    strict = _write_plan(logs, PLAN.replace("eps_min = 0.5", "eps_min = 0.999"))
    assert main(["report", str(strict), "--out", str(out)]) == 1


BAD_PLANS = [
    (
        ("frequency = 0.4", "frequency = 0.5"),
        "weights must sum to 1, got performance 0.3 + time 0.3 + frequency 0.5 = 1.1",
    ),
    (
        ('parameter = "mean"', 'parameter = "mean"\nhihgpass_hz = 5'),
        "key 'tests[0].hihgpass_hz' = 5: unknown key",
    ),
    (
        ("segment_s = [10.0, 20.0]", "segmnet_s = [10.0, 20.0]"),
        "key 'tests[0].segmnet_s' = [10.0, 20.0]: unknown key",
    ),
    (('sim_low = "sim_low.csv"', 'sim_low = "missing.csv"'), "missing.csv: log file not found"),
    (
        ('compare = ["sim_low"]', 'compare = ["sim_x"]'),
        "key 'tests[0].compare' = 'sim_x': not in [logs] ['real', 'sim', 'sim_low']",
    ),
    (
        ('parameter = "mean"', 'parameter = "median"'),
        "key 'tests[0].parameter' = 'median': expected 'mean', 'std'",
    ),
    (("[plan]", "[plan\n"), "not valid TOML"),
]


@pytest.mark.parametrize(("edit", "message"), BAD_PLANS)
def test_bad_plans_give_one_line_and_exit_2(logs, capsys, edit, message):
    plan = _write_plan(logs, PLAN.replace(*edit, 1))
    assert main(["report", str(plan), "--out", str(logs / "out")]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.startswith("credibility: error: ")
    assert err.count("\n") == 1


def test_a_segment_past_the_log_is_not_scored_and_exits_3(logs, capsys):
    """The logs are readable, so this is no bad input (2): the only time test is listed as
    not scored with the span it needed, and with no time test left there is no verdict."""
    plan = _write_plan(logs, PLAN.replace("segment_s = [10.0, 30.0]", "segment_s = [50.0, 70.0]"))
    out = logs / "out"
    assert main(["report", str(plan), "--out", str(out)]) == 3
    report = json.loads((out / "plan.json").read_text())
    curve = report["tests"][1]
    assert (curve["name"], curve["scored"], curve["eta"]) == ("curve", False, None)
    assert curve["not_scored"]["kind"] == "short_signal"
    assert (
        "segment [50, 70] s is outside the logged span [0.000, 59.990] s"
        in (curve["not_scored"]["message"])
    )
    assert report["summary"]["outcome"] == "could not be scored"
    assert report["summary"]["unscorable_reason"] == (
        "no time test (of 1) could be scored: η̄_t is undefined"
    )
    assert "segment [50, 70] s is outside the logged span" in capsys.readouterr().err


def test_log_override_replaces_a_role(logs):
    plan = load_plan(_write_plan(logs), {"sim_low": logs / "sim.csv"})
    result = assess(plan)
    assert result.results[0].rows[1].p_s == pytest.approx(10.2)
    with pytest.raises(CredibilityError, match=r"the plan has no log role 'foo'"):
        load_plan(_write_plan(logs), {"foo": logs / "sim.csv"})


def test_average_hz_compares_per_sample_noise_with_interval_means(tmp_path):
    """White noise of σ = 1 logged per sample at 800 Hz (a SITL in lockstep) against PX4's
    means of it over 5 ms (a real sensor_combined at 200 Hz): the means have σ = 1/√4 = 0.5,
    so the 800 Hz log reads 2× too high unless it is averaged the same way first."""
    rng = np.random.default_rng(3)
    fast_t = np.arange(0.0, 30.0, 1 / 800.0)
    fast = rng.standard_normal(fast_t.size)
    real_noise = rng.standard_normal(fast_t.size).reshape(-1, 4).mean(axis=1)
    pd.DataFrame({"time_s": fast_t[3::4], "imu.x": real_noise}).to_csv(
        tmp_path / "real.csv", index=False
    )
    pd.DataFrame({"time_s": fast_t, "imu.x": fast}).to_csv(tmp_path / "sim.csv", index=False)
    plan = """
[plan]
name = "averaging"
k_p = 0.1

[logs]
real = "real.csv"
sim = "sim.csv"

[[tests]]
name = "sigma"
kind = "performance"
parameter = "std"
signal = "imu.x"
segment_s = [1.0, 29.0]
"""
    raw = assess(load_plan(_write_plan(tmp_path, plan))).results[0].rows[0]
    averaged_plan = _write_plan(tmp_path, plan + "average_hz = 200.0\n")
    averaged = assess(load_plan(averaged_plan)).results[0].rows[0]
    assert raw.p_e == pytest.approx(0.5, rel=0.03)
    assert raw.p_s == pytest.approx(1.0, rel=0.03)
    assert averaged.p_e == raw.p_e  # already 200 Hz means: left as logged
    assert averaged.p_s == pytest.approx(0.5, rel=0.03)


def test_a_log_not_in_the_tests_arming_state_is_not_compared(tmp_path):
    """σ at rest after the landing compares a disarmed vehicle with a disarmed one: a sim
    still armed there (a replay that landed late) is listed as not scored, with the time
    its state differed; a compared sim in the right state keeps its row."""
    t = np.arange(0.0, 30.0, 0.01)
    noise = np.random.default_rng(5).standard_normal(t.size)

    def log(name, armed_until_s):
        state = np.where(t < armed_until_s, 2, 1)  # vehicle_status ARMED, STANDBY
        pd.DataFrame({"time_s": t, "imu.x": noise, "vehicle_status.arming_state": state}).to_csv(
            tmp_path / name, index=False
        )

    log("real.csv", 5.0)
    log("sim.csv", 15.5)
    log("sim_low.csv", 8.0)
    tests = "".join(
        f"""
[[tests]]
name = "{name}"
kind = "performance"
parameter = "std"
signal = "imu.x"
segment_s = {list(segment)}
armed = {str(armed).lower()}
compare = {list(compare)}
"""
        for name, segment, armed, compare in (
            ("sigma_disarmed", (10.0, 20.0), False, ["sim_low"]),
            ("sigma_disarmed_early", (20.0, 29.0), False, ["sim_low"]),
            ("sigma_armed", (1.0, 4.0), True, []),
        )
    ).replace("'", '"')
    plan = _write_plan(tmp_path, """
[plan]
name = "arming"
k_p = 0.1

[logs]
real = "real.csv"
sim = "sim.csv"
sim_low = "sim_low.csv"
""" + tests)  # fmt: skip
    result = assess(load_plan(plan), strict=False)
    (late,) = result.not_scored
    assert late.test.name == "sigma_disarmed"
    assert late.reason.kind == "state_mismatch"
    assert late.detail == (
        f"{tmp_path / 'sim.csv'}: the vehicle is armed at 10 s (vehicle_status.arming_state), "
        "inside 10-20 s where this test compares a disarmed vehicle"
    )
    early, armed = result.results
    assert [row.role for row in early.rows] == ["sim", "sim_low"]
    assert early.eta == pytest.approx(1.0, abs=1e-6)  # the same noise: σ equal
    assert armed.test.name == "sigma_armed"
    # a late disarm inside the segment names its time; the real log is checked too
    late_inside = plan.read_text().replace("[20.0, 29.0]", "[14.0, 29.0]")
    late_inside = late_inside.replace("[1.0, 4.0]", "[1.0, 6.0]")
    result = assess(load_plan(_write_plan(tmp_path, late_inside)), strict=False)
    details = [item.detail for item in result.not_scored]
    assert any("the vehicle is armed at 14 s" in d and "sim.csv" in d for d in details)
    assert any("the vehicle is disarmed at 5 s" in d and "real.csv" in d for d in details)
