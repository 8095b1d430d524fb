"""cocotb module: the shared transcript (``transcript.py``) over the pin-level masters.

Run by ``test_cosim_harness.py`` on SensorTop; writes the transcript to $TRANSCRIPT_OUT.
"""

import json
import os

import cocotb
from transcript import run_script

from fpga_hdl.cosim.host import CocotbHost
from fpga_hdl.cosim.i2c_master import CocotbI2cMaster
from fpga_hdl.cosim.spi_master import CocotbSpiMaster
from fpga_hdl.top import HOST_MAP, SYS_CLK_HZ


class HostChips:
    def __init__(self, host: CocotbHost) -> None:
        self.host = host

    async def load(self, samples, now_us):
        await self.host.load(samples, now_us=now_us)


@cocotb.test()
async def transcript(dut):
    host = CocotbHost(dut, HOST_MAP, sys_clk_hz=SYS_CLK_HZ)
    spi = CocotbSpiMaster(
        sclk=dut.spi_sclk,
        mosi=dut.spi_mosi,
        miso=dut.spi_miso,
        miso_oe=dut.spi_miso_oe,
        chip_selects={"imu": dut.imu_cs_n, "baro": dut.baro_cs_n},
        after_release=host.settle,
    )
    spi.idle()
    i2c = CocotbI2cMaster(
        scl=dut.i2c_scl,
        sda_i=dut.i2c_sda_i,
        sda_oe=dut.i2c_sda_oe,
        clk=dut.clk,
        sys_clk_hz=SYS_CLK_HZ,
    )
    dut.pwm.value = 0
    dut.pwm_clk.value = 0
    dut.pwm_rst.value = 0
    await host.reset()
    log = await run_script(spi, i2c, HostChips(host))
    with open(os.environ["TRANSCRIPT_OUT"], "w") as out:
        json.dump(log, out)
