"""Amaranth cores that impersonate sensor chips (SPI, I2C, PWM capture), co-simulated in cocotb."""
