"""quad_model speed: real-time factor of one vehicle at 5 kHz, batched throughput, sensor
cost, and RotorPy (a peer simulator) on a comparable hover. Figures only, no pass/fail.

Targets from the issue: one vehicle ≥ 100× real time; batched ≥ 10,000 vehicle-s/s.
"""

import math
import time

import numpy as np

from quad_model import Environment, QuadBatch, QuadModel, SensorSuite, load_vehicle
from quad_model.model import PARALLEL_MIN_VEHICLES, VehicleTruth
from quad_model.sensors import BaroModel, GpsModel, ImuModel, MagModel

FRAME_S = 0.001  # the rig's lockstep frame: 5 physics substeps
#: µs per ``sample()`` call at commit abaed09, before the sensor speed work (numpy per sample,
#: one generator call per draw): medians of 3 runs of :func:`sensors` alternating with the
#: block-draw/numba code on the shared 2-core machine (load average < 1).
SENSORS_BEFORE_US = {
    "ImuModel.sample": 43.6,
    "MagModel.sample": 6.8,
    "BaroModel.sample": 3.1,
    "GpsModel.sample": 1.2,
    "SensorSuite.sample": 49.6,
}


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


def _hover_truths(vehicle, frames: int) -> list[VehicleTruth]:
    """One truth per 1 ms frame of a hover with slightly unequal rotors, as the rig sees it."""
    model, throttle = _hovering_model(vehicle)
    command = throttle * np.array([1.0, 1.01, 0.99, 1.02])
    truths = []
    for _ in range(frames):
        model.advance(command, FRAME_S)
        truths.append(model.truth)
    return truths


def _sampling_us(make, truths: list[VehicleTruth], repeats: int = 3) -> float:
    """Best µs per ``sample()`` over ``truths``; each repeat samples a fresh model, as time
    only moves forward for one."""
    best = math.inf
    for _ in range(repeats):
        sample = make().sample
        start = time.perf_counter()
        for truth in truths:
            sample(truth)
        best = min(best, time.perf_counter() - start)
    return best / len(truths) * 1e6


def sensors(vehicle) -> None:
    truths = _hover_truths(vehicle, 2000)
    env = Environment()
    rates = {"imu_rate_hz": 1000.0, "mag_rate_hz": 100.0, "baro_rate_hz": 50.0}
    cases = {
        "ImuModel.sample": lambda: ImuModel(vehicle, env, np.random.default_rng(1)),
        "MagModel.sample": lambda: MagModel(vehicle, env, np.random.default_rng(1)),
        "BaroModel.sample": lambda: BaroModel(vehicle, env, np.random.default_rng(1)),
        "GpsModel.sample": lambda: GpsModel(vehicle, env, np.random.default_rng(1)),
        "SensorSuite.sample": lambda: SensorSuite(vehicle, env, np.random.default_rng(1), **rates),
    }
    _sampling_us(cases["SensorSuite.sample"], truths[:10], repeats=1)  # compile/load kernels
    print("sensor physics on a 2 s hover, one call per 1 ms frame; the suite samples IMU 1 kHz,")
    print("mag 100 Hz, baro 50 Hz, GPS 10 Hz, so its figure is the rig frame's sensor physics:")
    print(f"  {'µs per sample() call':<22}{'before':>8}{'now':>8}{'speed-up':>10}")
    for name, make in cases.items():
        before, now = SENSORS_BEFORE_US[name], _sampling_us(make, truths)
        print(f"  {name:<22}{before:8.1f}{now:8.2f}{before / now:9.1f}×")


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
