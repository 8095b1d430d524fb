"""cocotb side of the co-simulation: the runner, the harness and its peripherals, host access."""
