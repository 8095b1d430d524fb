"""Co-simulation harness: SensorTop wired to the autopilot's bus peripherals, gated clocks.

SensorTop stays exactly the FPGA's pins. Around it this Amaranth top puts what sits on
the other side of those pins on the real rig, as gateware, so a whole transaction runs
inside the simulator and Python only asks and waits once:

- the flight controller MCU's peripherals: :class:`~fpga_hdl.buses.spi_controller.SpiController`
  on the shared SPI bus (chip selects ``imu``, ``baro``, ``flow``),
  :class:`~fpga_hdl.buses.i2c_controller.I2cController` on the IST8310's bus (the wired-AND of
  SDA resolved here), :class:`~fpga_hdl.buses.pwm_generator.PwmGenerator` on the PWM pins,
  :class:`UartPeer` on the GPS receiver's UART;
- the real-time computer's side of the host port: :class:`HostWriter` writes a list of
  staged words, commits and waits until every chip has taken its sample;
  :class:`HostReader` lets the PWM results settle in ``sync``, freezes them with
  SensorTop's ``read_latch`` and reads every result word into one wide port.

Each peripheral takes a *request toggle* and answers with an *acknowledge*: Python flips
``<name>_request`` and awaits a change of ``<name>_acknowledge``, two wake-ups per
transaction however many bits it moves.

Clocks, without Python per cycle: five :data:`GATED_CLOCK_VERILOG` instances, a behavioural
Verilog clock that *waits* on its enable (no polling, so a stopped clock costs nothing). The
system clock (``sync``, :data:`HARNESS_SYS_CLK_HZ`) runs while a host-port request is
pending, a host-port peripheral is busy, an SPI transfer's settle cycles are due, a chip
still waits to take a sample, or ``rst`` is high. The SPI
controller has a clock of its own at the same rate (``spi_ctrl``, as the flight controller's
peripheral runs on the MCU's clock): an SPI transfer clocks only the controller and the
chips' SCLK domains, not every register of the design, and then the system clock runs
:data:`SPI_SETTLE_CYCLES` cycles, in which the chips' system side sees the transfer end (its
chip select through their synchronisers, the flow chip's take of its motion), before the
transfer is acknowledged. What a transfer moves is the same, clock for clock on the bus; the
system side sees its chip select only after the transfer, as it would see a transfer too
short for its synchronisers. The I2C bus's controller and chips (SensorTop's
``i2c_domain``) have a domain of their own too, ``i2c``: the system clock's edges clock it
while the host writer runs (the chips take their samples, time and faults from the host
port then) or ``rst`` is high, and so does an I2C clock of the same rate that runs alone
while a transfer is requested or under way (and the system clock stands still). Nothing
else in SensorTop sees the bus, so a transfer clocks only the bus, and a host read or an
SPI transfer's settle cycles do not clock it. The PWM tick clock (``pwm``,
``pwm_tick_hz``) runs while ``pwm_run`` is high: the capture must count every tick of
every period, so in a closed loop it runs all the time. Under cocotb every tick is an
edge; the compiled harness (``fpga_hdl.cosim.native``) lets one edge stand for
``1 + pwm_skip`` ticks while ``pwm_quiet`` says nothing moves through them but counters
(the generator's and the capture core's own account, both checked tick for tick in the
tests). The UART clock
(``uart``, SensorTop's ``UART_CLK_HZ``: the GPS receiver and the autopilot's UART) runs
while a UART exchange is requested or under way, or ``rst`` is high: a fix the host loaded
crosses into the receiver in the exchange's first cycles, before its first start bit, so
the line times are those of a free-running clock. The compiled harness runs it by event
too: one edge for ``1 + uart_skip`` cycles while ``uart_quiet`` (the u-blox core's and the
peer's) says only bit timers and counters move through them. The I2C clock likewise:
one edge for ``1 + i2c_skip`` cycles while ``i2c_quiet`` (the controller's duration
counter, while both chips say they are ``settled``) says nothing else moves.
Verilator needs ``--timing`` for these delays (``fpga_hdl.cosim.runner`` adds it when a
design brings behavioural Verilog).

The age of a result read (SensorTop's fixed latency, ``fpga_hdl.top``): the system
clock starts half a period after a read request, and the reader latches at its
``PWM_RESULT_COPY_CYCLES + 1``-th edge, so it takes every result published at a tick
edge before the clock's first edge. A read requested just before tick edge ``k`` (and
ticks longer than ``PWM_RESULT_COPY_CYCLES + 0.5`` system periods, which SensorTop's
``sys_clk_hz >= 4 × pwm_tick_hz`` ensures) sees exactly the results published at edge
``k`` and before: no later edge falls inside the read.
"""

from __future__ import annotations

from amaranth.build import Platform
from amaranth.hdl import (
    Cat,
    ClockDomain,
    ClockSignal,
    DomainRenamer,
    Instance,
    Module,
    Mux,
    ResetSignal,
    Signal,
)
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.by_event import least, skip_members
from fpga_hdl.buses.i2c_controller import I2cController
from fpga_hdl.buses.pwm_generator import PwmGenerator
from fpga_hdl.buses.spi_controller import SpiController
from fpga_hdl.buses.spi_target import CS_SYNC_STAGES
from fpga_hdl.buses.transactions import check_spi_mode
from fpga_hdl.buses.uart import DIVIDER_BITS, QUIET_MAX, UartRx, UartTx
from fpga_hdl.chips.pwm_capture.core import LATENCY_TICKS, SKIP_BITS
from fpga_hdl.host.host_port import WORD_BITS, HostPortMap
from fpga_hdl.top import PWM_RESULT_COPY_CYCLES, PWM_TICK_HZ, UART_CLK_HZ, SensorTop

__all__ = [
    "GATED_CLOCK_VERILOG",
    "HARNESS_SYS_CLK_HZ",
    "HARNESS_TOPLEVEL",
    "I2C_READ_DEPTH",
    "I2C_WRITE_DEPTH",
    "PWM_COUNTER_BITS",
    "SPI_DEPTH",
    "SPI_DEVICES",
    "UART_RX_DEPTH",
    "UART_TX_DEPTH",
    "CosimHarness",
    "HostReader",
    "HostWriter",
    "UartPeer",
]

HARNESS_TOPLEVEL = "cosim_harness"
#: The harness's system clock. Slower than SensorTop's default (16 MHz) because every
#: cycle is simulated and this is the slowest clock that serves all three chips exactly:
#: above the 8 MHz the MPU-6000 needs at 20 MHz SCLK (``spi_target``), 25 cycles per
#: 400 kHz I2C bit (the I2C target's recommended rate), and SCLK = 10 MHz / 2 = 5 MHz,
#: exactly PX4's ``SPI_SPEED_SENSOR`` (16 MHz could only give 4 MHz: twice the cycles).
HARNESS_SYS_CLK_HZ = 10e6
#: Chip-select order of the SPI controller: the MPU-6000, the MS5611, the PMW3901.
SPI_DEVICES = ("imu", "baro", "flow")
#: The peripherals' buffers in bytes (the most one transfer moves) and the PWM generator's
#: counter width. Constants, so the compiled harness's drivers know them without making
#: the design (:func:`fpga_hdl.build.verilog_by_inputs` finds its Verilog without it).
SPI_DEPTH = 32
I2C_WRITE_DEPTH, I2C_READ_DEPTH = 8, 16
UART_TX_DEPTH, UART_RX_DEPTH = 64, 256
PWM_COUNTER_BITS = 16
#: System cycles after an SPI transfer before its acknowledge: the chips' chip-select
#: synchronisers (``CS_SYNC_STAGES``) see the select high, and what reacts to them (a
#: chip's ``busy``, the PMW3901's motion take) has a cycle more to act, with a margin.
SPI_SETTLE_CYCLES = 2 * CS_SYNC_STAGES + 2
#: A simulation-only clock that waits on ``enable`` (Amaranth cannot express delays, so
#: this one module is Verilog text, written to ``build/`` beside the generated design).
#: The first rising edge comes half a period after ``enable`` rises; it stops low.
GATED_CLOCK_VERILOG = """\
// Gated simulation clock, generated by fpga_hdl.cosim.harness (behavioural, not for
// synthesis): waits on `enable` without polling, then toggles every HALF_PERIOD_PS.
module cosim_gated_clock #(parameter integer HALF_PERIOD_PS = 1) (
    input wire enable,
    output reg clk
);
    initial clk = 1'b0;
    always begin
        wait (enable);
        #HALF_PERIOD_PS clk = 1'b1;
        #HALF_PERIOD_PS clk = 1'b0;
    end
endmodule
"""


def _half_period_ps(clk_hz: float, *, exact: bool = True) -> int:
    """The gated clock's half period; ``exact=False`` rounds it to whole picoseconds, for
    a clock whose edges only count (the UART's: 3.6864 MHz is 2.4 ppm slow then)."""
    half_ps = 0.5e12 / clk_hz
    if exact and abs(half_ps - round(half_ps)) > 1e-6:
        raise ValueError(f"{clk_hz:g} Hz has no whole-picosecond half period")
    return round(half_ps)


class HostWriter(wiring.Component):
    """Writes up to ``len(map.writes)`` staged words, commits, waits for the chips.

    Attributes
    ----------
    request : In(1), acknowledge : Out(1), busy : Out(1)
        Request toggle and its acknowledge (see the module docstring).
    words : In(ArrayLayout(StructLayout(address, data), n))
        The words to write, in order.
    count : In(range(n + 1))
        How many of ``words`` to write before the commit.
    pending : In(1)
        SensorTop's ``pending``: the acknowledge waits until it is low.
    write_addr, write_data, write_en, commit : Out
        To SensorTop's host port.
    """

    def __init__(self, host_map: HostPortMap) -> None:
        self.max_words = len(host_map.writes)
        word = data.StructLayout({"address": 8, "data": WORD_BITS})
        super().__init__(
            {
                "request": In(1),
                "acknowledge": Out(1),
                "busy": Out(1),
                "words": In(data.ArrayLayout(word, self.max_words)),
                "count": In(range(self.max_words + 1)),
                "pending": In(1),
                "write_addr": Out(8),
                "write_data": Out(WORD_BITS),
                "write_en": Out(1),
                "commit": Out(1),
            }
        )

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        index = Signal(range(self.max_words + 1))
        settle = Signal(range(3))
        # The words are taken at the request and shifted down one word per write, so the
        # next word is always the lowest: selecting word `index` of the wide input instead
        # would shift the whole input in every simulated cycle of every clock (Verilator
        # evaluates logic fed by a top-level input at each step).
        staged = Signal.like(self.words.as_value())
        layout = self.words.shape().elem_shape
        word = data.View(layout, staged[: layout.size])
        with m.FSM() as fsm:
            with m.State("IDLE"), m.If(self.request != self.acknowledge):
                m.d.sync += [index.eq(0), staged.eq(self.words)]
                m.next = "WRITE"
            with m.State("WRITE"):
                with m.If(index < self.count):
                    m.d.comb += [
                        self.write_addr.eq(word.address),
                        self.write_data.eq(word.data),
                        self.write_en.eq(1),
                    ]
                    m.d.sync += [index.eq(index + 1), staged.eq(staged >> len(word.as_value()))]
                with m.Else():
                    m.d.comb += self.commit.eq(1)
                    m.d.sync += settle.eq(2)
                    m.next = "SETTLE"
            with m.State("SETTLE"):
                # Two cycles for the commit's strobe to reach the chips' latches, then
                # until no chip waits to take its sample (HostPort, CoherentLatch).
                with m.If(settle != 0):
                    m.d.sync += settle.eq(settle - 1)
                with m.Elif(~self.pending):
                    m.d.sync += self.acknowledge.eq(self.request)
                    m.next = "IDLE"
        m.d.comb += self.busy.eq(~fsm.ongoing("IDLE"))
        return m


class HostReader(wiring.Component):
    """Freezes SensorTop's result words in one cycle, then reads them into one wide register.

    Timeline from the request, in system cycles: the first edge leaves IDLE and, with the
    next ``PWM_RESULT_COPY_CYCLES - 1``, lets the PWM results' synchroniser catch up
    after a gated pause; the following cycle asserts ``read_latch``; then one word per
    cycle from the frozen register file, and the acknowledge a cycle after the last.

    Attributes
    ----------
    request : In(1), acknowledge : Out(1), busy : Out(1)
        Request toggle and its acknowledge.
    words : Out(ArrayLayout(32, n))
        Result word ``i`` of the host-port map at index ``i``.
    read_latch : Out(1), read_addr : Out(8), read_data : In(32)
        To SensorTop's host port.
    """

    def __init__(self, host_map: HostPortMap) -> None:
        self.count = len(host_map.reads)
        super().__init__(
            {
                "request": In(1),
                "acknowledge": Out(1),
                "busy": Out(1),
                "words": Out(data.ArrayLayout(WORD_BITS, self.count)),
                "read_latch": Out(1),
                "read_addr": Out(8),
                "read_data": In(WORD_BITS),
            }
        )

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        settle = Signal(range(PWM_RESULT_COPY_CYCLES))
        address = Signal(range(self.count))
        with m.FSM() as fsm:
            with m.State("IDLE"), m.If(self.request != self.acknowledge):
                m.d.sync += [settle.eq(PWM_RESULT_COPY_CYCLES - 2), address.eq(0)]
                m.next = "SETTLE"
            with m.State("SETTLE"):  # the synchroniser's flip-flops and copy catch up
                m.d.sync += settle.eq(settle - 1)
                with m.If(settle == 0):
                    m.next = "LATCH"
            with m.State("LATCH"):  # every result word frozen in this one cycle
                m.d.comb += self.read_latch.eq(1)
                m.next = "READ"
            with m.State("READ"):  # one word per cycle (``read_data`` is combinational)
                m.d.comb += self.read_addr.eq(address)
                # Each word enters at the top and the earlier ones move down, so word `i`
                # ends at index `i`: writing `words[address]` in place would decode every
                # index in every cycle.
                shifted = Cat(self.words.as_value()[WORD_BITS:], self.read_data)
                m.d.sync += [self.words.eq(shifted), address.eq(address + 1)]
                with m.If(address == self.count - 1):
                    m.next = "DONE"
            with m.State("DONE"):
                # A cycle after the last word: a testbench woken by the acknowledge may
                # read ``words`` before the rest of that edge's updates (Icarus does).
                m.d.sync += self.acknowledge.eq(self.request)
                m.next = "IDLE"
        m.d.comb += self.busy.eq(~fsm.ongoing("IDLE"))
        return m


class UartPeer(wiring.Component):
    """The autopilot's UART on the GPS port: sends a burst, then listens until the line rests.

    It runs in the receiver's ``uart`` domain, as the autopilot's UART would on the same
    baud clock. A request sends ``tx[:tx_len]`` back to back at ``divider``, then keeps
    the clock running until the receiver's line has been idle for :data:`QUIET_BITS` bit
    times with nothing left to send; the acknowledge then publishes what was received
    since the previous acknowledge (the last ``rx_len`` bytes of ``rx``, in order; bytes
    past ``rx_depth`` counted in ``rx_len`` but dropped) and ``line_cycles``: clock
    cycles from the first start bit's falling edge to the strobe of the last byte
    (``fpga_hdl.buses.uart.line_cycles`` predicts it for the TLM twin). The receiver
    always listens, also between requests.

    Attributes
    ----------
    request : In(1), acknowledge : Out(1), busy : Out(1)
        Request toggle and its acknowledge.
    divider : In(DIVIDER_BITS)
        Cycles per bit, both directions (the autopilot's UART rate).
    tx : In(ArrayLayout(8, tx_depth)), tx_len : In(range(tx_depth + 1))
        The bytes to send.
    rx : Out(ArrayLayout(8, rx_depth)), rx_len : Out(16), line_cycles : Out(32)
        What the last request received.
    line_tx : Out(1), line_rx : In(1)
        The autopilot's TXD (to the receiver's RXD) and RXD (from its TXD).
    skip : In(DIVIDER_BITS), quiet : Out(DIVIDER_BITS)
        As :class:`~fpga_hdl.chips.ublox.core.UbloxM8Core`'s: the coming edges that move
        nothing but counters, none in the first :data:`SETTLE_CYCLES` of a request.
    """

    #: Idle bit times that end a request: the receiver answers within a few cycles of a
    #: frame's last byte and sends its frames back to back, so two byte times of silence
    #: mean it has nothing more to say.
    QUIET_BITS = 20
    #: Cycles at the start of a request clocked one by one: a fix or fault word the host
    #: loaded crosses into the receiver's domain then (synchronisers, the epoch decision
    #: and the fix's copy: under 40 cycles), through registers ``quiet`` does not watch.
    SETTLE_CYCLES = 64

    def __init__(self, *, tx_depth: int = 64, rx_depth: int = 256) -> None:
        self.tx_depth = tx_depth
        self.rx_depth = rx_depth
        super().__init__(
            {
                "request": In(1),
                "acknowledge": Out(1),
                "busy": Out(1),
                "divider": In(DIVIDER_BITS),
                "tx": In(data.ArrayLayout(8, tx_depth)),
                "tx_len": In(range(tx_depth + 1)),
                "rx": Out(data.ArrayLayout(8, rx_depth)),
                "rx_len": Out(16),
                "line_cycles": Out(32),
                "line_tx": Out(1, init=1),
                "line_rx": In(1, init=1),
                **skip_members(DIVIDER_BITS),
            }
        )

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        m.submodules.uart_tx = uart_tx = UartTx(skippable=True)
        m.submodules.uart_rx = uart_rx = UartRx(skippable=True)
        cycles = 1 + self.skip  # what this edge stands for
        m.d.comb += [
            uart_tx.divider.eq(self.divider),
            uart_rx.divider.eq(self.divider),
            uart_rx.rx.eq(self.line_rx),
            self.line_tx.eq(uart_tx.tx),
        ]
        # The receiving side, always on: bytes and the line's timing since the last publish.
        # A byte enters at the top of `received` and the older ones move down one place: a
        # fixed shift, where writing byte `count` in place would decode all rx_depth
        # places in every cycle (three quarters of a UART cycle's cost under Verilator).
        received = Signal(8 * self.rx_depth)
        count = Signal(16)
        cycle = Signal(32)  # cycles since the first start bit's edge
        started, previous = Signal(), Signal(init=1)
        last_cycles = Signal(32)
        m.d.sync += previous.eq(self.line_rx)
        with m.If(started):
            m.d.sync += cycle.eq(cycle + cycles)
        with m.Elif(previous & ~self.line_rx):
            m.d.sync += [started.eq(1), cycle.eq(1)]
        with m.If(uart_rx.stb):
            with m.If(count < self.rx_depth):
                m.d.sync += received.eq(Cat(received[8:], uart_rx.data))
            m.d.sync += [count.eq(count + 1), last_cycles.eq(cycle)]
        # Silence on the line, in cycles, up to the quiet limit.
        quiet = Signal(32)
        limit = Signal(32)
        m.d.comb += limit.eq(self.divider * self.QUIET_BITS)
        counting = self.line_rx & ~uart_rx.busy
        with m.If(~counting):
            m.d.sync += quiet.eq(0)
        with m.Elif(quiet < limit):
            m.d.sync += quiet.eq(quiet + cycles)

        index = Signal(range(self.tx_depth + 1))
        settle = Signal(range(self.SETTLE_CYCLES + 1))
        with m.If(settle != 0):
            m.d.sync += settle.eq(settle - 1)
        acting = Signal()  # this edge does more than count
        m.d.comb += uart_tx.data.eq(self.tx[index[: len(range(self.tx_depth))]])
        with m.FSM() as fsm:
            with m.State("IDLE"), m.If(self.request != self.acknowledge):
                m.d.comb += acting.eq(1)
                m.d.sync += [index.eq(0), settle.eq(self.SETTLE_CYCLES)]
                m.next = "SEND"
            with m.State("SEND"):
                with m.If(index < self.tx_len):
                    m.d.comb += uart_tx.valid.eq(1)
                    with m.If(uart_tx.ready):
                        m.d.sync += index.eq(index + 1)
                with m.Elif(~uart_tx.busy):
                    m.d.comb += acting.eq(1)
                    m.d.sync += quiet.eq(0)
                    m.next = "LISTEN"
            with m.State("LISTEN"), m.If(quiet == limit):
                m.d.comb += acting.eq(1)
                m.d.sync += [
                    self.rx.eq(received),
                    self.rx_len.eq(count),
                    self.line_cycles.eq(last_cycles),
                    count.eq(0),
                    started.eq(0),
                    last_cycles.eq(0),
                ]
                m.next = "DONE"
            with m.State("DONE"):  # a cycle after the results, as HostReader's
                m.d.comb += acting.eq(1)
                m.d.sync += self.acknowledge.eq(self.request)
                m.next = "IDLE"
        m.d.comb += self.busy.eq(~fsm.ongoing("IDLE"))

        # Quiet: the bit timers' own, and the line-quiet count's edges up to its limit.
        counted = Signal(DIVIDER_BITS)
        left = limit - quiet
        m.d.comb += counted.eq(
            Mux(counting & (quiet < limit) & (left < QUIET_MAX), left, QUIET_MAX)
        )
        still = ~acting & (settle == 0) & (previous == self.line_rx)
        m.d.comb += [
            uart_tx.skip.eq(self.skip),
            uart_rx.skip.eq(self.skip),
            self.quiet.eq(Mux(still, least(uart_tx.quiet, uart_rx.quiet, counted), 0)),
        ]
        return m


#: Harness ports forwarded to each peripheral, by the peripheral's own port names.
_SPI_PORTS = ("request", "acknowledge", "device", "length", "divider", "mode3", "tx", "rx")
_I2C_PORTS = (
    *("request", "acknowledge", "address", "write_len", "read_len", "tx", "rx", "fast"),
    *("nack", "nack_index"),
)
_HOST_PORTS = ("request", "acknowledge", "words", "count")
_READ_PORTS = ("request", "acknowledge", "words")
_PWM_PORTS = ("period_ticks", "width_ticks")
_UART_PORTS = ("request", "acknowledge", "divider", "tx", "tx_len", "rx", "rx_len", "line_cycles")


class CosimHarness(wiring.Component):
    """SensorTop with the autopilot's SPI/I2C/PWM peripherals, host-port DMA and clocks.

    Ports: ``rst`` and ``pwm_run`` (see the module docstring); per peripheral the ports
    of that peripheral prefixed with ``spi_``, ``i2c_``, ``host_``, ``read_`` and
    ``pwm_``, ``uart_`` (``spi_request``, ``i2c_nack_index``, ``host_words`` ...); the bus
    wires as monitor outputs (``spi_sclk``, ``spi_mosi``, ``spi_miso``, ``<device>_cs_n``
    per :data:`SPI_DEVICES`, ``i2c_scl``, ``i2c_sda``, ``pwm``, ``gps_tx``, ``gps_rx``, ``clk``,
    ``pwm_clk``, ``uart_clk``); and the cycle counters ``sync_cycles``, ``spi_cycles`` (the
    SPI controller's clock), ``i2c_cycles`` (the I2C clock's, alone), ``pwm_cycles`` and
    ``uart_cycles``, the simulation's cost.

    ``spi_mode`` (0 or 3): the build serves SPI transfers of that mode only, and SensorTop
    holds a deselected chip's SCLK at the mode's idle level (its ``spi_idle_sclk``), so a
    transfer clocks only the chip it selects; the compiled harness is built so. None (the
    cocotb builds): transfers of either mode, SCLK to every chip as on the FPGA.
    """

    def __init__(
        self,
        *,
        sys_clk_hz: float = HARNESS_SYS_CLK_HZ,
        pwm_tick_hz: float = PWM_TICK_HZ,
        uart_clk_hz: float = UART_CLK_HZ,
        spi_mode: int | None = None,
    ) -> None:
        self.sys_clk_hz = sys_clk_hz
        self.pwm_tick_hz = pwm_tick_hz
        self.uart_clk_hz = uart_clk_hz
        if spi_mode is not None:
            check_spi_mode(spi_mode)
        self.top = SensorTop(
            sys_clk_hz=sys_clk_hz, pwm_tick_hz=pwm_tick_hz, uart_clk_hz=uart_clk_hz,
            pwm_skippable=True, uart_skippable=True, i2c_skippable=True, i2c_domain="i2c",
            spi_idle_sclk=None if spi_mode is None else int(spi_mode == 3),
        )  # fmt: skip
        self.spi = SpiController(sys_clk_hz=sys_clk_hz, devices=len(SPI_DEVICES),
                                 depth=SPI_DEPTH)  # fmt: skip
        self.i2c = I2cController(sys_clk_hz=sys_clk_hz, write_depth=I2C_WRITE_DEPTH,
                                 read_depth=I2C_READ_DEPTH, skippable=True)  # fmt: skip
        # Its outputs settle through the capture's synchroniser and result registers.
        self.pwm_generator = PwmGenerator(counter_bits=PWM_COUNTER_BITS,
                                          settle_edges=LATENCY_TICKS + 1)  # fmt: skip
        self.uart = UartPeer(tx_depth=UART_TX_DEPTH, rx_depth=UART_RX_DEPTH)
        self.host_writer = HostWriter(self.top.host.map)
        self.host_reader = HostReader(self.top.host.map)
        members = {"rst": In(1), "pwm_run": In(1)}
        for prefix, part, names in self._forwarded():
            members |= {f"{prefix}_{n}": part.signature.members[n] for n in names}
        members |= {
            name: Out(1)
            for name in ("clk", "pwm_clk", "uart_clk", "spi_sclk", "spi_mosi", "spi_miso")
        }
        members |= {name: Out(1) for name in ("spi_miso_oe", "spi_contention")}
        members |= {f"{device}_cs_n": Out(1) for device in SPI_DEVICES}
        members |= {"i2c_scl": Out(1), "i2c_sda": Out(1), "pwm": Out(8)}
        members |= {"gps_tx": Out(1), "gps_rx": Out(1)}
        clocked_by_event = (("pwm", SKIP_BITS), ("uart", DIVIDER_BITS),
                            ("i2c", self.i2c.quiet_bits))  # fmt: skip
        for clock, bits in clocked_by_event:
            members |= {f"{clock}_{name}": member for name, member in skip_members(bits).items()}
        members |= {name: Out(32) for name in ("sync_cycles", "spi_cycles", "i2c_cycles",
                                               "pwm_cycles", "uart_cycles")}  # fmt: skip
        super().__init__(members)

    def _forwarded(self) -> tuple[tuple[str, wiring.Component, tuple[str, ...]], ...]:
        return (
            ("spi", self.spi, _SPI_PORTS),
            ("i2c", self.i2c, _I2C_PORTS),
            ("host", self.host_writer, _HOST_PORTS),
            ("read", self.host_reader, _READ_PORTS),
            ("pwm", self.pwm_generator, _PWM_PORTS),
            ("uart", self.uart, _UART_PORTS),
        )

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        top, spi, i2c = self.top, self.spi, self.i2c
        writer, reader = self.host_writer, self.host_reader
        m.submodules.top = top
        m.submodules.spi = DomainRenamer("spi_ctrl")(spi)
        m.submodules.i2c = DomainRenamer("i2c")(i2c)
        m.submodules.pwm_generator = DomainRenamer("pwm_out")(self.pwm_generator)
        m.submodules.host_writer = writer
        m.submodules.host_reader = reader
        m.submodules.uart = uart = DomainRenamer("uart_peer")(self.uart)
        for prefix, part, names in self._forwarded():
            for name in names:
                if (prefix, name) == ("spi", "acknowledge"):
                    continue  # after the settle cycles, below
                outer, inner = getattr(self, f"{prefix}_{name}"), getattr(part, name)
                if part.signature.members[name].flow == In:
                    m.d.comb += inner.eq(outer)
                else:
                    m.d.comb += outer.eq(inner)

        # Clocks. SensorTop's ``pwm`` and ``uart`` domains are local to it; the generator's
        # domain (``pwm_out``) runs on the capture clock, as if the autopilot's timer ticked
        # with it, and the UART peer's (``uart_peer``) on the receiver's UART clock.
        m.domains.sync = ClockDomain()
        m.domains.spi_ctrl = ClockDomain()
        m.domains.pwm_out = ClockDomain()
        # The SPI controller's acknowledge, passed on once the system clock has run the
        # settle cycles after it (see the module docstring).
        spi_settled = Signal()
        settle = Signal(range(SPI_SETTLE_CYCLES))
        with m.If(spi_settled != spi.acknowledge):
            with m.If(settle == SPI_SETTLE_CYCLES - 1):
                m.d.sync += [spi_settled.eq(spi.acknowledge), settle.eq(0)]
            with m.Else():
                m.d.sync += settle.eq(settle + 1)
        m.d.comb += self.spi_acknowledge.eq(spi_settled)
        sync_run = Signal()
        m.d.comb += sync_run.eq(
            self.rst
            | top.pending
            | (spi_settled != spi.acknowledge)
            | writer.busy
            | (writer.request != writer.acknowledge)
            | reader.busy
            | (reader.request != reader.acknowledge)
        )
        pwm_clk, spi_clk = Signal(), Signal()
        m.submodules.sync_clock = Instance(
            "cosim_gated_clock",
            p_HALF_PERIOD_PS=_half_period_ps(self.sys_clk_hz),
            i_enable=sync_run,
            o_clk=self.clk,
        )
        m.submodules.spi_clock = Instance(
            "cosim_gated_clock",
            p_HALF_PERIOD_PS=_half_period_ps(self.sys_clk_hz),
            i_enable=self.rst | spi.busy | (spi.request != spi.acknowledge),
            o_clk=spi_clk,
        )
        m.submodules.pwm_clock = Instance(
            "cosim_gated_clock",
            p_HALF_PERIOD_PS=_half_period_ps(self.pwm_tick_hz),
            i_enable=self.pwm_run | self.rst,
            o_clk=pwm_clk,
        )
        # The I2C bus: its controller and its chips run on the system clock's edges while
        # the host writer runs (or ``rst``), when they take samples, time and faults, and on
        # the I2C clock's alone while a transfer needs them (never both: the I2C clock
        # waits while the system clock runs). Nothing else in the system domain talks to
        # them, so a host read or an SPI transfer's settle cycles need not clock them.
        i2c_clk, sync_to_i2c = Signal(), Signal()
        m.d.comb += sync_to_i2c.eq(self.rst | writer.busy | (writer.request != writer.acknowledge))
        m.domains.i2c = ClockDomain()
        m.domains.i2c_alone = ClockDomain(reset_less=True)  # counts the I2C clock's cycles
        m.submodules.i2c_clock = Instance(
            "cosim_gated_clock",
            p_HALF_PERIOD_PS=_half_period_ps(self.sys_clk_hz),
            i_enable=(i2c.busy | (i2c.request != i2c.acknowledge)) & ~sync_run,
            o_clk=i2c_clk,
        )
        m.domains.uart_peer = ClockDomain()
        m.submodules.uart_clock = Instance(
            "cosim_gated_clock",
            p_HALF_PERIOD_PS=_half_period_ps(self.uart_clk_hz, exact=False),
            i_enable=self.rst | uart.busy | (uart.request != uart.acknowledge),
            o_clk=self.uart_clk,
        )
        m.d.comb += [
            ClockSignal("sync").eq(self.clk),
            ResetSignal("sync").eq(self.rst),
            ClockSignal("spi_ctrl").eq(spi_clk),
            ResetSignal("spi_ctrl").eq(self.rst),
            ClockSignal("i2c").eq((self.clk & sync_to_i2c) | i2c_clk),
            ResetSignal("i2c").eq(self.rst),
            ClockSignal("i2c_alone").eq(i2c_clk),
            ClockSignal("pwm_out").eq(pwm_clk),
            ResetSignal("pwm_out").eq(self.rst),
            top.pwm_clk.eq(pwm_clk),
            top.pwm_rst.eq(self.rst),
            self.pwm_clk.eq(pwm_clk),
            ClockSignal("uart_peer").eq(self.uart_clk),
            ResetSignal("uart_peer").eq(self.rst),
            top.uart_clk.eq(self.uart_clk),
            top.uart_rst.eq(self.rst),
        ]
        m.d.sync += self.sync_cycles.eq(self.sync_cycles + 1)
        m.d.spi_ctrl += self.spi_cycles.eq(self.spi_cycles + 1)
        m.d.i2c_alone += self.i2c_cycles.eq(self.i2c_cycles + 1 + self.i2c_skip)
        m.d.pwm_out += self.pwm_cycles.eq(self.pwm_cycles + 1 + self.pwm_skip)
        m.d.uart_peer += self.uart_cycles.eq(self.uart_cycles + 1 + self.uart_skip)

        # Host port.
        m.d.comb += [
            top.write_addr.eq(writer.write_addr),
            top.write_data.eq(writer.write_data),
            top.write_en.eq(writer.write_en),
            top.commit.eq(writer.commit),
            writer.pending.eq(top.pending),
            top.read_latch.eq(reader.read_latch),
            top.read_addr.eq(reader.read_addr),
            reader.read_data.eq(top.read_data),
        ]
        # SPI: one controller, the chips' shared SCLK/MOSI/MISO, a chip select each. An
        # undriven MISO reads 1 (the bus pull-up).
        m.d.comb += [
            top.spi_sclk.eq(spi.sclk),
            top.spi_mosi.eq(spi.mosi),
            spi.miso.eq(top.spi_miso | ~top.spi_miso_oe),
        ]
        for index, device in enumerate(SPI_DEVICES):
            m.d.comb += getattr(top, f"{device}_cs_n").eq(spi.cs_n[index])
            m.d.comb += getattr(self, f"{device}_cs_n").eq(getattr(top, f"{device}_cs_n"))
        # I2C: open drain, SDA is the wired-AND of the controller and the target.
        sda = Signal()
        m.d.comb += [
            sda.eq(i2c.sda_o & ~top.i2c_sda_oe),
            top.i2c_scl.eq(i2c.scl),
            top.i2c_sda_i.eq(sda),
            i2c.sda_i.eq(sda),
        ]
        # The I2C clock by event: the controller's duration counter is all that moves while
        # both chips are settled. (The system clock's edges that clock the bus while the
        # host writer runs are single cycles: ``i2c_skip`` is 0 then.)
        settled = top.mag.settled & top.range.settled
        m.d.comb += [i2c.skip.eq(self.i2c_skip), self.i2c_quiet.eq(Mux(settled, i2c.quiet, 0))]
        m.d.comb += top.pwm.eq(self.pwm_generator.pwm.pulses)
        # Advancing the capture clock by event: one edge for 1 + ``pwm_skip`` ticks, as
        # many as both the generator and the capture core say are quiet.
        m.d.comb += [
            self.pwm_generator.skip.eq(self.pwm_skip),
            top.capture.skip.eq(self.pwm_skip),
            self.pwm_quiet.eq(least(self.pwm_generator.quiet, top.capture.quiet)),
        ]
        m.d.comb += [top.gps_rx.eq(uart.line_tx), uart.line_rx.eq(top.gps_tx)]
        # The UART clock by event likewise: both ends of the line quiet.
        m.d.comb += [
            top.gps.skip.eq(self.uart_skip),
            uart.skip.eq(self.uart_skip),
            self.uart_quiet.eq(least(top.gps.quiet, uart.quiet)),
        ]
        # Monitor outputs: the pins as a logic analyser on the rig would see them.
        m.d.comb += [
            self.spi_sclk.eq(spi.sclk),
            self.spi_mosi.eq(spi.mosi),
            self.spi_miso.eq(top.spi_miso),
            self.spi_miso_oe.eq(top.spi_miso_oe),
            self.spi_contention.eq(top.spi_contention),
            self.i2c_scl.eq(i2c.scl),
            self.i2c_sda.eq(sda),
            self.pwm.eq(self.pwm_generator.pwm.pulses),
            self.gps_tx.eq(top.gps_tx),
            self.gps_rx.eq(uart.line_tx),
        ]
        return m
