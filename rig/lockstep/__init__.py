"""The closed loop: model → chips → autopilot → PWM → model, one lockstep frame at a time.

May import: every rig subpackage but the applications.
"""
