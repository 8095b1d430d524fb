"""Reading real ULogs and tables; every bad input is one clear line."""

import struct

import numpy as np
import pandas as pd
import pytest

from credibility.errors import CredibilityError
from credibility.logs import SignalSpec, open_log
from credibility.signals import window


def test_x500_log_loads_with_its_corruption_warning_as_one_line(x500_log, capsys):
    log = open_log(x500_log)
    assert capsys.readouterr().out == ""  # pyulog's print() is captured, not leaked
    assert len(log.warnings) == 1
    assert "no subscription found for message id 32812" in log.warnings[0]
    assert "\n" not in log.warnings[0]
    pitch = log.signal(SignalSpec("vehicle_attitude.q.pitch", convert="rad->deg"))
    # data/flight_logs/README.md: attitude range pitch −22.7 … +13.2°
    assert pitch.values.min() == pytest.approx(-22.7, abs=1.0)
    assert pitch.values.max() == pytest.approx(13.2, abs=1.0)


def test_multi_instance_topics_and_hover_noise(quad4001_log):
    log = open_log(quad4001_log)
    accel0 = log.signal(SignalSpec("sensor_accel.0.x"))
    accel1 = log.signal(SignalSpec("sensor_accel.1.x"))
    assert not np.array_equal(accel0.values, accel1.values)
    # the logs' README: motors stopped, gyro σ = 0.0031 / 0.0037 rad/s (x / y), 104.9–108.9 s
    for axis, sigma in ((0, 0.0031), (1, 0.0037)):
        gyro = log.signal(SignalSpec(f"sensor_combined.gyro_rad[{axis}]"))
        assert window(gyro, (105.0, 108.9), 0.1).values.std() == pytest.approx(sigma, rel=0.1)


def test_missing_topic_and_field_name_the_problem(quad4001_log):
    log = open_log(quad4001_log)
    with pytest.raises(CredibilityError, match=r"no topic 'sensor_accel' instance 5.*sensor_accel"):
        log.signal(SignalSpec("sensor_accel.5.x"))
    with pytest.raises(CredibilityError, match=r"no field 'xyz\[7\]'.*xyz\[0\]"):
        log.signal(SignalSpec("vehicle_angular_velocity.xyz[7]"))


def test_segment_outside_the_log_is_an_error(quad4001_log):
    sig = open_log(quad4001_log).signal(SignalSpec("vehicle_angular_velocity.xyz[0]"))
    with pytest.raises(CredibilityError) as info:
        window(sig, (190.0, 200.0), 0.5)
    assert str(info.value) == (
        f"vehicle_angular_velocity.xyz[0] in {quad4001_log}: segment [190, 200] s is outside "
        "the logged span [104.957, 197.419] s"
    )


def test_truncated_and_foreign_files(tmp_path, quad4001_log):
    data = quad4001_log.read_bytes()
    head_only = tmp_path / "head_only.ulg"
    head_only.write_bytes(data[:100_000])
    with pytest.raises(CredibilityError, match=r"ULog has no logged data \(the file is truncated"):
        open_log(head_only)
    # Cut mid-flight: it loads, and asking for the hover then fails on the span.
    half = tmp_path / "half.ulg"
    half.write_bytes(data[:2_000_000])
    sig = open_log(half).signal(SignalSpec("vehicle_angular_velocity.xyz[0]"))
    with pytest.raises(CredibilityError, match=r"outside the logged span \[104.957, 151.7"):
        window(sig, (115.0, 188.0), 0.5)
    text = tmp_path / "notes.ulg"
    text.write_text("time,value\n0,1\n")
    with pytest.raises(CredibilityError, match=r"notes.ulg: not a readable ULog file"):
        open_log(text)
    with pytest.raises(CredibilityError, match=r"log file not found"):
        open_log(tmp_path / "absent.ulg")
    (tmp_path / "x.bin").write_bytes(b"")
    with pytest.raises(CredibilityError, match=r"unknown log format '.bin'"):
        open_log(tmp_path / "x.bin")


def test_a_damaged_header_that_ends_past_the_file_is_refused_not_looped(tmp_path):
    """pyulog resumes after a damaged header by seeking back the size the header claims;
    when the file ends inside that message it lands before the header and reads the same
    bytes for ever. Here it lands on the info message before, which leads back to it."""
    key = b"char[3] abc"
    body = bytes([len(key)]) + key + b"xyz"
    info = struct.pack("<HB", len(body), ord("I")) + body
    tail = b"\x00" * 4  # what is left of the damaged message
    claimed = len(info) + 1 + len(tail)  # seeking back 2 + this from the end lands on info
    damaged = struct.pack("<HB", claimed, 0)  # message type 0: pyulog's "corrupt" mark
    path = tmp_path / "looping.ulg"
    path.write_bytes(b"ULog\x01\x12\x35\x01" + bytes(8) + info + damaged + tail)
    with pytest.raises(CredibilityError, match=r"looping.ulg: not a readable ULog file \(a "
                       r"damaged message at byte 16 ends past the file\)"):  # fmt: skip
        open_log(path)


def test_tables_nan_and_gaps(tmp_path):
    t = np.arange(0.0, 10.0, 0.01)
    y = np.sin(t)
    y[500] = np.nan
    frame = pd.DataFrame({"time_s": t, "rig.y": y})
    frame.to_parquet(tmp_path / "run.parquet")
    frame.assign(timestamp=np.round(t * 1e6).astype(np.int64)).drop(columns="time_s").to_csv(
        tmp_path / "run.csv", index=False
    )
    for name in ("run.parquet", "run.csv"):
        log = open_log(tmp_path / name)
        sig = log.signal(SignalSpec("rig.y"))
        np.testing.assert_allclose(sig.time_s, t, atol=1e-9)
        with pytest.raises(
            CredibilityError, match=r"1 NaN/inf samples in \[1, 9\] s, the first at t = 5.000 s"
        ):
            window(sig, (1.0, 9.0), 0.5)
        assert window(sig, (1.0, 9.0), 0.5, drop_nan=True).values.size == 800
        with pytest.raises(CredibilityError, match=r"0.020 s without samples at t = 4.990 s"):
            window(sig, (1.0, 9.0), 0.015, drop_nan=True)
    pd.DataFrame({"t": t}).to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(CredibilityError, match=r"no time column"):
        open_log(tmp_path / "bad.csv")


def test_euler_angles_of_a_quaternion_are_pxs_zyx_with_yaw_unwrapped(tmp_path):
    """Closed form: q = yaw(ψ) ⊗ pitch(θ) ⊗ roll(φ) gives back (φ, θ, ψ); a yaw passing
    ±180° continues instead of jumping by 360°."""
    roll, pitch = np.radians(10.0), np.radians(-20.0)
    yaw = np.radians(np.array([170.0, 179.0, 181.0, 190.0]))
    half = lambda a: (np.cos(a / 2), np.sin(a / 2))  # noqa: E731
    (cr, sr), (cp, sp), (cy, sy) = half(roll), half(pitch), half(yaw)
    table = pd.DataFrame({
        "timestamp": [1_000_000, 2_000_000, 3_000_000, 4_000_000],
        "vehicle_attitude.q[0]": cr * cp * cy + sr * sp * sy,
        "vehicle_attitude.q[1]": sr * cp * cy - cr * sp * sy,
        "vehicle_attitude.q[2]": cr * sp * cy + sr * cp * sy,
        "vehicle_attitude.q[3]": cr * cp * sy - sr * sp * cy,
    })  # fmt: skip
    path = tmp_path / "attitude.csv"
    table.to_csv(path, index=False)
    log = open_log(path)
    for angle, expected in (("roll", np.full(4, roll)), ("pitch", np.full(4, pitch)),
                            ("yaw", yaw)):  # fmt: skip
        signal = log.signal(SignalSpec(f"vehicle_attitude.q.{angle}"))
        assert signal.values == pytest.approx(expected, abs=1e-12)


def test_velocity_in_the_heading_frame_is_the_sticks_axes(tmp_path):
    """Closed form: facing east (90°) and flying north at 3 m/s is 3 m/s to the left
    (v_right = −3), none forward; facing north-east and flying east at √2 m/s is 1 m/s
    forward and 1 m/s to the right."""
    table = pd.DataFrame({
        "timestamp": [1_000_000, 2_000_000],
        "vehicle_local_position.vx": [3.0, 0.0],
        "vehicle_local_position.vy": [0.0, np.sqrt(2.0)],
        "vehicle_local_position.heading": [np.pi / 2, np.pi / 4],
    })  # fmt: skip
    path = tmp_path / "position.csv"
    table.to_csv(path, index=False)
    log = open_log(path)
    forward = log.signal(SignalSpec("vehicle_local_position.v_forward")).values
    right = log.signal(SignalSpec("vehicle_local_position.v_right")).values
    assert forward == pytest.approx([0.0, 1.0], abs=1e-12)
    assert right == pytest.approx([-3.0, 1.0], abs=1e-12)
