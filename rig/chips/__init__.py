"""The emulated sensor chips in the loop: the sensor-layer protocol and its TLM, RTL
(cocotb in its own process, behind a binary channel) and bypass implementations, and the
autopilot's PWM outputs as the capture core sees them.

May import: quad_model, fpga_hdl, rig.errors. Nothing else of the rig.
"""
