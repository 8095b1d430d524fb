# amaranth: UnusedElaboratable=no
"""PMW3901 TLM model, PX4-side driver and core without a cocotb simulator: PX4's sequence and
arithmetic, the datasheet's motion rules, and the core under ``amaranth.sim`` scored against
the model (the pin-level timing is in cocotb_pmw3901.py)."""

import numpy as np
import pytest

from fpga_hdl.buses.transactions import TlmSpiBus
from fpga_hdl.chips.pmw3901 import regs
from fpga_hdl.chips.pmw3901.core import Pmw3901
from fpga_hdl.chips.pmw3901.driver import (
    MOTION_READ,
    FlowReport,
    Pmw3901Driver,
    motion_read,
)
from fpga_hdl.chips.pmw3901.model import Pmw3901Model
from fpga_hdl.chips.pmw3901.regs import Pmw3901Sample, Reg
from fpga_hdl.top import SYS_CLK_HZ
from fpga_hdl.verification.amaranth_spi import AmaranthSpiController, run_spi_testbench
from fpga_hdl.verification.scoreboard import ScoredSpiBus
from rig.chips.layer import run_now


class WireLog:
    """A TLM bus that keeps every transfer, to rebuild what reached the chip."""

    def __init__(self, model: Pmw3901Model) -> None:
        self.bus = TlmSpiBus({"flow": model})
        self.sent: list[bytes] = []

    async def transfer(self, device: str, tx: bytes, *, sclk_hz: float) -> bytes:
        self.sent.append(tx)
        return await self.bus.transfer(device, tx, sclk_hz=sclk_hz)


@pytest.fixture
def chip():
    model = Pmw3901Model()
    log = WireLog(model)
    return model, Pmw3901Driver(log), log


def test_sample_fields_are_checked():
    with pytest.raises(ValueError, match=r"^PMW3901 sample shutter=8192 outside 0\.\.8191$"):
        Pmw3901Sample(0, 0, 0, 8192)
    with pytest.raises(
        ValueError, match=r"^PMW3901 sample delta_x=-32769 outside -32768\.\.32767$"
    ):
        Pmw3901Sample(-32769, 0, 0, 0)


def test_px4_init_reaches_the_chip_whole(chip):
    """Every register PX4's sensorInit writes holds the last value sent on the wire, and
    the chip tracks only once the last write arrived after a power-up reset."""
    model, driver, log = chip
    assert run_now(driver.probe())
    run_now(driver.init())
    assert model.tracking
    bank, last = 0, {}
    for tx in log.sent:
        if tx[0] & regs.WRITE_FLAG and tx[0] & 0x7F == Reg.BANK_SELECT:
            bank = tx[1]
        elif tx[0] & regs.WRITE_FLAG and tx[0] & 0x7F != Reg.POWER_UP_RESET:
            last[(bank, tx[0] & 0x7F)] = tx[1]
    assert last == model.stored
    assert len(last) == 61
    assert log.sent[:2] == [bytes([Reg.PRODUCT_ID, 0]), bytes([0x3A | 0x80, 0x5A])]
    assert log.sent[-1] == bytes([0x40 | 0x80, 0x80])
    # A chip that missed the power-up reset does not track after the same writes.
    fresh = Pmw3901Model()
    for tx in log.sent[2:]:
        fresh.transfer(tx)
    assert not fresh.tracking


def test_frames_before_tracking_are_not_taken(chip):
    model, driver, _ = chip
    model.load_sample(Pmw3901Sample(10, 10, 90, 100))
    run_now(driver.init())
    assert motion_read(model.transfer(MOTION_READ)) == (0, 0, 0)  # no frame taken yet
    model.load_sample(Pmw3901Sample(10, -10, 90, 100))
    assert motion_read(model.transfer(MOTION_READ)) == (10, -10, 90)
    model.transfer(bytes([Reg.SHUTDOWN | 0x80, regs.SHUTDOWN_VALUE]))
    model.load_sample(Pmw3901Sample(10, -10, 90, 100))
    assert motion_read(model.transfer(MOTION_READ)) == (0, 0, 0)


@pytest.mark.parametrize(
    ("deltas", "expected"),
    [
        ([(100, -100)] * 3, (300, -300)),
        ([(20_000, -20_000)] * 2, (32767, -32768)),  # saturates at int16
        ([(32767, -32768), (-1, 1)], (32766, -32767)),  # and counts back from the limit
    ],
)
def test_accumulation_saturates_and_clears_on_read(chip, deltas, expected):
    model, driver, _ = chip
    run_now(driver.init())
    for dx, dy in deltas:
        model.load_sample(Pmw3901Sample(dx, dy, 50, 0))
    burst = model.transfer(bytes([Reg.MOTION_BURST]) + bytes(6))
    assert burst[1] == regs.MOTION_MOT
    assert (int.from_bytes(burst[3:5], "little", signed=True),
            int.from_bytes(burst[5:7], "little", signed=True)) == expected  # fmt: skip
    assert model.transfer(MOTION_READ)[1::2][:5] == bytes(5)  # nothing since, MOT clear


def px4_radians(counts: int) -> float:
    """PX4's ``(float)sum / 385.0f``: single precision."""
    return float(np.float32(counts) / np.float32(385.0))


def test_driver_is_px4_run_impl():
    """A delta beyond ±240 is garbage (quality 0, not summed); a report every 20 ms with
    the sum / 385 in single precision and the mean quality of the reads used."""
    model = Pmw3901Model()
    driver = Pmw3901Driver(TlmSpiBus({"flow": model}))
    run_now(driver.init(now_us=5))
    frames = {10_005: (100, -7, 60), 20_005: (241, 0, 90), 30_005: (-3, 240, 31)}
    reports = []
    for now_us in (10_005, 20_005, 30_005, 40_005):
        if now_us in frames:
            model.load_sample(Pmw3901Sample(*frames[now_us], 0))
        reports.append(run_now(driver.cycle(now_us)))
    assert reports[0] is None
    # The garbage read (241) is neither summed nor in the mean quality.
    assert reports[1] == FlowReport((px4_radians(100), px4_radians(-7)), 20_000, 60, 20_005)
    assert reports[2] is None
    assert reports[3] == FlowReport((px4_radians(-3), px4_radians(240)), 20_000, 31, 40_005)
    assert reports[1].pixel_flow_rad[0] == pytest.approx(100 / 385, rel=1e-7)
    with pytest.raises(ValueError, match=r"^PMW3901 motion read is 12 bytes, not 2$"):
        motion_read(b"\x00\x00")


def test_faults(chip):
    model, driver, _ = chip
    run_now(driver.init())
    model.load_sample(Pmw3901Sample(5, 6, 70, 0))
    model.fault_own = regs.FAULT_DROP_FRAMES
    assert motion_read(model.transfer(MOTION_READ)) == (0, 0, 70)
    model.fault_own = 0
    model.fault_flip, model.fault_mute = 0xFF, False
    assert model.transfer(bytes([Reg.PRODUCT_ID, 0])) == bytes([0, 0x49 ^ 0xFF])
    model.fault_mute = True
    assert model.transfer(bytes([Reg.PRODUCT_ID, 0])) == b"\xff\xff"


def test_core_rejects_a_clock_too_slow_for_2_mhz_sclk():
    with pytest.raises(
        ValueError, match=r"^sys_clk_hz 500000 is too slow for SCLK up to 2e\+06 Hz"
    ):
        Pmw3901(sys_clk_hz=500e3)


def test_core_equals_model_under_amaranth_sim():
    """PX4's init and motion cycles, then random pairs and bursts, mode 3 at 2 MHz, on the
    core with a free-running system clock, every transfer scored against the model."""
    dut = Pmw3901(sys_clk_hz=SYS_CLK_HZ)
    model = Pmw3901Model()
    rng = np.random.default_rng(35)

    async def bench(ctx):
        spi = AmaranthSpiController(ctx, {"flow": dut.spi}, mode=3)
        await spi.idle()
        await ctx.tick().repeat(4)
        bus = ScoredSpiBus(spi, TlmSpiBus({"flow": model}))
        driver = Pmw3901Driver(bus)

        async def load(sample: Pmw3901Sample) -> None:
            ctx.set(dut.sample, sample.fields())
            ctx.set(dut.sample_stb, 1)
            await ctx.tick()
            ctx.set(dut.sample_stb, 0)
            await ctx.tick().repeat(3)
            model.load_sample(sample)

        assert await driver.probe()
        await driver.init()
        reports = 0
        for cycle in range(12):
            for _ in range(int(rng.integers(0, 3))):
                dx, dy = (int(v) for v in rng.integers(-300, 301, 2))
                await load(Pmw3901Sample(dx, dy, int(rng.integers(256)), int(rng.integers(8192))))
            reports += await driver.cycle(10_000 * (cycle + 1)) is not None
        for _ in range(20):
            register = int(rng.choice([*(int(r) for r in Reg), 0x48, 0x67]))
            tx = bytes([register | int(rng.integers(2)) * 0x80, int(rng.integers(256)),
                        Reg.MOTION_BURST, 0, 0, 0])  # fmt: skip
            await bus.transfer("flow", tx, sclk_hz=regs.SPI_TIMING.sclk_max_hz)
        assert reports == 6
        assert len(bus.scoreboard) > 120

    run_spi_testbench(dut, bench, sys_clk_hz=SYS_CLK_HZ)
