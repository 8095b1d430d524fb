"""rig.identify.vibration: the X500 vehicle file's vibration against the real log's IMU stream at
each operating point, the fit recovering known levels, and the window detection; the X8's
from its raw IMU FIFO at named windows, its motors through DShot."""

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from px4_logs import FlightLog
from quad_model.vehicle import load_vehicle
from rig import cli
from rig.identify.results import IdentificationError
from rig.identify.vibration import (
    FITTED_POINTS,
    RAW_PIPELINE,
    fit_vibration,
    log_motor_drive,
    model_spectrum,
    read_log_vibration,
    read_raw_imu,
    read_raw_vibration,
)

#: The real X500 flight (a module-scoped fixture cannot use the function-scoped x500_log).
X500_LOG = (
    Path(__file__).resolve().parents[2] / "data/flight_logs/px4_x500v2_v6xrt_flight_2026-03-20.ulg"
)
#: The PX4 replay's lockstep rate (the log's IMU_GYRO_RATEMAX), at which the file was fitted.
IMU_RATE_HZ = 800.0
#: At the fitted points σ and the power of each band that holds most of an axis' power come
#: out within this of the log's: two parameters per axis fit two bands, the rest is the beat
#: of four rotors' tones (±10 % from seed to seed) and the white floor, one density per triad
#: from the log at rest: its RMS over the axes is above the idle gyro z axis' own, which the
#: model therefore reads about 1.2× the log's.
FITTED_RTOL = 0.3
#: Climb and descent are not fitted: the model predicts them from the rotor speed alone. The
#: real climb shakes the gyro's x axis 1.6× more than hover at the same rotor speed (inflow,
#: not speed), so a factor 1.8 either way is what the model holds there.
CHECKED_FACTOR = 1.8


@pytest.fixture(scope="module")
def measured():
    return read_log_vibration(FlightLog.read(X500_LOG))


def test_operating_points_of_the_x500_log(measured):
    """The log's timeline (data/flight_logs/README.md): idle on the ground before 411.2 s,
    the take-off climb, hover, the AUTO_LAND descent, the props stopped after the 503.1 s
    disarm; the IMU stream is PX4's 200 Hz means (IMU_INTEG_RATE)."""
    assert measured.stream_rate_hz == 200.0
    windows = {p.name: p.windows_s for p in measured.points}
    assert set(windows) == {"stopped", "idle", "hover", "climb", "descent"}
    assert len(windows["hover"]) == 4  # identify's steady hover windows, pooled
    for name, (earliest, latest) in {
        "idle": (408.9, 411.5),
        "hover": (418.0, 482.5),
        "climb": (413.0, 419.0),
        "descent": (482.0, 490.0),
        "stopped": (503.2, 504.1),  # 0.1 s after the 503.1 s disarm: the props coasted
    }.items():
        assert all(earliest <= start < end <= latest for start, end in windows[name]), name
    hover = measured.point("hover")
    assert np.mean(hover.throttle) == pytest.approx(0.52, abs=0.02)  # identify's σ_h


@pytest.mark.parametrize("name", ["idle", "hover", "climb", "descent"])
def test_x500_vibration_matches_the_log_at_each_operating_point(measured, name):
    """The model's 200 Hz stream (800 Hz IMU on the thrust stand at the point's motor
    commands and voltage, 5 ms means, 5 Hz high-pass) against the log's: σ per axis and
    the RMS of each band holding at least 40 % of an axis' power (5-50 or 50-100 Hz).
    Powers are averaged over four seeds: rotors at one command turn at one speed, so their
    tones' relative phases (the seed's) stay put: one seed's idle σ alone came out at
    0.68-1.42 of the log's."""
    vehicle = load_vehicle("x500_v2")
    point = measured.point(name)
    runs = [model_spectrum(vehicle, point, IMU_RATE_HZ, measured.stream_rate_hz, seed=seed)
            for seed in (0, 3, 7, 11)]  # fmt: skip
    real = point.spectrum
    sigma_ratio = np.sqrt(np.mean([run.sigma**2 for run in runs], axis=0)) / real.sigma
    band_rms = np.sqrt(np.mean([run.band_rms**2 for run in runs], axis=0))
    power_share = real.band_rms**2 / (real.band_rms**2).sum(axis=-1, keepdims=True)
    band_ratio = (band_rms / real.band_rms)[power_share >= 0.4]
    if name in FITTED_POINTS:
        np.testing.assert_allclose(sigma_ratio, 1.0, atol=FITTED_RTOL)
        np.testing.assert_allclose(band_ratio, 1.0, atol=FITTED_RTOL)
    else:
        for ratio in (sigma_ratio, band_ratio):
            assert np.all((ratio > 1 / CHECKED_FACTOR) & (ratio < CHECKED_FACTOR)), ratio


def test_the_fit_recovers_known_levels(measured):
    """A stand-made "log" from known levels (the file's, each axis scaled differently)
    fitted back: the levels come out within 15 % (the fit and the stand runs beat with
    different seeds)."""
    vehicle = load_vehicle("x500_v2")
    scale = np.array([0.5, 1.0, 2.0])
    vib = vehicle.vibration
    truth = replace(
        vehicle,
        vibration=replace(
            vib,
            accel_tone_level=tuple(tuple(np.array(r) * scale) for r in vib.accel_tone_level),
            gyro_broadband_level=tuple(
                tuple(np.array(r) * scale[::-1]) for r in vib.gyro_broadband_level
            ),
        ),
    )
    points = tuple(
        replace(
            p,
            spectrum=model_spectrum(truth, p, IMU_RATE_HZ, measured.stream_rate_hz, seed=11),
        )
        for p in measured.points
        if p.name in FITTED_POINTS
    )
    fitted, _ = fit_vibration(vehicle, replace(measured, points=points), IMU_RATE_HZ)
    hover = 1  # the table's second point; its levels carry most of the power
    for name in ("accel_tone_level", "gyro_broadband_level"):
        got = np.array(getattr(fitted.vibration, name))[hover]
        want = np.array(getattr(truth.vibration, name))[hover]
        np.testing.assert_allclose(got, want, rtol=0.15)


def test_the_vehicle_files_levels_are_what_rig_identify_prints(capsys):
    """x500_v2.toml's [imu] densities and [vibration] operating points are the output of
    `rig identify LOG --vibration`, to the digits the file keeps."""
    assert cli.main(["identify", str(X500_LOG), "--vibration"]) == 0
    printed = capsys.readouterr().out
    lines = [line for line in printed.splitlines() if not line.startswith("#")]
    sections = tomllib.loads("\n".join(lines))
    vehicle = load_vehicle("x500_v2")
    for key, value in sections["imu"].items():
        assert getattr(vehicle.imu, key) == pytest.approx(value, rel=1e-3), key
    for key, value in sections["vibration"].items():
        np.testing.assert_allclose(getattr(vehicle.vibration, key), value, atol=1e-3, err_msg=key)


# -- the raw IMU FIFO: the X8's ground run ---------------------------------------------------
#: The X8's windows as auriol_x8.toml's header gives them (boot seconds).
X8_REST = (926.82, 927.28)
X8_POINTS = {"idle": (920.8, 922.4), "spin_up": (923.5, 924.1), "ground_run": (924.4, 926.3)}
X8_DISARM_S = 926.34


def test_the_x8s_motors_reach_the_stand_through_dshots_range(auriol_log):
    """DShot's armed floor is DSHOT_MIN × 1999 = 299 of its 1999: command c is ESC throttle
    (299 + 1700·c)/1999; from the disarm (the log's message: it logs no arming topic) the
    ESCs get 0. A log without an arming topic and no --disarm is one line."""
    log = FlightLog.read(auriol_log)
    vehicle = load_vehicle("auriol_x8")
    drive = log_motor_drive(log, vehicle, X8_DISARM_S)
    armed = drive.time_s < X8_DISARM_S
    np.testing.assert_allclose(
        drive.throttle[armed], (299.0 + 1700.0 * drive.command[armed]) / 1999.0, rtol=1e-12
    )
    assert np.all(drive.throttle[~armed] == 0.0)
    _, idle = drive.window(*X8_POINTS["idle"])
    np.testing.assert_allclose(idle, 299.0 / 1999.0, atol=1e-6)
    with pytest.raises(IdentificationError, match=r"no arming state .* give --disarm SECONDS"):
        log_motor_drive(log, vehicle, None)
    with pytest.raises(IdentificationError, match=r": 8 rotors \(dshot .*vehicle 'Holybro X500"):
        log_motor_drive(log, load_vehicle("x500_v2"), X8_DISARM_S)


def test_the_raw_fit_recovers_known_levels(auriol_log):
    """The X8's idle and spin-up windows (their motors' throttles) made into a "log" by the
    model with known levels, at a 2 kHz chip rate to keep the stand runs short, then fitted
    back through the chip's own samples (no PX4 pipeline): within 15 %, the seeds differing."""
    log = FlightLog.read(auriol_log)
    vehicle = load_vehicle("auriol_x8")
    drive = log_motor_drive(log, vehicle, X8_DISARM_S)
    windows = {name: X8_POINTS[name] for name in ("idle", "spin_up")}
    measured = read_raw_vibration(log, read_raw_imu(log), drive, 48.0, windows)
    rate = 2000.0
    bands = ((5.0, 100.0), (100.0, rate / 2))
    vib = vehicle.vibration
    scale = np.array([0.5, 1.0, 2.0])
    truth = replace(
        vehicle,
        vibration=replace(
            vib,
            level_rotor_speed_radps=vib.level_rotor_speed_radps[::2],  # idle, spin-up
            accel_tone_level=tuple(tuple(np.array(r) * scale) for r in vib.accel_tone_level[::2]),
            accel_broadband_level=vib.accel_broadband_level[::2],
            gyro_tone_level=vib.gyro_tone_level[::2],
            gyro_broadband_level=tuple(
                tuple(np.array(r) * scale[::-1]) for r in vib.gyro_broadband_level[::2]
            ),
        ),
    )
    points = tuple(
        replace(p, spectrum=replace(p.spectrum, bands_hz=bands)) for p in measured.points
    )
    points = tuple(
        replace(p, spectrum=model_spectrum(truth, p, rate, rate, seed=11, pipeline=RAW_PIPELINE))
        for p in points
    )
    fitted, _ = fit_vibration(
        vehicle, replace(measured, points=points, stream_rate_hz=rate), rate, tuple(windows)
    )
    spin_up = 1  # the faster point: its levels carry the most power
    for name in ("accel_tone_level", "gyro_broadband_level"):
        got = np.array(getattr(fitted.vibration, name))[spin_up]
        want = np.array(getattr(truth.vibration, name))[spin_up]
        np.testing.assert_allclose(got, want, rtol=0.15)


def test_the_x8_files_noise_and_levels_are_what_rig_identify_prints(auriol_log, capsys):
    """auriol_x8.toml's [imu] densities and [vibration] operating points are the output of
    `rig identify LOG --vibration --rest ... --at ...` from the raw FIFO, to the digits the
    file keeps."""
    at = [arg for name, (a, b) in X8_POINTS.items() for arg in ("--at", name, str(a), str(b))]
    argv = ["identify", str(auriol_log), "--vibration", "--disarm", str(X8_DISARM_S)]
    assert cli.main([*argv, "--rest", *map(str, X8_REST), *at]) == 0
    printed = capsys.readouterr().out
    lines = [line for line in printed.splitlines() if not line.startswith("#")]
    sections = tomllib.loads("\n".join(lines))
    vehicle = load_vehicle("auriol_x8")
    for key, value in sections["imu"].items():
        np.testing.assert_allclose(getattr(vehicle.imu, key), value, rtol=1e-3, err_msg=key)
    for key, value in sections["vibration"].items():
        np.testing.assert_allclose(getattr(vehicle.vibration, key), value, atol=1e-3, err_msg=key)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--vibration", "--at", "idle", "920.8", "soon"],
         "--at idle 920.8 soon: START and END are boot seconds"),
        (["--vibration", "--at", "idle", "922", "921"], "START before END"),
        (["--vibration", "--rest", "926.8", "927.3"], "--rest names the rest of a raw --vibration"),
        (["--at", "idle", "920.8", "922.4"], "--at names the operating points of a --vibration"),
        (["--vibration", "--at", "idle", "900", "901"], "window idle 900-901 s holds 0 raw IMU"),
    ],
)  # fmt: skip
def test_bad_raw_windows_are_one_line(auriol_log, capsys, argv, message):
    argv = ["identify", str(auriol_log), "--disarm", str(X8_DISARM_S), *argv]
    assert cli.main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert message in err
