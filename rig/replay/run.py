"""Flying a planned replay: its run folder with ``vehicle.toml`` and ``replay.json``."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import replace
from datetime import UTC, datetime

import tomli_w

from rig.lockstep.loop import (
    RUNS_DIR,
    Progress,
    RunOptions,
    RunResult,
    claim_run_dir,
    run_scenario,
)
from rig.replay.plan import Replay


def run_replay(
    replay: Replay,
    run_options: RunOptions | None = None,
    progress: Callable[[Progress], None] | None = None,
) -> RunResult:
    """Fly a planned replay; the run folder also gets ``vehicle.toml`` and ``replay.json``.

    ``run_options`` says where and how (instance, folder, timeouts); its ``--param`` values
    are applied after the log's, so they win. The autopilot and PX4's build are the plan's.
    """
    run_options = run_options or RunOptions()
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    default_dir = RUNS_DIR / f"replay-{replay.log_path.stem}-{stamp}"
    run_dir = claim_run_dir(run_options.out_dir or default_dir, run_options.force)
    vehicle_path = (run_dir / "vehicle.toml").resolve()
    vehicle_path.write_text(tomli_w.dumps(replay.vehicle_document))
    (run_dir / "replay.json").write_text(json.dumps(replay.summary(), indent=2) + "\n")
    scenario = replay.scenario(vehicle_path)
    flown = replace(
        run_options,
        autopilot=replay.options.autopilot,
        px4_dir=replay.options.px4_dir or run_options.px4_dir,
        out_dir=run_dir,
        sensor_layer=replay.options.sensor_layer,
        autopilot_params=(*replay.autopilot_params, *run_options.autopilot_params),
        notes=(*replay.notes, *run_options.notes),
    )
    return run_scenario(scenario, flown, progress)
