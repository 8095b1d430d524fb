"""SensorTop's pins under cocotb, wired the way a flight controller wires them.

The one place that knows SensorTop's port names for the pin-level masters, so every
cocotb bench on the generated ``sensor_top`` starts from the same idle bus levels.
"""

from __future__ import annotations

from typing import Any  # a cocotb DUT: its ports, the generated Verilog's, are known at run time

from fpga_hdl.buses.i2c_target import I2cTiming
from fpga_hdl.cosim.host import CocotbHost
from fpga_hdl.top import HOST_MAP, SYS_CLK_HZ
from fpga_hdl.verification.i2c_master import CocotbI2cMaster
from fpga_hdl.verification.spi_master import DEFAULT_TIMING, CocotbSpiMaster, SpiMasterTiming


class SensorTopPins:
    """Host port, SPI controller (``imu``, ``baro``, ``flow``) and I2C controller on a
    SensorTop DUT.

    Construction drives every input to its idle level (chip selects high, SCL and SDA
    released, PWM inputs low with their domain unclocked, the GPS UART's RXD high with the
    receiver's ``uart`` domain unclocked);
    ``await pins.host.reset()`` then resets the design before the first transfer.
    """

    def __init__(
        self,
        dut: Any,
        *,
        spi_timing: SpiMasterTiming = DEFAULT_TIMING,
        i2c_timing: I2cTiming | None = None,
    ) -> None:
        self.host = CocotbHost(dut, HOST_MAP, sys_clk_hz=SYS_CLK_HZ)
        self.spi = CocotbSpiMaster(
            sclk=dut.spi_sclk,
            mosi=dut.spi_mosi,
            miso=dut.spi_miso,
            miso_oe=dut.spi_miso_oe,
            chip_selects={"imu": dut.imu_cs_n, "baro": dut.baro_cs_n, "flow": dut.flow_cs_n},
            timing=spi_timing,
            after_release=self.host.settle,  # a released CS clocks the deferred sample in
        )
        self.spi.idle()
        self.i2c = CocotbI2cMaster(
            scl=dut.i2c_scl,
            sda_i=dut.i2c_sda_i,
            sda_oe=dut.i2c_sda_oe,
            clk=dut.clk,
            sys_clk_hz=SYS_CLK_HZ,
            timing=i2c_timing,
        )
        for name in ("pwm", "pwm_clk", "pwm_rst", "uart_clk", "uart_rst"):
            getattr(dut, name).value = 0
        dut.gps_rx.value = 1  # the GPS UART's RXD idles high (a low line is a break)
