"""Open-loop model demo for ``make hil-sim`` until the closed-loop rig exists.

The F450 rests on the ground, spins up to the predicted hover throttle plus a small climb
margin, then is trimmed back to hover. There is NO autopilot and there are NO sensor chips
in the loop: the throttles are a fixed schedule, so the vehicle drifts as any open-loop
multicopter would.
"""

import time

import numpy as np
from rich.console import Console
from rich.live import Live
from rich.table import Table

from quad_model import QuadModel, load_vehicle
from quad_model.frames import euler_from_quat

DURATION_S = 10.0
FRAME_S = 0.001  # the rig's 1 kHz lockstep frame
CLIMB_MARGIN = 0.04  # throttle above hover during the climb
CLIMB_END_S = 3.0


def _status(truth, throttle: float, wall_s: float) -> Table:
    table = Table(title="quad_model open-loop demo (no autopilot, no sensor chips)")
    for column in ("sim time", "RTF", "altitude", "climb rate", "throttle", "battery"):
        table.add_column(column, justify="right")
    rtf = truth.time_s / wall_s if wall_s > 0 else float("nan")
    table.add_row(
        f"{truth.time_s:5.2f} s",
        f"{rtf:6.0f}×",
        f"{-truth.position_ned_m[2]:6.2f} m",
        f"{-truth.velocity_ned_mps[2]:5.2f} m/s",
        f"{throttle:.3f}",
        f"{truth.battery_voltage_v:.2f} V {truth.battery_current_a:4.1f} A",
    )
    return table


def main() -> None:
    console = Console()
    vehicle = load_vehicle("f450_high_precision")
    model = QuadModel(vehicle, np.random.default_rng(0))
    hover = model.hover_throttle()
    console.print(
        f"[bold]{vehicle.name}[/]: open-loop, model only (no autopilot, no sensor chips). "
        f"Predicted hover throttle {hover:.3f}; climbing at +{CLIMB_MARGIN} until "
        f"{CLIMB_END_S:g} s, then trimmed to hover."
    )
    start = time.perf_counter()
    frames = round(DURATION_S / FRAME_S)
    with Live(console=console, refresh_per_second=10) as live:
        for frame in range(frames):
            climbing = frame * FRAME_S < CLIMB_END_S
            throttle = hover + CLIMB_MARGIN if climbing else model.hover_throttle()
            model.advance([throttle] * 4, FRAME_S)
            if frame % 100 == 0 or frame == frames - 1:
                live.update(_status(model.truth, throttle, time.perf_counter() - start))
    wall = time.perf_counter() - start
    truth = model.truth
    roll, pitch, yaw = np.degrees(euler_from_quat(truth.attitude_quat))
    altitude, climb = -truth.position_ned_m[2], -truth.velocity_ned_mps[2]
    console.print(
        f"Done: {truth.time_s:.1f} s simulated in {wall:.2f} s wall "
        f"(RTF {truth.time_s / wall:.0f}×); altitude {altitude:.2f} m, climb rate "
        f"{climb:.2f} m/s, attitude roll {roll:.2f}° pitch {pitch:.2f}° yaw {yaw:.2f}°, "
        f"battery {truth.battery_voltage_v:.2f} V."
    )
    console.print(
        "[yellow]Open loop: nothing corrects drift. The closed-loop rig (autopilot + RTL "
        "sensor chips) replaces this demo.[/]"
    )


if __name__ == "__main__":
    main()
