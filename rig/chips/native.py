"""``sensor_layer = "rtl"``: the generated Verilog, compiled, in this process.

:class:`NativeSensorLayer` runs :class:`rig.chips.layer.SensorEngine` (PX4's drivers, the
same code as the ``tlm`` layer and the cocotb worker) over fpga_hdl's compiled
co-simulation harness (:mod:`fpga_hdl.cosim.native`: SensorTop, every chip and the PWM
capture core as Verilated RTL, with the flight controller's SPI/I2C controllers and PWM
timer around it as gateware). Each bus transaction is one call into the simulator, and
the capture clock runs as one call per frame, so no Python runs per clock edge. The
coroutines never suspend, so :func:`rig.chips.layer.run_now` drives them as for ``tlm``.

Why not cocotb here: the cocotb layer (:mod:`rig.chips.rtl`, kept for the identity tests,
and the benchmarks as ``"rtl-cocotb"``) pays the simulator's timing coroutines and two
Python wake-ups per transaction, 1.8 ms of wall time per 1 ms frame at IMU 1 kHz and a
1 µs capture tick; this layer runs the same Verilog from compiled code
(``benchmarks/bench_rig.py`` has the figures). The identity tests
(``tests/rig/test_cosim.py``) demand the same readouts from the three layers.

PWM timing, in capture ticks ``k`` of rig time (``k / pwm_tick_hz``): the capture clock's
edge ``k`` is sample ``k`` of fpga_hdl's tick-exact model, which the ``tlm`` layer
evaluates. The generator runs from edge ``-1`` with zero widths. A pulse the rig starts at
tick ``k`` leaves the registered generator at edge ``k - 1``, so its width must be
written before that edge runs. The capture is read after edge ``now_tick`` (the last
tick at or before the frame time) and before the next one, once the reader has let the
results' synchroniser catch up, so the read sees exactly what the cocotb worker's read
just before edge ``now_tick`` sees (its reader latches after that edge)
(``rig/chips/cosim_worker.py``). The two domains meet only in that synchroniser, so
where the bus transfers fall between two capture edges changes nothing read. A frame's
transfers must still fit in its span of time, as they do on the real bus. The harness
runs the capture clock by event (:mod:`fpga_hdl.cosim.native`), so a frame's ticks cost a
few dozen edges, run at once when the frame's pulses are fed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING

from fpga_hdl.chips.pwm_capture.core import CHANNELS
from fpga_hdl.cosim.harness import HARNESS_SYS_CLK_HZ
from rig.chips.layer import (
    ChipFault,
    ChipFrame,
    ChipReadout,
    SensorEngine,
    SensorLayer,
    host_port_inputs,
    run_now,
)
from rig.chips.pwm import PWM_TICK_HZ, Pulse, PwmTimingError, replay_periods
from rig.errors import CosimError

if TYPE_CHECKING:  # the harness module builds a simulator: imported when a layer starts
    from fpga_hdl.cosim.native import CallCost, NativeHarness


class NativeChips:
    """:class:`rig.chips.layer.ChipHost` over the compiled harness: host port, PWM, capture
    (the first ``motors`` of the core's channels)."""

    def __init__(self, harness: NativeHarness, *, motors: int, pwm_tick_hz: float) -> None:
        self.harness = harness
        self.motors = motors
        self.tick_us = 1e6 / pwm_tick_hz
        self.tick_ps = round(1e12 / pwm_tick_hz)
        self.period_us = 0
        self._next_edge = 0  # the capture clock's next edge, in rig ticks
        self._next_start_us = 0  # the next PWM period start not replayed yet
        self._loaded: list[int] = [0] * CHANNELS  # widths (ticks) in the preload register
        self._read_us = 0  # the previous frame's time, and the system cycles then
        self._read_cycles = 0
        self._held_faults: Mapping[str, ChipFault] | None = None  # what the chips were loaded with

    def start_pwm(self, period_us: int) -> None:
        """Start the generator with zero widths; its first edge is rig tick -1."""
        if period_us * 1_000_000 % self.tick_ps:
            raise PwmTimingError(
                f"the PWM period ({period_us} µs) is not a whole number of capture ticks "
                f"({self.tick_us:g} µs)"
            )
        self.period_us = period_us
        self.harness.pwm.write([0] * CHANNELS, period_ticks=self._ticks(period_us))
        self._next_edge = -1
        self._read_cycles = self.harness.cycles()[0]

    def _ticks(self, time_us: int) -> int:
        return round(time_us / self.tick_us)

    def _run_to(self, tick: int) -> None:
        """Run the capture clock's edges up to ``tick`` (excluded)."""
        if tick > self._next_edge:
            self.harness.pwm.cycles(tick - self._next_edge)
            self._next_edge = tick

    def _read_tick(self, now_us: int) -> int:
        """The last tick at or before ``now_us``: its edge is the last a read there sees."""
        return now_us * 1_000_000 // self.tick_ps

    async def load(self, frame: ChipFrame) -> None:
        samples, faults = host_port_inputs(frame, self._held_faults)
        self.harness.host.load(samples, now_us=frame.now_us, faults=faults)
        self._held_faults = frame.faults

    def _preload(self, start_us: int, widths: list[int]) -> None:
        """Write the widths of the period at ``start_us`` before the generator takes them."""
        if widths == self._loaded:
            return
        if self._next_edge > self._ticks(start_us) - 1:
            raise PwmTimingError(
                f"the PWM period at {start_us} µs starts too soon after the previous frame "
                "for the RTL PWM generator to take its new widths; choose rates so that no "
                "PWM period starts within a few µs after an IMU frame"
            )
        self.harness.pwm.write(widths, period_ticks=self._ticks(self.period_us))
        self._loaded = widths

    async def capture(
        self, pulses: tuple[Pulse, ...], now_us: int
    ) -> tuple[tuple[float, ...], tuple[bool, ...]]:
        """Replay this frame's PWM periods, run the capture clock to ``now_us``, read."""
        periods, self._next_start_us = replay_periods(
            pulses, now_us, self._next_start_us, self.period_us, self.tick_us
        )
        previous_us = None
        for start_us, widths in periods:
            if previous_us is not None and widths != self._loaded:
                self._run_to(self._ticks(previous_us))  # past the edge that took the last
            self._preload(start_us, widths)
            previous_us = start_us
        self._check_bus_time(now_us)
        self._run_to(self._read_tick(now_us) + 1)  # every edge up to now's, then the read
        captures = self.harness.host.pwm_capture(self.motors)
        widths_us = tuple(capture.width_ticks * self.tick_us for capture in captures)
        return widths_us, tuple(capture.timeout for capture in captures)

    def _check_bus_time(self, now_us: int) -> None:
        """The frame's transfers at the system clock must fit between two frame times."""
        cycles = self.harness.cycles()[0]
        bus_us = (cycles - self._read_cycles) / HARNESS_SYS_CLK_HZ * 1e6
        if bus_us > now_us - self._read_us:
            raise PwmTimingError(
                f"the frame's bus transfers ran past its time ({now_us} µs): the PWM capture "
                "cannot be read then; lower the sensor rates or the frame rate"
            )
        self._read_us, self._read_cycles = now_us, cycles


class NativeSensorLayer(SensorLayer):
    """The chips as compiled RTL in this process (see the module docstring).

    ``motors`` is the vehicle's rotor count: the capture channels read. ``pwm_hz`` is the
    autopilot's PWM rate (its timer period is replayed by the harness's
    PWM generator); ``pwm_tick_hz`` the capture core's tick, a build parameter of the
    gateware. Failures are :class:`~rig.errors.CosimError` lines, as the cocotb layer's.
    """

    def __init__(self, *, motors: int, pwm_hz: int, pwm_tick_hz: float = PWM_TICK_HZ) -> None:
        from fpga_hdl.cosim.native import NativeHarness  # builds or reuses the library

        self.pwm_period_us = round(1e6 / pwm_hz)
        try:
            self.harness = NativeHarness(pwm_tick_hz=pwm_tick_hz)
        except Exception as error:
            raise CosimError(f"the RTL co-simulation could not start: {error}") from error
        self.chips = NativeChips(self.harness, motors=motors, pwm_tick_hz=pwm_tick_hz)
        # The GPS UART runs on its own clock (SensorTop's ``uart`` domain), so its frames,
        # longer than a rig frame, cost none of the frame's system-clock bus time.
        self.engine = SensorEngine(
            self.harness.spi, self.harness.i2c, self.harness.uart, self.chips
        )

    def start(self) -> None:
        """Reset, PX4's probe/configure sequences, then the PWM generator and capture clock."""
        try:
            self.harness.reset()
            run_now(self.engine.start())
            self.chips.start_pwm(self.pwm_period_us)
        except Exception as error:  # one line, as the cocotb layer reports its worker's
            raise CosimError(f"the RTL co-simulation failed: {_one_line(error)}") from error

    def sense(self, frame: ChipFrame) -> None:
        try:
            run_now(self.engine.sense(frame))
        except Exception as error:
            raise CosimError(f"the RTL co-simulation failed: {_one_line(error)}") from error

    def finish(self, pulses: tuple[Pulse, ...]) -> ChipReadout:
        try:
            return run_now(self.engine.finish(pulses))
        except Exception as error:
            raise CosimError(f"the RTL co-simulation failed: {_one_line(error)}") from error

    def costs(self) -> tuple[CallCost, ...]:
        """The harness's calls so far, the I2C ones named by the chip at the address."""
        addresses = {"mag": self.engine.mag.address, "range": self.engine.range.address}
        chips = {f"I2C 0x{address:02x}": f"I2C {name}" for name, address in addresses.items()}
        return tuple(
            dataclasses.replace(cost, what=chips.get(cost.what, cost.what))
            for cost in self.harness.costs()
        )

    def close(self) -> None:
        self.harness.close()


def _one_line(error: Exception) -> str:
    return f"{type(error).__name__}: {error}"
