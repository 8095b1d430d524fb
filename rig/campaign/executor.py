"""Running the cases: each in its own process under a wall-clock timeout, on any
``concurrent.futures.Executor`` (local processes or a Dask cluster)."""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from dataclasses import asdict
from pathlib import Path
from typing import Any

import tomli_w

from rig.campaign.expansion import CaseSpec, expand
from rig.campaign.results import RESULTS_DB, CaseResult, ResultsDb
from rig.campaign.schema import CASE_LOGS, Campaign, CampaignError
from rig.processes import start_child, stop_process_group

#: Grace after SIGINT for a timed-out case to close its logs and stop its autopilot.
STOP_GRACE_S = 10.0


def run_case(spec: CaseSpec) -> CaseResult:
    """Run one case in its own process under the wall-clock timeout; never raises for a
    failure of the run itself (that is the case's result)."""
    run_dir = Path(spec.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "outcome.json").unlink(missing_ok=True)  # from an interrupted earlier attempt
    vehicle_path = (run_dir / "vehicle.toml").resolve()
    scenario = {**spec.scenario_document, "vehicle": str(vehicle_path)}
    (run_dir / "scenario.toml").write_text(tomli_w.dumps(scenario))
    (run_dir / "vehicle.toml").write_text(tomli_w.dumps(spec.vehicle_document))
    (run_dir / "case.json").write_text(json.dumps(asdict(spec), indent=1, default=str))
    started = time.monotonic()
    with open(run_dir / "case.log", "wb") as output:
        process = start_child([sys.executable, "-m", "rig.campaign.case", str(run_dir)],
                              stdout=output, stderr=subprocess.STDOUT)  # fmt: skip
        try:
            process.wait(timeout=spec.timeout_s)
            hung = False
        except subprocess.TimeoutExpired:
            hung = True
            stop_process_group(process, STOP_GRACE_S)
        except BaseException:  # Ctrl-C or a cancelled worker: never leave the case running
            stop_process_group(process, STOP_GRACE_S)
            raise
    wall_s = time.monotonic() - started
    outcome = _read_outcome(run_dir)
    metrics = outcome.get("metrics", {}) if outcome else {}
    if hung:
        status, reason = "hung", f"no result after {spec.timeout_s:g} s wall time (stopped)"
    elif outcome is None:
        status, reason = (
            "crashed",
            f"case process exit code {process.returncode}: " + _tail(run_dir / "case.log"),
        )
    elif outcome["error"]:
        status, reason = "crashed", outcome["error"]
    else:
        violations = [v for c in spec.criteria if (v := c.violation(metrics.get(c.metric)))]
        # Notes (e.g. why a credibility index is missing) come with the reason either way.
        status = "failed" if violations else "ok"
        reason = "; ".join([*violations, *outcome.get("notes", [])])
    logs = {
        name: str(run_dir / f"{name}.ulg")
        for name in CASE_LOGS
        if (run_dir / f"{name}.ulg").is_file()
    }
    return CaseResult(
        case_id=spec.case_id,
        index=spec.index,
        labels=spec.labels,
        status=status,
        reason=reason,
        metrics=metrics,
        wall_s=wall_s,
        run_dir=spec.run_dir,
        rig_log=logs.get("rig"),
        autopilot_log=logs.get("autopilot"),
    )


def _read_outcome(run_dir: Path) -> dict[str, Any] | None:
    try:
        return json.loads((run_dir / "outcome.json").read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None


def _tail(path: Path) -> str:
    lines = [line for line in path.read_text(errors="replace").splitlines() if line.strip()]
    return lines[-1].strip() if lines else "no output"


def run_campaign(
    campaign: Campaign,
    out_dir: Path,
    executor: Executor,
    on_result: Callable[[CaseResult], None] | None = None,
) -> list[CaseResult]:
    """Run the cases not yet in ``out_dir/results.sqlite``; returns the new results.

    Each result is committed as it arrives; on Ctrl-C the queued cases are cancelled and
    the running ones stopped by their workers, and every committed row stays."""
    out_dir.mkdir(parents=True, exist_ok=True)
    cases = expand(campaign, out_dir)
    with ResultsDb(out_dir / RESULTS_DB) as db:
        if campaign.credibility is not None:
            db.record_plan(campaign.credibility)
        done = db.finished_ids()
        futures: list[Future[CaseResult]] = [
            executor.submit(run_case, case) for case in cases if case.case_id not in done
        ]
        results = []
        try:
            for future in as_completed(futures):
                result = future.result()
                db.record(result)
                results.append(result)
                if on_result is not None:
                    on_result(result)
        finally:
            for future in futures:
                future.cancel()
    return results


@contextlib.contextmanager
def campaign_executor(
    scheduler: str | None = None, workers: int | None = None
) -> Iterator[Executor]:
    """A local process pool of ``workers`` (default: the cores this process may use), or
    the Dask cluster at ``scheduler`` (``tcp://HOST:8786``) through its executor.

    The pool's workers come from a fork server, not a fork of this process: the caller
    may have threads (a progress display, a rig flying), and a forked copy of them can
    deadlock or crash the worker."""
    if scheduler is None:
        workers = workers or len(os.sched_getaffinity(0))
        context = multiprocessing.get_context("forkserver")
        with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
            yield pool
        return
    from dask.distributed import Client  # imported on demand: Dask is slow to import

    try:
        client = Client(scheduler, timeout="20s")
    except OSError as error:
        raise CampaignError(
            f"--scheduler {scheduler}: cannot reach the Dask scheduler ({error})"
        ) from None
    with client, client.get_executor(pure=False) as executor:
        yield executor
