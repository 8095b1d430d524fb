"""Vehicle parameters identified from a flight log (``rig identify LOG``): hover throttle and
the speed curve, roll/pitch control effectiveness, motor lag and delay, and the inertia.

The paper's high-precision model has "all model parameters accurately measured or obtained
by system identification"; this package is the identification half, for any PX4-style ULog
(a real flight, PX4 SITL, or the rig's reference autopilot) at any logging rate. The wind a
flight met (:mod:`rig.identify.wind`) and the IMU's noise and vibration per operating point
(:mod:`rig.identify.vibration`) are identified here too.

Methods, each reported with its data window and an uncertainty:

- **Hover**: steady windows found automatically (airborne, small velocity and body rates).
  The ESC throttle there is ``actuator_motors`` mapped through the range of the driver that
  runs the motors (:func:`px4_logs.motor_outputs`: PWM, DShot, UAVCAN ESCs) onto the model's
  1000-2000 µs throttle (:func:`quad_model.frames.pwm_to_throttle`). The hover rotor speed ω_h
  must sit at that throttle on the speed curve; the curve's full-throttle point is kept and
  its offset solved for. ω_h is measured where the log shows it (the ESCs' ``esc_status``,
  else the rotor line), else ω_h = √(mg/4k_T) with the vehicle's k_T.
- **Rotor line**: the rotors' once-per-revolution line (prop and motor imbalance) is the
  strongest peak of the accelerometer's spectrum in hover. A logged stream folds lines above
  its Nyquist frequency, so the line must also *rise* with the motor command × voltage
  across the flight (a folded line falls; neither: not identified), and the rotors' shaft
  power at that speed must stay below the battery's power into the motors (a harmonic read
  as the 1× would not). Then ω_h = 2πf and k_T = mg/(4ω_h²), the thrust coefficient at the
  vehicle's reference air density.
- **Battery**: V = E₀ − s·Q − R·I over the armed flight (``battery_status``: voltage, current,
  charge drawn) by least squares gives the internal resistance R; the current after the
  disarm (rotors stopped) the avionics' power; the hover's electrical power against the
  rotors' shaft power 4·k_Q·ω_h³ (the vehicle's torque coefficient) the propulsion efficiency.
- **Rate-loop plant** per axis: the frequency response torque set-point → body rate, fitted
  to ``B·e^{−sd}/(s(τ_m s+1))`` times the log's gyro low-pass (``IMU_GYRO_CUTOFF``,
  PX4's 2nd-order Butterworth), so the filter's phase is not blamed on the motors. The data
  are closed-loop: where the loop's own noise dominates (above a few Hz in hover), the plain
  H1 estimate torque→rate tends to −1/C(s), the inverse of the rate controller, not the plant
  (on the X500 log: phase ≈ +170°, |H| flat from 3 to 20 Hz). So the response is the
  joint input-output estimate with the rate set-point as instrument,
  G = Ĥ(rate_sp→rate) / Ĥ(rate_sp→torque_sp) (Ljung, *System Identification*, §13.5), each
  leg from :func:`credibility.spectral.estimate_response` and both gated on coherence.
- **Inertia**: I = (body torque per unit normalized torque at hover) / B. The numerator is
  computed through the real parts: the reference autopilot's mixer
  (:class:`rig.autopilots.reference.control.ControlAllocator` with the log's ``CA_ROTOR*`` geometry)
  turns a torque set-point into motor commands, and the vehicle model on its thrust stand
  (:class:`quad_model.model.QuadModel`, ``Mount.THRUST_STAND``), fed from a bench supply at
  the log's hover voltage, turns them into a moment.
- **Yaw** is not identified: its reaction-torque path (rotor drag plus spin-up torque) is not
  the rate model above, and ordinary flying excites it little; the result says so.

An estimate outside its physical bounds (:mod:`rig.identify.bounds`) is refused with its
reason, never shown or written as a result; the vehicle keeps its prior value.
"""

from rig.identify.report import identification_table, identification_toml
from rig.identify.results import (
    AxisIdentification,
    BatteryIdentification,
    Estimate,
    HoverIdentification,
    Identification,
    IdentificationError,
    RotorLine,
)
from rig.identify.vehicle import identify_vehicle

__all__ = [
    "AxisIdentification",
    "BatteryIdentification",
    "Estimate",
    "HoverIdentification",
    "Identification",
    "IdentificationError",
    "RotorLine",
    "identification_table",
    "identification_toml",
    "identify_vehicle",
]
