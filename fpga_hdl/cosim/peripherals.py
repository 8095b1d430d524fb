"""The fast path: ``SpiBus``, ``I2cBus``, ``UartPort``, host port and PWM over the harness.

Each class drives one peripheral of :class:`fpga_hdl.cosim.harness.CosimHarness` under
cocotb: it sets the peripheral's inputs, flips its request toggle and awaits the
acknowledge, so a transaction costs two Python wake-ups whatever its length, and the
gated system clock runs only while something is in flight. The same PX4-like drivers
run over these buses unchanged; the pin-level masters (``fpga_hdl.verification``) stay
for the interface-timing tests that probe the specification limits.

:class:`Harness` bundles them for a testbench or the rig's co-simulation process::

    harness = Harness(dut)
    await harness.reset()
    await harness.host.load({"imu": sample.fields()}, now_us=1000)
    rx = await harness.spi.transfer("imu", bytes([0x3B | 0x80]) + bytes(14), sclk_hz=20e6)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any  # a cocotb DUT: its ports, the generated Verilog's, are known at run time

from cocotb.triggers import Timer
from cocotb.utils import get_sim_time

from fpga_hdl.buses.i2c_controller import RATES_HZ, controller_rate_hz
from fpga_hdl.buses.spi_controller import divider_for
from fpga_hdl.buses.transactions import (
    I2cNack,
    UartTransfer,
    check_clock_hz,
    check_i2c_request,
    check_spi_mode,
    check_spi_request,
)
from fpga_hdl.buses.uart import cycles_to_us
from fpga_hdl.buses.uart import divider_for as uart_divider
from fpga_hdl.chips.pwm_capture.core import CHANNELS
from fpga_hdl.chips.pwm_capture.model import ChannelCapture, channel_captures
from fpga_hdl.cosim.harness import HARNESS_SYS_CLK_HZ, SPI_DEVICES
from fpga_hdl.host.host_port import WORD_BITS, FaultInputs, HostPortMap
from fpga_hdl.top import HOST_MAP, PWM_TICK_HZ, UART_CLK_HZ, sensor_top_host_map

__all__ = [
    "Harness",
    "HarnessHost",
    "HarnessI2cBus",
    "HarnessPwm",
    "HarnessSpiBus",
    "HarnessUart",
]

#: Where the PWM clock's edges sit relative to the system clock's 31.25 ns grid: a
#: quarter system period off it, so no PWM edge ever shares a time step with a system
#: clock edge or a testbench write (whose order would then be up to the simulator).
PWM_PHASE_PS = round(0.25e12 / HARNESS_SYS_CLK_HZ)


class _Requester:
    """One peripheral's request toggle and acknowledge, and the inputs a request carries."""

    def __init__(self, dut: Any, prefix: str, inputs: Sequence[str] = ()) -> None:
        self._request = getattr(dut, f"{prefix}_request")
        self._acknowledge = getattr(dut, f"{prefix}_acknowledge")
        self._inputs = [getattr(dut, f"{prefix}_{name}") for name in inputs]
        self._level = 0
        self.count = 0  # transactions so far

    def reset(self) -> None:
        """Request low and every request input 0: a simulator leaves an undriven input
        unknown, and no net of the design should hold X after a reset."""
        self._request.value = self._level = 0
        for handle in self._inputs:
            handle.value = 0

    async def __call__(self) -> None:
        self._level ^= 1
        self._request.value = self._level
        await self._acknowledge.value_change
        self.count += 1


def _pack(values: Sequence[int], bits: int) -> int:
    """Values into one wide port, element ``i`` at bit ``i * bits``."""
    return sum((value & ((1 << bits) - 1)) << (i * bits) for i, value in enumerate(values))


class HarnessSpiBus:
    """A :class:`~fpga_hdl.buses.transactions.SpiBus` over the harness's SPI controller
    (mode 0 or 3)."""

    def __init__(self, dut: Any, *, mode: int = 0, sys_clk_hz: float = HARNESS_SYS_CLK_HZ) -> None:
        check_spi_mode(mode)
        self.dut = dut
        self.sys_clk_hz = sys_clk_hz
        self.depth = len(dut.spi_tx) // 8
        self._request = _Requester(dut, "spi", ("device", "length", "divider", "tx"))
        dut.spi_mode3.value = int(mode == 3)

    @property
    def transfers(self) -> int:
        return self._request.count

    def reset(self) -> None:
        self._request.reset()

    async def transfer(self, device: str, tx: bytes, *, sclk_hz: float) -> bytes:
        check_clock_hz("sclk_hz", sclk_hz)
        check_spi_request(device, tx, SPI_DEVICES, depth=self.depth)
        dut = self.dut
        dut.spi_device.value = SPI_DEVICES.index(device)
        dut.spi_length.value = len(tx)
        dut.spi_divider.value = divider_for(self.sys_clk_hz, sclk_hz)
        dut.spi_tx.value = int.from_bytes(tx, "little")
        await self._request()
        return int(dut.spi_rx.value).to_bytes(self.depth, "little")[: len(tx)]


class HarnessI2cBus:
    """:class:`fpga_hdl.buses.transactions.I2cBus` over the harness's I2C controller (100/400 kHz).

    A requested rate is rounded down to the controller's rates (:data:`RATES_HZ`).
    """

    def __init__(self, dut: Any) -> None:
        self.dut = dut
        self.write_depth = len(dut.i2c_tx) // 8
        self.read_depth = len(dut.i2c_rx) // 8
        self._request = _Requester(dut, "i2c", ("address", "write_len", "read_len", "tx", "fast"))

    @property
    def transfers(self) -> int:
        return self._request.count

    def reset(self) -> None:
        self._request.reset()

    async def write_read(
        self, address: int, write: bytes, read_len: int, *, scl_hz: float
    ) -> bytes:
        rate_hz = controller_rate_hz(scl_hz)
        check_i2c_request(
            address, write, read_len, write_depth=self.write_depth, read_depth=self.read_depth
        )
        dut = self.dut
        dut.i2c_address.value = address
        dut.i2c_write_len.value = len(write)
        dut.i2c_read_len.value = read_len
        dut.i2c_tx.value = int.from_bytes(write, "little")
        dut.i2c_fast.value = int(rate_hz == RATES_HZ[1])
        await self._request()
        if int(dut.i2c_nack.value):
            raise I2cNack(address, int(dut.i2c_nack_index.value))
        return int(dut.i2c_rx.value).to_bytes(self.read_depth, "little")[:read_len]


class HarnessUart:
    """:class:`~fpga_hdl.buses.transactions.UartPort` over the harness's GPS UART peer."""

    def __init__(self, dut: Any, *, clk_hz: float = UART_CLK_HZ) -> None:
        self.dut = dut
        self.clk_hz = clk_hz
        self.tx_depth = len(dut.uart_tx) // 8
        self.rx_depth = len(dut.uart_rx) // 8
        self._request = _Requester(dut, "uart", ("divider", "tx", "tx_len"))

    def reset(self) -> None:
        self._request.reset()

    async def exchange(self, tx: bytes, *, baud: int) -> UartTransfer:
        if len(tx) > self.tx_depth:
            raise ValueError(f"UART burst of {len(tx)} bytes exceeds {self.tx_depth}")
        dut = self.dut
        dut.uart_divider.value = uart_divider(self.clk_hz, baud)
        dut.uart_tx.value = int.from_bytes(tx, "little")
        dut.uart_tx_len.value = len(tx)
        await self._request()
        count = int(dut.uart_rx_len.value)
        if count > self.rx_depth:
            raise ValueError(
                f"the GPS UART received {count} bytes in one exchange; the peer keeps "
                f"{self.rx_depth}"
            )
        # The peer keeps the newest bytes at the top of `rx` (UartPeer).
        data = int(dut.uart_rx.value).to_bytes(self.rx_depth, "little")[self.rx_depth - count :]
        return UartTransfer(data, cycles_to_us(int(dut.uart_line_cycles.value), self.clk_hz))


class HarnessHost:
    """The rig's side of SensorTop's host port: one burst write per load, one burst read."""

    def __init__(self, dut: Any, host_map: HostPortMap = HOST_MAP) -> None:
        self.dut = dut
        self.map = host_map
        self._write = _Requester(dut, "host", ("words", "count"))
        self._read = _Requester(dut, "read")

    def reset(self) -> None:
        self._write.reset()
        self._read.reset()

    async def load(
        self,
        samples: Mapping[str, Mapping[str, int]],
        *,
        now_us: int | None = None,
        faults: Mapping[str, FaultInputs] | None = None,
    ) -> None:
        """Stage the fields (and time, faults), commit, and return once the chips took them."""
        words = self.map.encode_frame(samples, now_us=now_us, faults=faults)
        self.dut.host_words.value = _pack(
            [address | data << 8 for address, data in words], 8 + WORD_BITS
        )
        self.dut.host_count.value = len(words)
        await self._write()

    async def results(self) -> dict[tuple[str, str], int]:
        """Every result word, keyed by (channel, field), sign-extended where signed."""
        await self._read()
        packed = int(self.dut.read_words.value)
        values = {}
        for word in self.map.reads:
            raw = packed >> (word.address * WORD_BITS) & ((1 << word.width) - 1)
            if word.signed and raw >> (word.width - 1):
                raw -= 1 << word.width
            values[(word.channel, word.field)] = raw
        return values

    async def pwm_capture(self, channels: int = CHANNELS) -> list[ChannelCapture]:
        """The PWM capture's results for the first ``channels``, as the host port shows them."""
        return channel_captures(await self.results(), channels)


class HarnessPwm:
    """The autopilot's PWM outputs: period and widths in ticks, written once per frame."""

    def __init__(self, dut: Any, *, tick_hz: float = PWM_TICK_HZ) -> None:
        self.dut = dut
        self.tick_hz = tick_hz
        self.counter_bits = len(dut.pwm_period_ticks)

    def write(self, widths_ticks: Sequence[int], *, period_ticks: int) -> None:
        """New widths (0 = no pulse) from the next period start; period 0 stops all."""
        if len(widths_ticks) > CHANNELS:
            raise ValueError(f"at most {CHANNELS} PWM channels, got {len(widths_ticks)}")
        limit = (1 << self.counter_bits) - 1
        for value in (*widths_ticks, period_ticks):
            if not 0 <= value <= limit:
                raise ValueError(f"PWM ticks must be in 0..{limit}, not {value}")
        self.dut.pwm_width_ticks.value = _pack(widths_ticks, self.counter_bits)
        self.dut.pwm_period_ticks.value = period_ticks

    async def run(self) -> None:
        """Start the PWM tick clock off the system clock's grid (:data:`PWM_PHASE_PS`),
        then return on the grid, as the caller was."""
        grid_ps = round(0.5e12 / HARNESS_SYS_CLK_HZ)
        offset_ps = (PWM_PHASE_PS - get_sim_time("ps")) % grid_ps
        await Timer(offset_ps, unit="ps")
        self.dut.pwm_run.value = 1
        await Timer(grid_ps - offset_ps, unit="ps")


class Harness:
    """Host port, SPI, I2C and PWM of a :class:`~fpga_hdl.cosim.harness.CosimHarness`.

    ``pwm_tick_hz`` must be the one the harness was built with: it sets the result words'
    widths (:func:`fpga_hdl.top.sensor_top_host_map`) and how long the reset holds.
    """

    def __init__(self, dut: Any, *, spi_mode: int = 0, pwm_tick_hz: float = PWM_TICK_HZ) -> None:
        self.dut = dut
        self.pwm_tick_hz = pwm_tick_hz
        self.host = HarnessHost(dut, sensor_top_host_map(pwm_tick_hz))
        self.spi = HarnessSpiBus(dut, mode=spi_mode)
        self.i2c = HarnessI2cBus(dut)
        self.pwm = HarnessPwm(dut, tick_hz=pwm_tick_hz)
        self.uart = HarnessUart(dut)

    async def reset(self) -> None:
        """Reset every clock domain (every clock runs for it), then leave them stopped."""
        dut = self.dut
        for part in (self.host, self.spi, self.i2c, self.uart):
            part.reset()
        dut.pwm_run.value = 0
        dut.pwm_skip.value = 0  # every tick an edge: the simulator's clock is exact
        dut.uart_skip.value = 0  # and every UART cycle
        dut.i2c_skip.value = 0  # and every I2C cycle
        self.pwm.write([0] * CHANNELS, period_ticks=0)
        tick_ps = round(1e12 / self.pwm_tick_hz)
        dut.rst.value = 1
        await Timer(3 * tick_ps, unit="ps")  # three ticks: every domain reset
        dut.rst.value = 0
        await Timer(tick_ps, unit="ps")  # let the clocks stop

    def cycles(self) -> tuple[int, int, int]:
        """(system, PWM, UART) clock cycles so far: what the simulation has cost. The SPI
        controller's and the I2C bus's clocks run at the system clock's rate and count with
        it (bus time)."""
        dut = self.dut
        system = sum(int(getattr(dut, f"{clock}_cycles").value) for clock in ("sync", "spi", "i2c"))
        return system, int(dut.pwm_cycles.value), int(dut.uart_cycles.value)

    async def wait_until_s(self, time_s: float) -> None:
        """Let simulated time reach ``time_s`` (only the clocks that are enabled run)."""
        delta_ps = round(time_s * 1e12) - get_sim_time("ps")
        if delta_ps > 0:
            await Timer(delta_ps, unit="ps")
