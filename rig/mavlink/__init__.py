"""PX4's simulator MAVLink API and the links that speak it: the shared facts (ports,
message fields), the HIL messages, the simulator TCP link with its lockstep and watchdog,
and the scenario's ground link.

May import: quad_model, rig.errors. Nothing else of the rig.
"""
