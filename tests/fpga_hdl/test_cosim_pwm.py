# amaranth: UnusedElaboratable=no
"""cocotb tests of the PWM capture core on generated Verilog, on every simulator."""

from pathlib import Path

import pytest

from fpga_hdl.chips.pwm_capture.core import PwmCapture
from fpga_hdl.cosim.runner import SIMULATOR_PARAMS, run_cocotb

HERE = Path(__file__).parent


@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)
def test_pwm_capture_on_generated_verilog(simulator):
    core = PwmCapture(tick_hz=1e6, timeout_s=0.03)
    run_cocotb(core, "pwm_capture", "cocotb_pwm_capture", module_dir=HERE, simulator=simulator)
