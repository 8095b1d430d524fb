"""cocotb interface-timing tests of SensorTop's SPI chips, on every simulator."""

from pathlib import Path

import pytest

from fpga_hdl.build import verilog_text
from fpga_hdl.cosim.runner import SIMULATOR_PARAMS, run_cocotb
from fpga_hdl.top import SensorTop

HERE = Path(__file__).parent


@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)
def test_spi_chips_on_generated_verilog(simulator):
    run_cocotb(SensorTop(), "sensor_top", "cocotb_sensor_top", module_dir=HERE, simulator=simulator)


def test_sensor_top_verilog_is_reproducible():
    first, again = verilog_text(SensorTop(), "sensor_top"), verilog_text(SensorTop(), "sensor_top")
    assert first == again
    assert "module sensor_top" in first
