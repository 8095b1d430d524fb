"""PX4 SITL through the rig: real-time factor and per-frame budget, TLM and RTL chips, IMU
250 Hz and 1 kHz (PX4 found as ``rig run --autopilot px4`` finds it: ``$PX4_DIR``).

Each case starts a fresh PX4 (the rig does), which arms and takes off to 2 m, and flies
``SIMULATED_S`` of simulated time; the RTF counts the lockstep frames only, not PX4's
start-up. ``bypass`` is the same rig with its sensor layer skipped (SI samples straight
into HIL_SENSOR, commanded widths straight to the motors): what the chips cost. The anchor,
PX4 + the barest simulator that flies it (``benchmarks.bare_px4_sim``), is measured in the
same run at each rate; the goals are shares of it (:data:`GOAL_SHARES`). Both start PX4
alike (``Px4Sitl``: held to one CPU once its start-up script has ended). A single short
flight's factor moved ±10 % from run to run, so each is flown ``REPEATS`` times, the
anchor and the rig's cases in turn (a load that comes and goes then falls on all of them).
A factor's figure is the median, the range in its detail; a share's is the lowest of the
rounds' shares (each the rig's factor over the anchor's flown just before it), since a
goal counts the low end of the spread.
Figures only, no pass/fail.
"""

from __future__ import annotations

import math
import statistics
import tempfile
from collections.abc import Callable, Iterator
from functools import partial
from pathlib import Path

from benchmarks.bare_px4_sim import fly_bare
from benchmarks.figures import Figure, run_detail
from rig.autopilots.px4 import PX4_DIR_ENV, Px4Build, find_px4
from rig.errors import RigError
from rig.lockstep.loop import RunOptions, run_scenario
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import scenario_from_dict

INSTANCE = 92  # away from the instances tests and users pick first
SIMULATED_S = {"bypass": 20.0, "tlm": 20.0, "rtl": 6.0}
ANCHOR_S = 20.0
#: PX4 passes its pre-flight checks ~6.5 s after boot; the flight starts after that.
ARM_S = 8.0
#: The goals, as a share of the anchor measured in the same run, by (layer, IMU rate).
GOAL_SHARES = {("tlm", 250): 0.8, ("rtl", 250): 0.25, ("rtl", 1000): 0.5}
REPEATS = 3


def _anchor(build: Px4Build, imu_hz: int) -> Figure:
    name = f"anchor: PX4 + a bare Python simulator, IMU {imu_hz} Hz"
    try:
        run = fly_bare(build, instance=INSTANCE, imu_hz=imu_hz, arm_s=ARM_S, simulated_s=ANCHOR_S)
    except RigError as error:
        return Figure(name, float("nan"), "× real time", detail=f"failed: {error}")
    detail = f"{ANCHOR_S:g} s after arming; climbed to {run.altitude_m:.1f} m"
    return Figure(name, run.real_time_factor, "× real time", detail=detail)


def _case(build_root: Path, sensor_layer: str, imu_hz: int) -> Figure:
    layer = "chips bypassed" if sensor_layer == "bypass" else sensor_layer.upper()
    name = f"PX4 + rig, {layer}, IMU {imu_hz} Hz"
    document = {
        "name": "bench_px4", "vehicle": "f450_high_precision", "seed": 1,
        "duration_s": ARM_S + SIMULATED_S[sensor_layer],
        "rates": {"imu_hz": imu_hz},
        "commands": [{"at_s": ARM_S, "action": "arm"},
                     {"at_s": ARM_S + 0.5, "action": "takeoff", "altitude_m": 2.0}],
    }  # fmt: skip
    try:
        with tempfile.TemporaryDirectory() as folder:
            options = RunOptions(autopilot="px4", px4_dir=build_root, instance=INSTANCE,
                                 out_dir=Path(folder), sensor_layer=sensor_layer,
                                 timeouts=LinkTimeouts(connect_s=60, answer_s=30))  # fmt: skip
            result = run_scenario(scenario_from_dict(document), options)
    except RigError as error:
        return Figure(name, float("nan"), "× real time", detail=f"failed: {error}")
    return Figure(name, result.real_time_factor, "× real time", detail=run_detail(result))


def _median(runs: list[Figure]) -> Figure:
    """The median run's figure (its detail: its frame budget), with the range of all."""
    failed = [run for run in runs if math.isnan(run.value)]
    if failed:
        return failed[0]
    middle = sorted(runs, key=lambda run: run.value)[len(runs) // 2]
    values = [run.value for run in runs]
    spread = f"median of {len(runs)}, {min(values):.2f}..{max(values):.2f}"
    value = statistics.median(values)
    return Figure(middle.name, value, middle.unit, detail=f"{spread}; {middle.detail}")


def lowest_share(runs: list[Figure], anchors: list[Figure], goal: float) -> Figure:
    """The lowest of the rounds' shares of the anchor: in each round the anchor flew just
    before the rig, so a spell of the machine's pace falls on both."""
    name = f"{runs[0].name}, share of the anchor"
    if any(math.isnan(run.value) for run in (*runs, *anchors)):
        return Figure(name, math.nan, "% of the anchor", detail="a flight failed (see above)")
    rounds = sorted((run.value / anchor.value * 100, run.value, anchor.value)
                    for run, anchor in zip(runs, anchors, strict=True))  # fmt: skip
    each = ", ".join(f"{share:.0f} % ({rig:.2f}× / {bare:.2f}×)" for share, rig, bare in rounds)
    detail = f"lowest of {len(rounds)} rounds (rig / anchor): {each}"
    return Figure(name, rounds[0][0], "% of the anchor", f"≥ {goal:.0%}", detail)


def figures() -> Iterator[Figure]:
    try:
        build = find_px4()
    except RigError as error:
        build, reason = None, str(error)
    else:
        reason = f"no PX4 SITL build (set {PX4_DIR_ENV})"
    if build is None:
        yield Figure("PX4 + rig", float("nan"), "× real time", detail=f"skipped: {reason}")
        return
    for imu_hz in (250, 1000):
        flights: dict[str, Callable[[], Figure]] = {"anchor": partial(_anchor, build, imu_hz)}
        for layer in ("bypass", "tlm", "rtl"):
            flights[layer] = partial(_case, build.root, layer, imu_hz)
        runs: dict[str, list[Figure]] = {label: [] for label in flights}
        for _ in range(REPEATS):
            for label, fly in flights.items():
                runs[label].append(fly())
        anchors = runs.pop("anchor")
        yield _median(anchors)
        for layer_runs in runs.values():
            yield _median(layer_runs)
        for (label, rate), goal in GOAL_SHARES.items():
            if rate == imu_hz:
                yield lowest_share(runs[label], anchors, goal)
