"""The plans shipped in credibility/plans run on the carried real logs."""

import math
from pathlib import Path

import control
import numpy as np
import pandas as pd
import pytest

import credibility
from credibility.assess import assess
from credibility.plan import load_plan

PLANS = Path(credibility.__file__).parent / "plans"


@pytest.mark.parametrize(
    "name", ["paper_sensor_noise", "paper_frequency_sweep", "paper_level_flight"]
)
def test_paper_plans_score_a_log_against_itself_as_one(name):
    """Until the rig writes its runs, the real log stands in for every sim role: every
    signal path and segment of the plan must resolve, and identical logs must give η = 1."""
    plan = load_plan(PLANS / f"{name}.toml")
    real = plan.logs["real"]
    plan = load_plan(PLANS / f"{name}.toml", {role: real for role in plan.logs if role != "real"})
    result = assess(plan)
    assert result.eta_all == pytest.approx(1.0, abs=1e-12)
    assert result.eta_min == pytest.approx(1.0, abs=1e-12)


def test_repeatability_example_on_the_real_log():
    result = assess(load_plan(PLANS / "quad4001_repeatability.toml"))
    by_name = {r.test.name: r for r in result.results}
    # data/flight_logs/README.md: gyro x σ = 0.0031 rad/s with the motors stopped
    assert by_name["gyro_x_sigma_stopped"].rows[0].p_e == pytest.approx(0.0031, rel=0.1)
    # The rate setpoint leads the measured roll rate by a few tens of milliseconds.
    tracking = by_name["roll_rate_tracking"].rows[0]
    assert -0.15 < tracking.alignment_shift_s < -0.02
    # the logs' README: roll rate_sp → rate coherence > 0.8 at about 1–3.3 Hz in this hover.
    roll = by_name["roll_rate_response"]
    in_band = (roll.real.freqs_hz > 1.0) & (roll.real.freqs_hz < 3.3)
    assert roll.real.coherence[in_band].min() > 0.7
    assert set(result.means) == {"performance", "time", "frequency"}
    assert 0.0 < result.eta_min <= result.eta_all <= 1.0


def _real_for_every_role(name: str):
    plan = load_plan(PLANS / f"{name}.toml")
    real = plan.logs["real"]
    return load_plan(PLANS / f"{name}.toml", {role: real for role in plan.logs if role != "real"})


def test_x500_validation_roles_follow_the_replay_layout():
    """Each test assesses a high-precision replay and compares the low-precision replay of
    the same drive (Table 2 rows), at runs/credibility/x500/<drive>_<model>/autopilot.ulg."""
    plan = load_plan(PLANS / "x500_validation.toml")
    runs = (PLANS / "../../runs/credibility/x500").resolve()
    drive = {"sim": "velocity", "sim_attitude": "attitude", "sim_rates": "rates"}
    for role, name in drive.items():
        assert plan.logs[role] == runs / f"{name}_high" / "autopilot.ulg"
        assert plan.logs[f"{role}_low"] == runs / f"{name}_low" / "autopilot.ulg"
    for test in plan.tests:
        assert test.roles.real == "real"
        assert test.roles.compare == (f"{test.roles.sim}_low",), test.name
    assert dict(plan.weights) == {"performance": 0.3, "time": 0.3, "frequency": 0.4}
    assert plan.pass_mark == 0.6
    assert {t.kind for t in plan.tests} == {"performance", "time", "frequency"}
    unscorable = {item.name for item in plan.not_scorable}
    assert unscorable == {"raw_imu_spectrum", "response_above_25_hz", "rotor_speeds"}


def test_x500_validation_scores_the_real_flight_against_itself_as_one():
    result = assess(_real_for_every_role("x500_validation"))
    for test_result in result.results:
        for row in test_result.rows:
            assert row.eta == pytest.approx(1.0, abs=1e-12), test_result.test.name
    assert result.eta_all == pytest.approx(1.0, abs=1e-12)
    by_name = {r.test.name: r for r in result.results}
    # the logs' README, X500 armed at idle: gyro σ ≈ 0.0106/0.0070/0.0090 rad/s (its window
    # starts before sensor_combined does; ours is the logged part of it).
    for axis, sigma in zip("xyz", (0.0106, 0.0070, 0.0090), strict=True):
        p_e = by_name[f"gyro_{axis}_sigma_idle"].rows[0].p_e
        assert p_e == pytest.approx(sigma, rel=0.15)
    # the logs' README: rate_sp → rate coherence 0.91 (pitch) over 0.2–1 Hz in 455–481.5 s.
    pitch = by_name["pitch_rate_response"]
    below_1hz = pitch.real.freqs_hz < 1.0
    assert pitch.real.coherence[below_1hz].mean() > 0.8


RATE_HZ = 250.0  # the rig autopilot's fast-log rate


def _sweep_log(path, natural_hz: float) -> None:
    """A closed-form stand-in for a pitch_sweep_bench run: the scenario's log chirp (2–67 s,
    0.25 → 40 rad/s, 5°) through a 2nd-order attitude loop (ζ = 0.7) and a first-order rate
    loop at 3× its bandwidth."""
    t = np.arange(0.0, 70.0, 1.0 / RATE_HZ)
    duration, amplitude, w0, w1 = 65.0, math.radians(5.0), 0.25, 40.0
    tau = np.clip(t - 2.0, 0.0, duration)
    phase = w0 * duration * ((w1 / w0) ** (tau / duration) - 1.0) / math.log(w1 / w0)
    command = np.where((t >= 2.0) & (t <= 67.0), amplitude * np.sin(phase), 0.0)
    s = control.tf("s")
    wn = 2 * np.pi * natural_hz

    def respond(system, u):
        discrete = control.sample_system(system, 1.0 / RATE_HZ, "tustin")
        return control.forced_response(discrete, U=u).outputs

    rate_sp = np.gradient(command, 1.0 / RATE_HZ)
    pd.DataFrame(
        {
            "time_s": t,
            "vehicle_attitude_setpoint.q_d.pitch": command,
            "vehicle_attitude.q.pitch": respond(wn**2 / (s**2 + 1.4 * wn * s + wn**2), command),
            "vehicle_rates_setpoint.pitch": rate_sp,
            "vehicle_angular_velocity.xyz[1]": respond(1 / (s / (3 * wn) + 1), rate_sp),
        }
    ).to_csv(path, index=False)


def test_x500_pitch_bench_recovers_a_known_loop_from_the_scenario_sweep(tmp_path):
    """The plan's band and windows on the scenario's own chirp: the reference estimate
    matches the closed-form loop, identical models score 1 and a slower one less."""
    _sweep_log(tmp_path / "high.csv", 1.5)
    _sweep_log(tmp_path / "low.csv", 1.2)
    path = PLANS / "x500_pitch_bench.toml"
    result = assess(
        load_plan(path, {"reference": tmp_path / "high.csv", "sim": tmp_path / "low.csv"})
    )
    attitude = result.results[0]
    assert attitude.test.roles.real == "reference"
    f = attitude.real.freqs_hz
    wn = 2 * np.pi * 1.5
    s = 2j * np.pi * f
    ratio = attitude.real.complex_response / (wn**2 / (s**2 + 1.4 * wn * s + wn**2))
    # Up to 4 Hz within 0.2 dB and 1.5°; the chirp ends at f_b, so the last third of an
    # octave is estimated from little data (about 1.5 dB, 7° there).
    inner = f < 4.0
    assert np.abs(20 * np.log10(np.abs(ratio[inner]))).max() < 0.2
    assert np.abs(np.degrees(np.angle(ratio[inner]))).max() < 1.5
    assert np.abs(20 * np.log10(np.abs(ratio))).max() < 2.0
    assert attitude.real.coherence.min() > 0.95
    assert all(r.rows[0].included.all() for r in result.results)
    assert all(r.eta < 0.9 for r in result.results)
    same = assess(
        load_plan(path, {"reference": tmp_path / "high.csv", "sim": tmp_path / "high.csv"})
    )
    assert same.eta_all == pytest.approx(1.0, abs=1e-12)


def test_quad4001_validation_scores_the_real_hover_against_itself_as_one():
    """Every test of the 8S quad's study resolves on the real log (its signals, its
    segments, the 200 Hz averaging), identical logs give η = 1, the real σ are the logs' README's,
    and the plan names what the log cannot score (no GNSS, the pilot's height, yaw)."""
    result = assess(_real_for_every_role("quad4001_validation"))
    assert not result.not_scored
    assert result.eta_all == pytest.approx(1.0, abs=1e-12)
    assert set(result.means) == {"performance", "time", "frequency"}
    by_name = {r.test.name: r.rows[0] for r in result.results}
    # the logs' README, motors stopped: gyro σ 0.0031/0.0037/0.0036 rad/s, accel 0.017/0.019/0.020
    rest = zip("xyz", (0.0031, 0.0037, 0.0036), (0.017, 0.019, 0.020), strict=True)
    for axis, gyro, accel in rest:
        assert by_name[f"gyro_{axis}_sigma_rest"].p_e == pytest.approx(gyro, rel=0.1)
        assert by_name[f"accel_{axis}_sigma_rest"].p_e == pytest.approx(accel, rel=0.1)
    # hover, 5 Hz high-pass: accel 0.55/0.42/0.74 m/s²
    for axis, accel in zip("xyz", (0.55, 0.42, 0.74), strict=True):
        assert by_name[f"accel_{axis}_sigma_hover"].p_e == pytest.approx(accel, rel=0.1)
    unscorable = {item.name: item.kind for item in result.plan.not_scorable}
    assert unscorable["position_and_velocity"] == "time"
    assert unscorable["yaw_rate_response"] == "frequency"
    assert "height_and_climb_rate" in unscorable


def test_x8_plan_compares_the_fifo_tables_at_rest_idle_and_ground_run():
    """Each test pairs the real FIFO table with the model's of the same triad, inside the
    rest after the props coasted down, the armed idle before the logger's dropout, or the
    ground run; what needs flight is listed."""
    plan = load_plan(PLANS / "x8_raw_imu.toml")
    windows = {"rest": (926.8, 927.3), "idle": (920.8, 922.45), "ground_run": (923.4, 926.3)}
    for test in plan.tests:
        triad = "gyro" if test.name.startswith("gyro") else "accel"
        assert (test.roles.real, test.roles.sim) == (f"real_{triad}", f"sim_{triad}")
        assert test.signal.path.startswith(f"sensor_{triad}_fifo.")
        window = next(w for name, w in windows.items() if f"_sigma_{name}" in test.name)
        assert window[0] <= test.segment_s[0] < test.segment_s[1] <= window[1]
    assert len(plan.tests) == 24
    assert {item.name for item in plan.not_scorable} >= {"vibration_in_flight", "flight_dynamics"}
