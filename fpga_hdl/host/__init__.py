"""The host side of the FPGA: the port the real-time computer loads samples, time and
faults through and reads results from (``host_port``), and the clock-domain crossing of
whole result sets (``snapshot_cdc``). Imports nothing else of fpga_hdl.
"""
