# amaranth: UnusedElaboratable=no
"""cocotb UART timing tests of the u-blox M8 core on generated Verilog, on every simulator."""

from pathlib import Path

import pytest

from fpga_hdl.chips.ublox.core import UbloxM8Core
from fpga_hdl.cosim.runner import SIMULATOR_PARAMS, run_cocotb
from fpga_hdl.top import UART_CLK_HZ

HERE = Path(__file__).parent


#: On the second simulator, the interface timing only: PX4's whole handshake (minutes of
#: simulated 9600-baud traffic, five on Icarus) runs on Verilator, where it costs one.
TIMING_TESTS = ",".join((
    "bit_timing_at_every_supported_rate", "receiver_accepts_a_sender_three_percent_off",
    "bad_checksum_and_framing_error_are_dropped", "faults_flip_bytes_and_mute_the_line",
))  # fmt: skip


@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)
def test_ublox_uart_on_generated_verilog(simulator):
    core = UbloxM8Core(sys_clk_hz=UART_CLK_HZ)
    run_cocotb(core, "ublox_m8", "cocotb_ublox_uart", module_dir=HERE, simulator=simulator,
               testcase=None if simulator == "verilator" else TIMING_TESTS)  # fmt: skip
