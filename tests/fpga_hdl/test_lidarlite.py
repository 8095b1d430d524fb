"""LIDAR-Lite v3 TLM model and PX4-side driver: the datasheet's register behaviour and PX4's
decoding, without a simulator (the RTL is compared with this model in cocotb_lidarlite.py)."""

import pytest

from fpga_hdl.buses.transactions import I2cNack, TlmI2cBus
from fpga_hdl.chips.lidarlite import regs
from fpga_hdl.chips.lidarlite.driver import (
    LidarLiteDriver,
    LidarLiteVersion,
    Range,
    decode_range,
    sample_from_range,
)
from fpga_hdl.chips.lidarlite.model import LidarLiteModel
from fpga_hdl.chips.lidarlite.regs import LidarLiteSample, Register
from rig.chips.layer import run_now

DISTANCE = Register.FULL_DELAY_HIGH | regs.POINTER_AUTO_INCREMENT


@pytest.fixture
def chip():
    model = LidarLiteModel()
    return model, LidarLiteDriver(TlmI2cBus({regs.DEFAULT_ADDRESS: model}))


@pytest.mark.parametrize(
    ("distance_m", "expected"),
    [
        (1.234, LidarLiteSample(123, 128, 234)),
        (1.235, LidarLiteSample(124, 128, 234)),  # to the nearest cm
        (0.0, LidarLiteSample(0, 128, 234)),
        (400.0, LidarLiteSample(0x7FFF, 128, 234)),  # bit 15 would mark it invalid
        (None, LidarLiteSample(regs.NO_RETURN_CM, 0, 0)),
    ],
)
def test_sample_from_range_quantizes_to_centimetres(distance_m, expected):
    assert sample_from_range(distance_m) == expected


@pytest.mark.parametrize(
    ("raw", "signal", "peak", "expected"),
    [
        (b"\x01\xf4", 128, 234, Range(5.0, 100)),  # 500 cm, full peak
        (b"\x01\xf4", 128, 184, Range(5.0, 49)),  # 100·(184−135)/99 = 49.49 → 49
        (b"\x01\xf4", 128, 100, Range(5.0, 0)),  # peak below 135
        (b"\x01\xf4", 24, 234, Range(5.0, 0)),  # signal at PX4's threshold: ambiguous
        (b"\x00\x04", 128, 234, Range(0.04, 0)),  # below PX4's 5 cm
        (b"\x80\x10", 128, 234, None),  # high bit: invalid
    ],
)
def test_decode_is_px4_collect(raw, signal, peak, expected):
    result = decode_range(raw, signal, peak)
    if expected is None:
        assert result is None
    else:
        assert result.signal_quality == expected.signal_quality
        assert result.distance_m == pytest.approx(expected.distance_m, abs=1e-12)


def test_decode_rejects_a_short_read():
    with pytest.raises(ValueError, match=r"^LIDAR-Lite distance read must be 2 bytes, not 1$"):
        decode_range(b"\x00", 0, 0)


def test_sample_fields_are_checked():
    with pytest.raises(
        ValueError, match=r"^LIDAR-Lite sample distance_cm must fit 16 bits, not 65536$"
    ):
        LidarLiteSample(65536, 0, 0)


def test_px4_probe_takes_it_for_a_v3_and_reset_restores_defaults(chip):
    _, driver = chip
    assert run_now(driver.probe()) is LidarLiteVersion.V1_V3
    assert driver.max_distance_m == 25.0  # PX4's limit for v1/v3
    run_now(driver.write_register(Register.ACQ_CONFIG_REG, 0x5A))
    run_now(driver.reset())
    config, count = (run_now(driver.read_register(r))[0]
                     for r in (Register.ACQ_CONFIG_REG, Register.SIG_COUNT_VAL))  # fmt: skip
    assert (config, count) == (0x08, 0xFF)  # reset value; PX4 wrote the count after


def test_acquisition_shows_the_previous_result_until_the_datasheet_time(chip):
    model, driver = chip
    model.load_sample(sample_from_range(2.5))
    model.now_us = 2**32 - 100  # spans the wrap of the µs counter
    run_now(driver.measure())
    model.load_sample(sample_from_range(9.0))  # the scene changes after the command
    (status,) = run_now(driver.read_register(Register.STATUS))
    assert status == regs.STATUS_HEALTH | regs.STATUS_BUSY | regs.STATUS_INVALID_SIGNAL
    assert run_now(driver.collect()) == Range(0.0, 0)  # nothing measured before
    model.now_us = regs.ACQUISITION_TIME_US - 100 - 1
    assert run_now(driver.collect()) == Range(0.0, 0)
    model.now_us += 1
    assert run_now(driver.collect()) == Range(2.5, 100)  # the scene at the command
    (status,) = run_now(driver.read_register(Register.STATUS))
    assert status == regs.STATUS_HEALTH
    model.now_us += 2**32 - 1  # much later (wrapped): the result stands
    assert run_now(driver.collect()) == Range(2.5, 100)


def test_pointer_bit7_auto_increments_within_seven_bits(chip):
    model, _ = chip
    model.load_sample(LidarLiteSample(0x1234, 0x56, 0x78))
    model.write_read(bytes([Register.ACQ_COMMAND, regs.ACQ_MEASURE]), 0)
    model.now_us = regs.ACQUISITION_TIME_US
    assert model.write_read(bytes([DISTANCE]), 2) == b"\x12\x34"
    assert model.write_read(bytes([Register.FULL_DELAY_HIGH]), 2) == b"\x12\x12"
    assert model.write_read(bytes([0xFF]), 2) == b"\x00\x00"  # 0x7F then 0x00 (ACQ_COMMAND)
    assert model.pointer == 0x81


def test_faults(chip):
    model, driver = chip
    model.fault_flip = 0xFF
    assert run_now(driver.read_register(Register.SIG_COUNT_VAL)) == bytes([0x80 ^ 0xFF])
    model.fault_mute = True
    with pytest.raises(I2cNack, match=r"^I2C target 0x62 did not acknowledge the address$"):
        run_now(driver.measure())
