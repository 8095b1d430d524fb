"""The emulated chips, one folder each: ``regs`` (the datasheet's register map), ``core``
(the gateware), ``model`` (the transaction-level twin, byte-identical on the bus) and
``driver`` (PX4's driver sequence, run against any bus of :mod:`fpga_hdl.buses`).

A chip imports :mod:`fpga_hdl.buses` (its bus signature and shift engine) and
:mod:`fpga_hdl.host`; never the top, the co-simulation or another chip.
"""
