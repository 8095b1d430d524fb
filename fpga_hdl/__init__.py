"""Amaranth cores that impersonate sensor chips (SPI, I2C, PWM capture), co-simulated in cocotb.

- ``chips/``: one folder per chip (register map, core, model, driver);
- ``buses/``: the bus signatures, shift engines, the MCU-side peripherals and the
  transaction-level buses;
- ``verification/``: testbench-side bus masters (cocotb, ``amaranth.sim``) and the
  scoreboard of the RTL-equals-TLM checks;
- ``host/``: the host port and clock-domain crossing;
- ``top.py``: ``SensorTop``, every chip behind one host port (the rig's FPGA);
- ``cosim/``: the cocotb harness, runner and host access; ``build.py``: Verilog.

Layers (checked by import-linter): cosim, then build (Verilog), then the top, then the
chips or verification, then buses and host; no gateware imports verification, and
fpga_hdl never imports the rig.
"""
