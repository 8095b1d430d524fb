"""cocotb side of ``bench_fpga_hdl``: the rig's full sensor frame over the harness's fast path.

A frame is one 1 kHz IMU period as the closed loop runs it: load the samples and the
time (one host-port burst), read the MPU-6000 burst at 5 MHz, every 10th frame the
IST8310 (STAT1 + 6 data bytes, then the next single-measurement trigger, 400 kHz) and
the MS5611 cycle (ADC READ, next CONVERT), write the four motor widths to the PWM
generator (400 Hz), read the PWM capture back through the host port, then let simulated
time reach the frame's end, with the PWM clock running throughout. Figures go to
$BENCH_OUT as JSON: wall time, clock cycles and transactions per part.
"""

import json
import os
import time

import cocotb
import numpy as np
from cocotb.utils import get_sim_time

from fpga_hdl.chips.ist8310.driver import Ist8310Driver
from fpga_hdl.chips.mpu6000 import regs as mpu
from fpga_hdl.chips.mpu6000.driver import Mpu6000Driver
from fpga_hdl.chips.ms5611 import regs as baro
from fpga_hdl.chips.ms5611.driver import Ms5611Driver
from fpga_hdl.cosim.peripherals import Harness

FRAMES = int(os.environ.get("BENCH_FRAMES", "200"))
PWM = os.environ.get("BENCH_PWM", "1") == "1"
FRAME_US = 1000
PWM_PERIOD_TICKS = 2500  # 400 Hz at 1 µs


@cocotb.test()
async def frames(dut):
    harness = Harness(dut)
    await harness.reset()
    now_us = [1]

    async def sleep_us(us):
        now_us[0] += us
        await harness.host.load({}, now_us=now_us[0])

    imu = Mpu6000Driver(harness.spi)
    barometer = Ms5611Driver(harness.spi, sleep_us)
    mag = Ist8310Driver(harness.i2c)
    await imu.start()
    await barometer.start()
    await mag.configure()
    await barometer.convert(baro.CMD_CONVERT_D1)
    await mag.start_measurement()
    if PWM:
        await harness.pwm.run()
    rng = np.random.default_rng(1)
    samples = [
        mpu.Mpu6000Sample.from_si(rng.normal(0, 3, 3), rng.normal(0, 1, 3), 30.0).fields()
        for _ in range(FRAMES)
    ]
    parts = {name: [0.0, 0, 0] for name in ("host", "imu", "mag", "baro", "pwm", "wait")}

    async def timed(name, coroutine):
        cycles0, start = harness.cycles(), time.perf_counter()
        result = await coroutine
        cycles1 = harness.cycles()
        part = parts[name]
        part[0] += time.perf_counter() - start
        part[1] += cycles1[0] - cycles0[0]
        part[2] += cycles1[1] - cycles0[1]
        return result

    async def pwm_frame(frame):
        harness.pwm.write([1100 + frame % 800, 1200, 1300, 1400], period_ticks=PWM_PERIOD_TICKS)
        return await harness.host.pwm_capture()

    spi0, i2c0, cycles0 = harness.spi.transfers, harness.i2c.transfers, harness.cycles()
    sim0_s, start = get_sim_time("ps") / 1e12, time.perf_counter()
    for frame, sample in enumerate(samples):
        frame_end_s = sim0_s + (frame + 1) * FRAME_US * 1e-6
        now_us[0] += FRAME_US
        loads = {"imu": sample}
        if frame % 10 == 9:
            loads |= {
                "mag": {"x": 100, "y": -200, "z": 300},
                "baro": {"d1": 8_000_000, "d2": 8_300_000},
            }
        await timed("host", harness.host.load(loads, now_us=now_us[0]))
        await timed("imu", imu.read_raw())
        if frame % 10 == 9:
            await timed("mag", mag.read_measurement())
            await timed("mag", mag.start_measurement())
            await timed("baro", barometer.read_adc())
            await timed("baro", barometer.convert(baro.CMD_CONVERT_D1))
        if PWM:
            await timed("pwm", pwm_frame(frame))
        await timed("wait", harness.wait_until_s(frame_end_s))
    wall_s = time.perf_counter() - start
    cycles1 = harness.cycles()
    figures = {
        "frames": FRAMES,
        "pwm": PWM,
        "wall_s": wall_s,
        "sim_s": get_sim_time("ps") / 1e12 - sim0_s,
        "spi_transfers": harness.spi.transfers - spi0,
        "i2c_transfers": harness.i2c.transfers - i2c0,
        "sync_cycles": cycles1[0] - cycles0[0],
        "pwm_cycles": cycles1[1] - cycles0[1],
        "parts": parts,
    }
    with open(os.environ["BENCH_OUT"], "w") as out:
        json.dump(figures, out)
