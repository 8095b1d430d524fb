"""Fault injection at every layer of the rig, in one place.

Each fault of a scenario (``rig.scenarios.scenario.FaultSpec``) acts on the layer where it would
happen on the real rig, from its start time until its end time (or the end of the run),
and is logged when it starts and when it ends:

| kind | layer | effect |
|---|---|---|
| ``motor_loss``, ``motor_degradation`` | vehicle (quad_model) | motor health 0 or ``efficiency`` |
| ``sensor_stuck`` | sensor physics, before the chips | the value freezes at its last sample |
| ``sensor_bias`` | sensor physics | ``bias`` added (SI units of that sensor) |
| ``noise_burst`` | sensor physics | white noise of ``std`` added, from the seeded generator |
| ``bus_bit_flip`` | chip (RTL or TLM) | ``fault_flip``: XOR ``mask`` on every byte sent |
| ``chip_mute`` | chip (RTL or TLM) | ``fault_mute``: the chip stops answering |
| ``gps_loss`` | GPS receiver | no HIL_GPS is sent |
| ``gps_receiver`` | u-blox chip | ``loss_of_fix``/``jammed`` solution; ``bad_checksum`` on UART |
| ``flow_chip`` | PMW3901 chip | ``stuck`` image, ``zero_quality`` SQUAL, ``drop_frames`` |
| ``pwm_dropout`` | PWM lines | no pulses on ``channel`` (all if absent): the capture times out |

A motor fault names a motor of the vehicle flown (``0`` to its rotor count less one, in PX4's
motor order), which the scenario file cannot know (``--vehicle`` may change it): the run
checks it (:func:`check_motors`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType
from typing import Protocol

import numpy as np

from fpga_hdl.chips.pmw3901 import regs as pmw3901_regs
from fpga_hdl.chips.ublox.link import BAD_CHECKSUM_FLIP, GpsFault
from quad_model.sensors import SensorReadings
from rig.chips.layer import Chip, ChipFault
from rig.errors import ScenarioError
from rig.scenarios.scenario import FaultSpec

#: Which sample and field each sensor name of a scenario refers to.
_SAMPLE_FIELD = {
    "accel": ("imu", "accel_mps2"),
    "gyro": ("imu", "gyro_radps"),
    "mag": ("mag", "field_gauss"),
    "baro": ("baro", "pressure_pa"),
}
#: The fault keys that name a motor (PWM channel ``i`` drives motor ``i``).
_MOTOR_KEYS = ("motor", "channel")


def check_motors(faults: Sequence[FaultSpec], motors: int, source: str, vehicle: str) -> None:
    """Refuse, in one line naming the scenario key, a fault on a motor ``vehicle`` (with
    ``motors`` rotors) does not have."""
    for index, fault in enumerate(faults):
        for key in _MOTOR_KEYS:
            motor = getattr(fault, key, None)
            if motor is not None and motor >= motors:
                raise ScenarioError(f"{source}: key 'faults[{index}].{key}' = {motor}: vehicle "
                                    f"{vehicle!r} has motors 0..{motors - 1}")  # fmt: skip


class MotorHealth(Protocol):
    """What the injector needs of the vehicle model: quad_model's per-motor health hook."""

    def set_motor_health(self, motor: int, thrust_fraction: float) -> None: ...


class FaultInjector:
    """Applies the scenario's faults as simulated time passes.

    Parameters
    ----------
    faults
        The scenario's fault list.
    rng
        Seeded generator for noise bursts (the same seed gives the same noise).
    announce
        Called ``(time_us, text)`` when a fault starts or ends, so the rig logs it.
    motors
        The vehicle's rotor count: a PWM dropout without a channel silences them all.
    """

    def __init__(
        self,
        faults: Sequence[FaultSpec],
        rng: np.random.Generator,
        announce: Callable[[int, str], None],
        motors: int,
    ) -> None:
        self.faults = tuple(faults)
        self._motors = motors
        self._rng = rng
        self._announce = announce
        self._active_index: frozenset[int] = frozenset()
        self._active: tuple[FaultSpec, ...] = ()
        self._stuck: dict[str, object] = {}  # sensor → frozen value
        self._last: dict[str, object] = {}  # sensor → latest healthy value
        #: Only a scenario with a stuck fault needs the latest healthy value of each sensor.
        self._tracks_last = any(f.kind == "sensor_stuck" for f in self.faults)
        # What the chips and the PWM lines see changes only when a fault starts or ends.
        self._chip_faults: Mapping[str, ChipFault] = MappingProxyType({})
        self._pwm_dropped: frozenset[int] = frozenset()
        self._gps_fault: GpsFault | None = None

    def update(self, time_us: int, model: MotorHealth) -> None:
        """Start and end faults at this frame; motor faults act on the model here."""
        time_s = time_us / 1e6
        now_active = frozenset(i for i, f in enumerate(self.faults) if f.active(time_s))
        for index, fault in enumerate(self.faults):
            was, now = index in self._active_index, index in now_active
            if was == now:
                continue
            self._announce(time_us, f"fault {describe(fault)} {'started' if now else 'ended'}")
            if fault.kind in ("motor_loss", "motor_degradation"):
                health = getattr(fault, "efficiency", 0.0) if now else 1.0
                model.set_motor_health(fault.motor, health)
            if fault.kind == "sensor_stuck":
                sensor = fault.sensor
                if now:
                    self._stuck[sensor] = self._last.get(sensor)
                else:
                    self._stuck.pop(sensor, None)
        if now_active != self._active_index:
            self._active_index = now_active
            self._active = tuple(self.faults[i] for i in sorted(now_active))
            self._chip_faults = MappingProxyType(self._chip_inputs())
            self._pwm_dropped = self._dropped_channels()
            self._gps_fault = self._receiver_fault()

    def samples(self, readings: SensorReadings) -> SensorReadings:
        """Sensor-physics faults: stuck, bias, noise burst, GPS loss."""
        if not (self._active or self._tracks_last):
            return readings  # the healthy frame: nothing to change, nothing to remember
        for sensor, (sample_name, field) in _SAMPLE_FIELD.items():
            sample = getattr(readings, sample_name)
            if sample is None:
                continue
            value = getattr(sample, field)
            if sensor in self._stuck:
                frozen = self._stuck[sensor]
                value = value if frozen is None else frozen
            else:
                self._last[sensor] = value
            for fault in self._active:
                if getattr(fault, "sensor", None) != sensor:
                    continue
                if fault.kind == "sensor_bias":
                    value = value + np.asarray(fault.bias)
                elif fault.kind == "noise_burst":
                    shape = np.shape(value)
                    value = value + fault.std * self._rng.standard_normal(shape)
            if value is not getattr(sample, field):
                sample = dataclasses.replace(sample, **{field: _like(value, sample, field)})
                readings = dataclasses.replace(readings, **{sample_name: sample})
        if readings.gps is not None and any(f.kind == "gps_loss" for f in self._active):
            readings = dataclasses.replace(readings, gps=None)
        return readings

    def chip_faults(self) -> Mapping[str, ChipFault]:
        """Bus faults for the chips' ``fault_mute`` / ``fault_flip`` inputs."""
        return self._chip_faults

    def gps_fault(self) -> GpsFault | None:
        """The GPS receiver's solution fault now (``loss_of_fix`` / ``jammed``); a line
        fault (``bad_checksum``) is in :meth:`chip_faults` as the receiver's flip."""
        return self._gps_fault

    def _receiver_fault(self) -> GpsFault | None:
        """The latest-started solution fault wins (both at once is not one receiver state)."""
        solution = [f.fault for f in self._active if f.kind == "gps_receiver"]
        solution = [fault for fault in solution if fault is not GpsFault.BAD_CHECKSUM]
        return solution[-1] if solution else None

    def pwm_dropped(self) -> frozenset[int]:
        """PWM channels that emit no pulses now."""
        return self._pwm_dropped

    def _chip_inputs(self) -> dict[str, ChipFault]:
        faults: dict[str, ChipFault] = {}
        for fault in self._active:
            chip = Chip.PMW3901 if fault.kind == "flow_chip" else getattr(fault, "chip", None)
            if chip is None:
                continue
            current = faults.get(chip, ChipFault())
            if fault.kind == "chip_mute":
                faults[chip] = dataclasses.replace(current, mute=True)
            elif fault.kind == "bus_bit_flip":
                faults[chip] = dataclasses.replace(current, flip=current.flip | fault.mask)
            elif fault.kind == "flow_chip":
                own = current.own | pmw3901_regs.FAULT_BITS[fault.mode]
                faults[chip] = dataclasses.replace(current, own=own)
        if any(getattr(f, "fault", None) is GpsFault.BAD_CHECKSUM for f in self._active):
            current = faults.get(Chip.UBLOX, ChipFault())
            faults[Chip.UBLOX] = dataclasses.replace(current, flip=current.flip | BAD_CHECKSUM_FLIP)
        return faults

    def _dropped_channels(self) -> frozenset[int]:
        dropped: set[int] = set()
        for fault in self._active:
            if fault.kind == "pwm_dropout":
                channel = fault.channel
                dropped |= set(range(self._motors)) if channel is None else {channel}
        return frozenset(dropped)


def describe(fault: FaultSpec) -> str:
    """``motor_loss (motor=0)``: the kind and its parameters, for log lines."""
    params = ", ".join(f"{k}={v}" for k, v in fault.parameters.items() if v is not None)
    return f"{fault.kind} ({params})" if params else fault.kind


def _like(value: float | np.ndarray, sample: object, field: str) -> float | np.ndarray:
    """Keep the sample field's type: a float stays a float, an array an array."""
    original = getattr(sample, field)
    return float(value) if isinstance(original, float) else np.asarray(value, dtype=float)
