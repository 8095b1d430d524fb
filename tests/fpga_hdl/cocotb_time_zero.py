"""cocotb module for ``test_verilog_time_zero.py``: combinational logic has a value at time 0."""

import cocotb
from cocotb.triggers import Timer


@cocotb.test()
async def combinational_output_is_defined_before_any_input_changes(dut):
    """No clock, no input write: ``out`` must already be 7 (``held`` is 0 from its init)."""
    await Timer(1, unit="ns")
    assert dut.out.value.is_resolvable, f"out = {dut.out.value} at time 0"
    assert int(dut.out.value) == 7
