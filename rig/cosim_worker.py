"""cocotb module of the RTL sensor layer: serves the rig's channel inside the simulator.

Started by :class:`rig.cosim.RtlSensorLayer` through fpga_hdl's cocotb runner on
SensorTop's generated Verilog. It connects to the Unix socket named by
``RIG_COSIM_SOCKET`` and answers the requests of :mod:`rig.cosim_channel` one by one.
While it waits for a request no simulated time passes, and SensorTop's clock only runs
while the host port is written or a bus transfer is under way (fpga_hdl's gated-clock
host), so an idle millisecond costs nothing.

Which parts are RTL: the MPU-6000 and MS5611 on the shared SPI bus, driven by
fpga_hdl's pin-level SPI controller, with samples, time and faults loaded through the
host port. The IST8310 (I2C) and the PWM capture run on their transaction-level models
in this process until fpga_hdl ships a cocotb I2C controller and puts the PWM capture
core in SensorTop; the rig log's ``ver_hw`` says ``RIG_RTL``.
"""

from __future__ import annotations

import os
import socket

import cocotb

from fpga_hdl.buses import TlmI2cBus
from fpga_hdl.cosim.host import CocotbHost
from fpga_hdl.cosim.spi_master import CocotbSpiMaster
from fpga_hdl.ist8310.model import Ist8310Model
from fpga_hdl.top import HOST_MAP, SYS_CLK_HZ
from rig.cosim_channel import (
    ERROR,
    FRAME,
    OK,
    START,
    STOP,
    decode_frame,
    encode_readout,
    receive_message,
    send_message,
)
from rig.pwm import MOTOR_CHANNELS, Pulse, PwmCapture
from rig.sensor_layer import CHIPS, NO_FAULT, ChipFrame, SensorEngine

#: SensorTop's host-port channel and fault names for the rig's chip names.
_HOST_CHIP = {"mpu6000": "imu", "ms5611": "baro", "ist8310": "mag"}


class RtlChips:
    """:class:`rig.sensor_layer.ChipHost` over SensorTop's host port."""

    def __init__(self, host: CocotbHost) -> None:
        self.host = host
        self.ist8310 = Ist8310Model()
        self.pwm = PwmCapture(MOTOR_CHANNELS)

    async def load(self, frame: ChipFrame) -> None:
        samples: dict[str, dict[str, int]] = {}
        if frame.imu is not None:
            samples["imu"] = frame.imu.fields()
        if frame.baro_d1_d2 is not None:
            samples["baro"] = {"d1": frame.baro_d1_d2[0], "d2": frame.baro_d1_d2[1]}
        faults = {}
        for chip in CHIPS:
            fault = frame.faults.get(chip, NO_FAULT)
            faults[_HOST_CHIP[chip]] = (fault.mute, fault.flip)
        await self.host.load(samples, now_us=frame.now_us, faults=faults)
        mag_fault = frame.faults.get("ist8310", NO_FAULT)
        self.ist8310.now_us = frame.now_us
        self.ist8310.fault_mute, self.ist8310.fault_flip = mag_fault.mute, mag_fault.flip
        if frame.mag is not None:
            self.ist8310.load_sample(frame.mag)

    async def capture(
        self, pulses: tuple[Pulse, ...], now_us: int
    ) -> tuple[tuple[float, ...], tuple[bool, ...]]:
        return self.pwm.capture(pulses, now_us)


@cocotb.test()
async def serve(dut) -> None:
    """Answer the rig's requests until it sends STOP (or closes the channel)."""
    channel = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    channel.connect(os.environ["RIG_COSIM_SOCKET"])
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
    dut.i2c_scl.value = 1
    dut.i2c_sda_i.value = 1
    await host.reset()
    chips = RtlChips(host)
    engine = SensorEngine(spi, TlmI2cBus({chips.ist8310.address: chips.ist8310}), chips)
    while True:
        request = receive_message(channel)
        kind = request[0]
        try:
            if kind == START:
                await engine.start()
                answer = bytes([OK])
            elif kind == FRAME:
                answer = encode_readout(await engine.frame(decode_frame(request[1:])))
            elif kind == STOP:
                send_message(channel, bytes([OK]))
                channel.close()
                return
            else:
                answer = bytes([ERROR]) + f"unknown request kind {kind}".encode()
        except Exception as error:  # reported to the rig as one line, then the run stops
            answer = bytes([ERROR]) + f"{type(error).__name__}: {error}".encode()
        send_message(channel, answer)
