"""The compiled co-simulation harness (``fpga_hdl.cosim.native``): the same generated
Verilog as the cocotb tests, driven from C++ one transaction per call.

Byte equality with the transaction-level models on the shared script of PX4 traffic
(``transcript.py``, which ``test_cosim_harness`` also runs under cocotb and on the pins),
NACKs included; the rig's layer compares the PWM capture with the TLM frame by frame
(``tests/rig/test_cosim.py``).
"""

import asyncio
import contextlib
import random
import struct
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import pytest
from amaranth.hdl import Shape

from fpga_hdl.build import verilog_by_inputs, verilog_text
from fpga_hdl.buses.transactions import I2cNack, UnknownDevice
from fpga_hdl.buses.uart import divider_for, line_cycles
from fpga_hdl.chips.ist8310 import regs as ist
from fpga_hdl.chips.lidarlite import regs as lidar
from fpga_hdl.chips.pwm_capture.core import CHANNELS
from fpga_hdl.chips.ublox import ubx
from fpga_hdl.chips.ublox.driver import (
    GpsFix,
    UbloxDriver,
    UbxDecoder,
    px4_configuration,
)
from fpga_hdl.chips.ublox.link import TlmUbloxUart, receiver_solution
from fpga_hdl.chips.ublox.model import UbloxM8Model
from fpga_hdl.cosim.harness import (
    HARNESS_TOPLEVEL,
    I2C_READ_DEPTH,
    I2C_WRITE_DEPTH,
    PWM_COUNTER_BITS,
    SPI_DEPTH,
    UART_RX_DEPTH,
    UART_TX_DEPTH,
    CosimHarness,
)
from fpga_hdl.cosim.runner import missing_simulator_reason
from fpga_hdl.top import PWM_TICK_HZ, UART_CLK_HZ
from fpga_hdl.verification.scoreboard import Scoreboard
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


@contextlib.contextmanager
def _compared(**every_cycle: bool) -> Iterator[tuple[Any, Any]]:
    """A harness clocked by event (the default) and one clocking every cycle of what
    ``every_cycle`` names, both reset: the two a by-event test compares."""
    from fpga_hdl.cosim.native import NativeHarness

    harnesses = (NativeHarness(), NativeHarness(**every_cycle))
    try:
        for harness in harnesses:
            harness.reset()
        yield harnesses
    finally:
        for harness in harnesses:
            harness.close()


class _HostChips:
    def __init__(self, harness) -> None:
        self.harness = harness

    async def load(self, samples, now_us):
        self.harness.host.load(samples, now_us=now_us)


def test_compiled_harness_equals_tlm_byte_for_byte(harness):
    native = _run(run_script(harness.spi, harness.i2c, _HostChips(harness)))
    Scoreboard("compiled harness vs TLM").check_transcript(asyncio.run(tlm_transcript()), native)
    assert any(rx.startswith("nack") for _, _, rx in native)  # the absent address
    sys_cycles, _, _ = harness.cycles()
    assert sys_cycles > 10_000  # the transfers really ran on the system clock


def test_a_build_for_spi_mode_3_equals_tlm_byte_for_byte():
    """Built for mode 3, a deselected chip's SCLK rests high (SensorTop's ``spi_idle_sclk``),
    where the rig's mode-0 build holds it low: the IMU and barometer traffic reads the same."""
    from fpga_hdl.cosim.native import NativeHarness

    harness = NativeHarness(spi_mode=3)
    try:
        harness.reset()
        native = _run(run_script(harness.spi, harness.i2c, _HostChips(harness)))
    finally:
        harness.close()
    reference = asyncio.run(tlm_transcript())
    Scoreboard("compiled harness in SPI mode 3 vs TLM").check_transcript(reference, native)


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
    assert len(captures) == CHANNELS
    assert harness.host.pwm_capture(2) == captures[:2]  # a read of the first channels only


def test_the_capture_clock_by_event_equals_every_tick():
    """One edge per quiet stretch (the default) against one edge per tick: the same results
    at every read and the same tick count, through pulses, period starts, width changes,
    widths of 0, 1 and beyond the period, a stopped generator and the 0.1 s timeout."""
    rng = random.Random(36)
    timeouts = 0
    with _compared(pwm_by_event=False) as harnesses:
        by_event, every_tick = harnesses
        for _ in range(1500):
            if rng.random() < 0.3:
                period = rng.choice([2500, 2500, 2500, 3000, 20, 5, 2, 0])
                choices = [0, 1, 2, 3, max(0, period - 1), period, period + 1]
                widths = [rng.choice([*choices, rng.randint(900, 2100)]) for _ in range(CHANNELS)]
                for harness in harnesses:
                    harness.pwm.write(widths, period_ticks=period)
            ticks = rng.choice([1, 2, 3, 4, 7, 100, 1000, 2499, 4000, 150_000])
            for harness in harnesses:
                harness.pwm.cycles(ticks)
            captures = by_event.host.pwm_capture()
            assert captures == every_tick.host.pwm_capture()
            assert by_event.cycles() == every_tick.cycles()
            timeouts += sum(capture.timeout for capture in captures)
    assert timeouts > 0  # the programs reached the capture's timeout


def test_px4s_gps_handshake_is_answered_and_timed_as_the_twin_predicts(harness):
    """The u-blox core answers each step of PX4's configuration over the UART peer with the
    twin's bytes, and the line time the peer measures is ``line_cycles`` to the cycle, on
    the UART clock alone: the system clock does not run for an exchange."""
    model = UbloxM8Model()
    twin, scoreboard = TlmUbloxUart(model, clk_hz=UART_CLK_HZ), Scoreboard()
    for step in px4_configuration():
        before = harness.cycles()
        rtl = _run(harness.uart.exchange(step.frame, baud=step.baud))
        after = harness.cycles()
        expected = asyncio.run(twin.exchange(step.frame, baud=step.baud))
        scoreboard.check(f"{step.frame.hex()} at {step.baud} Bd", expected, rtl)
        divider = divider_for(UART_CLK_HZ, step.baud)
        assert harness.uart.line_cycles == line_cycles(len(rtl.data), divider)
        assert after[:2] == before[:2]
        # The frame out, the answer back (the line in both directions), then the quiet time.
        out_cycles = len(step.frame) * 10 * divider
        assert after[2] - before[2] >= out_cycles + harness.uart.line_cycles
    assert model.baud == 115200
    silence = _run(harness.uart.exchange(b"", baud=115200))
    assert (silence.data, silence.line_us) == (b"", 0)


def test_every_call_is_charged_to_its_bus_and_clock(harness):
    """The per-frame budget's source: each SPI device, I2C address, host-port burst and
    capture run has its own calls, cycles (of its clock) and wall time, and together the
    cycles are the clocks' counters."""

    def costs():
        return {cost.what: cost for cost in harness.costs()}

    before, cycles_before = costs(), harness.cycles()
    for _ in range(3):
        _run(harness.spi.transfer("baro", bytes(4), sclk_hz=1e6))
    _run(harness.i2c.write_read(0x0E, bytes([0x00]), 1, scl_hz=400e3))
    _run(harness.i2c.write_read(0x0E, bytes([0x00]), 1, scl_hz=400e3))
    harness.host.results()
    harness.pwm.cycles(250)
    harness.pwm.cycles(750)
    after, cycles_after = costs(), harness.cycles()
    spent = {what: cost.since(before.get(what)) for what, cost in after.items()}
    spent = {what: cost for what, cost in spent.items() if cost.calls}
    assert {what: (cost.calls, cost.clock) for what, cost in spent.items()} == {
        "SPI baro": (3, "system"),
        "I2C 0x0e": (2, "system"),
        "host-port read": (1, "system"),
        "PWM capture clock": (2, "capture"),
    }
    # A 4-byte transfer at a fifth of the system clock: 32 SCLK periods of 10 cycles.
    assert spent["SPI baro"].cycles >= 3 * 32 * 10
    assert spent["PWM capture clock"].cycles == 1000
    system = sum(cost.cycles for cost in spent.values() if cost.clock == "system")
    assert system == cycles_after[0] - cycles_before[0]
    assert all(cost.seconds > 0 for cost in spent.values())


FIX = GpsFix(
    fix_type=3, satellites_used=12, latitude_deg=47.3977419, longitude_deg=8.5455938,
    altitude_msl_m=488.1, altitude_ellipsoid_m=535.4, eph=0.8, epv=1.2, vel_n_m_s=1.0,
    vel_e_m_s=-2.0, vel_d_m_s=0.1, vel_m_s=2.24, cog_rad=1.0, s_variance_m_s=0.2,
    c_variance_rad=0.1, vel_ned_valid=True,
)  # fmt: skip


def test_the_uart_clock_by_event_equals_every_cycle():
    """One UART edge per quiet stretch (the default) against one edge per cycle: the same
    bytes, line times and cycle counts through PX4's configuration from 9600 Bd (rate
    switches, ACKs, NAKs, MON-VER), CFG-RATE, fixes at 10 Hz loaded just before an
    exchange or while a NAV-PVT is still on the line, the mute and flip faults, and
    bytes the receiver drops (garbage, a bad checksum, a frame split over exchanges)."""
    rng = random.Random(36)
    rate = ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_RATE, struct.pack("<HHH", 100, 1, 0))
    bad = bytearray(rate)
    bad[-1] ^= 0xFF

    def exchange(frame: bytes, baud: int) -> None:
        transfers = [_run(h.uart.exchange(frame, baud=baud)) for h in harnesses]
        assert transfers[0] == transfers[1], (frame.hex(), baud)
        assert by_event.uart.line_cycles == every_cycle.uart.line_cycles
        assert by_event.cycles() == every_cycle.cycles()

    with _compared(uart_by_event=False) as harnesses:
        by_event, every_cycle = harnesses
        for step in px4_configuration():
            exchange(step.frame, step.baud)
        exchange(rate, 115200)
        epoch_ms = 345_600_000
        for k in range(60):
            epoch_ms += 100
            fault = rng.choice([(False, 0)] * 6 + [(True, 0), (False, 0x5A)])
            pvt = receiver_solution(FIX, epoch_ms * 1000)
            for harness in harnesses:
                harness.host.load({"gps": pvt.fields()}, now_us=epoch_ms * 1000,
                                  faults={"gps": fault})  # fmt: skip
            extra = rng.choice([b"", b"", b"", bytes(rng.randrange(256) for _ in range(5)),
                                bytes(bad), rate[:5], rate[5:]])  # fmt: skip
            exchange(extra, 115200)
            if k % 7 == 3:  # the next fix lands while this one's NAV-PVT is on the line
                exchange(b"", 115200)
        assert by_event.cycles()[2] > 1_000_000  # whole frames really crossed the line


def test_the_i2c_clock_by_event_equals_every_cycle():
    """One I2C edge per quiet stretch (the default) against one edge per cycle: the same
    bytes, NACKs and cycle counts through random transfers to the IST8310, the LIDAR-Lite
    and an absent address at both rates (probes, register writes that start measurements,
    reads of up to the buffer's length, with and without auto-increment), samples, time
    and mute/flip faults loaded between them, and a sample loaded while the host writer
    clocks the bus between two transfers."""
    rng = random.Random(36)
    addresses = (ist.DEFAULT_ADDRESS, lidar.DEFAULT_ADDRESS, 0x30)
    nacks = reads = 0
    now_us = 1
    with _compared(i2c_by_event=False) as harnesses:
        by_event, every_cycle = harnesses
        for _ in range(400):
            if rng.random() < 0.3:
                now_us += rng.choice([1, 100, 6_000, 20_000])
                samples = {
                    "mag": {axis: rng.randrange(-32768, 32768) for axis in "xyz"},
                    "range": {"distance_cm": rng.randrange(1 << 16),
                              "signal_strength": rng.randrange(256),
                              "peak_strength": rng.randrange(256)},
                }  # fmt: skip
                faults = {chip: rng.choice([(False, 0)] * 6 + [(True, 0), (False, 0x5A)])
                          for chip in ("mag", "range")}  # fmt: skip
                for harness in harnesses:
                    harness.host.load(samples, now_us=now_us, faults=faults)
            address = rng.choice(addresses)
            register = rng.choice([0x00, 0x01, 0x02, 0x0C, 0x0F, 0x8F, 0x0A, 0x41, 0x03])
            noise = bytes(rng.randrange(256) for _ in range(I2C_WRITE_DEPTH))
            write = rng.choice([b"", bytes([register]), bytes([register, rng.choice([1, 4])]),
                                noise])  # fmt: skip
            read_len = rng.choice([0, 1, 2, 6, I2C_READ_DEPTH]) if write else rng.choice([0, 1])
            scl_hz = rng.choice([100e3, 400e3])
            results = []
            for harness in harnesses:
                try:
                    results.append(_run(harness.i2c.write_read(address, write, read_len,
                                                               scl_hz=scl_hz)))  # fmt: skip
                except I2cNack as nack:
                    results.append(f"nack {nack.byte_index}")
            assert results[0] == results[1], (hex(address), write.hex(), read_len, scl_hz)
            assert by_event.cycles() == every_cycle.cycles()
            nacks += isinstance(results[0], str)
            reads += isinstance(results[0], bytes) and len(results[0]) > 0
    assert nacks > 20  # the absent address and the muted chips refused
    assert reads > 100  # the others answered


def test_nav_pvt_follows_cfg_rate_on_the_rtl_as_on_the_twin():
    """After PX4's configuration, CFG-RATE measRate 1000, 200 and 100 ms: two seconds of
    the rig's 10 Hz measurements (the receiver's maximum) give NAV-PVT at 1, 5 and 10 Hz,
    the epochs whose iTOW measRate divides, through the host port, the crossing into the
    UART clock and the core, byte for byte and µs for µs as the twin. 50 ms (20 Hz, above
    what the rig measures) is ACKed and gives the 10 Hz measured; 10 ms (below u-blox's
    25 ms floor) is NAKed and the rate in force stays."""
    from fpga_hdl.cosim.native import NativeHarness

    harness = NativeHarness()
    try:
        harness.reset()
        model = UbloxM8Model()
        twin, scoreboard = TlmUbloxUart(model, clk_hz=UART_CLK_HZ), Scoreboard()
        rtl_driver, tlm_driver = UbloxDriver(harness.uart), UbloxDriver(twin)
        _run(rtl_driver.configure())
        asyncio.run(tlm_driver.configure())
        assert model.meas_rate_ms == 200
        start_ms = 345_600_000  # Tuesday 00:00 GPS time: every measRate divides it
        epochs = {}
        for meas_rate_ms, answer in ((1000, ubx.ID_ACK_ACK), (200, ubx.ID_ACK_ACK),
                                     (100, ubx.ID_ACK_ACK), (50, ubx.ID_ACK_ACK),
                                     (10, ubx.ID_ACK_NAK)):  # fmt: skip
            frame = ubx.frame(
                ubx.CLASS_CFG, ubx.ID_CFG_RATE, struct.pack("<HHH", meas_rate_ms, 1, 0)
            )
            rtl = _run(harness.uart.exchange(frame, baud=115200))
            expected = asyncio.run(twin.exchange(frame, baud=115200))
            scoreboard.check(f"CFG-RATE {meas_rate_ms} ms", expected, rtl)
            (reply,) = UbxDecoder().feed(rtl.data)
            assert (reply.cls, reply.msg_id, reply.payload) == (ubx.CLASS_ACK, answer, frame[2:4])
            itows = []
            for k in range(20):
                epoch_us = (start_ms + k * 100) * 1000
                pvt = receiver_solution(FIX, epoch_us)
                harness.host.load({"gps": pvt.fields()}, now_us=epoch_us)
                model.load_fix(pvt)
                rtl = _run(harness.uart.exchange(b"", baud=115200))
                expected = asyncio.run(twin.exchange(b"", baud=115200))
                scoreboard.check(f"epoch {k} at {meas_rate_ms} ms", expected, rtl)
                itows += [
                    ubx.NavPvt.from_payload(f.payload).iTOW for f in UbxDecoder().feed(rtl.data)
                ]
            epochs[meas_rate_ms] = itows
            start_ms += 2000
        assert model.meas_rate_ms == 50
    finally:
        harness.close()
    assert {rate: len(itows) for rate, itows in epochs.items()} == {
        1000: 2,
        200: 10,
        100: 20,
        50: 20,
        10: 20,
    }
    assert epochs[1000] == [345_600_000, 345_601_000]
    assert all(itow % 200 == 0 for itow in epochs[200])


def test_an_unknown_spi_device_is_refused_before_the_simulator(harness):
    with pytest.raises(UnknownDevice, match="no SPI device 'gps'"):
        _run(harness.spi.transfer("gps", b"\x00", sclk_hz=1e6))


def test_the_verilog_found_by_its_inputs_is_the_harness_converted_now():
    """The compiled harness's Verilog is found again by its parameters and fpga_hdl's
    sources, without Amaranth; what is found is what a conversion gives now, and the
    sizes its drivers are given are the design's."""
    found = verilog_by_inputs(CosimHarness, HARNESS_TOPLEVEL, {"pwm_tick_hz": PWM_TICK_HZ,
                                                             "spi_mode": 0})  # fmt: skip
    harness = CosimHarness(pwm_tick_hz=PWM_TICK_HZ, spi_mode=0)
    assert found.path.read_text() == verilog_text(harness, HARNESS_TOPLEVEL)
    widths = {
        name: Shape.cast(harness.signature.members[name].shape).width
        for name in ("spi_tx", "i2c_tx", "i2c_rx", "uart_tx", "uart_rx", "pwm_period_ticks")
    }
    assert widths == {
        "spi_tx": 8 * SPI_DEPTH,
        "i2c_tx": 8 * I2C_WRITE_DEPTH,
        "i2c_rx": 8 * I2C_READ_DEPTH,
        "uart_tx": 8 * UART_TX_DEPTH,
        "uart_rx": 8 * UART_RX_DEPTH,
        "pwm_period_ticks": PWM_COUNTER_BITS,
    }


def test_the_library_is_built_once_per_content():
    from fpga_hdl.cosim.native import build_native_harness

    first = build_native_harness()
    assert build_native_harness() == first
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
