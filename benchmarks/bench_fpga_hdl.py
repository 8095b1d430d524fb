"""fpga_hdl co-simulation cost: the whole sensor frame through SensorTop, per simulator.

Prints, for Verilator and Icarus: wall time per frame (IMU burst at 1 kHz, baro at
50 Hz, host-port loads), SPI transactions per wall second, and simulated clock edges
(SCLK edges + system-clock cycles) per wall second. Also the TLM frame for comparison.
A closed loop at 1 kHz runs faster than real time when a frame costs under 1 ms.
"""

import asyncio
import json
import tempfile
import time
from pathlib import Path

from fpga_hdl.buses import TlmSpiBus
from fpga_hdl.cosim.runner import SIMULATORS, build_simulation, missing_simulator_reason, run_cocotb
from fpga_hdl.mpu6000 import regs as mpu
from fpga_hdl.mpu6000.driver import Mpu6000Driver
from fpga_hdl.mpu6000.model import Mpu6000Model
from fpga_hdl.top import SensorTop

HERE = Path(__file__).parent
FRAMES = 200


def cosim_frame(simulator: str) -> dict:
    build_simulation(SensorTop(), "sensor_top", simulator=simulator)  # build outside the timing
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "figures.json"
        run_cocotb(
            SensorTop(),
            "sensor_top",
            "cocotb_fpga_frame",
            module_dir=HERE,
            simulator=simulator,
            extra_env={"BENCH_OUT": str(out), "BENCH_FRAMES": str(FRAMES)},
        )
        return json.loads(out.read_text())


def tlm_frame_s() -> float:
    model = Mpu6000Model()
    driver = Mpu6000Driver(TlmSpiBus({"imu": model}))
    sample = mpu.Mpu6000Sample(1, 2, 3, 4, 5, 6, 7)

    async def frames():
        await driver.start()
        start = time.perf_counter()
        for _ in range(FRAMES):
            model.load_sample(sample)
            await driver.read_raw()
        return (time.perf_counter() - start) / FRAMES

    return asyncio.run(frames())


def main() -> None:
    print("frame = host load + IMU 15-byte burst at 5 MHz; baro ADC READ + CONVERT every 20th")
    print(
        f"{'simulator':<10} {'frame µs':>9} {'transfers/s':>12} {'edges/s':>10} "
        f"{'SCLK edges/frame':>17} {'sys cycles/frame':>17}"
    )
    for simulator in SIMULATORS:
        reason = missing_simulator_reason(simulator)
        if reason is not None:
            print(f"{simulator:<10} skipped: {reason}")
            continue
        f = cosim_frame(simulator)
        edges = f["sclk_edges"] + 2 * f["sys_cycles"]
        print(
            f"{simulator:<10} {1e6 * f['wall_s'] / f['frames']:>9.0f} "
            f"{f['transfers'] / f['wall_s']:>12.0f} {edges / f['wall_s']:>10.3g} "
            f"{f['sclk_edges'] / f['frames']:>17.0f} {f['sys_cycles'] / f['frames']:>17.1f}"
        )
    print(f"{'tlm':<10} {1e6 * tlm_frame_s():>9.1f}  (pure-Python model, IMU burst only)")
    print("not in the frame yet: IST8310 over I2C and PWM capture (no cocotb masters for them)")


if __name__ == "__main__":
    main()
