"""Scenarios and faults: the scenario file (and the bundled ones beside it), the command
script that turns its commands into ground-link conversations, and fault injection.

May import: quad_model, fpga_hdl, rig.chips, rig.mavlink, rig.errors. Not the lockstep
loop, the autopilots or the applications.
"""
