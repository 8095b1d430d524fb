"""Vehicle and sensor physics of a multicopter at 5 kHz: pure numerics, no I/O."""
