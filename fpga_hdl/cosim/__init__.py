"""cocotb side of the co-simulation: the runner and the pin-level bus masters."""
