"""The live view (``rig run --view``) and the playback (``rig view RUN``), in a real headless
Chromium driven by Playwright: the page must show the rig's own numbers, not just load.

Chromium is Debian's ``chromium`` package (.ci/run installs it; Playwright's browser
download is not used); without /usr/bin/chromium the browser tests skip. The live test
keeps a screenshot; ``RIG_UPDATE_SCREENSHOT=1`` writes it to docs/live_view.png.
"""

from __future__ import annotations

import json
import math
import os
import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import pyulog
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from rig.cli import main
from rig.lockstep.loop import Progress, RunOptions, RunResult, run_scenario
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import scenario_from_dict
from rig.view import ViewServer, load_recording, mode_name
from tests.instances import free_test_instance

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]  # fmt: skip
SCREENSHOT = Path(__file__).parents[2] / "docs" / "live_view.png"
needs_chromium = pytest.mark.skipif(
    not CHROMIUM.exists(), reason="no /usr/bin/chromium (Debian's chromium; .ci/run installs it)"
)
#: Take off to 3 m, fly 2 m north and 1 m east, with a gyro noise burst from 2 s on.
SCENARIO = {
    "name": "view", "vehicle": "f450_high_precision", "duration_s": 12.0, "seed": 3,
    "sensor_layer": "tlm", "rates": {"imu_hz": 250},
    "commands": [{"at_s": 0.5, "action": "arm"},
                 {"at_s": 1.0, "action": "takeoff", "altitude_m": 3.0},
                 {"at_s": 6.0, "action": "goto", "position_ned_m": [2.0, 1.0, -3.0]}],
    "faults": [{"kind": "noise_burst", "sensor": "gyro", "std": 0.02, "start_s": 2.0}],
}  # fmt: skip
#: Slow enough that the page sees the climb, fast enough for a short test.
SPEED = 2.0
PAGE_TIMEOUT_S = 90.0
#: Every number the page shows, read at one instant (the page is single-threaded).
READ_PAGE = """() => {
  const value = (id) => document.getElementById(id).dataset.value;
  return {t: Number(value("t")), alt: Number(value("alt")), altMax: Number(value("alt-max")),
          armed: value("armed"), mode: value("mode"), rtf: value("rtf"),
          motors: [0, 1, 2, 3].map((i) => Number(value(`motor-${i}`))),
          faults: JSON.parse(value("faults") || "[]"),
          state: document.getElementById("conn").dataset.state};
}"""


def _fly(instance: int, out_dir: Path, progress=None, speed: float = SPEED) -> RunResult:
    options = RunOptions(instance=instance, out_dir=out_dir, speed=speed,
                         timeouts=LinkTimeouts(connect_s=60, answer_s=30))  # fmt: skip
    return run_scenario(scenario_from_dict(SCENARIO), options, progress)


@pytest.fixture(scope="module")
def browser():
    if not CHROMIUM.exists():
        pytest.skip("no /usr/bin/chromium (Debian's chromium; .ci/run installs it)")
    from playwright.sync_api import sync_playwright  # the dev extra; only with a browser

    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield chromium
        chromium.close()


@dataclass
class LiveFlight:
    shown: dict  # the page's numbers once it showed the vehicle armed and airborne
    last_shown: dict  # ... after the run ended
    reports: dict[float, Progress]  # every report of the loop, by its time
    result: RunResult
    screenshot: Path
    instance: int  # its ports are in rig.ulg's events


@pytest.fixture(scope="module")
def live_flight(browser, tmp_path_factory) -> LiveFlight:
    """Open the page, then fly with the view on; read the page while it flies."""
    folder = tmp_path_factory.mktemp("view")
    reports: dict[float, Progress] = {}
    outcome: dict[str, object] = {}
    instance = free_test_instance()
    with ViewServer(0, name="view test") as server:
        page = browser.new_page(viewport={"width": 1280, "height": 760})
        page.goto(server.url)
        page.wait_for_function("document.getElementById('conn').dataset.state === 'live'")

        def report(progress: Progress) -> None:
            reports[round(progress.time_s, 3)] = progress
            server.publish(progress)

        def fly() -> None:
            try:
                outcome["result"] = _fly(instance, folder / "run", report)
            except BaseException as error:  # reported by the test, not lost in the thread
                outcome["error"] = error

        thread = threading.Thread(target=fly, daemon=True)
        thread.start()

        def wait_for(condition: str) -> None:
            """Until the page shows ``condition``; a failed run fails at once, with its error."""
            deadline = time.monotonic() + PAGE_TIMEOUT_S
            while not page.evaluate(f"() => {condition}"):
                assert "error" not in outcome, outcome["error"]
                assert time.monotonic() < deadline, f"the page never showed {condition}"
                page.wait_for_timeout(100)

        wait_for("document.getElementById('armed').dataset.value === 'true'"
                 " && Number(document.getElementById('alt').dataset.value) > 2.0")  # fmt: skip
        shown = page.evaluate(READ_PAGE)
        # the screenshot during the step north-east, with the fault acting
        wait_for("Number(document.getElementById('t').dataset.value) > 8.5")
        screenshot = folder / "live_view.png"
        page.screenshot(path=str(screenshot))
        if os.environ.get("RIG_UPDATE_SCREENSHOT"):
            SCREENSHOT.parent.mkdir(exist_ok=True)
            page.screenshot(path=str(SCREENSHOT))
        thread.join(120)
        assert "error" not in outcome, outcome["error"]
    page.wait_for_function("document.getElementById('conn').dataset.state === 'ended'")
    last_shown = page.evaluate(READ_PAGE)
    page.close()
    return LiveFlight(shown, last_shown, reports, outcome["result"], screenshot, instance)


@needs_chromium
@pytest.mark.closed_loop
def test_live_page_shows_the_rigs_state(live_flight):
    shown = live_flight.shown
    rig = live_flight.reports[shown["t"]]  # what the loop reported at the instant shown
    assert shown["armed"] == "true"
    assert rig.armed
    assert shown["alt"] == pytest.approx(rig.altitude_m, abs=1e-3)
    assert shown["alt"] > 2.0
    assert shown["motors"] == pytest.approx(rig.motor_throttles, abs=1e-3)
    assert min(shown["motors"]) > 0.3  # hovering motors, not idle ones
    assert shown["mode"] == mode_name(rig.custom_mode)
    assert shown["mode"] in ("Takeoff", "Hold")  # PX4's names for the reference's modes
    assert shown["faults"] == list(rig.active_faults) == ["noise_burst (sensor=gyro, std=0.02)"]
    assert float(shown["rtf"]) > 0
    assert live_flight.screenshot.read_bytes().startswith(b"\x89PNG")


@needs_chromium
@pytest.mark.closed_loop
def test_live_page_gets_the_last_frame_and_says_the_run_ended(live_flight):
    last = live_flight.last_shown
    assert last["state"] == "ended"
    assert last["t"] == max(live_flight.reports)  # the final report, pushed at the close
    final = live_flight.reports[last["t"]]
    assert last["alt"] == pytest.approx(final.altitude_m, abs=1e-3)
    assert last["altMax"] == pytest.approx(
        max(p.altitude_m for p in live_flight.reports.values()), abs=0.05
    )  # the page saw the pushed frames only, at most 25 a second


@needs_chromium
@pytest.mark.closed_loop
def test_the_view_leaves_the_log_unchanged(live_flight, tmp_path):
    """Same seed and instance (the log names its ports), same rig.ulg bytes, with or without
    the view (and at any speed)."""
    plain = _fly(live_flight.instance, tmp_path / "plain", speed=math.inf)
    assert plain.rig_log.read_bytes() == live_flight.result.rig_log.read_bytes()


@needs_chromium
@pytest.mark.closed_loop
def test_playback_shows_the_finished_run(browser, live_flight):
    run_dir = live_flight.result.run_dir
    truth = pyulog.ULog(str(run_dir / "rig.ulg")).get_dataset(
        "vehicle_local_position_groundtruth"
    ).data  # fmt: skip
    start_us = 2 * int(truth["timestamp"][0]) - int(truth["timestamp"][1])
    with ViewServer(0, recording=load_recording(run_dir)) as server:
        page = browser.new_page()
        page.goto(server.url)
        page.wait_for_function("document.getElementById('conn').dataset.state === 'playback'")
        shown = page.evaluate(READ_PAGE)
        assert shown["altMax"] == pytest.approx(-truth["z"].min(), abs=0.02)
        # the slider, as a user drags it, to 5 s: the log's altitude at that instant
        page.evaluate("""() => { const seek = document.getElementById('seek');
                                 seek.value = '5'; seek.dispatchEvent(new Event('input')); }""")
        shown = page.evaluate(READ_PAGE)
        assert shown["t"] == 5.0
        index = np.searchsorted(truth["timestamp"], start_us + 5_000_000, side="right") - 1
        assert shown["alt"] == pytest.approx(-truth["z"][index], abs=1e-3)
        assert (shown["armed"], shown["mode"]) == ("true", "Hold")  # from autopilot.ulg
        assert shown["faults"] == ["noise_burst (sensor=gyro, std=0.02)"]
        page.click("#play")
        page.wait_for_function("Number(document.getElementById('t').dataset.value) > 5.5")
        page.close()


def _report(time_s: float) -> Progress:
    return Progress(
        time_s=time_s, duration_s=10.0, real_time_factor=math.inf, altitude_m=1.0, armed=True,
        last_event="", attitude_quat=(1.0, 0.0, 0.0, 0.0), position_ned_m=(0.0, 0.0, -1.0),
        velocity_ned_mps=(0.0, 0.0, 0.0), accel_mps2=(0.0, 0.0, -9.8),
        gyro_radps=(0.0, 0.0, 0.0), motor_throttles=(0.5,) * 4,
        custom_mode=None, active_faults=(),
    )  # fmt: skip


def test_publish_never_waits_for_a_page():
    """A page that never reads cannot slow the loop, nor starve a page that does read."""
    with ViewServer(0) as server:
        stalled = socket.create_connection(("127.0.0.1", server.port))
        stalled.sendall(
            f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\nUpgrade: websocket\r\n"
            "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n".encode()
        )  # and never reads a byte
        with connect(f"ws://127.0.0.1:{server.port}/ws") as page:
            hello = json.loads(page.recv(timeout=5))
            assert (hello["type"], hello["frames"]) == ("live", [])
            reports = [_report(n / 10) for n in range(20_000)]
            started = time.perf_counter()
            for report in reports:
                server.publish(report)
            per_call_s = (time.perf_counter() - started) / len(reports)
            assert per_call_s < 20e-6  # a slot store, whoever is connected
            newest = json.loads(page.recv(timeout=5))["frame"]
            while newest["t"] != reports[-1].time_s:  # skips what it had no time for
                newest = json.loads(page.recv(timeout=5))["frame"]
        stalled.close()


def test_served_on_loopback_only_and_to_its_own_pages():
    with ViewServer(0) as server:
        assert server.url == f"http://127.0.0.1:{server.port}/"
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect(("10.255.255.255", 9))  # no packet leaves: finds the LAN address
            address = probe.getsockname()[0]
        if not address.startswith("127."):
            with pytest.raises(ConnectionRefusedError):
                socket.create_connection((address, server.port), timeout=2).close()
        # another site's page in the same browser cannot read the flight
        with pytest.raises(InvalidStatus), connect(f"ws://127.0.0.1:{server.port}/ws",
                                                   origin="http://example.com"):  # fmt: skip
            pass
        with connect(f"ws://127.0.0.1:{server.port}/ws",
                     origin=f"http://127.0.0.1:{server.port}") as page:  # fmt: skip
            assert json.loads(page.recv(timeout=5))["type"] == "live"


def test_mode_names_are_px4s():
    assert mode_name(None) is None
    assert mode_name(3 << 16) == "Position"
    assert mode_name((4 << 16) | (2 << 24)) == "Takeoff"
    assert mode_name((4 << 16) | (3 << 24)) == "Hold"
    assert mode_name(6 << 16) == "Offboard"


def test_rig_view_without_a_log_is_one_line(capsys, tmp_path):
    assert main(["view", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err == f"rig: error: {tmp_path / 'rig.ulg'}: no such log (is this a run folder?)\n"


@pytest.mark.closed_loop
def test_a_taken_port_is_a_warning_and_the_run_goes_on(capsys, tmp_path):
    scenario = tmp_path / "short.toml"
    scenario.write_text('name = "short"\nvehicle = "f450_high_precision"\nduration_s = 1.0\n'
                        'seed = 1\nsensor_layer = "tlm"\n[rates]\nimu_hz = 250\n')  # fmt: skip
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        code = main(["run", str(scenario), "--view", "--view-port", str(port), "--instance",
                     str(free_test_instance()), "--out", str(tmp_path / "run")])  # fmt: skip
    assert code == 0
    err = capsys.readouterr().err
    warning = [line for line in err.splitlines() if "live view" in line]
    assert warning == [f"rig: warning: no live view: cannot serve the view on 127.0.0.1:{port} "
                       "(Address already in use); is another view running there? "
                       "(--view-port picks another port)"]  # fmt: skip
    assert (tmp_path / "run" / "rig.ulg").is_file()
