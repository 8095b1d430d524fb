"""The flight controllers on the autopilot side of the link: PX4 SITL from the user's
build (:mod:`rig.autopilots.px4`) and the embedded reference autopilot
(:mod:`rig.autopilots.reference`, a separate process speaking PX4's protocol).

May import: quad_model, rig.mavlink, rig.logs, rig.errors, rig.processes. Not the
lockstep loop, the chips or the applications.
"""

from enum import StrEnum


class Autopilot(StrEnum):
    """Which flight controller a run flies (``--autopilot``)."""

    #: The embedded reference autopilot (``python -m rig.autopilots.reference``).
    REFERENCE = "reference"
    #: PX4 SITL, from the user's build or started by hand.
    PX4 = "px4"
