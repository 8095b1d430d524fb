# amaranth: UnusedElaboratable=no
"""cocotb UART timing tests of the u-blox M8 core on generated Verilog, on every simulator."""

from pathlib import Path

import pytest

from fpga_hdl.chips.ublox.core import UbloxM8Core
from fpga_hdl.cosim.runner import SIMULATOR_PARAMS, run_cocotb
from fpga_hdl.top import SYS_CLK_HZ

HERE = Path(__file__).parent


@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)
def test_ublox_uart_on_generated_verilog(simulator):
    core = UbloxM8Core(sys_clk_hz=SYS_CLK_HZ)
    run_cocotb(core, "ublox_m8", "cocotb_ublox_uart", module_dir=HERE, simulator=simulator)
