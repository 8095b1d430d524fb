"""An 8-case campaign of real runs (reference autopilot, TLM chips, IMU 250 Hz, 3 s each)
on the local process pool, interrupted and resumed, then on a Dask LocalCluster: the same
statuses and metrics from both. One case's autopilot is killed mid-run (a crash) and one
is frozen with SIGSTOP (a hang, as a deadlocked PX4): both are real runs failing for real,
recorded with their reasons while the campaign goes on."""

import json
import os
import signal
import sqlite3
import threading
from pathlib import Path

import pytest
from dask.distributed import LocalCluster

from rig.campaign import campaign_executor, campaign_from_dict, read_results, run_campaign
from rig.campaign.report import write_report
from tests.instances import worker_instances

pytestmark = pytest.mark.closed_loop
#: This worker's instances (tests.instances): campaigns of two workers never share one.
CAMPAIGN_INSTANCES = worker_instances(20, 40)

#: A case flies in about 12 s on an idle machine of this kind; with the other test worker
#: and both campaign workers' autopilots on two cores it has taken over 25 s, so the
#: timeout leaves a margin of nearly 4x before a real run counts as hung.
CASE_TIMEOUT_S = 45.0
KILLED, FROZEN = 3, 6  # case indices whose autopilot the test sabotages


def campaign(tmp_path: Path):
    scenario = tmp_path / "short_hover.toml"
    scenario.write_text(
        'name = "short_hover"\nvehicle = "f450_high_precision"\nduration_s = 4.0\nseed = 1\n'
        "[rates]\nimu_hz = 250\n"
        '[[commands]]\nat_s = 0.2\naction = "arm"\n'
        '[[commands]]\nat_s = 0.3\naction = "takeoff"\naltitude_m = 2.0\n'
    )
    return campaign_from_dict(
        {
            "name": "small",
            "scenario": str(scenario),
            "case_timeout_s": CASE_TIMEOUT_S,
            "answer_timeout_s": 60.0,  # longer than the case timeout: a stall is a hang
            "first_instance": CAMPAIGN_INSTANCES.start,
            "instances": len(CAMPAIGN_INSTANCES),
            "axes": {
                # m0_weak's two efficiencies make it two levels of the fault axis
                "fault": ["none", "m0_lost", "m0_weak"],
                "fault_onset_s": [2.5],
                "seed": [1, 2],
            },
            "faults": {
                "m0_lost": {"kind": "motor_loss", "motor": 0},
                "m0_weak": {
                    "kind": "motor_degradation",
                    "motor": 0,
                    "severity": "efficiency",
                    "efficiency": [0.5, 0.9],
                },
            },
            "criteria": {"max_tilt_deg": {"max": 30.0}, "crashed": {"equals": False}},
        },
        "small.toml",
    )


class Saboteur:
    """Signals the autopilot of chosen cases as soon as it starts (found by its log path)."""

    def __init__(self, out_dir: Path, signals: dict[int, signal.Signals]) -> None:
        self.targets = {f"case-{index:04d}-": sig for index, sig in signals.items()}
        self.done: set[str] = set()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._watch, args=(str(out_dir),), daemon=True)

    def _watch(self, out_dir: str) -> None:
        while not self.stop.wait(0.01):
            for pid in filter(str.isdigit, os.listdir("/proc")):
                try:
                    cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
                except OSError:
                    continue
                if "rig.autopilots.reference" not in cmdline or out_dir not in cmdline:
                    continue
                for prefix, sig in self.targets.items():
                    if prefix in cmdline and prefix not in self.done:
                        os.kill(int(pid), sig)
                        self.done.add(prefix)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *_):
        self.stop.set()
        self.thread.join()


SABOTAGE = {KILLED: signal.SIGKILL, FROZEN: signal.SIGSTOP}


def outcomes(results):
    return {r.case_id: (r.index, r.status, json.dumps(r.metrics, sort_keys=True)) for r in results}


@pytest.fixture(scope="module")
def pool_run(tmp_path_factory):
    """The campaign on a 2-process pool, Ctrl-C after the first 3 results, then resumed."""
    tmp_path = tmp_path_factory.mktemp("pool")
    spec, out = campaign(tmp_path), tmp_path / "results"
    seen = []

    def interrupt_after_three(result):
        seen.append(result)
        if len(seen) == 3:
            raise KeyboardInterrupt

    with (
        Saboteur(out, SABOTAGE),
        campaign_executor(workers=2) as executor,
        pytest.raises(KeyboardInterrupt),
    ):
        run_campaign(spec, out, executor, interrupt_after_three)
    interrupted = read_results(out)
    with Saboteur(out, SABOTAGE), campaign_executor(workers=2) as executor:
        resumed = run_campaign(spec, out, executor)
    return spec, out, seen, interrupted, resumed


def test_interrupted_campaign_keeps_its_rows_and_resumes_the_rest(pool_run):
    _spec, out, seen, interrupted, resumed = pool_run
    assert outcomes(interrupted) == outcomes(seen)  # every result seen was committed
    assert {r.case_id for r in resumed}.isdisjoint(r.case_id for r in interrupted)
    final = read_results(out)
    assert len(final) == 8
    assert sorted(r.index for r in final) == list(range(8))
    with sqlite3.connect(out / "results.sqlite") as db:
        assert db.execute("PRAGMA integrity_check").fetchone() == ("ok",)


def test_crash_and_hang_are_recorded_with_their_reasons(pool_run):
    _, out, *_ = pool_run
    by_index = {r.index: r for r in read_results(out)}
    killed, frozen = by_index[KILLED], by_index[FROZEN]
    assert killed.status == "crashed"
    assert "SIGKILL" in killed.reason  # the rig's own one-line error, from the case
    assert frozen.status == "hung"
    assert frozen.reason == f"no result after {CASE_TIMEOUT_S:g} s wall time (stopped)"
    assert frozen.wall_s >= CASE_TIMEOUT_S
    others = [r for i, r in by_index.items() if i not in SABOTAGE]
    assert all(r.status in ("ok", "failed") and r.rig_log for r in others)
    labels = {r.index: dict(r.labels) for r in others}
    # Physics, not bookkeeping: losing a motor in the climb flips the quad (no fault-tolerant
    # control in PX4's multicopter stack); with no fault it stays near level.
    for r in others:
        if labels[r.index]["fault"] == "m0_lost":
            assert r.metrics["crashed"]
            assert r.status == "failed"
        if labels[r.index]["fault"] == "none":
            assert not r.metrics["crashed"]
            assert r.metrics["max_tilt_deg"] < 15.0


def test_seeds_change_the_numbers(pool_run):
    _, out, *_ = pool_run
    tilts = {
        tuple(dict(r.labels).values()): r.metrics.get("max_tilt_deg") for r in read_results(out)
    }
    assert tilts[("none", "2.5", "1")] != tilts[("none", "2.5", "2")]


def test_dask_local_cluster_gives_the_same_results_as_the_pool(pool_run, tmp_path):
    spec, pool_out, *_ = pool_run
    out = tmp_path / "results"
    cluster = LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    )
    with cluster, Saboteur(out, SABOTAGE), campaign_executor(cluster.scheduler_address) as pool:
        run_campaign(spec, out, pool)
    assert outcomes(read_results(out)) == outcomes(read_results(pool_out))


def test_report_shows_axes_envelope_and_failed_cases(pool_run):
    _, out, *_ = pool_run
    html_path = write_report(out)
    report = json.loads((out / "report.json").read_text())
    assert report["cases"] == 8
    assert report["statuses"]["crashed"] == 1
    assert report["statuses"]["hung"] == 1
    assert {row["value"] for row in report["axes"]["seed"]} == {"1", "2"}
    envelope = {(c["fault"], c["onset_s"]): (c["survived"], c["cases"]) for c in report["envelope"]}
    assert envelope[("m0_lost", "2.5")] == (0, 2)
    assert sum(cases for _, cases in envelope.values()) == 8
    assert {row["index"] for row in report["not_ok"]} >= {KILLED, FROZEN}
    assert "data:image/png;base64," in html_path.read_text()
