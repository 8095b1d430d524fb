"""η_f: the pilot's inputs as the broadband excitation of the rate responses, each band
where the response is coherent; and what the log's rates rule out whatever was flown."""

import math

import numpy as np
from numpy.typing import NDArray

from credibility import indices, spectral
from credibility.autoplan.draft import Found, PlannedTest, runs, span, without_path
from credibility.errors import CredibilityError
from credibility.plan import NotScorable
from px4_logs import FlightLog, LogError

#: PX4's nav_state values (msg/VehicleStatus.msg) a pilot flies by stick: Manual, Altitude,
#: Position, Position slow, Acro, Stabilized.
PILOT_MODES = frozenset({0, 1, 2, 6, 10, 15})
#: The lift-off, the touch-down and the climb and descent next to them are not the
#: pilot's excitation of the airborne dynamics (ground contact, the land detector's
#: thrust ramps): the spans keep this far from both.
GROUND_S = 5.0
#: Pilot-flown airborne spans shorter than this give too few averages at low frequency.
MIN_EXCITATION_S = 20.0
#: The frequency grid the coherence is searched on, up to this fraction of Nyquist (the
#: estimate's last bins are aliased) …
BAND_TOP_NYQUIST = 0.8
COHERENCE_GRID_POINTS = 60
#: … the coherent band must span at least this ratio f_b/f_a (an octave) …
MIN_BAND_RATIO = 2.0
#: … with at least this share of its grid points coherent.
COHERENT_SHARE = 2.0 / 3.0
#: The points scored across the band (x500_validation.toml).
N_POINTS = 30
#: The responses: (name, input topic and field, output field, caveat).
TORQUE_CAVEAT = (
    "CAVEAT: closed-loop data; at high frequency part of the coherence comes from the "
    "feedback path (the rate D-term acting on measured noise), so the real curve is a "
    "biased plant estimate. The sim has the same loop and the same bias, so sim and real "
    "compare, but neither curve is the open-loop plant."
)
RESPONSES = tuple(
    (f"{axis}_{what}", f"{topic}.{field}", f"vehicle_angular_velocity.xyz[{index}]", caveat)
    for index, axis in enumerate(("roll", "pitch", "yaw"))
    for what, topic, field, caveat in (
        ("rate_response", "vehicle_rates_setpoint", axis, ""),
        ("torque_to_rate", "vehicle_torque_setpoint", f"xyz[{index}]", TORQUE_CAVEAT),
    )
)
#: The responses' topics; the slowest one's rate is every response's sample rate.
RATE_TOPICS = ("vehicle_rates_setpoint", "vehicle_torque_setpoint", "vehicle_angular_velocity")


def pilot_spans(log: FlightLog) -> list[tuple[float, float]]:
    """Airborne spans flown in pilot modes (PILOT_MODES) of at least MIN_EXCITATION_S, at
    least GROUND_S from the lift-off and the touch-down: the pilot's stick inputs are the
    only broadband excitation of a flight without a sweep. (start, end), the most excited
    first (the highest RMS of the roll and pitch rate set-points: larger inputs stand
    further above the noise)."""
    airborne = log.airborne_span()
    time_s, mode = log.series("vehicle_status", "nav_state", "flight modes")
    spans = []
    piloted = np.isin(mode.astype(int), list(PILOT_MODES)).astype(float)
    for start, end, state in runs(time_s, piloted, log.last_s):
        start, end = max(start, airborne[0] + GROUND_S), min(end, airborne[1] - GROUND_S)
        if state and end - start >= MIN_EXCITATION_S:
            spans.append(span(start, end))
    time_s, roll = log.series("vehicle_rates_setpoint", "roll", "pilot's inputs")
    pitch = log.series("vehicle_rates_setpoint", "pitch", "pilot's inputs")[1]

    def excitation(span: tuple[float, float]) -> float:
        inside = (time_s >= span[0]) & (time_s <= span[1])
        return float(np.sqrt(np.mean(roll[inside] ** 2 + pitch[inside] ** 2)))

    return sorted(spans, key=excitation, reverse=True)


def logged_rate_hz(log: FlightLog, topic: str) -> float:
    """The rate the logger wrote ``topic`` at (Hz, whole): its samples over its span. Each
    interval jitters around the logger's period (the X500's body rates: median 21 ms for a
    20 ms period), the mean does not."""
    time_s = log.time_s(topic)
    return float(round((time_s.size - 1) / float(time_s[-1] - time_s[0])))


def _uniform(log: FlightLog, path: str, grid: NDArray[np.float64]) -> NDArray[np.float64]:
    topic, field = path.split(".", 1)
    time_s, values = log.series(topic, field, "frequency response")
    return np.interp(grid, time_s, values)


def coherent_band(
    freqs_hz: NDArray[np.float64], coherence: NDArray[np.float64], minimum: float
) -> tuple[float, float] | None:
    """The widest band from one coherent grid point (γ² ≥ ``minimum``) to another in which
    at least COHERENT_SHARE of the points are coherent; None below MIN_BAND_RATIO.

    A dip below the threshold inside the band does not end it: the scoring leaves out
    each incoherent point and the report lists it, so the band keeps the coherent
    frequencies on both sides of a dip (x500_validation.toml's 0.2-3 Hz, mean γ² 0.55 over
    1-3 Hz in roll)."""
    coherent = coherence >= minimum
    share = np.concatenate(([0], np.cumsum(coherent)))
    best: tuple[float, float] | None = None
    for first in np.flatnonzero(coherent):
        for last in np.flatnonzero(coherent[first:]) + first:
            if share[last + 1] - share[first] < COHERENT_SHARE * (last + 1 - first):
                continue
            band = (float(freqs_hz[first]), float(freqs_hz[last]))
            if best is None or band[1] / band[0] > best[1] / best[0]:
                best = band
    if best is None or best[1] / best[0] < MIN_BAND_RATIO:
        return None
    return best


def response_tests(log: FlightLog) -> Found:
    """rate_sp → rate and torque_sp → rate per axis over the most excited pilot-flown span,
    each over the band where its coherence reaches the plan's ``coherence_min``
    (:func:`coherent_band`, from :func:`credibility.spectral.estimate_response`)."""
    try:
        spans = pilot_spans(log)
        sample_rate = min(logged_rate_hz(log, topic) for topic in RATE_TOPICS)
    except LogError as error:
        reason = f"no flight dynamics: {without_path(error)}"
        return [], [NotScorable(name="frequency_responses", kind="frequency", reason=reason)]
    if not spans:
        reason = (f"no airborne span of ≥ {MIN_EXCITATION_S:g} s in a pilot-flown mode "
                  "(nav_state Manual, Altitude, Position, Acro or Stabilized): no broadband "
                  "excitation without a sweep")  # fmt: skip
        return [], [NotScorable(name="frequency_responses", kind="frequency", reason=reason)]
    start, end = spans[0]
    # the longest window half the span: three averages at 50 % overlap
    windows = tuple(math.floor((end - start) / 2**k * 100) / 100 for k in (4, 3, 2, 1))
    grid = np.arange(start, end, 1.0 / sample_rate)
    top_hz = BAND_TOP_NYQUIST * sample_rate / 2
    lowest_hz = math.ceil(spectral.MIN_CYCLES / windows[-1] * 100) / 100
    freqs = np.geomspace(lowest_hz, top_hz, COHERENCE_GRID_POINTS)
    minimum = indices.DEFAULT_COHERENCE_MIN
    tests: list[PlannedTest] = []
    skipped: list[NotScorable] = []
    for name, input_path, output_path, caveat in RESPONSES:
        try:
            estimate = spectral.estimate_response(
                _uniform(log, input_path, grid), _uniform(log, output_path, grid),
                sample_rate, freqs, windows)  # fmt: skip
        except (LogError, CredibilityError) as error:
            skipped.append(NotScorable(name=name, kind="frequency", reason=without_path(error)))
            continue
        band = coherent_band(freqs, estimate.coherence, minimum)
        if band is None:
            reason = (f"{input_path} → {output_path}: no octave between {lowest_hz:g} and "
                      f"{top_hz:g} Hz with γ² ≥ {minimum:g} at {COHERENT_SHARE:.0%} of it "
                      f"over the pilot's inputs {start:.2f}-{end:.2f} s: too little "
                      "excitation on this axis")  # fmt: skip
            skipped.append(NotScorable(name=name, kind="frequency", reason=reason))
            continue
        in_band = (freqs >= band[0]) & (freqs <= band[1])
        share = float(np.mean(estimate.coherence[in_band] >= minimum))
        band = (round(band[0], 2), round(band[1], 2))
        found = (
            f"Pilot's inputs, {start:.2f}-{end:.2f} s (the pilot-flown span with the "
            f"largest rate set-points): γ² ≥ {minimum:g} at {share:.0%} of the grid "
            f"over {band[0]:g}-{band[1]:g} Hz (the widest band at least "
            f"{COHERENT_SHARE:.0%} coherent; logged at {sample_rate:g} Hz). {caveat}"
        ).strip()
        keys = {"kind": "frequency", "input": input_path, "output": output_path,
                "segment_s": (start, end), "sample_rate_hz": sample_rate,
                "band_hz": band, "windows_s": windows, "n_points": N_POINTS}  # fmt: skip
        tests.append(PlannedTest(name, "frequency", found, keys))
    return tests, skipped


def log_limits(log: FlightLog) -> list[NotScorable]:
    """What the log's topics and rates rule out whatever the flight: a band above the rate
    topics' Nyquist frequency, rotor speeds without esc_status."""
    limits = []
    if all(topic in log.topics for topic in RATE_TOPICS):
        rate = min(logged_rate_hz(log, topic) for topic in RATE_TOPICS)
        reason = (
            f"the rate and torque topics are logged at {rate:g} Hz: nothing above the "
            f"{rate / 2:g} Hz Nyquist frequency"
        )
        limits.append(NotScorable(name=f"response_above_{rate / 2:g}_hz", kind="frequency",
                                  reason=reason))  # fmt: skip
    if "esc_status" not in log.topics:
        reason = "no esc_status in the log: the rotor speeds were not measured, only commanded"
        limits.append(NotScorable(name="rotor_speeds", kind="performance", reason=reason))
    return limits
