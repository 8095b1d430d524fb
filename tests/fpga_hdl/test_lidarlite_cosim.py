"""cocotb tests of the LIDAR-Lite v3 core on generated Verilog, on every simulator."""

from pathlib import Path

import pytest

from fpga_hdl.chips.lidarlite.core import LidarLiteCore
from fpga_hdl.cosim.runner import SIMULATOR_PARAMS, run_cocotb
from fpga_hdl.top import SYS_CLK_HZ

HERE = Path(__file__).parent


@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)
def test_lidarlite_on_generated_verilog(simulator):
    core = LidarLiteCore(sys_clk_hz=SYS_CLK_HZ)
    run_cocotb(core, "lidarlite_v3", "cocotb_lidarlite", module_dir=HERE, simulator=simulator)
