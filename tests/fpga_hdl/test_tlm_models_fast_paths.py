"""The TLM models' fast paths: cached data bytes, burst slices, the MS5611 inverse's guess.

Each cache must be invisible: a new sample or a configuration write shows in the very next
read, a burst equals the same registers read one by one, and the checked closed-form guess
of the MS5611 inverse gives the bisection's answer. Expected register values come from the
datasheet scale rules (RM-MPU-6000A-00 FS_SEL/AFS_SEL, IST8310 16/14-bit output), not from
the models.
"""

import asyncio

import numpy as np
import pytest

from fpga_hdl.buses.transactions import TlmI2cBus
from fpga_hdl.chips.ist8310 import regs as ist
from fpga_hdl.chips.ist8310.model import Ist8310Model
from fpga_hdl.chips.mpu6000 import regs as mpu
from fpga_hdl.chips.mpu6000.model import Mpu6000Model
from fpga_hdl.chips.ms5611 import regs as ms
from fpga_hdl.chips.ms5611.model import ADC_MAX, Ms5611Model, _nearest, raw_from_si

READ = mpu.READ_FLAG


def awake_mpu() -> Mpu6000Model:
    model = Mpu6000Model()
    model.transfer(bytes([mpu.Reg.PWR_MGMT_1, 0x01]))  # CLKSEL = 1, SLEEP cleared
    return model


def burst(model: Mpu6000Model, start: int, count: int) -> bytes:
    rx = model.transfer(bytes([start | READ]) + bytes(count))
    assert rx[0] == 0x00  # the command byte answers 0x00
    return rx[1:]


def int16s(data: bytes) -> list[int]:
    return [int.from_bytes(data[i : i + 2], "big", signed=True) for i in range(0, len(data), 2)]


def test_mpu6000_full_scale_write_rescales_the_next_burst():
    model = awake_mpu()
    one_g = int(mpu.ACCEL_LSB_PER_G_FINEST)  # 16384 LSB/g at AFS_SEL = 0
    model.load_sample(mpu.Mpu6000Sample(one_g, -one_g, 3 * one_g, -3400, 131, -262, 0))
    assert int16s(burst(model, mpu.Reg.ACCEL_XOUT_H, 14)) == [16384, -16384, 32767, -3400, 131,
                                                               -262, 0]  # fmt: skip
    model.transfer(bytes([mpu.Reg.ACCEL_CONFIG, 3 << mpu.FULL_SCALE_SHIFT]))  # ±16 g
    model.transfer(bytes([mpu.Reg.GYRO_CONFIG, 1 << mpu.FULL_SCALE_SHIFT]))  # ±500 °/s
    # Each selector step halves the sensitivity: 2048 LSB/g, 65.5 LSB/(°/s) (floor shift).
    assert int16s(burst(model, mpu.Reg.ACCEL_XOUT_H, 14)) == [2048, -2048, 6144, -3400, 65,
                                                               -131, 0]  # fmt: skip


def test_mpu6000_new_sample_shows_in_the_next_burst_and_reset_drops_the_scale():
    model = awake_mpu()
    model.transfer(bytes([mpu.Reg.ACCEL_CONFIG, 3 << mpu.FULL_SCALE_SHIFT]))
    model.load_sample(mpu.Mpu6000Sample(4096, 0, 0, 0, 0, 0, 0))
    assert int16s(burst(model, mpu.Reg.ACCEL_XOUT_H, 2)) == [512]
    model.load_sample(mpu.Mpu6000Sample(8192, 0, 0, 0, 0, 0, 0))
    assert int16s(burst(model, mpu.Reg.ACCEL_XOUT_H, 2)) == [1024]
    model.transfer(bytes([mpu.Reg.PWR_MGMT_1, mpu.PWR_MGMT_1_DEVICE_RESET]))
    assert int16s(burst(model, mpu.Reg.ACCEL_XOUT_H, 2)) == [8192]  # AFS_SEL back to 0
    model.load_sample(mpu.Mpu6000Sample(1, 0, 0, 0, 0, 0, 0))  # asleep after reset: dropped
    assert int16s(burst(model, mpu.Reg.ACCEL_XOUT_H, 2)) == [8192]


@pytest.mark.parametrize(
    ("start", "count"),
    [(0x3B, 14), (0x3A, 16), (0x41, 2), (0x47, 4), (0x6A, 12), (0x7E, 4), (0x00, 3)],
)
def test_mpu6000_burst_equals_single_register_reads(start, count):
    model = awake_mpu()
    model.transfer(bytes([mpu.Reg.GYRO_CONFIG, 0x18]))
    model.load_sample(mpu.Mpu6000Sample(-70000, 1, 2, 3, 200000, -5, 6))
    singles = bytes(burst(model, (start + i) & 0x7F, 1)[0] for i in range(count))
    assert burst(model, start, count) == singles


def test_mpu6000_write_burst_answers_old_values_then_writes():
    model = awake_mpu()
    rx = model.transfer(bytes([mpu.Reg.GYRO_CONFIG, 0x18, 0x10]))  # GYRO_CONFIG, ACCEL_CONFIG
    assert rx == bytes([0x00, 0x00, 0x00])  # reset values, read before each write
    assert burst(model, mpu.Reg.GYRO_CONFIG, 2) == bytes([0x18, 0x10])


def test_mpu6000_flip_and_mute_on_the_burst_path():
    model = awake_mpu()
    model.load_sample(mpu.Mpu6000Sample(0x1234, 0, 0, 0, 0, 0, 0))
    model.fault_flip = 0x81
    assert model.transfer(bytes([mpu.Reg.ACCEL_XOUT_H | READ, 0, 0])) == bytes([0x00, 0x93, 0xB5])
    model.fault_flip, model.fault_mute = 0, True
    assert model.transfer(bytes([mpu.Reg.WHO_AM_I | READ, 0])) == b"\xff\xff"
    model.transfer(bytes([mpu.Reg.ACCEL_CONFIG, 0x08]))  # a muted chip still takes writes
    model.fault_mute = False
    assert burst(model, mpu.Reg.ACCEL_CONFIG, 1) == b"\x08"


def test_mpu6000_from_si_closed_form_rounding_and_saturation():
    g = mpu.STANDARD_GRAVITY_MPS2
    lsb = g / mpu.ACCEL_LSB_PER_G_FINEST
    assert (2.5 * lsb) / g * mpu.ACCEL_LSB_PER_G_FINEST == 2.5  # an exact tie in floating point
    sample = mpu.Mpu6000Sample.from_si(
        [g, 2.5 * lsb, -40 * g], [1.0, -1e3, 0.0], mpu.TEMP_OFFSET_C + 1.0
    )
    # 1 g = 16384 LSB; 2.5 LSB rounds to even (2); -40 g saturates the 20-bit sample (±32 g);
    # 1 rad/s = 57.2958 °/s × 131 = 7505.75 → 7506; -1000 rad/s saturates; 1 °C = 340 LSB.
    assert sample == mpu.Mpu6000Sample(16384, 2, -(1 << 19), 340, 7506, -(1 << 19), 0)


def test_mpu6000_from_si_matches_numpy_over_the_whole_range():
    """Scalar quantisation against numpy's vectorised round-half-even and clip, for values
    across and beyond both full scales."""
    rng = np.random.default_rng(7)
    accel = rng.uniform(-40, 40, (500, 3)) * mpu.STANDARD_GRAVITY_MPS2
    gyro = rng.uniform(-50, 50, (500, 3))
    limit = 1 << 19
    want_accel = np.clip(np.round(accel / mpu.STANDARD_GRAVITY_MPS2 * mpu.ACCEL_LSB_PER_G_FINEST),
                         -limit, limit - 1)  # fmt: skip
    want_gyro = np.clip(np.round(np.degrees(gyro) * mpu.GYRO_LSB_PER_DPS_FINEST), -limit, limit - 1)
    for a, g, wa, wg in zip(accel, gyro, want_accel, want_gyro, strict=True):
        sample = mpu.Mpu6000Sample.from_si(a, g, 25.0)
        assert (sample.accel_x, sample.accel_y, sample.accel_z) == tuple(wa)
        assert (sample.gyro_x, sample.gyro_y, sample.gyro_z) == tuple(wg)


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_mpu6000_from_si_refuses_non_finite_values(bad):
    with pytest.raises(ValueError, match=r"^accel and gyro must be finite, not "):
        mpu.Mpu6000Sample.from_si([0.0, bad, 0.0], [0.0, 0.0, 0.0], 25.0)


def test_mpu6000_from_si_refuses_a_wrong_axis_count():
    with pytest.raises(ValueError, match=r"^accel and gyro must have 3 axes, not \(2,\)/\(3,\)$"):
        mpu.Mpu6000Sample.from_si([0.0, 0.0], [0.0, 0.0, 0.0], 25.0)


def read_field(bus: TlmI2cBus) -> list[int]:
    data = asyncio.run(bus.write_read(ist.DEFAULT_ADDRESS, bytes([ist.Register.DATAXL]), 6,
                                      scl_hz=400e3))  # fmt: skip
    return [int.from_bytes(data[i : i + 2], "little", signed=True) for i in (0, 2, 4)]


def test_ist8310_new_sample_and_resolution_change_show_in_the_next_read():
    model = Ist8310Model()
    bus = TlmI2cBus({model.address: model})
    model.load_sample(ist.Ist8310Sample(1320, -660, 4001))
    assert read_field(bus) == [330, -165, 1000]  # 14-bit default: counts >> 2 (floor)
    asyncio.run(bus.write_read(model.address, bytes([ist.Register.CNTL3, 0x70]), 0, scl_hz=400e3))
    assert read_field(bus) == [1320, -660, 4001]  # 16-bit output, 1320 LSB/G
    model.load_sample(ist.Ist8310Sample(-1, 2, -3))
    assert read_field(bus) == [-1, 2, -3]
    asyncio.run(bus.write_read(model.address, bytes([ist.Register.CNTL2, ist.CNTL2_SRST]), 0,
                               scl_hz=400e3))  # fmt: skip
    assert read_field(bus) == [-1, 0, -1]  # soft reset: back to 14-bit


def test_ms5611_adc_read_with_flip_pads_and_flips_every_byte():
    model = Ms5611Model()
    model.load_sample(0xABCDEF, 0x123456)
    model.transfer(bytes([ms.CMD_CONVERT_D1 + ms.Osr.OSR_256]))
    model.now_us += ms.CONVERSION_TIME_US[ms.Osr.OSR_256]
    model.fault_flip = 0x0F
    assert model.transfer(bytes([ms.CMD_ADC_READ, 0, 0, 0, 0])) == bytes([0, 0xA4, 0xC2, 0xE0,
                                                                          0x0F])  # fmt: skip


def pressure_at(d2: int):
    return lambda d1: ms.compensate(d1, d2, ms.DEFAULT_PROM).pressure


@pytest.mark.parametrize("temperature_c", [45.0, 20.0, 19.99, 3.2, -15.01, -39.0])
@pytest.mark.parametrize("pressure_pa", [1000.4, 54_321.5, 95_000.49, 101_325.0, 119_999.6])
def test_ms5611_inverse_is_the_nearest_input_in_every_compensation_branch(
    pressure_pa, temperature_c
):
    d1, d2 = raw_from_si(pressure_pa, temperature_c)
    target = round(pressure_pa)
    evaluate = pressure_at(d2)
    error = abs(evaluate(d1) - target)
    assert error <= abs(evaluate(d1 - 1) - target)
    assert error <= abs(evaluate(d1 + 1) - target)
    assert _nearest(target, evaluate, "pressure (Pa)") == d1  # bisection agrees with the guess
    temp = ms.compensate(d1, d2, ms.DEFAULT_PROM).temp
    assert abs(temp - round(temperature_c * 100)) <= 1  # 0.01 °C resolution near 2nd order


@pytest.mark.parametrize("guess", [None, 1, 5_000_000, 9_085_465, ADC_MAX, ADC_MAX + 7])
def test_ms5611_nearest_ignores_a_wrong_guess(guess):
    # The datasheet example: D1 = 9085466 at D2 = 8569150 gives P = 100009 (0.01 mbar).
    evaluate = pressure_at(8_569_150)
    bisection = _nearest(100_009, evaluate, "pressure (Pa)")
    assert evaluate(bisection) == 100_009
    assert _nearest(100_009, evaluate, "pressure (Pa)", guess) == bisection
