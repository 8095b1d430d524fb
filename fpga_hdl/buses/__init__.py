"""The buses between autopilot and chips: SPI, I2C and PWM.

- ``signatures``: each bus's pins as a ``wiring.Signature`` (and the bus-fault inputs);
- ``spi_target``, ``i2c_target``: the target-side shift engines every chip reuses;
- ``spi_controller``, ``i2c_controller``, ``pwm_generator``: the flight controller MCU's
  peripherals in gateware (the co-simulation harness puts them on the pins);
- ``transactions``: the ``SpiBus``/``I2cBus`` protocols the drivers are written against,
  the bus errors, and the transaction-level buses over the chips' Python models;
- the bus-master models that implement those protocols pin by pin: ``spi_master``,
  ``i2c_master``, ``pwm_source`` under cocotb, ``amaranth_spi`` under ``amaranth.sim``.

Imports nothing of the chips, the host port, the top or the co-simulation.
"""
