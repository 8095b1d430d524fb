"""Generated Verilog evaluates combinational logic at time 0 on a four-state simulator.

The regression behind the Icarus-only X on the MPU-6000's SDO (``fpga_hdl.build``): an
``m.If`` on a register that never changes, the smallest design whose ``always @*`` block
would never run under Icarus's SystemVerilog mode. Icarus only: Verilator is two-state
and settles all logic at start-up, so it cannot show the fault.
"""

from pathlib import Path

import pytest
from amaranth import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

from fpga_hdl.build import verilog_text
from fpga_hdl.cosim.runner import SIMULATOR_PARAMS, run_cocotb

HERE = Path(__file__).parent


class HeldChoice(wiring.Component):
    """``out`` = 2 while a register (init 0, never clocked) is set, else 7."""

    out: Out(3)

    def elaborate(self, platform):
        m = Module()
        held = Signal()
        m.d.sync += held.eq(held)
        with m.If(held):
            m.d.comb += self.out.eq(2)
        with m.Else():
            m.d.comb += self.out.eq(7)
        return m


def test_no_combinational_always_block_is_emitted():
    assert "always @*" not in verilog_text(HeldChoice(), "held_choice")


@pytest.mark.parametrize("simulator", [p for p in SIMULATOR_PARAMS if p.id == "icarus"])
def test_combinational_output_is_defined_at_time_zero(simulator):
    run_cocotb(
        HeldChoice(), "held_choice", "cocotb_time_zero", module_dir=HERE, simulator=simulator
    )
