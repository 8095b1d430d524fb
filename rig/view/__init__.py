"""The live view: a page on 127.0.0.1 that draws a run (the vehicle in 3D, its motors,
sensor traces, flight mode, injected faults, real-time factor) while it flies
(``rig run --view``), or plays a finished run back from its logs (``rig view RUN``)."""

from rig.view.frames import Recording, ViewError, load_recording, mode_name
from rig.view.server import VIEW_PORT, ViewServer

__all__ = ["VIEW_PORT", "Recording", "ViewError", "ViewServer", "load_recording", "mode_name"]
