"""The closed-loop rig: lockstep orchestration, PX4's simulator MAVLink API, faults, logs."""
