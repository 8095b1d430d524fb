"""cocotb module: the shared transcript (``transcript.py``) over the pin-level masters.

Run by ``test_cosim_harness.py`` on SensorTop; writes the transcript to $TRANSCRIPT_OUT.
"""

import json
import os

import cocotb
from transcript import run_script

from fpga_hdl.cosim.host import CocotbHost
from fpga_hdl.cosim.sensor_top import SensorTopPins


class HostChips:
    def __init__(self, host: CocotbHost) -> None:
        self.host = host

    async def load(self, samples, now_us):
        await self.host.load(samples, now_us=now_us)


@cocotb.test()
async def transcript(dut):
    pins = SensorTopPins(dut)
    await pins.host.reset()
    log = await run_script(pins.spi, pins.i2c, HostChips(pins.host))
    with open(os.environ["TRANSCRIPT_OUT"], "w") as out:
        json.dump(log, out)
