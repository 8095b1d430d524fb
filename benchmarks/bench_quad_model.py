"""quad_model speed: real-time factor of one vehicle at 5 kHz, batched throughput, sensor
cost, and RotorPy (a peer simulator) on a comparable hover. Figures only, no pass/fail.

Targets from the issue: one vehicle ≥ 100× real time; batched ≥ 10,000 vehicle-s/s.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import numpy as np

from benchmarks.figures import Figure
from quad_model import Environment, QuadBatch, QuadModel, SensorSuite, load_vehicle
from quad_model.model import PARALLEL_MIN_VEHICLES, VehicleTruth
from quad_model.sensors import BaroModel, GpsModel, ImuModel, MagModel

FRAME_S = 0.001  # the rig's lockstep frame: 5 physics substeps


def _hovering_model(vehicle, count=None):
    rng = np.random.default_rng(0)
    if count is None:
        model = QuadModel(vehicle, rng)
        model.reset(position_ned_m=(0, 0, -20), rotor_speed_radps=vehicle.hover_rotor_speed_radps)
        return model, model.hover_throttle()
    batch = QuadBatch(vehicle, count, rng)
    batch.reset(position_ned_m=(0, 0, -20), rotor_speed_radps=vehicle.hover_rotor_speed_radps)
    return batch, batch.hover_throttle()


def _best_of(repeats: int, run) -> float:
    """Best wall time of a few runs: the machine is shared, the minimum is the code's cost."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def single_vehicle(vehicle) -> Iterator[Figure]:
    model, throttle = _hovering_model(vehicle)
    command = [throttle] * vehicle.propulsion.rotor_count
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
    step_us = one_call / sim_s / 5000 * 1e6
    yield Figure("one vehicle, 5 kHz RK4, one advance() call", sim_s / one_call, "× real time",
                 detail=f"{step_us:.2f} µs/step")  # fmt: skip
    yield Figure("one vehicle, 1 ms frames", sim_s / per_frame, "× real time",
                 detail=f"{per_frame / frames * 1e6:.1f} µs/frame")  # fmt: skip
    yield Figure("one vehicle, 1 ms frames + truth (as the rig)", sim_s / with_truth,
                 "× real time", goal="≥ 100×")  # fmt: skip


def _hover_truths(vehicle, frames: int) -> list[VehicleTruth]:
    """One truth per 1 ms frame of a hover with slightly unequal rotors, as the rig sees it."""
    model, throttle = _hovering_model(vehicle)
    command = throttle * (1.0 + 0.01 * np.sin(np.arange(vehicle.propulsion.rotor_count)))
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


def sensors(vehicle) -> Iterator[Figure]:
    """Sensor physics on a 2 s hover, one call per 1 ms frame; the suite samples IMU 1 kHz,
    mag 100 Hz, baro 50 Hz, GPS 10 Hz, so its figure is a rig frame's sensor physics."""
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
    for name, make in cases.items():
        detail = "a rig frame's sensor physics" if name == "SensorSuite.sample" else ""
        yield Figure(name, _sampling_us(make, truths), "µs/call", detail=detail)


def batched(vehicle) -> Iterator[Figure]:
    """QuadBatch, 1 ms frames, 0.5 s simulated per vehicle."""
    for count in (1, 100, 1000):
        batch, throttle = _hovering_model(vehicle, count)
        commands = np.full((count, vehicle.propulsion.rotor_count), throttle)
        batch.advance(commands, FRAME_S)
        sim_s = 0.5
        frames = round(sim_s / FRAME_S)

        def run(batch=batch, commands=commands, frames=frames):
            for _ in range(frames):
                batch.advance(commands, FRAME_S)

        wall = _best_of(2, run)
        kernel = "all cores" if count >= PARALLEL_MIN_VEHICLES else "one core"
        yield Figure(f"QuadBatch, N = {count}", count * sim_s / wall, "vehicle-s/s",
                     goal="≥ 10,000" if count == 1000 else "", detail=kernel)  # fmt: skip


def rotorpy_hover() -> float | None:
    """RotorPy's Multirotor (scipy solve_ivp per step) hovering at the same 5 kHz step;
    None when RotorPy (the ``bench`` extra) is not installed."""
    try:
        from rotorpy.vehicles.hummingbird_params import quad_params
        from rotorpy.vehicles.multirotor import Multirotor
    except ImportError:
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

    return steps * dt / _best_of(1, run)


def rotor_counts() -> Iterator[Figure]:
    """One vehicle as the rig steps it, per rotor count: each count is its own compiled
    case of the kernel, so a rotor costs the same in each."""
    for name in ("f450_high_precision", "f550_hexa", "auriol_x8"):
        vehicle = load_vehicle(name)
        *_, with_truth = single_vehicle(vehicle)
        yield Figure(f"{vehicle.propulsion.rotor_count} rotors ({name}), 1 ms frames + truth",
                     with_truth.value, "× real time")  # fmt: skip


def figures() -> Iterator[Figure]:
    vehicle = load_vehicle("f450_high_precision")
    single = list(single_vehicle(vehicle))
    yield from single
    yield from rotor_counts()
    yield from sensors(vehicle)
    yield from batched(vehicle)
    peer = rotorpy_hover()
    if peer is None:
        yield Figure("anchor: RotorPy hover, 5 kHz", float("nan"), "× real time",
                     detail="RotorPy not installed (the 'bench' extra)")  # fmt: skip
        return
    yield Figure("anchor: RotorPy Multirotor hover, 5 kHz steps", peer, "× real time",
                 detail="a peer simulator, measured in this run")  # fmt: skip
    yield Figure("quad_model / RotorPy (1 ms frames)", single[1].value / peer, "×")
