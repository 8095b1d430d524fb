"""``make fuzz``: the property tests of every input path (``tests/fuzz``), coverage-guided.

Each target is one hypothesis test run by atheris (libFuzzer) in its own process for a
set time: libFuzzer mutates the bytes hypothesis draws its inputs from and keeps those
that reach new code of the rig's packages, instrumented on import. The table says how
many inputs each target tried and what failed: the goal is 0 tracebacks, 0 hangs.

A failure prints hypothesis's minimal reproducer (and is saved in ``.hypothesis/``, which
``pytest tests/fuzz`` replays first); make it a regression test with ``@example``.

``python -m benchmarks.fuzz --minutes 10`` (``make fuzz``, FUZZ_MINUTES=10 by default),
split evenly over the targets.
"""

from __future__ import annotations

import argparse
import importlib
import re
import subprocess
import sys
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

#: Target → (module, hypothesis property test) under tests/fuzz.
FILES, LINKS = "test_file_inputs", "test_mavlink_inputs"
TARGETS = {
    "flight_logs": (FILES, "test_a_damaged_flight_log_is_read_or_refused_in_one_line"),
    "toml_files": (FILES, "test_any_configuration_file_is_loaded_or_refused_in_one_line"),
    "simulator_link": (LINKS, "test_garbage_before_an_answer_on_the_simulator_link"),
    "onboard_link": (LINKS, "test_garbage_on_the_rigs_onboard_link"),
    "autopilot_ports": (LINKS, "test_garbage_then_a_command_on_the_autopilots_ground_port"),
}
#: The packages whose coverage guides the fuzzer (the rest is not ours to fuzz).
INSTRUMENTED = ["rig", "credibility", "hil_config", "pymavlink", "pyulog"]
#: numba compiles these from their bytecode, which atheris's probes would break.
NOT_INSTRUMENTED = ["quad_model", "rig.autopilots.reference.control",
                    "rig.autopilots.reference.estimator"]  # fmt: skip
REPO = Path(__file__).resolve().parent.parent
OUT_DIR = REPO / "build" / "fuzz"
#: A target that has not finished this long after its time is up has hung.
HANG_GRACE_S = 120.0


def fuzz_one(target: str, seconds: int) -> None:
    """In the child process: instrument, then hand the test to libFuzzer."""
    import atheris
    from hypothesis import HealthCheck, settings

    settings.register_profile("fuzz", deadline=None, suppress_health_check=list(HealthCheck))
    settings.load_profile("fuzz")
    module_name, test_name = TARGETS[target]
    with atheris.instrument_imports(include=INSTRUMENTED, exclude=NOT_INSTRUMENTED):
        for package in INSTRUMENTED:
            importlib.import_module(package)
        module = importlib.import_module(f"tests.fuzz.{module_name}")
    test = getattr(module, test_name)
    artifacts = OUT_DIR / target
    artifacts.mkdir(parents=True, exist_ok=True)
    atheris.Setup(
        [sys.argv[0], f"-max_total_time={seconds}", f"-artifact_prefix={artifacts}/",
         "-print_final_stats=1", "-rss_limit_mb=4096"],
        test.hypothesis.fuzz_one_input,
    )  # fmt: skip
    atheris.Fuzz()


def run_target(target: str, seconds: int, log: Path) -> tuple[int, str]:
    """Fuzz ``target`` in a child process → (inputs tried, what failed or "")."""
    command = [
        sys.executable,
        "-m",
        "benchmarks.fuzz",
        "--child",
        target,
        "--seconds",
        str(seconds),
    ]
    with log.open("w") as output:
        try:
            child = subprocess.run(command, cwd=REPO, stdout=output, stderr=subprocess.STDOUT,
                                   timeout=seconds + HANG_GRACE_S, check=False)  # fmt: skip
        except subprocess.TimeoutExpired:
            return _runs(log), f"hung (no end {HANG_GRACE_S:g} s after its time); see {log}"
    if child.returncode != 0:
        return _runs(log), f"exit {child.returncode}: a traceback or a crash; see {log}"
    return _runs(log), ""


def _runs(log: Path) -> int:
    """libFuzzer's count of inputs run (its final stats)."""
    found = re.findall(r"stat::number_of_executed_units:\s*(\d+)", log.read_text(errors="replace"))
    return int(found[-1]) if found else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="fuzz", description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="total time (default 10)")
    parser.add_argument("--child", choices=sorted(TARGETS), help=argparse.SUPPRESS)
    parser.add_argument("--seconds", type=int, default=60, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        fuzz_one(args.child, args.seconds)
        return 0
    console = Console()
    seconds = max(10, round(args.minutes * 60 / len(TARGETS)))
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    console.print(f"fuzz: {len(TARGETS)} targets, {seconds} s each; output in {OUT_DIR}")
    table = Table(title="fuzz (atheris + hypothesis)", title_justify="left")
    for column in ("target", "inputs", "inputs/s", "failures"):
        table.add_column(column, justify="left" if column in ("target", "failures") else "right")
    failures = 0
    for target in TARGETS:
        started = time.monotonic()
        log = OUT_DIR / f"{target}.log"
        runs, failure = run_target(target, seconds, log)
        elapsed = time.monotonic() - started
        failures += bool(failure)
        table.add_row(target, f"{runs:,}", f"{runs / elapsed:,.0f}", failure or "0")
        console.print(f"{target}: {runs:,} inputs, {failure or 'no failure'}", highlight=False)
    console.print(table)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
