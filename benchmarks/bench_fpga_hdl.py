"""fpga_hdl co-simulation cost: the rig's full sensor frame, fast path and pin-level path.

Fast path (``fpga_hdl.cosim.harness``): per 1 kHz frame a host-port burst, the MPU-6000
burst at 5 MHz, at 100 Hz the IST8310 read + trigger (400 kHz) and the MS5611 ADC read +
convert, the four motor widths to the PWM generator and the capture read back, with the
400 Hz PWM and its 1 µs capture clock running all the time; simulated time advances
1 ms per frame, so the real-time factor (RTF = simulated s / wall s) is the closed
loop's. Also without the PWM clock, to show its share, and the cycle budget per bus.

Pin-level path (the masters the interface-timing tests use), as before: host load +
IMU burst, baro every 20th frame; no I2C, no PWM, simulated time not advanced.
Numbers only; nothing passes or fails on time.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Iterator
from pathlib import Path

from benchmarks.figures import Figure
from fpga_hdl.cosim.harness import GATED_CLOCK_VERILOG, HARNESS_TOPLEVEL, CosimHarness
from fpga_hdl.cosim.runner import SIMULATORS, missing_simulator_reason, run_cocotb
from fpga_hdl.top import SensorTop

HERE = Path(__file__).parent
FRAMES = 200


def run_frames(simulator: str, module: str, **env: str) -> dict:
    fast = module == "cocotb_fast_frame"
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "figures.json"
        run_cocotb(
            CosimHarness() if fast else SensorTop(),
            HARNESS_TOPLEVEL if fast else "sensor_top",
            module,
            module_dir=HERE,
            simulator=simulator,
            extra_env={"BENCH_OUT": str(out), "BENCH_FRAMES": str(FRAMES), **env},
            extra_verilog={"cosim_gated_clock": GATED_CLOCK_VERILOG} if fast else None,
        )
        return json.loads(out.read_text())


def _fast(simulator: str, f: dict) -> Figure:
    frames, wall_s = f["frames"], f["wall_s"]
    transfers = f["spi_transfers"] + f["i2c_transfers"]
    cycles_per_s = (f["sync_cycles"] + f["pwm_cycles"]) / wall_s / 1e6
    return Figure(
        f"{simulator}, harness (fast path){'' if f['pwm'] else ', PWM clock off'}",
        f["sim_s"] / wall_s, "× real time",
        detail=f"{1e6 * wall_s / frames:.0f} µs/frame, {transfers / wall_s:.0f} transfers/s, "
        f"{f['sync_cycles'] / frames:.0f} sys + {f['pwm_cycles'] / frames:.0f} pwm cycles/frame, "
        f"{cycles_per_s:.2f} M cycles/s",
    )  # fmt: skip


def _budget(simulator: str, f: dict) -> Iterator[Figure]:
    """Wall time per simulated second and cycles, per part of the frame."""
    sim_s = f["sim_s"]
    for name, (wall_s, sync, pwm) in f["parts"].items():
        yield Figure(
            f"{simulator}, harness: {name} part", wall_s / sim_s, "wall s per simulated s",
            detail=f"sync {sync / sim_s / 1e3:.0f} k + pwm {pwm / sim_s / 1e3:.0f} k cycles "
            "per simulated s",
        )  # fmt: skip


def figures() -> Iterator[Figure]:
    for simulator in SIMULATORS:
        reason = missing_simulator_reason(simulator)
        if reason is not None:
            yield Figure(simulator, float("nan"), "", detail=f"skipped: {reason}")
            continue
        with_pwm = run_frames(simulator, "cocotb_fast_frame")
        yield _fast(simulator, with_pwm)
        yield _fast(simulator, run_frames(simulator, "cocotb_fast_frame", BENCH_PWM="0"))
        old = run_frames(simulator, "cocotb_fpga_frame")
        yield Figure(
            f"{simulator}, pin-level masters (IMU + baro)", 1e6 * old["wall_s"] / old["frames"],
            "µs/frame",
            detail=f"{old['transfers'] / old['wall_s']:.0f} transfers/s, "
            f"{old['sys_cycles'] / old['frames']:.0f} sys cycles + "
            f"{old['sclk_edges'] / old['frames']:.0f} SCLK edges from Python per frame",
        )  # fmt: skip
        yield from _budget(simulator, with_pwm)
