"""Amaranth cores that impersonate sensor chips on SPI/I2C and capture PWM, with cocotb co-simulation."""
