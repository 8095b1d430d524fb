"""cocotb bench for the runner's own test: one passing and one deliberately failing test."""

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, ReadOnly


async def count_ten(dut) -> int:
    Clock(dut.clk, 10, unit="ns").start()
    dut.rst.value = 1
    await ClockCycles(dut.clk, 2)
    dut.rst.value = 0
    await ClockCycles(dut.clk, 10)
    await ReadOnly()
    return int(dut.count.value)


@cocotb.test()
async def counts_in_reset_release(dut):
    assert await count_ten(dut) == 10


@cocotb.test()
async def fails_on_purpose(dut):
    assert await count_ten(dut) == 11
