"""cocotb tests of the PMW3901 on SensorTop's shared SPI bus, on every simulator."""

from pathlib import Path

import pytest

from fpga_hdl.cosim.runner import SIMULATOR_PARAMS, run_cocotb
from fpga_hdl.top import SensorTop

HERE = Path(__file__).parent


@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)
def test_pmw3901_on_generated_verilog(simulator):
    run_cocotb(SensorTop(), "sensor_top", "cocotb_pmw3901", module_dir=HERE, simulator=simulator)
