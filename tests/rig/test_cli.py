"""The ``rig`` command: one-line errors, and Ctrl-C leaving readable logs."""

import resource
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import pytest
import pyulog

from rig.campaign.results import CaseResult
from rig.cli import main
from rig.mavlink.px4_api import free_instance as find_free_instance
from tests.instances import worker_instances
from tests.sigint import sigint_in_children


def test_missing_scenario_is_one_line_on_stderr(capsys, tmp_path):
    assert main(["run", str(tmp_path / "nope.toml")]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"rig: error: {tmp_path / 'nope.toml'}: no such scenario file")
    assert "Traceback" not in err


def test_bad_scenario_value_names_file_key_and_value(capsys, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('name = "bad"\nvehicle = "f450_high_precision"\nduration_s = 5\nseed = -1\n')
    assert main(["run", str(path)]) == 1
    err = capsys.readouterr().err
    assert err == f"rig: error: {path}: key 'seed' = -1: expected a value >= 0\n"


def test_unknown_vehicle_is_a_scenario_error(capsys, tmp_path):
    path = tmp_path / "v.toml"
    path.write_text('name = "v"\nvehicle = "zeppelin"\nduration_s = 5\nseed = 1\n')
    assert main(["run", str(path), "--out", str(tmp_path / "run")]) == 1
    last = capsys.readouterr().err.splitlines()[-1]  # after the run's banner
    assert last.startswith(f"rig: error: {path}: key 'vehicle':")
    assert "zeppelin.toml: no such vehicle file" in last


@pytest.mark.closed_loop
def test_ctrl_c_stops_cleanly_with_readable_logs(tmp_path, free_instance):
    out = tmp_path / "run"
    with sigint_in_children(ignored=False):  # also when pytest runs in the background
        process = subprocess.Popen(
            [sys.executable, "-m", "rig", "run", "takeoff_hover_land", "--instance",
             str(free_instance()), "--out", str(out)],
            stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
    deadline = time.monotonic() + 180  # generous: a loaded CI machine compiles numba first
    while not ((out / "rig.ulg").is_file() and (out / "rig.ulg").stat().st_size > 200_000):
        if time.monotonic() > deadline or process.poll() is not None:
            process.kill()
            pytest.fail(f"the flight never got under way: {process.communicate()[1]}")
        time.sleep(0.2)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130
    assert "rig: interrupted; the logs written so far are readable" in err
    assert "Traceback" not in err
    rig_log = pyulog.ULog(str(out / "rig.ulg"))
    assert rig_log.logged_messages[-1].message == "run interrupted by the user (Ctrl-C)"
    assert len(rig_log.get_dataset("sensor_combined").data["timestamp"]) > 500  # ≥ 0.5 s flown
    autopilot_log = pyulog.ULog(str(out / "autopilot.ulg"))  # closed on SIGINT, readable
    assert len(autopilot_log.get_dataset("vehicle_attitude").data["timestamp"]) > 10


@pytest.mark.closed_loop
def test_two_rigs_fly_side_by_side_with_mavsdks_port_free(tmp_path, free_instance):
    """``--instance i`` and ``--instance j`` fly at once on one machine, each with its own
    autopilot; neither rig binds 14540+i, where a user's MAVSDK listens."""
    import socket

    first = free_instance()
    second = find_free_instance(first + 1, worker_instances(60, 40).stop - first - 1)
    mavsdk = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2)]
    for sock, instance in zip(mavsdk, (first, second), strict=True):
        sock.bind(("127.0.0.1", 14540 + instance))
    try:
        rigs = [
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "rig",
                    "run",
                    "takeoff_hover_land",
                    "--duration",
                    "6",
                    "--instance",
                    str(instance),
                    "--out",
                    str(tmp_path / f"i{instance}"),
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
            )
            for instance in (first, second)
        ]
        errors = [rig.communicate(timeout=300)[1] for rig in rigs]
    finally:
        for sock in mavsdk:
            sock.close()
    assert [rig.returncode for rig in rigs] == [0, 0], errors
    for instance in (first, second):
        log = pyulog.ULog(str(tmp_path / f"i{instance}" / "rig.ulg"))
        truth = log.get_dataset("vehicle_local_position_groundtruth").data
        assert truth["z"].min() < -1.0  # each took off


def test_a_folder_holding_a_run_is_refused_without_force(capsys, tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "rig.ulg").write_bytes(b"a finished run")
    assert main(["run", "level_step", "--out", str(out), "--connect-timeout", "1"]) == 1
    last = capsys.readouterr().err.splitlines()[-1]
    assert last == (f"rig: error: {out}: already holds a run (rig.ulg); choose another --out, "
                    "or pass --force to overwrite it")  # fmt: skip
    assert (out / "rig.ulg").read_bytes() == b"a finished run"  # untouched


def test_campaign_announces_its_name_and_runs_to_the_report(capsys, tmp_path, monkeypatch):
    """``rig campaign FILE`` names the campaign from its file, runs every case and writes
    the report; the cases are stood in for (no flights), the rest is the real command."""
    path = tmp_path / "c.toml"
    path.write_text('name = "two_seeds"\ndescription = "Hover, twice."\n'
                    'scenario = "takeoff_hover_land"\n[axes]\nseed = [1, 2]\n')  # fmt: skip

    def run_case(spec):
        return CaseResult(
            case_id=spec.case_id, index=spec.index, labels=spec.labels, status="ok", reason="",
            metrics={}, wall_s=0.0, run_dir=spec.run_dir, rig_log=None, autopilot_log=None,
        )  # fmt: skip

    monkeypatch.setattr("rig.campaign.executor.run_case", run_case)
    monkeypatch.setattr(
        "rig.cli.campaign.campaign_executor", lambda *_: ThreadPoolExecutor(max_workers=1)
    )
    monkeypatch.setattr("rig.cli.campaign.RUNS_DIR", tmp_path)
    out = tmp_path / "campaign-two_seeds"  # the default folder, named after the campaign
    assert main(["campaign", str(path)]) == 0
    err = capsys.readouterr().err
    assert err.splitlines()[0] == "two_seeds: Hover, twice.", err
    assert err.count(" ok ") == 2
    assert (out / "report.html").is_file()


@pytest.mark.closed_loop
def test_a_full_disk_ends_the_run_in_one_line_with_whole_logs(tmp_path, free_instance):
    """The disk fills mid-flight (a 3 MB file-size limit on the rig and its autopilot): the
    run stops with one line, and each log ends on its last whole message."""
    out = tmp_path / "run"
    rig = subprocess.Popen(
        [sys.executable, "-m", "rig", "run", "takeoff_hover_land", "--instance",
         str(free_instance()), "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    # set from here, as the rig's logs have not grown yet: its children inherit the limit,
    # and Python ignores SIGXFSZ, so a write fails (EFBIG) where a full disk's gives ENOSPC
    resource.prlimit(rig.pid, resource.RLIMIT_FSIZE, (3 << 20, 3 << 20))
    _, stderr = rig.communicate(timeout=600)
    assert rig.returncode == 1, stderr
    assert "Traceback" not in stderr
    last = stderr.splitlines()[-1]
    assert last.startswith("rig: error: "), stderr
    assert "File too large" in stderr  # the rig's or the autopilot's own line
    for name in ("rig.ulg", "autopilot.ulg"):
        log = pyulog.ULog(str(out / name))
        assert not log.file_corruption, name
        assert log.data_list, name


@pytest.mark.closed_loop
def test_a_rig_started_in_the_background_still_stops_its_autopilot_cleanly(tmp_path, free_instance):
    """A shell ignores SIGINT in what it starts in the background (``nohup rig run … &``,
    CI); the autopilot inherited that, ignored the rig's SIGINT at the end of the run and
    was killed before it wrote its last buffer (a 1-hour soak lost its last 2 s)."""
    out = tmp_path / "run"
    with sigint_in_children(ignored=True):
        rig = subprocess.Popen(
            [sys.executable, "-m", "rig", "run", "takeoff_hover_land", "--duration", "3",
             "--instance", str(free_instance()), "--out", str(out)],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
    _, stderr = rig.communicate(timeout=300)
    assert rig.returncode == 0, stderr
    rig_log = pyulog.ULog(str(out / "rig.ulg"), [])
    assert rig_log.logged_messages[-1].message == "run completed: 3000 frames"
    status = pyulog.ULog(str(out / "autopilot.ulg"), ["vehicle_status"])
    assert status.get_dataset("vehicle_status").data["timestamp"][-1] >= 2.9e6
