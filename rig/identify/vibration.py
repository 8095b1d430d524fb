"""IMU vibration per operating point (``rig identify LOG --vibration``): what the rotors do to
the IMU at idle, in hover, climbing and descending, measured in the log and fitted into the
vehicle's ``[vibration]`` operating points (:class:`quad_model.vehicle.VibrationParams`).

Why through the stream PX4 logs: a default-profile log has no raw IMU (``sensor_gyro`` and
``sensor_accel`` at 1 Hz), only ``sensor_combined``, PX4's means over 1/IMU_INTEG_RATE (5 ms
at 200 Hz). A rotor line above its Nyquist frequency folds into that stream, attenuated by
the averaging, so its frequency cannot be read off it; the model is therefore compared and
fitted through the same pipeline. The IMU sits on the thrust stand at the log's motor
commands and battery voltage, is sampled at the replay's IMU rate, averaged to the log's
IMU_INTEG_RATE and high-passed at 5 Hz (the flight's own motion out), exactly like the log.
The power of that stream in each band is linear in the squared tone and broadband levels, so
a non-negative least-squares fit per triad and axis gives the levels at each fitted point.

The noise floor at rest (motors stopped) is the IMU's white noise as the log sees it; its
density is scaled until the model's stream at rest has the log's σ.

A log with the raw IMU FIFO (SDLOG_PROFILE's raw-FIFO bits) needs no such pipeline: the chip's
own samples show the rotor lines where they are. There the operating points are windows
named on the command line (such a log may lack the arming, land-detector and battery topics
that find them), and the model is the chip's samples themselves.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, signal
from scipy.ndimage import uniform_filter1d

from credibility.signals import highpass
from px4_logs import FlightLog, LogError, motor_outputs
from quad_model.frames import pwm_to_throttle
from quad_model.model import Mount, QuadModel
from quad_model.sensors import ImuModel
from quad_model.vehicle import LEVEL_TABLES, ImuParams, Vehicle, VibrationParams
from rig.identify.results import IdentificationError
from rig.scenarios.scenario import model_rate_for

#: Above this the high-pass keeps vibration and drops the flight's own motion (as the
#: credibility plans' σ tests).
HIGHPASS_HZ = 5.0
#: A motor command at or below this is idle: PX4's armed idle is command 0 (0.002 on two of
#: the X500's motors); the first 10 Hz sample of its take-off ramp holds 0.008-0.019.
IDLE_COMMAND_MAX = 0.005
#: Climb and descent: airborne with |vz| averaged over 1 s at least this.
VERTICAL_SPEED_MPS = 1.0
#: A window starts this long after its state began: the props spin up, or coast down
#: after a disarm (the ESCs do not brake).
SETTLE_S = 0.1
#: Shortest usable window: the PSD's 0.5 s segments need a few averages.
MIN_WINDOW_S = {"stopped": 0.5, "idle": 1.5, "hover": 3.0, "climb": 2.0, "descent": 2.0}
#: Welch segment: 2 Hz resolution, enough for two bands.
WELCH_SEGMENT_S = 0.5
#: Seconds of thrust-stand data per model spectrum: four rotors at nearly one speed beat
#: over seconds (at idle about 0.3 Hz), and σ settles only over several beats.
MODEL_SECONDS = 20.0
#: What PX4 v1.14 SITL logs as ``sensor_combined`` per lockstep sample, as weights of the
#: rig's IMU samples k, k-1, k-2: measured, not PX4's documented integrator (which would be
#: the trapezoid 1/2, 1/2); ``tests/rig/test_px4_sitl.py`` checks it against the binary.
PX4_SITL_STREAM = (0.25, 0.5, 0.25)
#: The raw FIFO's pipeline: each chip sample as it is.
RAW_PIPELINE = (1.0,)
#: The raw FIFO's two bands split here: the model's tones below (1× and 2× of the X8's rotors
#: up to its spin-up's 42 Hz shaft rate), the frame's own modes (the X8's gyro lines at
#: 120-150 Hz) and the rest of the chip's band above.
RAW_TONE_BAND_HZ = 100.0
#: Shortest raw window: 3,300 chip samples, a σ to 1.2 % and PSD bins 2.5 Hz wide, enough
#: for bands from 5 Hz (the X8's rest after its props coasted down lasts 0.46 s).
RAW_MIN_WINDOW_S = 0.4
#: The stand runs this long (to a whole sample) at an operating point's throttles before its
#: first sample: its rotors at speed.
SPIN_UP_S = 0.5
#: The points whose levels are fitted; the others check the interpolation.
FITTED_POINTS = ("idle", "hover")
#: A ``[vibration]`` level table: the (x, y, z) levels at each operating point.
LevelTable = tuple[tuple[float, float, float], ...]
_TRIAD_FIELDS = ("accelerometer_m_s2", "gyro_rad")  # kernel order: accel, gyro


@dataclass(frozen=True)
class StreamSpectrum:
    """One window of a 5 Hz high-passed IMU mean stream: PSD, band RMS and σ per triad
    (accel, gyro) and body axis."""

    frequency_hz: NDArray[np.float64]
    psd: NDArray[np.float64]  # (triad, axis, frequency)
    bands_hz: tuple[tuple[float, float], ...]
    band_rms: NDArray[np.float64]  # (triad, axis, band)
    sigma: NDArray[np.float64]  # (triad, axis)


@dataclass(frozen=True)
class OperatingPoint:
    """One operating point of the log: its window, the motors and what the IMU saw."""

    name: str
    #: Hover pools every steady hover window of the log; each other point is its longest span.
    windows_s: tuple[tuple[float, float], ...]
    motor_command: tuple[float, ...]  # mean actuator_motors per motor
    throttle: tuple[float, ...]  # the model's ESC throttle (PWM 1000-2000 µs → 0..1)
    voltage_v: float
    spectrum: StreamSpectrum


@dataclass(frozen=True)
class LogVibration:
    """What one log says about its vehicle's vibration."""

    log: Path
    stream_rate_hz: float  # IMU_INTEG_RATE: sensor_combined's averaging rate
    points: tuple[OperatingPoint, ...]
    #: What the logger made of the IMU's samples before the means (PX4_SITL_STREAM), or
    #: (1.0,): the chip's own samples (the raw FIFO).
    pipeline: tuple[float, ...] = PX4_SITL_STREAM

    def point(self, name: str) -> OperatingPoint:
        for point in self.points:
            if point.name == name:
                return point
        found = ", ".join(p.name for p in self.points) or "none"
        raise IdentificationError(f"{self.log}: no {name} window found (found: {found})")


def bands_for(stream_rate_hz: float) -> tuple[tuple[float, float], ...]:
    """The two bands of a stream: high-pass to half Nyquist, half Nyquist to Nyquist (a rotor
    line folded from above Nyquist lands in the upper one or the lower one by its speed)."""
    nyquist = stream_rate_hz / 2.0
    return ((HIGHPASS_HZ, nyquist / 2.0), (nyquist / 2.0, nyquist))


def stream_spectrum(
    samples: NDArray[np.float64], rate_hz: float, bands: Sequence[tuple[float, float]]
) -> StreamSpectrum:
    """The spectrum of ``samples`` (time × 6: accel xyz, gyro xyz) logged at ``rate_hz``."""
    filtered = np.column_stack([highpass(x, 1.0 / rate_hz, HIGHPASS_HZ) for x in samples.T])
    segment = min(filtered.shape[0], round(WELCH_SEGMENT_S * rate_hz))
    frequency, psd = signal.welch(filtered, fs=rate_hz, nperseg=segment, axis=0)
    psd = psd.T.reshape(2, 3, -1)
    band_rms = np.empty((2, 3, len(bands)))
    for index, (low, high) in enumerate(bands):
        inside = (frequency >= low) & (frequency < high)
        band_rms[..., index] = np.sqrt(np.trapezoid(psd[..., inside], frequency[inside], axis=-1))
    sigma = filtered.std(axis=0, ddof=1).reshape(2, 3)
    return StreamSpectrum(frequency, psd, tuple(bands), band_rms, sigma)


# ------------------------------------------------------------------ the log
def read_log_vibration(log: FlightLog) -> LogVibration:
    """The operating points of a log (stopped, idle, hover, climb, descent: those it has)."""
    path, topics = log.path, log.topics
    for name in ("sensor_combined", "actuator_motors", "actuator_armed"):
        if name not in topics:
            raise IdentificationError(f"{path}: no topic {name!r} (vibration per operating point)")
    params = log.parameters
    stream_rate_hz = float(params.get("IMU_INTEG_RATE", 200.0))
    imu = topics["sensor_combined"]
    imu_time = imu["timestamp"] * 1e-6
    samples = np.column_stack(
        [imu[f"{field}[{axis}]"] for field in _TRIAD_FIELDS for axis in range(3)]
    ).astype(float)
    outputs = motor_outputs(log)
    rotors = outputs.rotor_count
    windows = _windows(log, (float(imu_time[0]), float(imu_time[-1])), rotors)
    pwm_range = outputs.pwm_range_us
    bands = bands_for(stream_rate_hz)
    motors = topics["actuator_motors"]
    motor_time = motors["timestamp"] * 1e-6
    points = []
    for name, spans in windows.items():
        weights = np.array([end - start for start, end in spans])
        weights /= weights.sum()
        spectra, commands, volts = [], [], []
        for start, end in spans:
            inside = (imu_time >= start) & (imu_time < end)
            rate_hz = 1.0 / float(np.median(np.diff(imu_time[inside])))
            spectra.append(stream_spectrum(samples[inside], rate_hz, bands))
            in_motors = (motor_time >= start) & (motor_time < end)
            commands.append([motors[f"control[{m}]"][in_motors].mean() for m in range(rotors)])
            volts.append(_mean_voltage(topics, path, start, end))
        command = weights @ np.array(commands, dtype=float)
        pwm = pwm_range[0] + (pwm_range[1] - pwm_range[0]) * command
        throttle = pwm_to_throttle(pwm) if name != "stopped" else np.zeros(rotors)
        points.append(
            OperatingPoint(
                name=name,
                windows_s=tuple(spans),
                motor_command=tuple(float(c) for c in command),
                throttle=tuple(float(t) for t in throttle),
                voltage_v=float(weights @ np.array(volts)),
                spectrum=_pooled(spectra, weights),
            )
        )
    return LogVibration(path, stream_rate_hz, tuple(points))


def _pooled(spectra: Sequence[StreamSpectrum], weights: NDArray[np.float64]) -> StreamSpectrum:
    """Several windows' spectra as one: powers (PSD, band power, σ²) averaged by duration."""
    first = spectra[0]
    if len(spectra) == 1:
        return first
    grid = first.frequency_hz
    pairs = list(zip(weights, spectra, strict=True))
    psd = np.zeros_like(first.psd)
    for weight, spectrum in pairs:
        for index in np.ndindex(psd.shape[:-1]):
            psd[index] += weight * np.interp(grid, spectrum.frequency_hz, spectrum.psd[index])
    band_power = sum(w * s.band_rms**2 for w, s in pairs)
    variance = sum(w * s.sigma**2 for w, s in pairs)
    return StreamSpectrum(grid, psd, first.bands_hz, np.sqrt(band_power), np.sqrt(variance))


def _mean_voltage(
    topics: Mapping[str, Mapping[str, NDArray[Any]]], path: Path, start: float, end: float
) -> float:
    battery = topics.get("battery_status")
    if battery is None:
        raise IdentificationError(f"{path}: no topic 'battery_status' (the motors' speed curve)")
    time_s = battery["timestamp"] * 1e-6
    inside = (time_s >= start - 1.0) & (time_s < end + 1.0)
    return float(battery["voltage_v"][inside].mean())


def _windows(
    log: FlightLog, imu_span: tuple[float, float], rotors: int
) -> dict[str, list[tuple[float, float]]]:
    """Each operating point's spans inside the IMU stream, SETTLE_S after it began: every
    steady hover window, the longest span of each other point (the log's ``rotors`` motors)."""
    topics = log.topics
    armed = topics["actuator_armed"]
    motors = topics["actuator_motors"]
    grid = motors["timestamp"] * 1e-6
    is_armed = _held(armed["timestamp"] * 1e-6, armed["armed"], grid) > 0.5
    command = np.max([motors[f"control[{m}]"] for m in range(rotors)], axis=0)
    masks = {"stopped": ~is_armed, "idle": is_armed & (command <= IDLE_COMMAND_MAX)}
    position = topics.get("vehicle_local_position")
    try:
        landed = ~log.airborne_at(grid)
    except LogError:  # no land detector nor what derives it: no climb, descent or hover
        landed = None
    if landed is not None:
        masks["idle"] &= landed
        if position is not None:
            time_s = position["timestamp"] * 1e-6
            step = float(np.median(np.diff(time_s)))
            vz = np.interp(grid, time_s, uniform_filter1d(position["vz"], max(1, round(1 / step))))
            masks["climb"] = is_armed & ~landed & (vz <= -VERTICAL_SPEED_MPS)
            masks["descent"] = is_armed & ~landed & (vz >= VERTICAL_SPEED_MPS)
    windows: dict[str, list[tuple[float, float] | None]] = {}
    for name, mask in masks.items():
        span = _longest(grid, mask, imu_span)
        if span is not None:
            windows[name] = [span]
    if position is not None and landed is not None:
        windows["hover"] = [_clip(w, imu_span) for w in log.hover_windows()]
    settled = {}
    for name, spans in windows.items():
        kept = [(start + SETTLE_S, end) for start, end in filter(None, spans)]
        kept = [(start, end) for start, end in kept if end - start >= MIN_WINDOW_S[name]]
        if kept:
            settled[name] = kept
    order = ("stopped", "idle", "hover", "climb", "descent")
    return {name: settled[name] for name in order if name in settled}


def _held(time_s: NDArray, values: NDArray, grid: NDArray) -> NDArray:
    """A logged state at each grid time: the last value logged at or before it."""
    index = np.clip(np.searchsorted(time_s, grid, "right") - 1, 0, None)
    return np.asarray(values, dtype=float)[index]


def _clip(span: tuple[float, float], limits: tuple[float, float]) -> tuple[float, float] | None:
    start, end = max(span[0], limits[0]), min(span[1], limits[1])
    return (start, end) if end > start else None


def _longest(
    grid: NDArray, mask: NDArray, limits: tuple[float, float]
) -> tuple[float, float] | None:
    """The longest span of ``mask`` over ``grid``, from its first to its last sample in
    the state: the state is known only at the samples (``actuator_motors`` at 10 Hz), so a
    span run on to the next sample could take in up to 0.1 s of the next state (the X500's
    idle took in the start of the take-off's spin-up: accel x σ 14 % high)."""
    best = None
    start = last = None
    # A sentinel sample out of the state closes a span that runs to the end.
    for t, ok in zip(np.append(grid, np.inf), np.append(mask, False), strict=True):
        if ok:
            start = t if start is None else start
            last = t
        elif start is not None:
            assert last is not None  # set with start
            span = _clip((float(start), float(last)), limits)
            if span is not None and (best is None or span[1] - span[0] > best[1] - best[0]):
                best = span
            start = None
    return best


# ------------------------------------------------------------------ the model
def model_spectrum(
    vehicle: Vehicle,
    point: OperatingPoint,
    imu_rate_hz: float,
    stream_rate_hz: float,
    seed: int = 0,
    seconds: float = MODEL_SECONDS,
    pipeline: Sequence[float] = PX4_SITL_STREAM,
) -> StreamSpectrum:
    """The model's stream at ``point``: the IMU on the thrust stand at the point's throttles,
    fed from a bench supply at its voltage, sampled at ``imu_rate_hz``, passed through what
    the logger makes of each sample (``pipeline``: PX4 SITL's, :data:`PX4_SITL_STREAM`) and
    averaged over 1/``stream_rate_hz``, as the credibility plans average the replay's log."""
    per_mean = imu_rate_hz / stream_rate_hz
    if abs(per_mean - round(per_mean)) > 1e-9 or per_mean < 1:
        raise IdentificationError(
            f"IMU rate {imu_rate_hz:g} Hz is not a multiple of the stream's {stream_rate_hz:g} Hz"
        )
    bench = on_bench(vehicle, point.voltage_v)
    rng = np.random.default_rng(seed)
    model = QuadModel(
        bench, rng, mount=Mount.THRUST_STAND, physics_rate_hz=model_rate_for(round(imu_rate_hz))
    )
    imu = ImuModel(bench, model.environment, np.random.default_rng(seed + 1), imu_rate_hz)
    throttle = np.array(point.throttle)
    model.advance(throttle, round(SPIN_UP_S * imu_rate_hz) / imu_rate_hz)
    taps = len(pipeline)
    count = round(seconds * stream_rate_hz) * round(per_mean) + taps - 1
    samples = np.empty((count, 6))
    for k in range(count):
        model.advance(throttle, 1.0 / imu_rate_hz)
        reading = imu.sample(model.truth)
        samples[k, :3], samples[k, 3:] = reading.accel_mps2, reading.gyro_radps
    logged = sum(w * samples[taps - 1 - i : count - i] for i, w in enumerate(pipeline))
    assert isinstance(logged, np.ndarray)  # a pipeline has taps: not the empty sum's 0
    means = logged.reshape(-1, round(per_mean), 6).mean(axis=1)
    return stream_spectrum(means, stream_rate_hz, point.spectrum.bands_hz)


def on_bench(vehicle: Vehicle, voltage_v: float) -> Vehicle:
    """``vehicle`` fed from a bench supply at ``voltage_v``: the motors' speed curve holds
    there whatever current they draw."""
    battery = replace(
        vehicle.battery,
        cell_full_v=voltage_v / vehicle.battery.cell_count,
        internal_resistance_ohm=0.0,
    )
    return replace(vehicle, battery=battery)


def fit_vibration(
    vehicle: Vehicle,
    measured: LogVibration,
    imu_rate_hz: float,
    fitted: Sequence[str] = FITTED_POINTS,
) -> tuple[Vehicle, tuple[float, float]]:
    """``vehicle`` with its IMU noise densities from the log at rest (when it has a stopped
    window) and its vibration levels fitted at the ``fitted`` points; also the fitted
    (gyro, accel) densities. Each point's band powers are those of three stand runs (tones
    alone, broadband alone, the white noise alone) weighted by the squared levels."""
    stream_hz = measured.stream_rate_hz
    rotors = vehicle.propulsion.rotor_count
    for point in measured.points:
        if len(point.throttle) != rotors:
            raise IdentificationError(
                f"{measured.log}: {len(point.throttle)} motors; vehicle {vehicle.name!r} has "
                f"{rotors} rotors"
            )

    def spectrum(run: Vehicle, point: OperatingPoint) -> StreamSpectrum:
        return model_spectrum(run, point, imu_rate_hz, stream_hz, pipeline=measured.pipeline)

    imu = vehicle.imu
    stopped = rest_point(vehicle, measured)
    if stopped is not None:
        # The white noise that gives the log's σ at rest through the same pipeline (the
        # rotors stopped: white noise alone, linear in its σ): a density per triad from the
        # RMS over the axes, and an axis's own gain where its σ stands out of the triad's
        # by more than the window can tell apart (twice a σ estimate's standard error).
        alike = (1.0, 1.0, 1.0)
        imu = replace(imu, gyro_noise_axis_gain=alike, accel_noise_axis_gain=alike)
        vehicle = replace(vehicle, imu=imu)
        model = spectrum(vehicle, stopped).sigma
        accel, gyro = (
            float(np.sqrt(np.mean(stopped.spectrum.sigma[t] ** 2) / np.mean(model[t] ** 2)))
            for t in (0, 1)
        )
        samples = sum(end - start for start, end in stopped.windows_s) * stream_hz
        resolvable = 2.0 / np.sqrt(2.0 * (samples - 1.0))
        accel_gain, gyro_gain = (
            _gains(np.where(np.abs(gain - 1.0) > resolvable, gain, 1.0))
            for gain in (stopped.spectrum.sigma[t] / model[t] / d
                         for t, d in enumerate((accel, gyro)))
        )  # fmt: skip
        imu = replace(
            imu,
            gyro_noise_density_radps_per_sqrthz=imu.gyro_noise_density_radps_per_sqrthz * gyro,
            accel_noise_density_mps2_per_sqrthz=imu.accel_noise_density_mps2_per_sqrthz * accel,
            gyro_noise_axis_gain=gyro_gain,
            accel_noise_axis_gain=accel_gain,
        )
        vehicle = replace(vehicle, imu=imu)
    densities = (imu.gyro_noise_density_radps_per_sqrthz, imu.accel_noise_density_mps2_per_sqrthz)
    turning = [name for name in fitted if stopped is None or name != stopped.name]
    points = sorted((measured.point(name) for name in turning), key=_mean_speed(vehicle))
    speeds = tuple(_mean_speed(vehicle)(p) for p in points)
    ones = tuple((1.0, 1.0, 1.0) for _ in points)
    zeros = tuple((0.0, 0.0, 0.0) for _ in points)
    quiet = replace(
        vehicle.imu,
        gyro_noise_density_radps_per_sqrthz=0.0,
        accel_noise_density_mps2_per_sqrthz=0.0,
    )

    def variant(tone: LevelTable, broadband: LevelTable, imu: ImuParams) -> Vehicle:
        vib = replace(
            vehicle.vibration,
            level_rotor_speed_radps=speeds,
            accel_tone_level=tone,
            accel_broadband_level=broadband,
            gyro_tone_level=tone,
            gyro_broadband_level=broadband,
        )
        return replace(vehicle, vibration=vib, imu=imu)

    runs = {
        "tone": variant(ones, zeros, quiet),
        "broadband": variant(zeros, ones, quiet),
        "white": variant(zeros, zeros, vehicle.imu),
    }
    levels = np.zeros((2, 2, 3, len(points)))  # triad, tone|broadband, axis, point
    for index, point in enumerate(points):
        power = {name: spectrum(run, point).band_rms ** 2 for name, run in runs.items()}
        wanted = point.spectrum.band_rms**2 - power["white"]
        for triad in range(2):
            for axis in range(3):
                basis = np.column_stack(
                    [power["tone"][triad, axis], power["broadband"][triad, axis]]
                )
                squared, _ = optimize.nnls(basis, np.maximum(wanted[triad, axis], 0.0))
                levels[triad, :, axis, index] = np.sqrt(squared)

    def table(triad: int, kind: int) -> LevelTable:
        """One of ``levels``' tables: triad 0 accel, 1 gyro; kind 0 tone, 1 broadband."""
        return tuple(_triple(levels[triad, kind, :, p]) for p in range(len(points)))

    vib = replace(
        vehicle.vibration,
        level_rotor_speed_radps=speeds,
        accel_tone_level=table(0, 0),
        accel_broadband_level=table(0, 1),
        gyro_tone_level=table(1, 0),
        gyro_broadband_level=table(1, 1),
    )
    return replace(vehicle, vibration=vib), densities


def rest_point(vehicle: Vehicle, measured: LogVibration) -> OperatingPoint | None:
    """The log's window with the rotors stopped, if any. An armed idle at which the
    vehicle's ESCs do not start the motors (the 8S quad: 1100 µs armed, below its ESCs'
    start) comes first: a disarmed window may hold the props coasting down (the X500's)."""
    names = {point.name for point in measured.points}
    if "idle" in names and _mean_speed(vehicle)(measured.point("idle")) == 0.0:
        return measured.point("idle")
    return measured.point("stopped") if "stopped" in names else None


def _mean_speed(vehicle: Vehicle) -> Callable[[OperatingPoint], float]:
    """The model's mean steady rotor speed at a point's throttles and voltage (the sort key
    and table position of a fitted point)."""

    def speed(point: OperatingPoint) -> float:
        bench = on_bench(vehicle, point.voltage_v)
        model = QuadModel(bench, np.random.default_rng(0), mount=Mount.THRUST_STAND)
        model.advance(np.array(point.throttle), SPIN_UP_S)
        return float(np.mean(np.abs(model.truth.rotor_speed_radps)))

    return speed


def _gains(values: NDArray[np.float64]) -> tuple[float, float, float]:
    """Per-axis gains as the vehicle file keeps them (3 decimals)."""
    x, y, z = (round(float(v), 3) for v in values)
    return x, y, z


def _triple(values: NDArray[np.float64]) -> tuple[float, float, float]:
    """A vibration level table's row: the x, y, z levels at one point."""
    x, y, z = (float(v) for v in values)
    return x, y, z


def vibration_toml(vehicle: Vehicle, measured: LogVibration, imu_rate_hz: float) -> str:
    """``[imu]`` densities and ``[vibration]`` operating-point lines for the vehicle file."""
    vib: VibrationParams = vehicle.vibration
    imu = vehicle.imu
    source = f"rig identify {measured.log.name} --vibration"
    windows = "; ".join(
        f"{p.name} " + ", ".join(f"{a:.1f}-{b:.1f}" for a, b in p.windows_s) + " s"
        for p in measured.points
    )
    stream = (
        "the chip's own samples"
        if measured.pipeline == RAW_PIPELINE
        else f"averaged to {measured.stream_rate_hz:g} Hz"
    )
    lines = [
        f"# {source} (windows: {windows}; model at IMU {imu_rate_hz:g} Hz, {stream})",
        "[imu]",
        f"gyro_noise_density_radps_per_sqrthz = {imu.gyro_noise_density_radps_per_sqrthz:.4g}",
        f"accel_noise_density_mps2_per_sqrthz = {imu.accel_noise_density_mps2_per_sqrthz:.4g}",
        f"gyro_noise_axis_gain = {list(imu.gyro_noise_axis_gain)}",
        f"accel_noise_axis_gain = {list(imu.accel_noise_axis_gain)}",
        "[vibration]",
        "level_rotor_speed_radps = " + str([round(s, 1) for s in vib.level_rotor_speed_radps]),
    ]
    for name in LEVEL_TABLES:
        rows = [[round(v, 3) for v in row] for row in getattr(vib, name)]
        lines.append(f"{name} = {rows}")
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ raw IMU
#: PX4's raw IMU FIFO topics (a log with SDLOG_PROFILE's raw-FIFO bit): each message holds up
#: to 32 consecutive chip samples ``dt`` µs apart, in counts times ``scale``, chip axes.
FIFO_TOPICS = {"gyro": "sensor_gyro_fifo", "accel": "sensor_accel_fifo"}
_FIFO_AXES = ("x", "y", "z")


@dataclass(frozen=True)
class RawImu:
    """One triad's raw samples: times (µs), values (SI, N × 3) and the chip's rate."""

    time_us: NDArray[np.int64]
    values: NDArray[np.float64]
    rate_hz: float


@dataclass(frozen=True)
class MotorDrive:
    """What the log's motors got: per ``actuator_motors`` sample, each motor's command (0..1)
    and the ESC throttle it made (0 while disarmed), each held to the next sample."""

    time_s: NDArray[np.float64]
    command: NDArray[np.float64]  # samples × motors
    throttle: NDArray[np.float64]  # samples × motors

    def window(
        self, start_s: float, end_s: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The mean command and throttle per motor over ``start_s``-``end_s``."""
        inside = (self.time_s >= start_s) & (self.time_s < end_s)
        if not np.any(inside):
            raise IdentificationError(
                f"window {start_s:g}-{end_s:g} s holds no actuator_motors sample"
            )
        return self.command[inside].mean(axis=0), self.throttle[inside].mean(axis=0)


def read_raw_imu(log: FlightLog) -> dict[str, RawImu]:
    """The log's raw gyro and accel FIFO samples, unpacked (``gyro``, ``accel``). A message's
    samples are laid ``dt`` apart from its ``timestamp_sample`` (the first sample's time in
    PX4's FIFO drivers); between messages the logger may have dropped a few."""
    path, topics = log.path, log.topics
    raw = {}
    for triad, topic in FIFO_TOPICS.items():
        data = topics.get(topic)
        if data is None:
            raise IdentificationError(
                f"{path}: no topic {topic!r} (the raw IMU FIFO: log it with SDLOG_PROFILE's "
                "raw-FIFO bit)"
            )
        slots = max((int(n) for n in data.get("samples", ())), default=0)
        fields = ("samples", "dt", "scale", "timestamp_sample",
                  *(f"{axis}[{k}]" for axis in _FIFO_AXES for k in range(slots)))  # fmt: skip
        missing = [field for field in fields if field not in data]
        if missing or slots == 0:
            what = f"no field {missing[0]}" if missing else "no samples"
            raise IdentificationError(f"{path}: topic {topic} has {what} (the raw IMU FIFO)")
        dt_us = np.asarray(data["dt"], dtype=float)
        offsets = np.arange(slots)[None, :] * dt_us[:, None]
        times = np.asarray(data["timestamp_sample"], dtype=float)[:, None] + offsets
        mask = np.arange(slots)[None, :] < np.asarray(data["samples"], dtype=int)[:, None]
        columns = [
            np.column_stack([data[f"{axis}[{k}]"] for k in range(slots)]).astype(float)
            * np.asarray(data["scale"], dtype=float)[:, None]
            for axis in _FIFO_AXES
        ]
        raw[triad] = RawImu(
            time_us=np.round(times[mask]).astype(np.int64),
            values=np.column_stack([column[mask] for column in columns]),
            rate_hz=1e6 / float(np.median(dt_us)),
        )
    return raw


def log_motor_drive(log: FlightLog, vehicle: Vehicle, disarm_s: float | None) -> MotorDrive:
    """The log's ``actuator_motors`` as the ESC throttles of ``vehicle``'s rotors, through the
    log's output range (:func:`px4_logs.motor_outputs`: DShot's armed floor is its
    DSHOT_MIN). Disarmed (a non-finite command, the arming topic's state, or from
    ``disarm_s`` on in a log with no arming topic) the ESCs get 0."""
    outputs = motor_outputs(log)
    rotors = vehicle.propulsion.rotor_count
    if outputs.rotor_count != rotors:
        raise IdentificationError(
            f"{log.path}: {outputs.rotor_count} rotors ({outputs.reason}); vehicle "
            f"{vehicle.name!r} has {rotors}"
        )
    fields = tuple(f"control[{m}]" for m in range(rotors))
    motors = log.topic("actuator_motors", "the motors' commands", fields)
    time_s = np.asarray(motors["timestamp"], dtype=float) * 1e-6
    command = np.column_stack([motors[field] for field in fields]).astype(float)
    armed = log.armed_samples()
    if armed is not None:
        on = _held(armed[0], armed[1], time_s) > 0.5
    elif disarm_s is not None:
        on = time_s < disarm_s
    else:
        raise IdentificationError(
            f"{log.path}: no arming state (actuator_armed, vehicle_status): give --disarm "
            "SECONDS, the log's disarm (its 'Disarmed' message)"
        )
    low, high = outputs.throttle_range
    running = on[:, None] & np.isfinite(command)
    command = np.where(running, np.clip(command, 0.0, 1.0), 0.0)
    throttle = np.where(running, low + (high - low) * command, 0.0)
    return MotorDrive(time_s, command, throttle)


def raw_imu_driven(
    vehicle: Vehicle, raw: Mapping[str, RawImu], drive: MotorDrive, voltage_v: float, seed: int = 0
) -> dict[str, RawImu]:
    """The vehicle's IMU on the thrust stand, its motors driven as the log's (``drive``) from
    a bench supply at ``voltage_v``, sampled at the chip's rate: one sample for each of the
    log's, at its timestamp (so a plan's segment selects the same samples). The rotors start
    at rest, as a log that starts at the arming (PX4's default) has them; through a logger
    dropout the model runs on with the last commands."""
    rate_hz = round(raw["gyro"].rate_hz)  # the model steps whole physics steps per sample
    start_us = min(int(r.time_us[0]) for r in raw.values())
    end_us = max(int(r.time_us[-1]) for r in raw.values())
    steps = round((end_us - start_us) * rate_hz / 1e6) + 1
    grid_s = (start_us + np.arange(steps) * 1e6 / rate_hz) * 1e-6
    throttles = drive.throttle[np.clip(np.searchsorted(drive.time_s, grid_s, "right") - 1, 0, None)]
    bench = on_bench(vehicle, voltage_v)
    model = QuadModel(
        bench,
        np.random.default_rng(seed),
        mount=Mount.THRUST_STAND,
        physics_rate_hz=model_rate_for(rate_hz),
    )
    imu = ImuModel(bench, model.environment, np.random.default_rng(seed + 1), rate_hz)
    samples = np.empty((steps, 6))
    for k in range(steps):
        model.advance(throttles[k], 1.0 / rate_hz)
        reading = imu.sample(model.truth)
        samples[k, :3], samples[k, 3:] = reading.accel_mps2, reading.gyro_radps
    modelled = {}
    for triad, log in raw.items():
        nearest = np.clip(np.round((log.time_us - start_us) * rate_hz / 1e6), 0, steps - 1)
        columns = slice(3, 6) if triad == "gyro" else slice(0, 3)
        modelled[triad] = RawImu(log.time_us, samples[nearest.astype(int), columns], rate_hz)
    return modelled


def supply_voltage(log: FlightLog, vehicle: Vehicle) -> float:
    """The pack's mean voltage over the log, else (no ``battery_status``) the vehicle's speed
    curve voltage: the speeds are then the curve's own."""
    battery = log.topics.get("battery_status", {})
    volts = np.asarray(battery.get("voltage_v", ()), dtype=float)
    volts = volts[np.isfinite(volts) & (volts > 0)]
    return float(volts.mean()) if volts.size else vehicle.propulsion.speed_curve_voltage_v


def read_raw_vibration(
    log: FlightLog,
    raw: Mapping[str, RawImu],
    drive: MotorDrive,
    voltage_v: float,
    windows: Mapping[str, tuple[float, float]],
) -> LogVibration:
    """The log's operating points from its raw FIFO: each named window (``stopped``: the
    rotors at rest) with its motors' mean throttle, its spectrum at the chip's rate in two
    bands split at :data:`RAW_TONE_BAND_HZ`."""
    rate_hz = float(round(raw["gyro"].rate_hz))
    bands = ((HIGHPASS_HZ, RAW_TONE_BAND_HZ), (RAW_TONE_BAND_HZ, rate_hz / 2.0))
    points = []
    for name, (start, end) in windows.items():
        triads = []
        for triad in ("accel", "gyro"):  # the kernel's order
            samples = raw[triad]
            inside = (samples.time_us >= start * 1e6) & (samples.time_us < end * 1e6)
            triads.append(samples.values[inside])
        count = min(len(values) for values in triads)
        if end <= start or count < RAW_MIN_WINDOW_S * rate_hz:
            raise IdentificationError(
                f"{log.path}: window {name} {start:g}-{end:g} s holds {count} raw IMU samples "
                f"(at least {RAW_MIN_WINDOW_S:g} s of them needed)"
            )
        command, throttle = drive.window(start, end)
        points.append(
            OperatingPoint(
                name=name,
                windows_s=((start, end),),
                motor_command=tuple(float(c) for c in command),
                throttle=tuple(float(t) for t in throttle),
                voltage_v=voltage_v,
                spectrum=stream_spectrum(
                    np.hstack([values[:count] for values in triads]), rate_hz, bands
                ),
            )
        )
    return LogVibration(log.path, rate_hz, tuple(points), RAW_PIPELINE)


def write_raw_imu_tables(
    log: FlightLog, vehicle: Vehicle, out_dir: Path, disarm_s: float | None = None
) -> tuple[Path, ...]:
    """``real_<triad>.parquet`` (the log's FIFO) and ``sim_<triad>.parquet`` (the model on the
    stand driven by the log's motors, :func:`raw_imu_driven`) in ``out_dir``, columns
    ``timestamp`` (µs) and ``sensor_<triad>_fifo.x|y|z`` (SI), for a credibility plan."""
    import pandas as pd  # on demand, as credibility reads tables

    raw = read_raw_imu(log)
    drive = log_motor_drive(log, vehicle, disarm_s)
    modelled = raw_imu_driven(vehicle, raw, drive, supply_voltage(log, vehicle))
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for role, triads in (("real", raw), ("sim", modelled)):
        for triad, samples in triads.items():
            columns = {"timestamp": samples.time_us} | {
                f"{FIFO_TOPICS[triad]}.{axis}": samples.values[:, k]
                for k, axis in enumerate(_FIFO_AXES)
            }
            path = out_dir / f"{role}_{triad}.parquet"
            pd.DataFrame(columns).to_parquet(path, index=False)
            written.append(path)
    return tuple(written)
