"""cocotb interface-timing tests of SensorTop's IST8310 on I2C, on every simulator."""

from pathlib import Path

import pytest

from fpga_hdl.cosim.runner import SIMULATOR_PARAMS, run_cocotb
from fpga_hdl.top import SensorTop

HERE = Path(__file__).parent


@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)
def test_ist8310_on_generated_verilog(simulator):
    run_cocotb(
        SensorTop(), "sensor_top", "cocotb_i2c_ist8310", module_dir=HERE, simulator=simulator
    )
