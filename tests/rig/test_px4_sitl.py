"""The real PX4 SITL through the rig: the rig starts the user's build (``$PX4_DIR``; CI
points it at the newest release it has, v1.17), reads its release, keeps lockstep at every
IMU rate (also on each older build in ``$PX4_OLDER_DIRS``; CI: v1.14), and owns PX4's
process. The longer flights are in ``test_px4_flights.py`` and ``test_px4_long_flight.py``.

Every test that needs PX4 skips, with the reason, where no build is given. Numbers come
from the rig's ground truth (``rig.ulg``) and PX4's own ULog (``px4.ulg``).
"""

import os
import shutil
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import pyulog

from rig.autopilots.px4 import (
    PX4_DIR_ENV,
    ParameterHook,
    Px4Sitl,
    airframe_parameters,
    cpus_of_pinned_px4,
    find_px4,
    sensor_parameters,
)
from rig.errors import RigError
from rig.lockstep.loop import RunOptions, run_scenario
from rig.mavlink.sim_messages import ACCEL_FIFO_SCALE_MPS2, GYRO_FIFO_SCALE_RADPS
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import scenario_from_dict
from tests.rig.px4_flights import fly_px4

pytestmark = pytest.mark.closed_loop


@pytest.mark.parametrize("imu_hz", [250, 400, 500, 1000])
def test_lockstep_holds_at_every_imu_rate(tmp_path, free_instance, any_px4, imu_hz):
    """20 s simulated at each IMU rate with zero stalls, on every release: from PX4's first
    answer on, every frame is answered by the HIL_ACTUATOR_CONTROLS stamped with its own
    time_usec, and PX4 ran with the lockstep parameters the rig gave it through the hook
    its release reads (px4-rc.params up to v1.15, px4-rc.simulator from v1.16)."""
    result = fly_px4(tmp_path, free_instance, any_px4.root, f"lockstep_{imu_hz}", 20.0,
                     rates={"imu_hz": imu_hz})  # fmt: skip
    link = result.link
    assert result.frames == 20 * imu_hz
    assert link.freewheel_frames < imu_hz  # PX4 boots within 1 s of simulated time
    assert link.answers == result.frames - link.freewheel_frames + 1
    assert link.malformed == 0
    assert (result.run_dir / "px4.log").is_file()
    px4_log = pyulog.ULog(str(result.autopilot_log))
    assert px4_log.initial_parameters["IMU_INTEG_RATE"] == imu_hz
    assert px4_log.initial_parameters["IMU_GYRO_RATEMAX"] == imu_hz
    assert result.autopilot == (
        f"{any_px4.description}, lockstep IMU_GYRO_RATEMAX = IMU_INTEG_RATE = {imu_hz} Hz"
    )  # the run's summary says so


def test_px4_logs_each_imu_sample_as_the_1_2_1_mean_of_the_rigs(tmp_path, free_instance, px4_dir):
    """What PX4 SITL logs as sensor_combined at lockstep: (x[k] + 2·x[k-1] + x[k-2])/4 of
    the samples the rig sent, not one trapezoid. The vibration fit (rig/identify/vibration.py)
    models the replay's stream so, at the X500 replay's 800 Hz."""
    result = fly_px4(tmp_path, free_instance, px4_dir, "imu_stream", 6.0, rates={"imu_hz": 800})
    sent = pyulog.ULog(str(result.rig_log), ["sensor_combined"]).get_dataset("sensor_combined")
    logged = pyulog.ULog(str(result.autopilot_log), ["sensor_combined"])
    logged = logged.get_dataset("sensor_combined").data
    at = np.searchsorted(sent.data["timestamp"], logged["timestamp"])
    assert np.array_equal(sent.data["timestamp"][at], logged["timestamp"])  # one per frame
    at = at[at >= 2]
    # PX4 holds each sample as int16 counts of its FIFO scale: one count may round apart.
    for field, count in (("gyro_rad", GYRO_FIFO_SCALE_RADPS),
                         ("accelerometer_m_s2", ACCEL_FIFO_SCALE_MPS2)):  # fmt: skip
        for axis in range(3):
            x = sent.data[f"{field}[{axis}]"].astype(float)
            y = logged[f"{field}[{axis}]"].astype(float)[-len(at) :]
            expected = [(x[at] + 2 * x[at - 1] + x[at - 2]) / 4, (x[at] + x[at - 1]) / 2]
            errors = [np.abs(y - e).max() for e in expected]
            assert errors[0] <= count * 1.001, (field, axis, errors)  # and float32
            assert errors[1] > 10 * errors[0], (field, axis, errors)  # the trapezoid is not it


def test_imu_rate_px4_cannot_follow_is_refused_before_the_run(tmp_path, monkeypatch):
    """Above IMU_INTEG_RATE's 1000 Hz PX4 cannot answer every frame: one line, the reason and
    the nearest rate that works, before any folder or process exists."""
    monkeypatch.delenv(PX4_DIR_ENV, raising=False)
    document = {"name": "fast", "vehicle": "f450_high_precision", "duration_s": 1.0, "seed": 1,
                "rates": {"imu_hz": 2000}}  # fmt: skip
    out = tmp_path / "never"
    with pytest.raises(RigError, match=r"imu_hz = 2000: .*IMU_INTEG_RATE.*nearest rate that works "
                                       r"is 1000 Hz"):  # fmt: skip
        run_scenario(scenario_from_dict(document),
                     RunOptions(autopilot="px4", out_dir=out))  # fmt: skip
    assert not out.exists()


def test_a_px4_dir_without_px4_fails_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv(PX4_DIR_ENV, str(tmp_path))
    with pytest.raises(RigError, match=r"^\$PX4_DIR = .*: no PX4 SITL build there"):
        find_px4()
    with pytest.raises(RigError, match=r"^--px4 = .*: no PX4 SITL build there"):
        find_px4(tmp_path / "missing")


#: What every PX4 binary holds besides its own tag: its versioning self-test's made-up ones.
_SELF_TEST_TAGS = b"\0v1.2.3\0v11.45.99-1.2.3rc3-7-g7e282f57\0v1.8.2beta4-dirty\0v255.255.255-11\0"


def _fake_build(root, binary=b"", rcs="", header=None) -> Path:
    (root / "bin").mkdir(parents=True)
    (root / "bin/px4").write_bytes(b"\x7fELF" + _SELF_TEST_TAGS + binary)
    (root / "bin/px4").chmod(0o755)
    (root / "etc/init.d-posix").mkdir(parents=True)
    (root / "etc/init.d-posix/rcS").write_text(rcs)
    if header is not None:
        (root / "src/lib/version").mkdir(parents=True)
        (root / "src/lib/version/build_git_version.h").write_text(header)
    return root


_RC_PARAMS = "#user defined params for instances can be in PATH\n. px4-rc.params\n"
_SIMULATOR = "if ! replay tryapplyparams\nthen\n\t. px4-rc.simulator\nfi\n"


@pytest.mark.parametrize(
    ("binary", "header", "rcs", "tag", "hook"),
    [
        (b"\0localhost\0v1.14.0-dirty\0master\0", None, _RC_PARAMS, "v1.14.0-dirty",
         ParameterHook.RC_PARAMS_FILE),
        (b"\0v1.15.4\0", None, _RC_PARAMS, "v1.15.4", ParameterHook.RC_PARAMS_FILE),
        (b"\0v1.17.0-alpha1\0", None, _SIMULATOR, "v1.17.0-alpha1", ParameterHook.SIMULATOR_SCRIPT),
        (b"", '#define PX4_GIT_TAG_STR  "v1.16.0-rc2-14-g0b6e4687"\n', _SIMULATOR,
         "v1.16.0-rc2-14-g0b6e4687", ParameterHook.SIMULATOR_SCRIPT),
        (b"\0custom\0", None, _SIMULATOR, "unknown", ParameterHook.SIMULATOR_SCRIPT),
    ],
)  # fmt: skip
def test_a_build_is_read_for_its_release_and_the_way_it_takes_parameters(
    tmp_path, binary, header, rcs, tag, hook
):
    """The release from the tag the binary carries (a checkout's build: its generated
    version header), never from PX4's self-test tags; the hook from the build's own rcS."""
    build = find_px4(_fake_build(tmp_path / "build/px4_sitl_default", binary, rcs, header)
                     .parent.parent)  # fmt: skip
    assert (build.tag, build.hook) == (tag, hook)
    assert build.description == f"PX4 {tag} ({build.root}; parameters through {hook.value})"


def test_a_px4_older_than_v1_14_or_without_a_parameter_hook_fails_in_one_line(tmp_path):
    old = _fake_build(tmp_path / "old", b"\0v1.13.3\0", _RC_PARAMS)
    with pytest.raises(RigError, match=r"^--px4 = .*/old: PX4 v1.13.3 is older than v1.14, the "
                                       r"oldest release the rig flies"):  # fmt: skip
        find_px4(old)
    odd = _fake_build(tmp_path / "odd", b"\0v1.15.0\0", "param set-default SDLOG_MODE 1\n")
    with pytest.raises(RigError, match=r"sources neither px4-rc.params nor px4-rc.simulator, "
                                       r"so the rig cannot give this PX4 \(v1.15.0\)"):  # fmt: skip
        find_px4(odd)


def test_the_parameters_are_written_for_either_hook_after_the_airframe(tmp_path):
    """Both scripts go first in PX4's PATH, so a PX4 started by hand, of any release, finds
    its own; the one for v1.16 on runs the build's own simulator script, then sets them."""
    sitl = Px4Sitl(None, tmp_path, 2, {"IMU_INTEG_RATE": 1000, "MPC_XY_VEL_MAX": 8.5})
    settings = ["param set IMU_INTEG_RATE 1000", "param set MPC_XY_VEL_MAX 8.5"]
    assert (sitl.bin_dir / "px4-rc.params").read_text().splitlines()[2:] == settings
    assert (sitl.bin_dir / "px4-rc.simulator").read_text().splitlines()[2:] == [
        ". ${R}etc/init.d-posix/px4-rc.simulator", *settings]  # fmt: skip
    assert sitl.command().startswith(f"PATH={sitl.bin_dir.resolve()}:$PATH "
                                     "PX4_SYS_AUTOSTART=10016 ")  # fmt: skip


def test_no_px4_given_means_the_user_starts_it(monkeypatch):
    monkeypatch.delenv(PX4_DIR_ENV, raising=False)
    assert find_px4() is None


def test_a_run_folder_used_again_gives_px4_a_clean_work_dir(tmp_path):
    """PX4 reads back its parameters.bson and dataman (missions, the current item) at boot:
    a run over an old run's folder (--force) must not inherit them."""
    stale = tmp_path / "px4"
    (stale / "log" / "2026-11-27").mkdir(parents=True)
    for name in ("dataman", "parameters.bson", "parameters_backup.bson", "log/2026-11-27/a.ulg"):
        (stale / name).write_bytes(b"last run")
    sitl = Px4Sitl(None, tmp_path, 3, {"MPC_XY_VEL_MAX": 8.5})
    assert sorted(p.relative_to(stale).as_posix() for p in stale.rglob("*")) == [
        "bin",
        "bin/px4-rc.params",
        "bin/px4-rc.simulator",
    ]
    assert "param set MPC_XY_VEL_MAX 8.5" in (sitl.bin_dir / "px4-rc.params").read_text()


def test_airframe_parameters_follow_the_vehicle_file():
    """Rotor geometry in PX4's motor order with KM + for the CCW rotors, as PX4's airframe
    files set CA_ROTORi_*; the hover thrust is the model's hover throttle."""
    from quad_model import load_vehicle

    vehicle = load_vehicle("f450_high_precision")
    params = airframe_parameters(vehicle, 0.6094)
    propulsion = vehicle.propulsion
    ratio = propulsion.torque_coefficient_nm_per_radps2 / propulsion.thrust_coefficient_n_per_radps2
    assert params["CA_ROTOR_COUNT"] == 4
    for i, (x, y, _) in enumerate(propulsion.position_frd_m):
        assert (params[f"CA_ROTOR{i}_PX"], params[f"CA_ROTOR{i}_PY"]) == (x, y)
    assert [params[f"CA_ROTOR{i}_KM"] for i in range(4)] == pytest.approx(
        [ratio, ratio, -ratio, -ratio]
    )
    assert params["MPC_THR_HOVER"] == 0.609
    assert params["BAT1_N_CELLS"] == 3
    assert params["MAV_TYPE"] == 2  # MAV_TYPE_QUADROTOR


def test_sensor_parameters_say_what_the_vehicle_flies_with():
    """A GPS receiver and no camera are PX4's defaults (nothing set); without GPS none is
    expected or fused and the height is the barometer's; a camera is fused from its mount."""
    from quad_model import load_vehicle

    vehicle = load_vehicle("f450_high_precision")
    assert sensor_parameters(vehicle, gps=True, optical_flow=False) == {}
    assert sensor_parameters(vehicle, gps=False, optical_flow=True) == {
        "SYS_HAS_GPS": 0, "EKF2_GPS_CTRL": 0, "EKF2_HGT_REF": 0, "EKF2_OF_CTRL": 1,
        "SENS_FLOW_ROT": 0, "EKF2_OF_POS_X": 0.03, "EKF2_OF_POS_Y": 0.0, "EKF2_OF_POS_Z": -0.10,
    }  # fmt: skip


def test_a_hexa_or_an_x8_gets_every_motor_on_its_own_output(tmp_path):
    """CA_ROTORi_PX/PY/PZ/KM for every rotor (an X8's lower rotor below its upper, the same
    arm, the other spin) and motor i on output i: PX4 SITL's airframe 10016 maps only
    outputs 1..4 (PWM_MAIN_FUNC1..4 = Motor 1..4); motors 5..8 need 105..108."""
    from quad_model import load_vehicle
    from tests.rig.vehicles import hexa_x, x8

    hexa = airframe_parameters(load_vehicle(hexa_x(tmp_path)), 0.45)
    assert hexa["CA_ROTOR_COUNT"] == 6
    assert hexa["MAV_TYPE"] == 13  # MAV_TYPE_HEXAROTOR
    assert [hexa[f"PWM_MAIN_FUNC{n}"] for n in range(1, 7)] == [101, 102, 103, 104, 105, 106]
    assert "PWM_MAIN_FUNC7" not in hexa
    octo = airframe_parameters(load_vehicle(x8(tmp_path)), 0.4)
    assert octo["MAV_TYPE"] == 14  # MAV_TYPE_OCTOROTOR
    assert [octo[f"PWM_MAIN_FUNC{n}"] for n in range(1, 9)] == list(range(101, 109))
    for upper, lower in ((0, 5), (1, 4), (2, 7), (3, 6)):  # PX4's 12001 octo coaxial pairs
        assert (octo[f"CA_ROTOR{upper}_PX"], octo[f"CA_ROTOR{upper}_PY"]) == (
            octo[f"CA_ROTOR{lower}_PX"], octo[f"CA_ROTOR{lower}_PY"])  # fmt: skip
        assert octo[f"CA_ROTOR{upper}_PZ"] < octo[f"CA_ROTOR{lower}_PZ"]
        assert octo[f"CA_ROTOR{upper}_KM"] == -octo[f"CA_ROTOR{lower}_KM"] != 0.0


def test_ports_leave_mavsdk_and_the_ground_station_free(tmp_path, free_instance, px4_dir):
    """While the rig flies PX4, a user's MAVSDK can bind UDP 14540+i (the rig never does)."""
    import socket

    instance = free_instance()
    user = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    user.bind(("127.0.0.1", 14540 + instance))
    try:
        document = {"name": "ports", "vehicle": "f450_high_precision", "duration_s": 3.0, "seed": 1,
                    "rates": {"imu_hz": 250}, "commands": []}  # fmt: skip
        options = RunOptions(autopilot="px4", px4_dir=px4_dir, instance=instance,
                             out_dir=tmp_path / "ports")  # fmt: skip
        result = run_scenario(scenario_from_dict(document), options)
    finally:
        user.close()
    assert result.frames == 750


def _start_rig_cli(px4_dir, instance, out):
    return subprocess.Popen(
        [sys.executable, "-m", "rig", "run", "takeoff_hover_land", "--autopilot", "px4",
         "--px4", str(px4_dir), "--instance", str(instance), "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def _px4_pids(out):
    """PIDs of the PX4 processes running in ``out``'s work dir (from /proc)."""
    work_dir = str((out / "px4").resolve()).encode()
    pids = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and work_dir in (entry / "cmdline").read_bytes():
                pids.append(int(entry.name))
        except OSError:
            continue
    return pids


def _wait_until_flying(rig, out):
    deadline = time.monotonic() + 120
    while not ((out / "rig.ulg").is_file() and (out / "rig.ulg").stat().st_size > 300_000):
        if time.monotonic() > deadline or rig.poll() is not None:
            rig.kill()
            pytest.fail(f"the run never got under way: {rig.communicate()[1]}")
        time.sleep(0.2)


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one CPU: PX4 is not pinned")
def test_every_px4_thread_runs_on_the_one_cpu_the_rig_chose(tmp_path, free_instance, px4_dir):
    """PX4's lockstep chain of threads on one core, not spread over the rig's (bench_px4),
    once its start-up script has ended."""
    out = tmp_path / "run"
    rig = _start_rig_cli(px4_dir, free_instance(), out)
    try:
        _wait_until_flying(rig, out)
        (pid,) = _px4_pids(out)
        allowed = {
            task.name: next(line.split()[1] for line in (task / "status").read_text().splitlines()
                            if line.startswith("Cpus_allowed_list:"))
            for task in Path(f"/proc/{pid}/task").iterdir()
        }  # fmt: skip
    finally:
        rig.send_signal(signal.SIGINT)
        rig.communicate(timeout=60)
    assert len(allowed) > 10  # PX4's modules and work queues, not just its main thread
    (cpu,) = set(allowed.values())
    assert int(cpu) in os.sched_getaffinity(0)
    messages = [m.message for m in pyulog.ULog(str(out / "rig.ulg")).logged_messages]
    assert f"PX4's start-up script has ended: PX4 held to CPU {cpu}" in messages


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one CPU: PX4 is not pinned")
def test_two_px4_side_by_side_run_on_different_cpus(tmp_path, free_instance, px4_dir):
    """A second PX4 (a campaign's, a parallel test's) goes beside the first, not onto it:
    onto a CPU with the fewest PX4s held to it, the first counted (and any other test's
    running meanwhile). Both boot and wait for their simulator, which never comes: their
    start-up scripts wait for it."""
    first = Px4Sitl(find_px4(px4_dir), tmp_path / "a", free_instance(), {})
    try:
        first.start()
        first.hold_to_one_cpu()
        second = Px4Sitl(find_px4(px4_dir), tmp_path / "b", first.instance + 1, {})
        try:
            taken = Counter(cpus_of_pinned_px4())
            second.start()
            second.hold_to_one_cpu()
            deadline = time.monotonic() + 30
            while not (first.starting() and second.starting()):  # until each runs its rcS
                assert time.monotonic() < deadline, "a PX4 ran no start-up script"
                time.sleep(0.05)
            cpus = os.sched_getaffinity(0)
            assert {first.cpu, second.cpu} <= cpus
            assert taken[first.cpu] >= 1
            assert taken[second.cpu] == min(taken[cpu] for cpu in cpus)
        finally:
            second.stop()
    finally:
        first.stop()


def test_sigterm_stops_px4_and_keeps_both_logs(tmp_path, free_instance, px4_dir):
    out = tmp_path / "run"
    rig = _start_rig_cli(px4_dir, free_instance(), out)
    _wait_until_flying(rig, out)
    assert _px4_pids(out)
    rig.send_signal(signal.SIGTERM)
    _, err = rig.communicate(timeout=60)
    assert rig.returncode == 143
    assert "rig: terminated (SIGTERM); the logs written so far are readable" in err
    assert "Traceback" not in err
    assert not _px4_pids(out)  # PX4 was stopped, not left spinning
    assert len(pyulog.ULog(str(out / "rig.ulg")).get_dataset("sensor_combined").data) > 0
    px4_log = pyulog.ULog(str(out / "px4.ulg"))  # PX4's own log, kept beside rig.ulg
    assert px4_log.initial_parameters["SYS_AUTOSTART"] == 10016


def test_px4_dying_mid_run_is_one_line_naming_its_console(tmp_path, free_instance, px4_dir):
    out = tmp_path / "run"
    rig = _start_rig_cli(px4_dir, free_instance(), out)
    _wait_until_flying(rig, out)
    for pid in _px4_pids(out):
        os.kill(pid, signal.SIGKILL)
    _, err = rig.communicate(timeout=60)
    assert rig.returncode == 1
    last = err.strip().splitlines()[-1]
    assert last.startswith("rig: error: ")
    assert "PX4 killed by SIGKILL" in last
    assert f"its console is in {out / 'px4.log'}" in last
    assert "Traceback" not in err
    pyulog.ULog(str(out / "rig.ulg"))  # readable up to that moment


def test_px4_does_not_outlive_a_killed_rig(tmp_path, free_instance, px4_dir):
    """PX4 spins forever once its simulator is gone; a rig killed outright (SIGKILL, no
    clean-up) still takes it down (the kernel's parent-death signal)."""
    out = tmp_path / "run"
    rig = _start_rig_cli(px4_dir, free_instance(), out)
    _wait_until_flying(rig, out)
    assert _px4_pids(out)
    rig.kill()
    rig.communicate(timeout=30)
    deadline = time.monotonic() + 10
    while _px4_pids(out) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _px4_pids(out)


@pytest.mark.parametrize("text", ["MPC_XY_P", "=1", "MPC_XY_P=fast", "MPC_XY_P=nan"])
def test_a_bad_param_for_px4_is_one_line(text):
    from rig.autopilots.px4 import parse_assignments

    with pytest.raises(RigError, match=r"^--param .*: expected NAME=VALUE with a finite number$"):
        parse_assignments((text,))
    assert parse_assignments(("MPC_XY_P=1.5", "SDLOG_MODE=0")) == {"MPC_XY_P": 1.5, "SDLOG_MODE": 0}


def _stalling_px4(root: Path, px4_dir: Path, stalls: int) -> Path:
    """A build whose ``bin/px4`` is the test double (tests/rig/autopilot_double.py), with
    ``px4_dir``'s parameters: on its first ``stalls`` starts it connects and never
    answers, as PX4 does when its start-up script hangs, then it answers like PX4."""
    build = _fake_build(root, rcs=_SIMULATOR)
    (build / "etc/extras").mkdir()
    shutil.copy(px4_dir / "etc/extras/parameters.json.xz", build / "etc/extras")
    double = Path(__file__).with_name("autopilot_double.py")
    (build / "bin/px4").write_text(
        "#!/bin/sh\n# TEST DOUBLE standing in for PX4 v1.17.0 (its tag, for find_px4)\n"
        f'starts={build}/bin/px4.starts; started=$(cat "$starts" 2>/dev/null || echo 0)\n'
        'echo $((started + 1)) > "$starts"\n'
        f'behaviour=px4; [ "$started" -lt {stalls} ] && behaviour=hang\n'
        f"exec {sys.executable} {double} --port $((4560 + $3)) --behaviour $behaviour\n"
    )
    return build


_START_UP = {"name": "t", "vehicle": "f450_high_precision", "duration_s": 0.5, "seed": 1,
             "sensor_layer": "tlm"}  # fmt: skip


def test_a_px4_that_stalls_in_its_start_up_is_started_again(tmp_path, free_instance, px4_dir):
    """PX4's lockstep start-up races now and then (a module's start waits for simulated
    time, which waits for it): before the scenario has sent it anything, the rig starts
    it again, says so, and keeps the stalled start's console."""
    build = _stalling_px4(tmp_path / "px4", px4_dir, stalls=1)
    options = RunOptions(autopilot="px4", px4_dir=build, instance=free_instance(),
                         out_dir=tmp_path / "run",
                         timeouts=LinkTimeouts(connect_s=30, first_answer_sim_s=0.3))  # fmt: skip
    result = run_scenario(scenario_from_dict(_START_UP), options)
    assert result.autopilot_starts == 2
    assert result.frames == 500
    assert (tmp_path / "run/px4.start-1.log").is_file()
    assert (tmp_path / "run/px4.log").is_file()
    messages = [m.message for m in pyulog.ULog(str(result.rig_log)).logged_messages]
    (note,) = [text for text in messages if "stalled in its start-up" in text]
    assert "started again (its console then: px4.start-1.log)" in note
    assert "sent no HIL_ACTUATOR_CONTROLS in 0.3 s of simulated time" in note


def test_a_px4_that_never_gets_through_its_start_up_fails_after_three_starts(
    tmp_path, free_instance, px4_dir
):
    build = _stalling_px4(tmp_path / "px4", px4_dir, stalls=99)
    options = RunOptions(autopilot="px4", px4_dir=build, instance=free_instance(),
                         out_dir=tmp_path / "run",
                         timeouts=LinkTimeouts(connect_s=30, first_answer_sim_s=0.3))  # fmt: skip
    with pytest.raises(RigError, match=r"sent no HIL_ACTUATOR_CONTROLS in 0\.3 s.*\(start 3: "):
        run_scenario(scenario_from_dict(_START_UP), options)
    assert (build / "bin/px4.starts").read_text().strip() == "3"
    kept = sorted(path.name for path in (tmp_path / "run").glob("px4*.log"))
    assert kept == ["px4.log", "px4.start-1.log", "px4.start-2.log"]
