"""Testbench-side verification components: what drives and checks the gateware, never in it.

- ``spi_master``, ``i2c_master``, ``pwm_source``: pin-level bus masters under cocotb that
  implement the ``SpiBus``/``I2cBus`` protocols of ``fpga_hdl.buses.transactions``;
- ``amaranth_spi``, ``amaranth_i2c``: the SPI and I2C masters for ``amaranth.sim`` unit tests;
- ``scoreboard``: the one "RTL equals its TLM twin" check, and the paired buses feeding it.

Why apart from ``fpga_hdl.buses``: that package is gateware and the protocols the product
ships; these are stimulus and checkers, and the import contracts keep every gateware
layer from importing them. Imports only ``fpga_hdl.buses``.
"""
