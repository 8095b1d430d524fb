"""The compiled co-simulation harness (``fpga_hdl.cosim.native``): the same generated
Verilog as the cocotb tests, driven from C++ one transaction per call.

Byte equality with the transaction-level models on the shared script of PX4 traffic
(``transcript.py``, which ``test_cosim_harness`` also runs under cocotb and on the pins),
NACKs included; the rig's layer compares the PWM capture with the TLM frame by frame
(``tests/rig/test_cosim.py``).
"""

import asyncio
import subprocess
import sys

import pytest

from fpga_hdl.buses.transactions import UnknownDevice
from fpga_hdl.buses.uart import divider_for, line_cycles
from fpga_hdl.chips.ublox.driver import px4_configuration
from fpga_hdl.chips.ublox.link import TlmUbloxUart
from fpga_hdl.chips.ublox.model import UbloxM8Model
from fpga_hdl.cosim.harness import CosimHarness
from fpga_hdl.cosim.runner import missing_simulator_reason
from fpga_hdl.top import UART_CLK_HZ
from tests.fpga_hdl.transcript import run_script, tlm_transcript

pytestmark = [
    pytest.mark.cosim,
    pytest.mark.skipif(
        missing_simulator_reason("verilator") is not None,
        reason=str(missing_simulator_reason("verilator")),
    ),
]


def _run(coroutine):
    """The native buses never suspend: run a coroutine to its end without an event loop."""
    try:
        coroutine.send(None)
    except StopIteration as done:
        return done.value
    raise AssertionError("a native bus transaction suspended")


@pytest.fixture(scope="module")
def harness():
    from fpga_hdl.cosim.native import NativeHarness

    harness = NativeHarness()
    harness.reset()
    yield harness
    harness.close()


class _HostChips:
    def __init__(self, harness) -> None:
        self.harness = harness

    async def load(self, samples, now_us):
        self.harness.host.load(samples, now_us=now_us)


def test_compiled_harness_equals_tlm_byte_for_byte(harness):
    native = _run(run_script(harness.spi, harness.i2c, _HostChips(harness)))
    assert native == asyncio.run(tlm_transcript())
    assert any(rx.startswith("nack") for _, _, rx in native)  # the absent address
    sys_cycles, _, _ = harness.cycles()
    assert sys_cycles > 10_000  # the transfers really ran on the system clock


def test_the_capture_clock_runs_only_when_asked(harness):
    harness.pwm.write([100, 0, 0, 0], period_ticks=400)
    before = harness.cycles()
    harness.pwm.cycles(1000)
    after = harness.cycles()
    assert after == (before[0], before[1] + 1000, before[2])
    captures = harness.host.pwm_capture()
    assert captures[0].width_ticks == 100
    assert captures[0].period_ticks == 400
    assert captures[1].timeout  # never a pulse on channel 1


def test_px4s_gps_handshake_is_answered_and_timed_as_the_twin_predicts(harness):
    """The u-blox core answers each step of PX4's configuration over the UART peer with the
    twin's bytes, and the line time the peer measures is ``line_cycles`` to the cycle, on
    the UART clock alone: the system clock does not run for an exchange."""
    model = UbloxM8Model()
    twin = TlmUbloxUart(model, clk_hz=UART_CLK_HZ)
    for step in px4_configuration():
        before = harness.cycles()
        rtl = _run(harness.uart.exchange(step.frame, baud=step.baud))
        after = harness.cycles()
        assert rtl == asyncio.run(twin.exchange(step.frame, baud=step.baud))
        divider = divider_for(UART_CLK_HZ, step.baud)
        assert harness.uart.line_cycles == line_cycles(len(rtl.data), divider)
        assert after[:2] == before[:2]
        # The frame out, the answer back (the line in both directions), then the quiet time.
        out_cycles = len(step.frame) * 10 * divider
        assert after[2] - before[2] >= out_cycles + harness.uart.line_cycles
    assert model.baud == 115200
    silence = _run(harness.uart.exchange(b"", baud=115200))
    assert (silence.data, silence.line_us) == (b"", 0)


def test_an_unknown_spi_device_is_refused_before_the_simulator(harness):
    with pytest.raises(UnknownDevice, match="no SPI device 'gps'"):
        _run(harness.spi.transfer("gps", b"\x00", sclk_hz=1e6))


def test_the_library_is_built_once_per_content():
    from fpga_hdl.cosim.native import build_native_harness

    first = build_native_harness(CosimHarness())
    assert build_native_harness(CosimHarness()) == first
    assert first.is_file()
    assert first.parent.parent.name == "native"


def test_two_harnesses_close_in_either_order():
    """Closing the first of two harnesses once went through the second's freed Verilator
    context and deadlocked; a child process with a time limit keeps a regression from
    hanging the suite."""
    code = (
        "from fpga_hdl.cosim.native import NativeHarness\n"
        "first, second = NativeHarness(), NativeHarness()\n"
        "second.close()\n"
        "first.close()\n"
        "print('closed')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.stdout.strip() == "closed", done.stderr
