"""The rig's exceptions: each carries one line that tells the user what went wrong and where."""

from __future__ import annotations


class RigError(Exception):
    """Base of every error the rig reports to a user as one line (no traceback)."""


class ScenarioError(RigError):
    """A scenario file that cannot be run: names the file, the key and the value."""


class LinkError(RigError):
    """The simulator link to the autopilot failed; the message says which side stalled."""


class AutopilotNotConnected(LinkError):
    """Nobody connected to the rig's TCP port in time."""


class AutopilotStalled(LinkError):
    """The autopilot stopped answering sensor frames (hung, died or closed the link)."""


class AutopilotProtocolError(LinkError):
    """The autopilot sent something no PX4 would (NaN motor commands, ...)."""


class GroundLinkError(RigError):
    """A scenario command was refused or not acknowledged in time."""


class LogWriteFailed(RigError):
    """A log could not be written (a full disk): the file stays whole up to its last message."""


class CosimError(RigError):
    """The RTL co-simulation process failed, stalled or answered out of protocol."""
