"""Takeoff and landing detection, PX4's ``land_detector`` module for multicopters.

Landing goes through PX4's three stages (``MulticopterLandDetector.cpp``), each of which
must hold for a third of ``LNDMC_TRIG_TIME`` before the next one is considered:

1. *ground contact*: descent commanded, thrust below 60 % of the range from ``MPC_THR_MIN``
   to the hover thrust (PX4 takes 30 % without a valid hover thrust estimate and 60 % with
   one, which its estimator gives in flight; this autopilot's hover thrust is
   ``MPC_THR_HOVER``, known), no vertical (``LNDMC_Z_VEL_MAX``) or horizontal
   (``LNDMC_XY_VEL_MAX``) movement, and, when a rangefinder gives the height above the
   ground, less than 1 m of it (PX4 ``_is_close_to_ground``). The position controller
   then cuts thrust to its minimum and resets its integrators (PX4 ``mc_pos_control``:
   "flying but ground contact"), which is what lets the next stages trigger within a
   second of touchdown;
2. *maybe landed*: ground contact, thrust below 10 % of that range, and no roll/pitch
   rotation faster than ``LNDMC_ROT_MAX``;
3. *landed*: maybe landed for its third of the trigger time.

Without the thrust cut the vertical velocity integrator alone has to unwind the hover
thrust on the ground, which takes several seconds; the vehicle then sits armed long after
touchdown.
"""

from __future__ import annotations

import math

from rig.autopilots.reference.params import Parameters

#: Ground contact's low thrust, as a fraction of the range from MPC_THR_MIN to the hover
#: thrust: PX4's value while its hover thrust estimate is valid (``thr_pct_hover``).
LOW_THRUST_FRACTION = 0.6
#: PX4 ``DIST_FROM_GROUND_THRESHOLD``: ground contact needs the rangefinder's height below it.
CLOSE_TO_GROUND_M = 1.0
#: Takeoff: with the motors above idle, climbing this far above the arming height or this
#: fast (a simpler test than PX4's throttle-based one, enough without a pilot on sticks).
TAKEOFF_CLIMB_M = 0.5
TAKEOFF_CLIMB_RATE_MPS = 0.5


class Hysteresis:
    """A condition that must hold for a delay before the state turns true; it turns false
    at once (PX4 ``systemlib::Hysteresis`` with a false→true delay only)."""

    def __init__(self) -> None:
        self.state = False
        self._since_us: int | None = None

    def update(self, condition: bool, time_us: int, delay_us: int) -> bool:
        if not condition:
            self.state, self._since_us = False, None
        elif not self.state:
            if self._since_us is None:
                self._since_us = time_us
            self.state = time_us - self._since_us >= delay_us
        return self.state

    def reset(self) -> None:
        self.state, self._since_us = False, None


class LandDetector:
    """Landed / ground-contact state of a multicopter from its estimate and thrust.

    ``landed`` starts true; :meth:`arm` records the height the takeoff is measured from.
    """

    def __init__(self) -> None:
        self.landed = True
        self.ground_contact = False
        self.maybe_landed = False
        self._ground_contact = Hysteresis()
        self._maybe_landed = Hysteresis()
        self._landed = Hysteresis()
        self._height_at_arming_m = 0.0

    def arm(self, down_m: float) -> None:
        """Armed on the ground at NED height ``down_m``."""
        self.landed = True
        self._height_at_arming_m = down_m
        self._reset_stages()

    def disarm(self) -> None:
        """Disarmed counts as landed, as in PX4."""
        self.landed = True
        self._reset_stages()

    def detect_takeoff(self, down_m: float, velocity_down_mps: float) -> bool:
        """While landed with the motors not idle: has the vehicle left the ground?"""
        climbed = self._height_at_arming_m - down_m
        if climbed > TAKEOFF_CLIMB_M or velocity_down_mps < -TAKEOFF_CLIMB_RATE_MPS:
            self.landed = False
            self._reset_stages()
            return True
        return False

    def detect_landing(
        self,
        params: Parameters,
        time_us: int,
        velocity_down_mps: float,
        horizontal_speed_mps: float | None,
        velocity_sp_down_mps: float,
        collective_thrust: float,
        roll_pitch_rate_radps: float,
        dist_bottom_m: float | None = None,
    ) -> bool:
        """In flight: advance the three stages; True at the frame landing is detected.

        ``horizontal_speed_mps`` is None without a horizontal velocity estimate (no GPS):
        PX4 then counts no horizontal movement. ``dist_bottom_m`` is the rangefinder's
        height above the ground, None without one (the close-to-ground check is skipped).
        The descent counted as commanded is 90 % of the slowest the navigator commands:
        MPC_LAND_SPEED, or MPC_LAND_CRWL under a rangefinder.
        """
        hover, thr_min = params["MPC_THR_HOVER"], params["MPC_THR_MIN"]
        land_speed = params["MPC_LAND_SPEED"]
        stage_us = round(params["LNDMC_TRIG_TIME"] * 1e6 / 3)
        # after ground contact the controller commands minimum thrust, no velocity: PX4 then
        # counts the cut itself as the commanded descent (its 100 m/s² down set-point)
        slowest = land_speed if dist_bottom_m is None else min(land_speed, params["MPC_LAND_CRWL"])
        descending = velocity_sp_down_mps >= 0.9 * slowest or self.ground_contact
        still = abs(velocity_down_mps) <= min(0.45 * land_speed, params["LNDMC_Z_VEL_MAX"]) and (
            horizontal_speed_mps is None or horizontal_speed_mps <= params["LNDMC_XY_VEL_MAX"]
        )
        low_thrust = collective_thrust <= thr_min + LOW_THRUST_FRACTION * (hover - thr_min)
        close_to_ground = dist_bottom_m is None or dist_bottom_m < CLOSE_TO_GROUND_M
        self.ground_contact = self._ground_contact.update(
            descending and still and low_thrust and close_to_ground, time_us, stage_us
        )
        minimal_thrust = collective_thrust <= thr_min + 0.1 * (hover - thr_min)
        not_rotating = roll_pitch_rate_radps <= math.radians(params["LNDMC_ROT_MAX"])
        self.maybe_landed = self._maybe_landed.update(
            self.ground_contact and minimal_thrust and not_rotating, time_us, stage_us
        )
        if self._landed.update(self.maybe_landed, time_us, stage_us):
            self.landed = True
            self._reset_stages()
            return True
        return False

    def _reset_stages(self) -> None:
        self.ground_contact = self.maybe_landed = False
        for stage in (self._ground_contact, self._maybe_landed, self._landed):
            stage.reset()
