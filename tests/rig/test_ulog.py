"""The streaming ULog writer produces files that pyulog reads back exactly."""

import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from pyulog import ULog

from rig.logs.ulog_writer import ULogWriteError, ULogWriter

TOPICS = {
    "vehicle_attitude": [("float[4]", "q"), ("float", "yawspeed")],
    "sensor_accel": [("uint32_t", "device_id"), ("float", "x"), ("float", "y"), ("float", "z")],
    "vehicle_status": [("uint8_t", "nav_state"), ("bool", "armed"), ("char[8]", "name")],
}


def test_round_trip_values_instances_info_parameters_and_messages(tmp_path):
    path = tmp_path / "run.ulg"
    q = np.array([0.9, 0.1, -0.2, 0.3])
    with ULogWriter(
        path,
        TOPICS,
        info={"sys_name": "HIL rig", "ver_hw": "EMULATED"},
        parameters={"MC_ROLLRATE_P": 0.15, "SYS_AUTOSTART": 4019},
        start_time_us=12,
    ) as log:
        for i in range(3):
            log.write("vehicle_attitude", 1000 * (i + 1), q=q * (i + 1), yawspeed=0.5 * i)
        log.write("sensor_accel", 1500, device_id=7, x=0.1, y=0.2, z=-9.81)
        log.write("sensor_accel", 1600, multi_id=1, device_id=8, x=1.0, y=2.0, z=3.0)
        log.write("vehicle_status", 2000, nav_state=4, armed=True, name="hover")
        log.log("warn", 2500, "GPS lost")
        log.set_parameter("MC_ROLLRATE_P", 0.2)

    ulog = ULog(str(path))
    assert ulog.start_timestamp == 12
    assert ulog.msg_info_dict["sys_name"] == "HIL rig"
    assert ulog.initial_parameters["MC_ROLLRATE_P"] == pytest.approx(0.15)
    assert ulog.initial_parameters["SYS_AUTOSTART"] == 4019
    assert ulog.changed_parameters[-1][1:] == ("MC_ROLLRATE_P", pytest.approx(0.2))
    att = ulog.get_dataset("vehicle_attitude").data
    np.testing.assert_array_equal(att["timestamp"], [1000, 2000, 3000])
    np.testing.assert_allclose(att["q[1]"], [0.1, 0.2, 0.3], rtol=1e-6)
    np.testing.assert_allclose(att["yawspeed"], [0.0, 0.5, 1.0])
    assert ulog.get_dataset("sensor_accel", 0).data["device_id"][0] == 7
    np.testing.assert_allclose(ulog.get_dataset("sensor_accel", 1).data["z"], [3.0])
    status = ulog.get_dataset("vehicle_status").data
    assert status["nav_state"][0] == 4
    assert status["armed"][0] == 1
    assert [(m.log_level_str(), m.message) for m in ulog.logged_messages] == [
        ("WARNING", "GPS lost")
    ]


def test_records_write_the_bytes_of_row_by_row_writes(tmp_path):
    """A block of records is the same data messages as the rows written one by one, for
    every kind of field (arrays, bool, char, a second instance)."""
    rows = [(1000 * i, [0.5 * i, 0.1, -0.2, 0.3], 0.25 * i) for i in range(1, 6)]
    with ULogWriter(tmp_path / "rows.ulg", TOPICS) as log:
        for t, q, yawspeed in rows:
            log.write("vehicle_attitude", t, q=q, yawspeed=yawspeed)
        log.write("vehicle_status", 10, nav_state=4, armed=True, name="hover")
        log.write("sensor_accel", 20, multi_id=1, device_id=8, x=1.0, y=2.0, z=3.0)
    with ULogWriter(tmp_path / "records.ulg", TOPICS) as log:
        attitude = log.records("vehicle_attitude", len(rows))
        attitude["timestamp"] = [t for t, _, _ in rows]
        attitude["q"] = [q for _, q, _ in rows]
        attitude["yawspeed"] = [yawspeed for _, _, yawspeed in rows]
        log.write_records("vehicle_attitude", attitude)
        status = log.records("vehicle_status", 1)
        status["timestamp"], status["nav_state"], status["armed"] = 10, 4, True
        status["name"] = b"hover"
        log.write_records("vehicle_status", status)
        accel = log.records("sensor_accel", 1)
        accel["timestamp"], accel["device_id"], accel["x"], accel["y"], accel["z"] = (
            20, 8, 1.0, 2.0, 3.0)  # fmt: skip
        log.write_records("sensor_accel", accel, multi_id=1)
        with pytest.raises(ULogWriteError, match="records not made by records"):
            log.write_records("sensor_accel", attitude)
    assert (tmp_path / "records.ulg").read_bytes() == (tmp_path / "rows.ulg").read_bytes()


def test_killed_writer_leaves_a_readable_log(tmp_path):
    """A process killed mid-run (no close, no atexit) keeps everything flushed before it."""
    path = tmp_path / "killed.ulg"
    script = textwrap.dedent(f"""
        import sys, time
        from rig.logs.ulog_writer import ULogWriter
        log = ULogWriter({str(path)!r}, {{"vehicle_air_data": [("float", "baro_alt_meter")]}},
                         flush_interval_s=0.0)
        for i in range(200):
            log.write("vehicle_air_data", 1000 * (i + 1), baro_alt_meter=float(i))
        print("written", flush=True)
        time.sleep(60)
    """)
    with subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.PIPE, text=True
    ) as proc:
        try:
            assert proc.stdout.readline().strip() == "written"
        finally:
            os.kill(proc.pid, signal.SIGKILL)
    data = ULog(str(path)).get_dataset("vehicle_air_data").data
    assert len(data["baro_alt_meter"]) == 200
    assert data["baro_alt_meter"][-1] == 199.0


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda log: log.write("nope", 1, x=1), "topic 'nope' was not declared"),
        (lambda log: log.write("vehicle_attitude", 1, q=[1, 0, 0, 0]), "field 'yawspeed' missing"),
        (
            lambda log: log.write("vehicle_attitude", 1, q=[1, 0], yawspeed=0),
            "needs 4 values, got 2",
        ),
        (
            lambda log: log.write("vehicle_attitude", 1, q=[1, 0, 0, 0], yawspeed=0, bad=1),
            "unknown fields ['bad']",
        ),
    ],
)
def test_bad_writes_name_the_problem(tmp_path, call, message):
    with ULogWriter(tmp_path / "x.ulg", TOPICS) as log, pytest.raises(ULogWriteError) as error:
        call(log)
    assert message in str(error.value)


def test_bad_declaration_names_topic_and_field(tmp_path):
    with pytest.raises(ULogWriteError, match="topic 't': field 'x' has unknown type 'float32'"):
        ULogWriter(tmp_path / "x.ulg", {"t": [("float32", "x")]})
