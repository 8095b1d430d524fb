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

import json
import tempfile
from pathlib import Path

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


def print_fast(simulator: str, f: dict) -> None:
    frames, wall_s = f["frames"], f["wall_s"]
    transfers = f["spi_transfers"] + f["i2c_transfers"]
    label = f"{simulator} fast{'' if f['pwm'] else ' (no PWM)'}"
    print(
        f"{label:<24} {1e6 * wall_s / frames:>9.0f} {f['sim_s'] / wall_s:>6.2f} "
        f"{transfers / wall_s:>12.0f} {f['sync_cycles'] / frames:>11.0f} "
        f"{f['pwm_cycles'] / frames:>10.0f} "
        f"{(f['sync_cycles'] + f['pwm_cycles']) / wall_s / 1e6:>8.2f}"
    )


def print_budget(f: dict) -> None:
    """Cycles per simulated second and wall time per simulated second, per part."""
    sim_s = f["sim_s"]
    print(f"  budget per simulated second ({f['frames']} frames):")
    for name, (wall_s, sync, pwm) in f["parts"].items():
        sync_k, pwm_k = sync / sim_s / 1e3, pwm / sim_s / 1e3
        print(
            f"    {name:<5} sync {sync_k:>7.0f} k cycles  pwm {pwm_k:>6.0f} k cycles  "
            f"wall {wall_s / sim_s:>6.3f} s"
        )


def main() -> None:
    print(
        f"{'path':<24} {'frame µs':>9} {'RTF':>6} {'transfers/s':>12} "
        f"{'sys cyc/fr':>11} {'pwm cyc/fr':>10} {'Mcyc/s':>8}"
    )
    for simulator in SIMULATORS:
        reason = missing_simulator_reason(simulator)
        if reason is not None:
            print(f"{simulator:<24} skipped: {reason}")
            continue
        with_pwm = run_frames(simulator, "cocotb_fast_frame")
        print_fast(simulator, with_pwm)
        print_fast(simulator, run_frames(simulator, "cocotb_fast_frame", BENCH_PWM="0"))
        old = run_frames(simulator, "cocotb_fpga_frame")
        label = f"{simulator} pin-level"
        print(
            f"{label:<24} {1e6 * old['wall_s'] / old['frames']:>9.0f} {'-':>6} "
            f"{old['transfers'] / old['wall_s']:>12.0f} "
            f"{old['sys_cycles'] / old['frames']:>11.0f} {'-':>10} "
            f"  (+{old['sclk_edges'] / old['frames']:.0f} SCLK edges/frame from Python)"
        )
        print_budget(with_pwm)


if __name__ == "__main__":
    main()
