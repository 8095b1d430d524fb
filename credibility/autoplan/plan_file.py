"""The plan as a whole: every finder's tests and reasons gathered, named from what the log
says of itself, and written as a TOML file a user can read, edit and score."""

import json
import os
import textwrap
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from credibility import indices
from credibility.autoplan.draft import Draft, PlannedTest
from credibility.autoplan.noise import noise_tests
from credibility.autoplan.responses import log_limits, response_tests
from credibility.autoplan.setpoints import step_tests
from credibility.errors import CredibilityError
from credibility.plan import NotScorable
from px4_logs import FlightLog

#: ε_min = the pass mark: a first identification from one flight rarely reaches the paper's
#: 0.9, and η_all is then still reported as a valid summary when no test falls below 0.6.
EPS_MIN = indices.DEFAULT_PASS_MARK
#: A PX4 log's fast topics come every 20 ms at the default logging profile; a longer gap
#: inside a segment is a dropout.
MAX_GAP_S = 0.2
#: Where the user's simulation log goes when ``--sim`` is not given: a name that cannot be
#: mistaken for a real file, so ``credibility report`` says it is missing.
SIM_PLACEHOLDER = "REPLACE-WITH-YOUR-SIMULATION.ulg"


def describe(log: FlightLog) -> tuple[str, str]:
    """A name and a description from what the log says of itself: airframe, rotors,
    firmware and, when GNSS gave it, the date."""
    autostart = log.parameters.get("SYS_AUTOSTART")
    airframe = f"PX4 airframe {int(autostart)}" if autostart else "airframe not logged"
    rotors = int(log.parameters.get("CA_ROTOR_COUNT", 0))
    vehicle = f"{rotors}-rotor vehicle" if rotors else "vehicle"
    date = ""
    utc = log.topics.get("vehicle_gps_position", {}).get("time_utc_usec")
    if utc is not None and np.any(np.asarray(utc) > 0):
        stamp = float(np.asarray(utc)[np.asarray(utc) > 0][0]) / 1e6
        date = datetime.fromtimestamp(stamp, UTC).strftime("%Y-%m-%d")
    name = f"{vehicle.capitalize()} ({airframe}): automatic plan from {log.path.name}"
    description = (f"{vehicle.capitalize()}, {airframe}, {log.firmware}"
                   + (f", flown {date}" if date else "")
                   + f"; log {log.first_s:.1f}-{log.last_s:.1f} s. Segments found by "
                   "credibility plan; every test it could not plan is listed below "
                   "with the reason.")  # fmt: skip
    return name, description


def draft_plan(log: FlightLog) -> Draft:
    """Every test the log supports, and every one it does not with the reason."""
    tests: list[PlannedTest] = []
    skipped: list[NotScorable] = []
    for finder in (noise_tests, response_tests, step_tests):
        more, less = finder(log)
        tests += more
        skipped += less
    name, description = describe(log)
    return Draft(name, description, tuple(tests), tuple(skipped + log_limits(log)))


def _value(value: Any) -> str:
    """A TOML value: strings as JSON writes them (a TOML basic string), tables inline."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(round(value, 4))
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_value(v)}" for k, v in value.items()) + " }"
    return "[" + ", ".join(_value(v) for v in value) + "]"


def _comment(text: str) -> list[str]:
    return textwrap.wrap(text, 92, initial_indent="# ", subsequent_indent="# ")


def _relative(path: Path, start: Path) -> str:
    return Path(os.path.relpath(path.resolve(), start.resolve())).as_posix()


def plan_toml(draft: Draft, real: Path, sim: Path | None, plan_dir: Path) -> str:
    """The plan file's text; log paths relative to ``plan_dir``, where it will be written."""
    sim_text = _relative(sim, plan_dir) if sim is not None else SIM_PLACEHOLDER
    header = (
        f"Written by `credibility plan` from {real.name}: every segment below was found "
        "automatically, with what was found and by what criterion above each test. Edit it "
        "freely; `credibility report PLAN --log sim=RUN.ulg` scores a simulation with it."
    )
    if sim is None:
        header += (
            f" [logs] sim is a placeholder ({SIM_PLACEHOLDER}): point it at your simulation's "
            "log, or pass --log sim=PATH."
        )
    lines = _comment(header)
    lines += [
        "",
        "[plan]",
        f"name = {_value(draft.name)}",
        f"description = {_value(draft.description)}",
        f"pass_mark = {indices.DEFAULT_PASS_MARK}",
        "# ε_min = the pass mark: a first model from one flight rarely reaches the paper's 0.9.",
        f"eps_min = {EPS_MIN}",
        f"k_p = {indices.DEFAULT_K_P}",
        f"max_gap_s = {MAX_GAP_S}",
        "",
        "# The paper's weights (section 4.2.4) over the kinds this plan holds, summing to 1.",
        "[weights]",
        *(f"{kind} = {alpha}" for kind, alpha in draft.weights.items()),
        "",
        "[logs]",
        f"real = {_value(_relative(real, plan_dir))}",
        f"sim = {_value(sim_text)}",
    ]
    for test in draft.tests:
        lines += ["", *_comment(test.found), "[[tests]]", f"name = {_value(test.name)}"]
        lines += [f"{key} = {_value(value)}" for key, value in test.keys.items()]
    for item in draft.not_scorable:
        lines += ["", "[[not_scorable]]", f"name = {_value(item.name)}",
                  f"kind = {_value(item.kind)}", f"reason = {_value(item.reason)}"]  # fmt: skip
    return "\n".join(lines) + "\n"


def write_plan(log: FlightLog, out: Path, sim: Path | None = None) -> Draft:
    """Find the plan in ``log`` and write it to ``out``; a log that supports no test is one
    line with every reason."""
    draft = draft_plan(log)
    if not draft.tests:
        reasons = "; ".join(f"{item.name}: {item.reason}" for item in draft.not_scorable)
        raise CredibilityError(f"{log.path}: no test can be planned from this log ({reasons})")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(plan_toml(draft, log.path, sim, out.parent), encoding="utf-8")
    return draft
