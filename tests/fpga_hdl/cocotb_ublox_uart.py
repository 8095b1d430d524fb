"""cocotb bench for the u-blox M8 core's UART: bit timing at every rate, back-to-back
frames, the receiver's rate tolerance, dropped bad input, faults, and PX4's whole
configuration handshake read by cocotbext-uart's UartSink, byte-identical to the TLM twin.

Run from ``test_ublox_cosim.py`` on every simulator, on a core built for SensorTop's UART
clock ``UART_CLK_HZ`` (3.6864 MHz: 32 cycles a bit at 115200 baud), driven here at the
nearest whole-picosecond period. The core's TXD is recorded edge by edge;
:func:`decode_line` samples it as a receiver does and checks every edge lies on the bit
grid measured from the frames.
"""

import itertools
import logging
import struct
import warnings

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, RisingEdge, Timer
from cocotb.utils import get_sim_time
from cocotbext.uart import UartSink, UartSource

from fpga_hdl.buses.uart import MAX_BAUD_ERROR, divider_for
from fpga_hdl.chips.ublox import ubx
from fpga_hdl.chips.ublox.core import BAUD_RATES, EPOCH_DECISION_CYCLES, RESET_BAUD
from fpga_hdl.chips.ublox.driver import (
    GpsFix,
    UbxDecoder,
    decode_nav_pvt,
    nav_pvt_for_fix,
    px4_configuration,
)
from fpga_hdl.chips.ublox.model import UbloxM8Model
from fpga_hdl.top import UART_CLK_HZ
from fpga_hdl.verification.scoreboard import Scoreboard

# cocotbext-uart 0.1.4 calls cocotb 2's deprecated ``setimmediatevalue`` once per source;
# the run turns warnings into errors, so this one line of third-party noise is let through.
warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"cocotbext\.uart")

#: Whole picoseconds in each half (cocotb's Clock wants it): 271268 ps, 2.4 ppm slow.
CLK_PS = 2 * round(0.5e12 / UART_CLK_HZ)
CFG_RATE = ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_RATE, struct.pack("<HHH", 200, 1, 0))
ENABLE_PVT = ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_MSG, bytes([ubx.CLASS_NAV, ubx.ID_NAV_PVT, 1]))


def cfg_prt(baud: int) -> bytes:
    block = struct.pack("<BBHIIHHHH", ubx.PORT_UART1, 0, 0, 0x8D0, baud, 0x21, 0x01, 0, 0)
    return ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_PRT, block)


def decode_line(edges, t_from: int, baud: int):
    """Frames on TXD after ``t_from`` (ps): their bytes, start times and bit period.

    Sampled mid-bit at the nominal rate, as a receiver does. Checks: the start bit is low
    and the stop bit high; the bit period measured over the whole run (start-to-start
    spacing of back-to-back frames, else the frame's last edge) is within the budget, and
    every edge lies on that grid within one system clock.
    """
    nominal = 1e12 / baud

    def level(t: float) -> int:
        value = 1
        for when, v in edges:
            if when > t:
                break
            value = v
        return value

    out, starts = bytearray(), []
    falls = [t for t, v in edges if v == 0 and t >= t_from]
    while falls:
        t0 = falls[0]
        bits = [level(t0 + (k + 0.5) * nominal) for k in range(10)]
        assert bits[0] == 0, f"start bit high at {t0} ps"
        assert bits[9] == 1, f"stop bit low in the frame starting at {t0} ps"
        out.append(sum(b << i for i, b in enumerate(bits[1:9])))
        starts.append(t0)
        falls = [t for t in falls if t > t0 + 9.5 * nominal]
    period = (starts[-1] - starts[0]) / (10 * (len(starts) - 1)) if len(starts) > 1 else nominal
    for t0 in starts:
        for t, _ in edges:
            if t0 <= t < t0 + 10 * period:
                k = round((t - t0) / period)
                assert abs(t - t0 - k * period) <= CLK_PS, f"edge {t} ps off the bit grid"
    return bytes(out), starts, period


class Bench:
    """The core with its clock, TXD recorder, UART source/sink and the TLM twin."""

    def __init__(self, dut) -> None:
        self.dut = dut
        self.model = UbloxM8Model()
        #: Each reply as the TXD line and as UartSink read it, against the twin's bytes.
        self.scoreboard = Scoreboard()
        self.edges: list[tuple[int, int]] = []
        self.baud = RESET_BAUD
        self.source = self.sink = None
        self.t_mark = 0

    async def start(self) -> None:
        dut = self.dut
        Clock(dut.clk, CLK_PS, unit="ps").start()
        dut.rst.value = 1
        dut.rx.value = 1
        dut.sample.value = 0
        dut.sample_stb.value = 0
        dut.fault__mute.value = 0
        dut.fault__flip.value = 0
        await ClockCycles(dut.clk, 4)
        dut.rst.value = 0
        await ClockCycles(dut.clk, 2)
        cocotb.start_soon(self._record())
        self.use_baud(RESET_BAUD)

    async def _record(self) -> None:
        while True:
            await self.dut.tx.value_change
            self.edges.append((get_sim_time("ps"), int(self.dut.tx.value)))

    def use_baud(self, baud: int, *, source_baud: float | None = None) -> None:
        """Sink at ``baud``, source at ``source_baud`` (default the same). cocotbext-uart
        0.1.4's baud setter recurses, so the old pair is stopped and a new one made."""
        for old in (self.source, self.sink):
            if old is not None:
                old._run_cr.cancel()
        self.source = UartSource(self.dut.rx, baud=source_baud or baud)
        self.sink = UartSink(self.dut.tx, baud=baud)
        for part in (self.source, self.sink):
            part.log.setLevel(logging.WARNING)
        self.baud = baud

    def mark(self) -> None:
        """Output after this instant is what the next :meth:`expect` checks."""
        self.t_mark = get_sim_time("ps")

    async def send(self, frame: bytes) -> None:
        """Send ``frame`` to RXD (the reply may start in its last stop bit)."""
        self.mark()
        await self.source.write(frame)
        await self.source.wait()
        self.model.receive(frame)

    async def expect(self, expected: bytes) -> bytes:
        """Wait for ``expected`` on TXD; check the line, the sink and the twin agree."""
        baud = self.baud
        await Timer(round((len(expected) + 2) * 10e12 / baud), "ps")
        line, _, _ = decode_line(self.edges, self.t_mark, baud)
        self.scoreboard.check(f"TXD at {baud} Bd", expected, line)
        self.scoreboard.check(f"UartSink at {baud} Bd", expected, bytes(self.sink.read_nowait()))
        return line

    async def load(self, fix: ubx.NavPvt) -> None:
        await RisingEdge(self.dut.clk)
        self.dut.sample.value = fix.as_bits()
        self.dut.sample_stb.value = 1
        await RisingEdge(self.dut.clk)
        self.dut.sample_stb.value = 0
        self.model.load_fix(fix)


FIX = GpsFix(
    fix_type=3,
    satellites_used=14,
    latitude_deg=47.3977419,
    longitude_deg=8.5455938,
    altitude_msl_m=488.123,
    altitude_ellipsoid_m=535.456,
    eph=0.812,
    epv=1.234,
    vel_n_m_s=-3.21,
    vel_e_m_s=12.5,
    vel_d_m_s=0.4,
    vel_m_s=12.906,
    cog_rad=1.8221,
    s_variance_m_s=0.15,
    c_variance_rad=0.02,
    vel_ned_valid=True,
)


@cocotb.test()
async def px4_handshake_then_nav_pvt_read_by_uartsink_equal_to_tlm(dut):
    """PX4's configure() against the core: 38400 attempt unanswered, NAK for CFG-VALSET,
    ACKs, rate switches 9600 -> 38400 -> 115200, MON-VER, then NAV-PVT back to back."""
    bench = Bench(dut)
    await bench.start()
    # PX4 tries 38400 first; the receiver listens at 9600 and must not answer garbage.
    bench.use_baud(38400)
    t_from = get_sim_time("ps")
    await bench.source.write(cfg_prt(38400))
    await bench.source.wait()
    await Timer(20, "ms")
    assert [e for e in bench.edges if e[0] >= t_from] == []
    bench.use_baud(9600)
    bench.model = UbloxM8Model()  # the twin never saw the garbled bytes
    for step in px4_configuration(9600):
        assert round(bench.baud) == step.baud
        await bench.send(step.frame)
        expected = bench.model.transmit()
        line = await bench.expect(expected)
        (reply,) = UbxDecoder().feed(line)
        if step.expect == "nak":
            assert (reply.cls, reply.msg_id) == (ubx.CLASS_ACK, ubx.ID_ACK_NAK)
        elif step.expect == "mon-ver":
            assert reply.payload[30:40].rstrip(b"\0") == b"00080000"
        else:
            assert (reply.cls, reply.msg_id) == (ubx.CLASS_ACK, ubx.ID_ACK_ACK)
            assert reply.payload == step.frame[2:4]
        if step.then_baud is not None:
            await Timer(round(20e12 / step.baud), "ps")  # the switch follows the ACK
            assert int(dut.baud.value) == step.then_baud == bench.model.baud
            bench.use_baud(step.then_baud)
    fixes = [nav_pvt_for_fix(FIX, itow_ms=1000 * i) for i in range(1, 4)]
    bench.mark()
    await bench.load(fixes[0])
    expected = bench.model.transmit()
    # The first NAV-PVT has started: the epoch decided, then a few cycles to its start bit.
    await ClockCycles(dut.clk, EPOCH_DECISION_CYCLES + 10)
    for fix in fixes[1:]:  # two epochs during it: the latest follows it at once
        await bench.load(fix)
    expected += bench.model.transmit()
    assert len(expected) == 2 * 100
    line = await bench.expect(expected)
    _, starts, period = decode_line(bench.edges, bench.t_mark, 115200)
    assert all(b - a == round(10 * period) for a, b in itertools.pairwise(starts))
    decoder = UbxDecoder()
    frames = decoder.feed(line)
    assert decoder.checksum_errors == 0
    decoded = [decode_nav_pvt(f.payload) for f in frames]
    assert [ubx.NavPvt.from_payload(f.payload).iTOW for f in frames] == [1000, 3000]
    assert decoded[0].fix_type == 3
    assert decoded[0].satellites_used == 14
    assert abs(decoded[0].latitude_deg - FIX.latitude_deg) <= 0.5e-7
    assert abs(decoded[0].vel_e_m_s - FIX.vel_e_m_s) <= 0.5e-3


@cocotb.test()
async def bit_timing_at_every_supported_rate(dut):
    """Start bit, 8 data bits LSB first, stop bit; the measured bit period is the
    divider's, within the budget of the nominal rate, at each rate of BAUD_RATES."""
    bench = Bench(dut)
    await bench.start()
    for i, baud in enumerate(BAUD_RATES):
        assert int(dut.baud.value) == baud
        nxt = BAUD_RATES[i + 1] if i + 1 < len(BAUD_RATES) else None
        frame = cfg_prt(nxt) if nxt else CFG_RATE
        await bench.send(frame)
        await bench.expect(bench.model.transmit())
        _, starts, period = decode_line(bench.edges, bench.t_mark, baud)
        assert len(starts) == 10
        assert period == divider_for(UART_CLK_HZ, baud) * CLK_PS
        error = period * baud / 1e12 - 1
        assert abs(error) <= MAX_BAUD_ERROR, f"{baud} baud: bit period off by {error:+.3%}"
        dut._log.info("%d baud: bit %.1f ns, error %+.3f %%", baud, period / 1e3, error * 100)
        if nxt:
            await Timer(round(20e12 / baud), "ps")
            bench.use_baud(nxt)


@cocotb.test()
async def receiver_accepts_a_sender_three_percent_off(dut):
    """The autopilot's UART may be off too: CFG frames at ±3 % still get their ACK."""
    bench = Bench(dut)
    await bench.start()
    for baud in (9600, 115200):
        if baud != bench.baud:
            await bench.send(cfg_prt(baud))
            await bench.expect(bench.model.transmit())
            await Timer(round(20e12 / bench.baud), "ps")
        for offset in (0.97, 1.03):
            bench.use_baud(baud, source_baud=baud * offset)
            await bench.send(CFG_RATE)
            await bench.expect(bench.model.transmit())


@cocotb.test()
async def bad_checksum_and_framing_error_are_dropped(dut):
    bench = Bench(dut)
    await bench.start()
    bad = bytearray(CFG_RATE)
    bad[-1] ^= 0x01
    await bench.send(bytes(bad))
    assert bench.model.transmit() == b""
    t_from = get_sim_time("ps")
    await Timer(round(40e12 / 9600), "ps")
    assert [e for e in bench.edges if e[0] >= t_from] == []
    # A low stop bit in the middle of an otherwise valid frame: the byte is lost.
    bit_ps = round(1e12 / 9600)
    for i, byte in enumerate(CFG_RATE):
        stop = 0 if i == 5 else 1
        for level in (0, *((byte >> k) & 1 for k in range(8)), stop):
            dut.rx.value = level
            await Timer(bit_ps, "ps")
    dut.rx.value = 1
    await Timer(round(40e12 / 9600), "ps")
    assert [e for e in bench.edges if e[0] >= t_from] == []
    await bench.send(CFG_RATE)
    await bench.expect(bench.model.transmit())


@cocotb.test()
async def faults_flip_bytes_and_mute_the_line(dut):
    bench = Bench(dut)
    await bench.start()
    await bench.send(cfg_prt(115200))
    await bench.expect(bench.model.transmit())
    await Timer(round(20e12 / 9600), "ps")
    bench.use_baud(115200)
    await bench.send(ENABLE_PVT)
    await bench.expect(bench.model.transmit())
    dut.fault__flip.value = 0x40
    bench.model.fault_flip = 0x40
    bench.mark()
    await bench.load(nav_pvt_for_fix(FIX))
    line = await bench.expect(bench.model.transmit())
    decoder = UbxDecoder()
    assert decoder.feed(line) == []  # the header is intact, the payload and checksum not
    assert decoder.checksum_errors == 1
    dut.fault__flip.value = 0
    dut.fault__mute.value = 1
    bench.model.fault_flip, bench.model.fault_mute = 0, True
    t_from = get_sim_time("ps")
    await bench.load(nav_pvt_for_fix(FIX))
    assert bench.model.transmit() == b""
    await Timer(round(1100e12 / 115200), "ps")
    assert [e for e in bench.edges if e[0] >= t_from] == []
