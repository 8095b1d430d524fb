"""The buses between autopilot and chips: SPI, I2C and PWM.

- ``signatures``: each bus's pins as a ``wiring.Signature`` (and the bus-fault inputs);
- ``spi_target``, ``i2c_target``: the target-side shift engines every chip reuses;
- ``spi_controller``, ``i2c_controller``, ``pwm_generator``: the flight controller MCU's
  peripherals in gateware (the co-simulation harness puts them on the pins);
- ``transactions``: the ``SpiBus``/``I2cBus`` protocols the drivers are written against,
  the bus errors, and the transaction-level buses over the chips' Python models;
- ``uart``: the GPS UART's 8N1 transmitter and receiver.

The testbench-side bus masters that drive these pins from Python live in
``fpga_hdl.verification``. Imports nothing of the chips, the host port, the top, the
co-simulation or the verification components.
"""
