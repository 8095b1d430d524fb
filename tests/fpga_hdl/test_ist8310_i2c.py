# amaranth: UnusedElaboratable=no
"""amaranth.sim unit tests: the I2C target engine and the IST8310 core, against the TLM model.

The cycle-level I2C controller of ``fpga_hdl.verification.amaranth_i2c`` drives the core
in amaranth's simulator at 10 MHz, with UM10204 Fast-mode minimum timings rounded up to
whole cycles. It implements the ``I2cBus`` protocol, so PX4's driver runs over it unchanged.
"""

import asyncio

import numpy as np
import pytest

from fpga_hdl.buses.i2c_target import FAST_MODE, I2cTarget, TargetSampling
from fpga_hdl.buses.transactions import I2cNack, TlmI2cBus
from fpga_hdl.chips.ist8310 import regs
from fpga_hdl.chips.ist8310.core import Ist8310Core
from fpga_hdl.chips.ist8310.driver import Ist8310Driver, decode_field_gauss, sample_from_field_gauss
from fpga_hdl.chips.ist8310.model import Ist8310Model
from fpga_hdl.chips.ist8310.regs import Ist8310Sample, Register
from fpga_hdl.verification.amaranth_i2c import run_i2c_testbench
from fpga_hdl.verification.scoreboard import Scoreboard

SYS_CLK_HZ = 10e6


def simulate(core: Ist8310Core, bench):
    """Run ``bench(ctx, controller, core)`` against ``core`` on an open-drain bus."""
    return run_i2c_testbench(
        core, core.i2c, lambda ctx, controller: bench(ctx, controller, core), sys_clk_hz=SYS_CLK_HZ
    )


async def load(ctx, core: Ist8310Core, sample: Ist8310Sample) -> None:
    ctx.set(core.sample.as_value(), sample.as_register_bits())
    ctx.set(core.sample_stb, 1)
    await ctx.tick()
    ctx.set(core.sample_stb, 0)


# --- constructor checks -----------------------------------------------------------------


def test_address_must_be_one_the_pins_select():
    with pytest.raises(
        ValueError, match=r"^IST8310 address must be one of 0x0C, 0x0D, 0x0E, 0x0F, not 16$"
    ):
        Ist8310Core(sys_clk_hz=SYS_CLK_HZ, address=0x10)
    with pytest.raises(
        ValueError, match=r"^I2C address must be a 7-bit address in 0x08..0x77, not 120$"
    ):
        I2cTarget(address=0x78, sys_clk_hz=SYS_CLK_HZ)


def test_sampling_clock_too_slow_for_fast_mode_is_refused():
    message = (
        r"^sys_clk_hz 6e\+06 is too slow for Fast-mode: SDA would be valid 1000 ns after "
        r"SCL falls, t_VD;DAT allows 900 ns$"
    )
    with pytest.raises(ValueError, match=message):
        TargetSampling.for_clock(6e6)
    with pytest.raises(ValueError, match=r"^sys_clk_hz must be a positive frequency in Hz, not 0$"):
        TargetSampling.for_clock(0)


@pytest.mark.parametrize(
    ("clk_hz", "samples", "hold"),
    [(10e6, 2, 0), (20e6, 2, 1), (30e6, 3, 3), (50e6, 4, 8)],
)
def test_spike_filter_length_covers_t_sp(clk_hz, samples, hold):
    # N samples at 1/clk_hz apart span (N-1)/clk_hz >= 50 ns: no t_SP spike fills them.
    sampling = TargetSampling.for_clock(clk_hz)
    assert (sampling.filter_samples, sampling.hold_cycles) == (samples, hold)
    assert (sampling.filter_samples - 1) / clk_hz >= FAST_MODE.t_sp_max_ns * 1e-9 - 1e-15
    assert sampling.scl_to_sda_ns[0] >= 300 - 1e-9  # UM10204 note 2: 300 ns internal hold
    assert sampling.scl_to_sda_ns[1] <= FAST_MODE.t_vd_dat_max_ns


# --- protocol --------------------------------------------------------------------------


def test_wai_read_and_wrong_address_nack():
    async def bench(ctx, bus, core):
        wai = await bus.write_read(0x0E, bytes([Register.WAI]), 1, scl_hz=400e3)
        with pytest.raises(I2cNack, match=r"^I2C target 0x0D did not acknowledge the address$"):
            await bus.write_read(0x0D, bytes([Register.WAI]), 1, scl_hz=400e3)
        alternative = await bus.write_read(0x0E, b"", 1, scl_hz=400e3)  # pointer is now 1
        return wai, alternative

    assert simulate(Ist8310Core(sys_clk_hz=SYS_CLK_HZ), bench) == (b"\x10", b"\x00")


@pytest.mark.parametrize("address", regs.ADDRESSES)
def test_every_pin_selected_address_answers(address):
    async def bench(ctx, bus, core):
        return await Ist8310Driver(bus, address=address).probe()

    assert simulate(Ist8310Core(sys_clk_hz=SYS_CLK_HZ, address=address), bench)


def test_sda_changes_within_the_computed_hold_window():
    """Measure SCL-fall to SDA on the ACK of the address: inside scl_to_sda_ns."""

    async def bench(ctx, bus, core):
        await bus.start()
        for i in range(7, -1, -1):
            await bus.clock_bit((0x0E << 1) >> i & 1)
        # SCL has just fallen after the 8th bit: count cycles until the target pulls SDA.
        waited = 0
        while not ctx.get(core.i2c.sda_oe):
            await ctx.tick()
            waited += 1
        ack = await bus.clock_bit(1)
        await bus.stop()
        return waited, ack

    waited, ack = simulate(Ist8310Core(sys_clk_hz=SYS_CLK_HZ), bench)
    low_ns, high_ns = TargetSampling.for_clock(SYS_CLK_HZ).scl_to_sda_ns
    assert ack == 0
    assert low_ns <= waited * 1e9 / SYS_CLK_HZ <= high_ns


def test_master_nack_ends_a_read_and_releases_sda():
    async def bench(ctx, bus, core):
        await bus.start()
        await bus.write_byte(0x0E << 1 | 1)
        first = await bus.read_byte(ack=False)
        # After the NACK the target must leave SDA alone for the whole next byte.
        released = []
        for _ in range(9):
            released.append(await bus.clock_bit(1))
        await bus.stop()
        return first, released

    first, released = simulate(Ist8310Core(sys_clk_hz=SYS_CLK_HZ), bench)
    assert first == regs.DEVICE_ID
    assert released == [1] * 9


# --- IST8310 behaviour -----------------------------------------------------------------


def test_single_measurement_drdy_after_measurement_time_and_cleared_by_data_read():
    sample = Ist8310Sample(1234, -2345, 32767)

    async def bench(ctx, bus, core):
        driver = Ist8310Driver(bus)
        await load(ctx, core, sample)
        ctx.set(core.now_us, 2**32 - 1000)  # the measurement spans the 32-bit wrap
        await driver.start_measurement()
        mode_while_measuring = await driver.read_register(Register.CNTL1)
        ctx.set(core.now_us, 2**32 - 1000 + regs.MEASUREMENT_TIME_US - 1 - 2**32)
        early = await driver.read_measurement()
        ctx.set(core.now_us, 2**32 - 1000 + regs.MEASUREMENT_TIME_US - 2**32)
        ready = await driver.read_measurement()
        again = await driver.read_measurement()
        mode_after = await driver.read_register(Register.CNTL1)
        return mode_while_measuring, early, ready, again, mode_after

    mode_while, early, ready, again, mode_after = simulate(
        Ist8310Core(sys_clk_hz=SYS_CLK_HZ), bench
    )
    assert mode_while == regs.CNTL1_MODE_SINGLE
    assert early[0] == 0
    assert ready[0] == regs.STAT1_DRDY
    # Power-on default is 14-bit output: counts >> 2, little-endian.
    assert ready[1:] == (1234 >> 2).to_bytes(2, "little", signed=True) + (-2345 >> 2).to_bytes(
        2, "little", signed=True
    ) + (32767 >> 2).to_bytes(2, "little", signed=True)
    assert again[0] == 0  # DRDY cleared by reading the data
    assert mode_after == 0  # back to standby


def test_px4_sequence_round_trip_within_one_lsb():
    """SI field -> counts -> I2C -> PX4 decoding, in 16-bit mode after PX4's configure."""
    field = (0.21, -0.043, 0.45)  # gauss, PX4 sensor frame (forward, right, down)

    async def bench(ctx, bus, core):
        driver = Ist8310Driver(bus)
        assert await driver.probe()
        await driver.reset()
        assert await driver.reset_done()
        assert await driver.configure()
        await load(ctx, core, sample_from_field_gauss(field))
        await driver.start_measurement()
        ctx.set(core.now_us, 20_000)  # PX4 reads 20 ms later
        return await driver.read_field_gauss()

    decoded = simulate(Ist8310Core(sys_clk_hz=SYS_CLK_HZ), bench)
    np.testing.assert_allclose(decoded, field, rtol=0, atol=0.5 / regs.LSB_PER_GAUSS_16BIT)


def test_soft_reset_clears_configuration():
    async def bench(ctx, bus, core):
        driver = Ist8310Driver(bus)
        await bus.write_read(0x0E, bytes([Register.AVGCNTL, 0x24, 0xC0]), 0, scl_hz=400e3)
        before = await bus.write_read(0x0E, bytes([Register.AVGCNTL]), 2, scl_hz=400e3)
        await driver.reset()
        after = await bus.write_read(0x0E, bytes([Register.AVGCNTL]), 2, scl_hz=400e3)
        return before, after

    assert simulate(Ist8310Core(sys_clk_hz=SYS_CLK_HZ), bench) == (b"\x24\xc0", b"\x00\x00")


def test_sample_offered_during_a_read_appears_only_after_stop():
    old, new = Ist8310Sample(0x0101, 0x0202, 0x0303), Ist8310Sample(-1, -2, -3)

    async def bench(ctx, bus, core):
        await bus.write_read(0x0E, bytes([Register.CNTL3, 0x70]), 0, scl_hz=400e3)
        await load(ctx, core, old)
        await bus.write_read(0x0E, bytes([Register.DATAXL]), 0, scl_hz=400e3)
        await bus.start()
        await bus.write_byte(0x0E << 1 | 1)
        first = [await bus.read_byte(ack=True) for _ in range(3)]
        await load(ctx, core, new)  # the host updates mid-read
        rest = [await bus.read_byte(ack=i < 2) for i in range(3)]
        await bus.stop()
        after = await bus.write_read(0x0E, bytes([Register.DATAXL]), 6, scl_hz=400e3)
        return bytes(first + rest), after

    during, after = simulate(Ist8310Core(sys_clk_hz=SYS_CLK_HZ), bench)
    assert during == regs.data_bytes(old, 0x70)
    assert after == regs.data_bytes(new, 0x70)


def test_fault_mute_nacks_and_fault_flip_xors_sent_bytes():
    async def bench(ctx, bus, core):
        ctx.set(core.fault.flip, 0xA5)
        flipped = await bus.write_read(0x0E, bytes([Register.WAI]), 1, scl_hz=400e3)
        ctx.set(core.fault.flip, 0)
        ctx.set(core.fault.mute, 1)
        with pytest.raises(I2cNack):
            await bus.write_read(0x0E, bytes([Register.WAI]), 1, scl_hz=400e3)
        ctx.set(core.fault.mute, 0)
        return flipped, await bus.write_read(0x0E, bytes([Register.WAI]), 1, scl_hz=400e3)

    assert simulate(Ist8310Core(sys_clk_hz=SYS_CLK_HZ), bench) == (bytes([0x10 ^ 0xA5]), b"\x10")


def random_transactions(rng: np.random.Generator, count: int):
    """Register traffic a driver could send: pointers, config writes, triggers, bursts."""
    interesting = [int(r) for r in Register] + [0x43, 0xFE, 0xFF]
    for _ in range(count):
        pointer = int(rng.choice(interesting))
        kind = rng.integers(3)
        now_step = int(rng.integers(0, 8000))
        if kind == 0:
            payload = rng.integers(0, 256, size=int(rng.integers(1, 3))).tolist()
            yield now_step, bytes([pointer, *payload]), 0
        else:
            yield now_step, bytes([pointer]), int(rng.integers(1, 8))


def test_rtl_and_tlm_give_identical_bytes_for_random_traffic():
    rng = np.random.default_rng(20240531)
    traffic = list(random_transactions(rng, 40))
    samples = [Ist8310Sample(*rng.integers(-32768, 32768, size=3).tolist()) for _ in traffic]

    async def bench(ctx, bus, core):
        out, now = [], 0
        for (step, write, read_len), sample in zip(traffic, samples, strict=True):
            now += step
            ctx.set(core.now_us, now)
            await load(ctx, core, sample)
            out.append(await bus.write_read(0x0E, write, read_len, scl_hz=400e3))
        return out

    rtl = simulate(Ist8310Core(sys_clk_hz=SYS_CLK_HZ), bench)

    model = Ist8310Model()
    tlm_bus = TlmI2cBus({0x0E: model})
    scoreboard, now = Scoreboard(), 0
    for (step, write, read_len), sample, observed in zip(traffic, samples, rtl, strict=True):
        now += step
        model.now_us = now
        model.load_sample(sample)
        expected = asyncio.run(tlm_bus.write_read(0x0E, write, read_len, scl_hz=400e3))
        scoreboard.check(f"i2c 0x0E write {write.hex()} read {read_len}", expected, observed)
    assert any(r and r != bytes(len(r)) for r in rtl)  # the traffic really read data


def test_decode_rejects_a_short_buffer():
    with pytest.raises(ValueError, match=r"^IST8310 measurement must be 7 bytes, not 6$"):
        decode_field_gauss(bytes(6))


def test_px4_z_flip_maps_int16_min_to_max():
    raw = bytes([regs.STAT1_DRDY, 0, 0, 0, 0]) + (-32768).to_bytes(2, "little", signed=True)
    assert decode_field_gauss(raw) == (0.0, 0.0, 32767 / 1320)
