"""cocotb side of ``bench_fpga_hdl``: one sensor frame after another through SensorTop.

A frame is what the rig does per 1 kHz IMU period: load an IMU sample and the time,
read the IMU burst as PX4 does; every 20th frame (50 Hz) also the MS5611 (ADC READ of
the finished conversion, then the next CONVERT). Figures go to $BENCH_OUT as JSON.
"""

import json
import os
import time

import cocotb
import numpy as np

from fpga_hdl.chips.mpu6000 import regs as mpu
from fpga_hdl.chips.mpu6000.driver import Mpu6000Driver
from fpga_hdl.chips.ms5611 import regs as baro
from fpga_hdl.chips.ms5611.driver import Ms5611Driver
from fpga_hdl.cosim.sensor_top import SensorTopPins

FRAMES = int(os.environ.get("BENCH_FRAMES", "200"))


@cocotb.test()
async def frames(dut):
    pins = SensorTopPins(dut)
    host, spi = pins.host, pins.spi
    await host.reset()
    now_us = [1]

    async def sleep_us(us):
        now_us[0] += us
        await host.load({}, now_us=now_us[0])

    imu, barometer = Mpu6000Driver(spi), Ms5611Driver(spi, sleep_us)
    await imu.start()
    await barometer.start()
    await barometer.convert(baro.CMD_CONVERT_D1)
    rng = np.random.default_rng(1)
    samples = [
        mpu.Mpu6000Sample.from_si(rng.normal(0, 3, 3), rng.normal(0, 1, 3), 30.0).fields()
        for _ in range(FRAMES)
    ]
    edges0, cycles0, transfers = spi.edges, host.cycles_run, 0
    start = time.perf_counter()
    for frame, sample in enumerate(samples):
        now_us[0] += 1000
        await host.load({"imu": sample}, now_us=now_us[0])
        await imu.read_raw()
        transfers += 1
        if frame % 20 == 19:
            await barometer.read_adc()
            await barometer.convert(baro.CMD_CONVERT_D1)
            transfers += 2
    wall_s = time.perf_counter() - start
    figures = {
        "frames": FRAMES,
        "wall_s": wall_s,
        "transfers": transfers,
        "sclk_edges": spi.edges - edges0,
        "sys_cycles": host.cycles_run - cycles0,
    }
    with open(os.environ["BENCH_OUT"], "w") as out:
        json.dump(figures, out)
