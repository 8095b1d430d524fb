"""quad_model speed: real-time factor of one vehicle at 5 kHz, batched throughput, sensor
cost, and RotorPy (a peer simulator) on a comparable hover. Figures only, no pass/fail.

Targets from the issue: one vehicle ≥ 100× real time; batched ≥ 10,000 vehicle-s/s.
"""

import math
import time

import numpy as np

from quad_model import QuadBatch, QuadModel, SensorSuite, load_vehicle
from quad_model.model import PARALLEL_MIN_VEHICLES

FRAME_S = 0.001  # the rig's lockstep frame: 5 physics substeps


def _hovering_model(vehicle, count=None):
    rng = np.random.default_rng(0)
    if count is None:
        model = QuadModel(vehicle, rng)
        model.reset(
            position_ned_m=(0, 0, -20), rotor_speed_radps=[vehicle.hover_rotor_speed_radps] * 4
        )
        return model, model.hover_throttle()
    batch = QuadBatch(vehicle, count, rng)
    batch.reset(position_ned_m=(0, 0, -20), rotor_speed_radps=[vehicle.hover_rotor_speed_radps] * 4)
    return batch, batch.hover_throttle()


def _best_of(repeats: int, run) -> float:
    """Best wall time of a few runs: the machine is shared, the minimum is the code's cost."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def single_vehicle(vehicle) -> float:
    model, throttle = _hovering_model(vehicle)
    command = [throttle] * 4
    model.advance(command, FRAME_S)  # compile or load the cache outside the timing
    sim_s = 2.0
    frames = round(sim_s / FRAME_S)

    def frames_only():
        for _ in range(frames):
            model.advance(command, FRAME_S)

    def frames_with_truth():
        for _ in range(frames):
            model.advance(command, FRAME_S)
            model.truth  # noqa: B018 (the rig reads truth every frame)

    one_call = _best_of(3, lambda: model.advance(command, sim_s))
    per_frame = _best_of(3, frames_only)
    with_truth = _best_of(3, frames_with_truth)
    print(f"one vehicle, 5 kHz RK4, {sim_s:g} s hover:")
    step_us = one_call / sim_s / 5000 * 1e6
    frame_us = per_frame / frames * 1e6
    print(f"  one advance() call    RTF {sim_s / one_call:7.0f}×  ({step_us:.2f} µs/step)")
    print(f"  1 ms frames           RTF {sim_s / per_frame:7.0f}×  ({frame_us:.1f} µs/frame)")
    print(f"  1 ms frames + truth   RTF {sim_s / with_truth:7.0f}×  (target ≥ 100×)")
    return sim_s / per_frame


def sensors(vehicle) -> None:
    model, throttle = _hovering_model(vehicle)
    suite = SensorSuite(vehicle, model.environment, np.random.default_rng(1))
    model.advance([throttle] * 4, FRAME_S)
    truth = model.truth
    frames = 2000
    wall = _best_of(3, lambda: [suite.sample(truth) for _ in range(frames)])
    print(
        f"sensor suite (IMU every frame, mag/baro/GPS when due): {wall / frames * 1e6:.1f} µs/frame"
    )


def batched(vehicle) -> None:
    print("batched, 1 ms frames, 0.5 s simulated per vehicle (target ≥ 10,000 vehicle-s/s):")
    for count in (1, 100, 1000):
        batch, throttle = _hovering_model(vehicle, count)
        commands = np.full((count, 4), throttle)
        batch.advance(commands, FRAME_S)
        sim_s = 0.5
        frames = round(sim_s / FRAME_S)

        def run(batch=batch, commands=commands, frames=frames):
            for _ in range(frames):
                batch.advance(commands, FRAME_S)

        wall = _best_of(2, run)
        kernel = "all cores" if count >= PARALLEL_MIN_VEHICLES else "one core"
        print(f"  N = {count:5d}: {count * sim_s / wall:8.0f} vehicle-s/s ({kernel})")


def rotorpy_hover() -> float | None:
    """RotorPy's Multirotor (scipy solve_ivp per step) hovering at the same 5 kHz step."""
    try:
        from rotorpy.vehicles.hummingbird_params import quad_params
        from rotorpy.vehicles.multirotor import Multirotor
    except ImportError as error:
        print(f"RotorPy not available ({error}); install the 'bench' extra")
        return None
    hover = math.sqrt(quad_params["mass"] * 9.81 / (4 * quad_params["k_eta"]))
    state = {
        "x": np.array([0.0, 0.0, 20.0]),
        "v": np.zeros(3),
        "q": np.array([0.0, 0.0, 0.0, 1.0]),
        "w": np.zeros(3),
        "wind": np.zeros(3),
        "rotor_speeds": np.full(4, hover),
    }
    vehicle = Multirotor(quad_params, initial_state=state)
    control = {"cmd_motor_speeds": np.full(4, hover)}
    steps, dt = 1000, 1.0 / 5000

    def run():
        s = state
        for _ in range(steps):
            s = vehicle.step(s, control, dt)

    wall = _best_of(1, run)
    rtf = steps * dt / wall
    print(f"RotorPy Multirotor hover, 5 kHz steps: RTF {rtf:.2f}×")
    return rtf


def main() -> None:
    vehicle = load_vehicle("f450_high_precision")
    rtf = single_vehicle(vehicle)
    sensors(vehicle)
    batched(vehicle)
    peer = rotorpy_hover()
    if peer:
        print(f"quad_model / RotorPy (1 ms frames): {rtf / peer:.0f}×")


if __name__ == "__main__":
    main()
