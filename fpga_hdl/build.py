"""Verilog generation from Amaranth, into ``build/`` (never committed), reproducibly.

The file name carries a hash of the Verilog text, so the same design always lands at
the same path with the same bytes, and a simulator build keyed by that path is reused
until the design really changes. Source-location attributes are left out
(``emit_src=False``): they hold absolute paths and would make the bytes depend on where
the repository is checked out.

Run ``python -m fpga_hdl.build`` to write the top level's Verilog and print its path.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from amaranth.back import verilog
from amaranth.lib import wiring

#: Repository root; ``build/`` beside pyproject.toml is ignored by git.
REPO_ROOT = Path(__file__).resolve().parent.parent
BUILD_DIR = REPO_ROOT / "build"


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
    return verilog.convert(component, name=toplevel, emit_src=False)


def generate_verilog(
    component: wiring.Component, toplevel: str, *, build_dir: Path = BUILD_DIR
) -> GeneratedVerilog:
    """Write ``component`` as Verilog under ``build_dir/verilog``; reuse an identical file."""
    text = verilog_text(component, toplevel)
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    path = build_dir / "verilog" / f"{toplevel}-{digest}.v"
    if not path.is_file():  # an existing file has these exact bytes: its name is their hash
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(text)
        tmp.replace(path)  # atomic: a parallel build never sees half a file
    return GeneratedVerilog(toplevel=toplevel, path=path, digest=digest)


def main() -> None:
    from fpga_hdl.top import SensorTop

    generated = generate_verilog(SensorTop(), "sensor_top")
    print(generated.path)


if __name__ == "__main__":
    main()
