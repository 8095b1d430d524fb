"""cocotb interface-timing tests of SensorTop's I2C bus (the IST8310, and the LIDAR-Lite beside
it), on every simulator."""

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


@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)
def test_ist8310_and_lidarlite_share_the_i2c_bus(simulator):
    run_cocotb(
        SensorTop(), "sensor_top", "cocotb_i2c_shared_bus", module_dir=HERE, simulator=simulator
    )
