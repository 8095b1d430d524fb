"""cocotb module of the RTL sensor layer: serves the rig's channel inside the simulator.

Started by :class:`rig.chips.rtl.RtlSensorLayer` through fpga_hdl's cocotb runner on the
co-simulation harness (:class:`fpga_hdl.cosim.harness.CosimHarness`: SensorTop unchanged,
with the flight controller's SPI/I2C controllers, its PWM timer and the host-port burst
writer/reader around it as gateware). It connects to the Unix socket named by
``RIG_COSIM_SOCKET`` and answers the requests of :mod:`rig.chips.channel` one by one.

Everything is RTL: the MPU-6000, the MS5611 and the PMW3901 on the shared SPI bus, the
IST8310 and the LIDAR-Lite on I2C, and the PWM capture core, which measures the pulses the
harness's PWM generator replays from the autopilot's outputs. Python only asks and waits
once per transaction (``fpga_hdl.cosim.peripherals``); the clocks are gated Verilog
clocks, so no Python runs per cycle.

Time. Simulated time follows rig time from an *epoch* (the simulated time of rig time 0,
fixed after start-up), so the capture core sees the real pulse durations. Its tick clock
(``pwm_tick_hz``) runs from then on with an edge a quarter system period after every rig
tick ``k / pwm_tick_hz``: edge ``k`` of the core is sample ``k`` of fpga_hdl's tick-exact
model, which is what the TLM layer evaluates. The generator's outputs are registered, so
a pulse the rig starts at tick ``k`` is set up to leave the generator at edge ``k - 1``,
and its width must be in the generator's preload register before that edge. A frame's
widths are therefore written when its request arrives, before the bus transfers, and
the capture is read once simulated time has reached the frame's ``now_us``.

Reading the capture. The read is requested at the frame time, on rig tick
``now_us / tick`` just before the capture clock's edge of that tick: the harness's
reader freezes every result word in one system cycle once the results' synchroniser has
caught up (SensorTop's fixed latency, ``fpga_hdl.top``), so the read sees exactly the
results published up to that edge, whole. The TLM layer models the same latency
(``rig.chips.pwm.PwmCapture``), so both layers agree by construction; the tests compare them
frame by frame, and nothing here looks at the model.
"""

from __future__ import annotations

import math
import os
import socket
from collections.abc import Mapping
from typing import Any

import cocotb
from cocotb.utils import get_sim_time

from fpga_hdl.buses.transactions import UartTransfer
from fpga_hdl.chips.pwm_capture.core import CHANNELS
from fpga_hdl.cosim.peripherals import PWM_PHASE_PS, Harness
from rig.chips.channel import (
    ERROR,
    FRAME,
    OK,
    START,
    STOP,
    decode_frame,
    decode_start,
    encode_readout,
    receive_message,
    send_message,
)
from rig.chips.layer import ChipFault, ChipFrame, SensorEngine, host_port_inputs
from rig.chips.pwm import Pulse, PwmTimingError, replay_periods


class RtlChips:
    """:class:`rig.chips.layer.ChipHost` over the harness: host port, PWM generator, capture."""

    def __init__(self, harness: Harness, *, pwm_tick_hz: float) -> None:
        self.harness = harness
        self.tick_us = 1e6 / pwm_tick_hz
        self.tick_ps = round(1e12 / pwm_tick_hz)
        self.period_us = 0
        self.motors = 0  # the capture channels read: the vehicle's rotors, set at start
        self._epoch_ps = 0
        self._next_start_us = 0  # the next PWM period start not replayed yet
        self._loaded: list[int] = [0] * CHANNELS  # widths (ticks) in the preload register
        self._later: list[tuple[int, list[int]]] = []  # this frame's further periods
        self._held_faults: Mapping[str, ChipFault] | None = None  # what the chips were loaded with

    async def start_pwm(self, period_us: int, motors: int) -> None:
        """Fix the epoch two ticks ahead, start the generator and the capture clock; the
        capture's first ``motors`` channels are read from now on.

        The generator runs from edge ``-1`` (one tick before rig time 0) with zero widths:
        no pulse until the first frame preloads the widths of the period at rig time 0.
        """
        if period_us * 1_000_000 % self.tick_ps:
            raise PwmTimingError(
                f"the PWM period ({period_us} µs) is not a whole number of capture ticks "
                f"({self.tick_us:g} µs)"
            )
        self.period_us, self.motors = period_us, motors
        now_ps = get_sim_time("ps")
        self._epoch_ps = (math.ceil(now_ps / self.tick_ps) + 2) * self.tick_ps
        self.harness.pwm.write([0] * CHANNELS, period_ticks=round(period_us / self.tick_us))
        # The gated clock's first rising edge comes half a period after it is enabled.
        await self._wait_until_ps(self._edge_ps(-1) - PWM_PHASE_PS - self.tick_ps // 2)
        await self.harness.pwm.run()

    def _edge_ps(self, tick: int) -> int:
        """Simulated time of the capture clock's rising edge ``tick`` (rig tick ``tick``)."""
        return self._epoch_ps + tick * self.tick_ps + PWM_PHASE_PS

    async def _wait_until_ps(self, time_ps: int) -> None:
        await self.harness.wait_until_s(time_ps * 1e-12)

    async def load(self, frame: ChipFrame) -> None:
        periods, self._next_start_us = replay_periods(
            frame.pulses, frame.now_us, self._next_start_us, self.period_us, self.tick_us
        )
        if periods:
            self._preload(*periods[0])
        self._later = periods[1:]
        samples, faults = host_port_inputs(frame, self._held_faults)
        await self.harness.host.load(samples, now_us=frame.now_us, faults=faults)
        self._held_faults = frame.faults

    def _preload(self, start_us: int, widths: list[int]) -> None:
        """Write the widths of the period at ``start_us`` before the generator takes them."""
        if widths == self._loaded:
            return
        latch_ps = self._edge_ps(round(start_us / self.tick_us) - 1)
        if get_sim_time("ps") >= latch_ps:
            raise PwmTimingError(
                f"the PWM period at {start_us} µs starts too soon after the previous frame "
                "for the RTL PWM generator to take its new widths; choose rates so that no "
                "PWM period starts within a few µs after an IMU frame"
            )
        self.harness.pwm.write(widths, period_ticks=round(self.period_us / self.tick_us))
        self._loaded = widths

    async def exchange(self, tx: bytes, *, baud: int) -> UartTransfer:
        """The GPS UART (:class:`~fpga_hdl.buses.transactions.UartPort`).

        A NAV-PVT takes 8.7 ms on the line, longer than a frame, while the bus transfers of
        a frame must end before its capture read. On the board the UART runs beside the
        other buses; here the capture clock (and the PWM generator on it) stands still while
        the exchange runs and rig time resumes after it: the epoch moves on by whole ticks,
        as in the compiled layer, whose capture clock runs only when asked.
        """
        if not self.period_us:  # start-up: the capture clock does not run yet
            return await self.harness.uart.exchange(tx, baud=baud)
        paused_ps = get_sim_time("ps")
        self.harness.dut.pwm_run.value = 0
        # The gated clock finishes the cycle it has begun (its rise comes half a tick after
        # the cycle starts): the last edge is the last one whose cycle began before now.
        half = self.tick_ps // 2
        last = math.ceil((paused_ps + half - self._edge_ps(0)) / self.tick_ps) - 1
        transfer = await self.harness.uart.exchange(tx, baud=baud)
        resume_ps = self._edge_ps(last + 1) - PWM_PHASE_PS - half
        late_ps = get_sim_time("ps") - resume_ps
        if late_ps > 0:
            self._epoch_ps += math.ceil(late_ps / self.tick_ps) * self.tick_ps
        await self._wait_until_ps(self._edge_ps(last + 1) - PWM_PHASE_PS - half)
        await self.harness.pwm.run()
        return transfer

    async def capture(
        self, pulses: tuple[Pulse, ...], now_us: int
    ) -> tuple[tuple[float, ...], tuple[bool, ...]]:
        """Replay this frame's further periods, let time reach ``now_us``, read the capture."""
        previous_us = None
        for start_us, widths in self._later:
            if previous_us is not None and widths != self._loaded:
                # After the previous period's start edge, which took the widths before.
                await self._wait_until_ps(
                    self._edge_ps(round(previous_us / self.tick_us) - 1) + self.tick_ps // 2
                )
            self._preload(start_us, widths)
            previous_us = start_us
        # The read starts on the last tick at or before now_us, just before that tick's
        # capture edge (PWM_PHASE_PS later), and freezes the results of that edge.
        now_tick = now_us * 1_000_000 // self.tick_ps
        read_ps = self._epoch_ps + now_tick * self.tick_ps
        if get_sim_time("ps") > read_ps:
            raise PwmTimingError(
                f"the frame's bus transfers ran past its time ({now_us} µs): the PWM capture "
                "cannot be read then; lower the sensor rates or the frame rate"
            )
        await self._wait_until_ps(read_ps)
        captures = await self.harness.host.pwm_capture(self.motors)
        widths_us = tuple(capture.width_ticks * self.tick_us for capture in captures)
        return widths_us, tuple(capture.timeout for capture in captures)


@cocotb.test()
async def serve(dut: Any) -> None:  # the DUT: its ports are known at run time
    """Answer the rig's requests until it sends STOP (or closes the channel)."""
    channel = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    channel.connect(os.environ["RIG_COSIM_SOCKET"])
    pwm_tick_hz = float(os.environ["RIG_COSIM_PWM_TICK_HZ"])
    harness = Harness(dut, pwm_tick_hz=pwm_tick_hz)
    await harness.reset()
    chips = RtlChips(harness, pwm_tick_hz=pwm_tick_hz)
    engine = SensorEngine(harness.spi, harness.i2c, chips, chips)
    while True:
        request = receive_message(channel)
        kind = request[0]
        try:
            if kind == START:
                await engine.start()
                await chips.start_pwm(*decode_start(request[1:]))
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
