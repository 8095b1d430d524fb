"""The autopilot process's simulator side: HIL message decoding, and a simulator that sends
garbage between frames (what the real rig never does; everything else is flown through the
rig in ``test_end_to_end.py``)."""

import math
import select
import socket
import threading
import time

import numpy as np
import pytest

from rig.autopilots.reference import process
from rig.autopilots.reference.process import (
    SIM_SILENCE_NOTE_S,
    gps_fix,
    sensor_frame,
    wait_readable,
)
from rig.mavlink.px4_api import Ports, mavlink
from rig.mavlink.sim_messages import hil_gps, hil_sensor_frame
from tests.rig.autopilot.gcs_client import GcsClient
from tests.rig.autopilot.mini_rig import MiniRig

pytestmark = pytest.mark.closed_loop


def test_hil_messages_decode_to_si_units():
    mav = mavlink.MAVLink(None)
    sensor = hil_sensor_frame(mav, 1000, accel_mps2=(0.1, -0.2, -9.8),
                              gyro_radps=(0.01, 0.0, -0.02), mag_gauss=(0.2, 0.01, 0.43),
                              baro=(95000.0, 20.0))  # fmt: skip
    frame = sensor_frame(mav.decode(bytearray(sensor)), None)
    assert frame.accel_mps2 == pytest.approx([0.1, -0.2, -9.8], abs=0.005)  # int16 FIFO step
    assert frame.gyro_radps == pytest.approx([0.01, 0.0, -0.02], abs=1e-3)
    assert frame.mag_gauss == pytest.approx([0.2, 0.01, 0.43])
    assert frame.baro_pressure_pa == pytest.approx(95000.0)
    imu_only = hil_sensor_frame(mav, 2000, accel_mps2=(0, 0, -9.8), gyro_radps=(0, 0, 0))
    no_mag = sensor_frame(mav.decode(bytearray(imu_only)), None)
    assert no_mag.mag_gauss is None
    assert no_mag.baro_pressure_pa is None
    fix = gps_fix(hil_gps(mav, 1000, lat_deg=47.5, lon_deg=8.5, alt_amsl_m=500.25,
                          vel_ned_mps=(1.0, -2.0, 0.5), eph_m=0.8, epv_m=1.2, fix_type=3,
                          satellites_visible=10))  # fmt: skip
    assert (fix.lat_deg, fix.lon_deg, fix.alt_amsl_m) == pytest.approx((47.5, 8.5, 500.25))
    assert fix.velocity_ned_mps == pytest.approx((1.0, -2.0, 0.5))
    assert (fix.eph_m, fix.epv_m) == pytest.approx((0.8, 1.2))


def test_noise_on_the_simulator_link_leaves_it_flying(tmp_path, free_instance):
    """Bytes that cannot start a MAVLink frame, between sensor frames on the TCP link, while
    hovering at 3 m: it keeps answering every frame with the right time stamp, holds its
    height and stays armed. (Only non-frame bytes: on a stream a bogus header would swallow
    the next real frame, in PX4 alike; a datagram link has no such problem and is fuzzed with
    frames in ``test_end_to_end.py``.)"""
    instance = free_instance()
    mini = MiniRig(instance, seed=5, log_path=tmp_path / "autopilot.ulg")
    api = GcsClient(Ports(instance).api_local_udp, Ports(instance).system_id)
    try:
        mini.step(2.0)  # warm-up: gyro calibrated, GPS origin set
        api.heartbeat()
        nan = math.nan
        api.send(api.mav.param_set_encode(api.target_system, 1, b"MIS_TAKEOFF_ALT", 3.0,
                                          mavlink.MAV_PARAM_TYPE_REAL32))  # fmt: skip
        api.wait_for("PARAM_VALUE", lambda m: m.param_id == "MIS_TAKEOFF_ALT")
        assert api.command(mavlink.MAV_CMD_NAV_TAKEOFF, -1, 0, 0, nan, nan, nan, nan).result == 0
        assert api.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == 0
        mini.step(8.0)
        assert mini.altitude_m == pytest.approx(3.0, abs=0.5)
        rng = np.random.default_rng(99)
        for _ in range(200):
            noise = rng.bytes(int(rng.integers(1, 50)))
            mini.send_raw(noise.replace(b"\xfd", b"\x00").replace(b"\xfe", b"\x00"))
            mini.step(0.02)
        mini.step(1.0)
        assert mini.armed
        assert mini.altitude_m == pytest.approx(3.0, abs=0.5)
    finally:
        api.close()
        assert mini.close() == 0


def test_a_silent_simulator_is_named_once_and_waited_for(tmp_path, free_instance):
    """The rig stops sending frames (paused, or hung): the autopilot's clock stands still
    (lockstep), it says once which side went quiet and since when, and flies on when the
    frames come back."""
    stderr = tmp_path / "autopilot.err"
    mini = MiniRig(free_instance(), seed=6, log_path=tmp_path / "autopilot.ulg",
                   stderr_path=stderr)  # fmt: skip
    try:
        mini.step(1.0)
        time.sleep(SIM_SILENCE_NOTE_S + 1.5)
        mini.step(0.2)  # it answers the next frames as before
    finally:
        mini.close()
    notes = [line for line in stderr.read_text().splitlines() if "no sensor frame" in line]
    assert notes == [
        f"rig.autopilots.reference: the simulator sent no sensor frame for "
        f"{SIM_SILENCE_NOTE_S:g} s of wall time; the clock stands at t=1.000 s (lockstep), "
        "waiting"
    ]


def test_waiting_for_a_frame_polls_then_sleeps(monkeypatch):
    """With a poll window, a frame that comes within it is found by ``select`` calls that do
    not sleep; without one, or once the window has passed, ``select`` sleeps; nothing
    coming within the timeout gives an empty list."""
    timeouts: list[float] = []
    real_select = select.select

    def recording_select(r, w, x, timeout):
        timeouts.append(timeout)
        return real_select(r, w, x, timeout)

    monkeypatch.setattr(process.select, "select", recording_select)
    rig_end, autopilot_end = socket.socketpair()
    try:
        later = threading.Timer(0.02, rig_end.send, (b"frame",))
        later.start()
        # Windows far wider than the frame's 20 ms, so that a loaded machine cannot make
        # the frame miss them.
        assert wait_readable([autopilot_end], 5.0, 10.0) == [autopilot_end]
        later.join()
        assert len(timeouts) > 1
        assert set(timeouts) == {0}
        autopilot_end.recv(16)

        timeouts.clear()
        later = threading.Timer(0.02, rig_end.send, (b"frame",))
        later.start()
        assert wait_readable([autopilot_end], 0.0, 10.0) == [autopilot_end]
        later.join()
        assert timeouts == [10.0]
        autopilot_end.recv(16)

        timeouts.clear()
        # A window long enough that a stalled thread still polls at least once within it.
        assert wait_readable([autopilot_end], 0.2, 0.01) == []
        assert timeouts[-1] == 0.01
        assert set(timeouts[:-1]) == {0}
    finally:
        rig_end.close()
        autopilot_end.close()
