# amaranth: UnusedElaboratable=no
"""Unit tests of the u-blox M8: UBX framing and checksum, the TLM twin, PX4's decoder,
the baud dividers, and the RTL core against the twin in amaranth.sim."""

import asyncio
import math
import struct

import pytest
from amaranth.sim import Simulator

from fpga_hdl.buses.uart import MIN_DIVIDER, baud_error, divider_for
from fpga_hdl.chips.ublox import ubx
from fpga_hdl.chips.ublox.core import BAUD_RATES, UbloxM8Core
from fpga_hdl.chips.ublox.driver import (
    PX4_BAUD_RATES,
    GpsFix,
    UbloxDriver,
    UbloxHandshakeError,
    UbxDecoder,
    decode_nav_pvt,
    nav_pvt_for_fix,
    px4_configuration,
)
from fpga_hdl.chips.ublox.link import (
    BAD_CHECKSUM_FLIP,
    GpsFault,
    TlmUbloxUart,
    receiver_solution,
)
from fpga_hdl.chips.ublox.model import UbloxM8Model
from fpga_hdl.chips.ublox.ubx import NavPvt
from fpga_hdl.top import SYS_CLK_HZ, UART_CLK_HZ
from fpga_hdl.verification.scoreboard import Scoreboard

FIX = GpsFix(
    fix_type=3,
    satellites_used=11,
    latitude_deg=-33.8688197,
    longitude_deg=151.2092955,
    altitude_msl_m=58.25,
    altitude_ellipsoid_m=80.5,
    eph=1.5,
    epv=2.25,
    vel_n_m_s=1.234,
    vel_e_m_s=-0.5,
    vel_d_m_s=-0.75,
    vel_m_s=1.3314,
    cog_rad=-0.3849,
    s_variance_m_s=0.3,
    c_variance_rad=0.05,
    vel_ned_valid=True,
)
CFG_RATE = ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_RATE, struct.pack("<HHH", 200, 1, 0))


# --- UBX framing ---------------------------------------------------------------------------


def test_checksum_of_a_known_frame():
    # MON-VER poll as every u-blox tool sends it: B5 62 0A 04 00 00 0E 34.
    assert ubx.frame(ubx.CLASS_MON, ubx.ID_MON_VER) == bytes.fromhex("b5620a0400000e34")
    assert ubx.checksum(bytes([0x06, 0x08, 0x06, 0x00, 0xC8, 0x00, 0x01, 0x00, 0x00, 0x00])) == (
        0xDD,
        0x68,
    )


def test_nav_pvt_layout_is_px4s_92_bytes_and_sources_render_the_payload():
    assert ubx.NAV_PVT_LEN == 92
    pvt = nav_pvt_for_fix(FIX, itow_ms=123_456)
    rendered = ubx.render(ubx.NAV_PVT_SOURCES, ubx.field_values(pvt))
    assert rendered == ubx.frame(ubx.CLASS_NAV, ubx.ID_NAV_PVT, pvt.payload())
    # PX4's struct offsets: fixType at 20, numSV 23, lon 24, lat 28, velN 48, pDOP 76.
    payload = pvt.payload()
    assert payload[20] == 3
    assert payload[23] == 11
    assert struct.unpack_from("<ii", payload, 24) == (pvt.lon, pvt.lat)
    assert struct.unpack_from("<i", payload, 48) == (1234,)
    assert struct.unpack_from("<H", payload, 76) == (pvt.pDOP,)
    assert NavPvt.from_payload(payload) == pvt


def test_nav_pvt_range_checked():
    with pytest.raises(ValueError, match=r"^NAV-PVT numSV=256 outside 0\.\.255$"):
        NavPvt(numSV=256)


# --- PX4's decoder -------------------------------------------------------------------------


def test_fix_round_trips_through_ubx_bytes_within_the_units():
    frame = ubx.frame(ubx.CLASS_NAV, ubx.ID_NAV_PVT, nav_pvt_for_fix(FIX).payload())
    decoder = UbxDecoder()
    (got,) = decoder.feed(b"\x00\xb5junk" + frame)
    fix = decode_nav_pvt(got.payload)
    assert fix.fix_type == 3
    assert fix.satellites_used == 11
    assert fix.vel_ned_valid
    for name, unit in (
        ("latitude_deg", 1e-7),
        ("longitude_deg", 1e-7),
        ("altitude_msl_m", 1e-3),
        ("eph", 1e-3),
        ("vel_d_m_s", 1e-3),
        ("cog_rad", math.radians(1e-5)),
    ):
        assert getattr(fix, name) == pytest.approx(getattr(FIX, name), abs=unit / 2 + 1e-12)


def test_decoder_drops_bad_checksums_like_px4():
    good = ubx.frame(ubx.CLASS_ACK, ubx.ID_ACK_ACK, bytes([0x06, 0x08]))
    bad_a, bad_b = bytearray(good), bytearray(good)
    bad_a[-2] ^= 1
    bad_b[-1] ^= 1
    decoder = UbxDecoder()
    assert decoder.feed(bytes(bad_a) + bytes(bad_b) + good) == [
        type(decoder.feed(good)[0])(ubx.CLASS_ACK, ubx.ID_ACK_ACK, bytes([0x06, 0x08]))
    ]
    assert decoder.checksum_errors == 2


def test_fix_type_rules_of_px4():
    no_fix = nav_pvt_for_fix(FIX).__class__(fixType=3, flags=0)
    assert decode_nav_pvt(no_fix.payload()).fix_type == 0  # gnssFixOK clear
    dgps = NavPvt(fixType=3, flags=ubx.FLAGS_GNSS_FIX_OK | ubx.FLAGS_DIFF_SOLN)
    assert decode_nav_pvt(dgps.payload()).fix_type == 4
    rtk_fixed = NavPvt(fixType=3, flags=ubx.FLAGS_GNSS_FIX_OK | 0x80)
    assert decode_nav_pvt(rtk_fixed.payload()).fix_type == 6


# --- TLM twin ------------------------------------------------------------------------------


def test_cfg_frames_are_acked_with_their_class_and_id():
    model = UbloxM8Model()
    model.receive(CFG_RATE)
    assert model.transmit() == ubx.frame(ubx.CLASS_ACK, ubx.ID_ACK_ACK, bytes([0x06, 0x08]))
    assert model.transmit() == b""


def test_bad_checksum_input_is_dropped_without_answer():
    model = UbloxM8Model()
    bad = bytearray(CFG_RATE)
    bad[-1] ^= 0x80
    model.receive(bytes(bad))
    assert model.transmit() == b""
    model.receive(CFG_RATE)  # the parser has recovered
    assert UbxDecoder().feed(model.transmit())[0].msg_id == ubx.ID_ACK_ACK


def test_px4_handshake_on_the_twin_ends_at_115200_with_nav_pvt():
    model = UbloxM8Model()
    decoder = UbxDecoder()
    for step in px4_configuration(9600):
        assert model.baud == step.baud
        model.receive(step.frame)
        (reply,) = decoder.feed(model.transmit())
        if step.expect == "nak":
            assert (reply.cls, reply.msg_id, reply.payload) == (ubx.CLASS_ACK, 0, b"\x06\x8a")
        elif step.expect == "mon-ver":
            assert reply.payload[30:38] == b"00080000"
        else:
            assert (reply.cls, reply.msg_id, reply.payload) == (ubx.CLASS_ACK, 1, step.frame[2:4])
    assert model.baud == 115200
    assert model.nav_pvt_enabled
    model.load_fix(nav_pvt_for_fix(FIX))
    (pvt,) = decoder.feed(model.transmit())
    assert decode_nav_pvt(pvt.payload).satellites_used == 11


def test_nav_pvt_is_off_until_cfg_msg_enables_it():
    model = UbloxM8Model()
    model.load_fix(nav_pvt_for_fix(FIX))
    assert model.transmit() == b""


def test_unsupported_rate_is_naked_and_kept():
    model = UbloxM8Model()
    block = struct.pack("<BBHIIHHHH", 1, 0, 0, 0x8D0, 921600, 1, 1, 0, 0)
    model.receive(ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_PRT, block))
    assert UbxDecoder().feed(model.transmit())[0].msg_id == ubx.ID_ACK_NAK
    assert model.baud == 9600


# --- baud dividers -------------------------------------------------------------------------


def test_every_supported_rate_divides_the_uart_clock_exactly():
    for baud in BAUD_RATES:
        assert baud_error(UART_CLK_HZ, baud) == 0
        assert UART_CLK_HZ / baud == divider_for(UART_CLK_HZ, baud) >= MIN_DIVIDER
    assert divider_for(UART_CLK_HZ, 115200) == 32
    assert set(BAUD_RATES) >= set(PX4_BAUD_RATES) - {921600}
    with pytest.raises(
        ValueError, match=r"^921600 baud at 3\.6864e\+06 Hz needs a divider of 4; at least 8$"
    ):
        divider_for(UART_CLK_HZ, 921600)
    with pytest.raises(
        ValueError, match=r"^921600 baud at 1\.6e\+07 Hz is off by \+2\.12% \(divider 17\)"
    ):
        divider_for(SYS_CLK_HZ, 921600)


# --- RTL against the twin (amaranth.sim, a slow clock keeps it short) -------------------------

SIM_CLK_HZ = 7.3728e6  # 4 x the classic UART crystal: every divider is exact
SIM_BAUD = 115200


def run_rtl(rx_frames: list[bytes], fixes: list[NavPvt], *, read_len: int) -> bytes:
    """Drive RXD with ``rx_frames``, then load ``fixes``; read ``read_len`` bytes off TXD."""
    core = UbloxM8Core(sys_clk_hz=SIM_CLK_HZ, baud=SIM_BAUD)
    divider = core.dividers[SIM_BAUD]
    sim = Simulator(core)
    sim.add_clock(1 / SIM_CLK_HZ)
    out = bytearray()

    async def drive(ctx):
        for frame in rx_frames:
            for byte in frame:
                for level in (0, *((byte >> k) & 1 for k in range(8)), 1):
                    ctx.set(core.rx, level)
                    await ctx.tick().repeat(divider)
        for fix in fixes:
            ctx.set(core.sample.as_value(), fix.as_bits())
            ctx.set(core.sample_stb, 1)
            await ctx.tick()
            ctx.set(core.sample_stb, 0)

    async def listen(ctx):
        while len(out) < read_len:
            await ctx.tick()
            if ctx.get(core.tx) == 0:  # a start bit began in the last cycle
                await ctx.tick().repeat(divider // 2)
                bits = []
                for _ in range(9):
                    await ctx.tick().repeat(divider)
                    bits.append(ctx.get(core.tx))
                assert bits[8] == 1, "stop bit low"
                out.append(sum(b << i for i, b in enumerate(bits[:8])))

    sim.add_testbench(drive, background=True)
    sim.add_testbench(listen)
    sim.run()
    return bytes(out)


def test_rtl_equals_twin_for_an_ack_and_a_nav_pvt():
    enable = ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_MSG, bytes([1, 7, 1]))
    fix = nav_pvt_for_fix(FIX, itow_ms=7000)  # an epoch of the power-on 1000 ms measRate
    model = UbloxM8Model(baud=SIM_BAUD)
    model.receive(enable)
    model.load_fix(fix)
    expected = model.transmit()
    assert len(expected) == 10 + 100
    observed = run_rtl([enable], [fix], read_len=len(expected))
    Scoreboard().check("CFG-MSG then a NAV-PVT epoch", expected, observed)


# --- the GNSS path for the sensor layers -----------------------------------------------------


def test_px4_driver_configures_the_twin_then_gets_each_fix_after_its_line_time():
    model = UbloxM8Model()
    driver = UbloxDriver(TlmUbloxUart(model, clk_hz=UART_CLK_HZ))
    asyncio.run(driver.configure())
    assert (driver.baud, model.baud, model.nav_pvt_enabled) == (115200, 115200, True)
    model.load_fix(receiver_solution(FIX, 200_000))
    asyncio.run(driver.receive(200_000))
    # 100 bytes at 115200 baud on the 3.6864 MHz UART clock (divider 32): 99 whole bytes,
    # then the last one's 9.5 bits and the receiver's three input registers.
    # 31,987 cycles of 1/3.6864 µs: 8677.03 µs, a byte there after it (was 8684 µs on the
    # 16 MHz system clock, whose divider 139 ran 0.07 % slow).
    line_us = math.ceil((99 * 10 * 32 + 9 * 32 + 16 + 3) * 1_000_000 / 3_686_400)
    assert line_us == 8678
    assert line_us == pytest.approx(100 * 10 / 115200 * 1e6, rel=0.001)
    assert driver.poll(200_000 + line_us - 1) == ()
    (got,) = driver.poll(200_000 + line_us)
    assert (got.time_us, got.sent_us) == (200_000 + line_us, 200_000)
    assert got.fix.latitude_deg == pytest.approx(FIX.latitude_deg, abs=1e-7)


@pytest.mark.parametrize(
    ("fault", "fix_type", "satellites", "eph"),
    [
        (GpsFault.LOSS_OF_FIX, 0, 0, FIX.eph),
        (GpsFault.JAMMED, 2, 3, 20 * FIX.eph),
    ],
)
def test_receiver_faults_reach_px4s_decoder(fault, fix_type, satellites, eph):
    got = decode_nav_pvt(receiver_solution(FIX, 0, fault).payload())
    assert (got.fix_type, got.satellites_used) == (fix_type, satellites)
    assert got.eph == pytest.approx(eph)
    assert got.vel_ned_valid is (fault is not GpsFault.LOSS_OF_FIX)


def test_a_bad_checksum_loses_that_epoch_only():
    model = UbloxM8Model()
    driver = UbloxDriver(TlmUbloxUart(model, clk_hz=UART_CLK_HZ))
    asyncio.run(driver.configure())
    for now_us, flip in ((0, BAD_CHECKSUM_FLIP), (200_000, 0)):
        model.fault_flip = flip
        model.load_fix(receiver_solution(FIX, now_us))
        asyncio.run(driver.receive(now_us))
    (got,) = driver.poll(10**6)
    assert got.sent_us == 200_000
    assert driver.decoder.checksum_errors == 1


def test_the_handshake_fails_in_one_line_when_the_receiver_stays_silent():
    model = UbloxM8Model()
    model.fault_mute = True
    driver = UbloxDriver(TlmUbloxUart(model, clk_hz=UART_CLK_HZ))
    with pytest.raises(UbloxHandshakeError, match="no ACK-NAK for message 0x06 0x8A at 9600"):
        asyncio.run(driver.configure())
