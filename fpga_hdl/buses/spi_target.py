"""Generic SPI target (slave) engine for SPI modes 0 and 3, clocked by SCLK itself.

Both emulated SPI chips (InvenSense MPU-6000, TE MS5611) latch SDI on the rising SCLK
edge and change SDO on the falling edge, MSB first, in mode 0 (SCLK idles low) and in
mode 3 (SCLK idles high): MPU-6000 product specification PS-MPU-6000A-00 rev 3.4, §9.5
"SPI operational features"; MS5611-01BA03 datasheet, "SPI mode".

Clocking: the shift engine runs on SCLK edges, as the real chips do, not on an
oversampling system clock. Why:

- Timing. The MPU-6000 reads sensor registers at up to 20 MHz, a 25 ns half period,
  and must present SDO within t_VD.SDO = 100 ns of the falling edge (PS-MPU-6000A-00
  §6.8). An oversampling engine needs a two-flop synchroniser plus an output register,
  three system-clock periods of delay, which must fit in half an SCLK period: a system
  clock above 120 MHz. Clocked by SCLK, SDO changes on the falling edge itself.
- Simulation cost. Only SCLK edges exist while a transfer runs; no system clock has to
  tick for the bus, so a 15-byte burst costs 240 edges however fast the system clock is.

The engine has three clock domains, all local to the chip that instantiates it:

- ``spi``: SCLK rising edge, reset with the chip. The chip's registers live here. The
  engine's strobes (``rx_stb`` ...) are combinational, valid at the rising edge that
  completes a byte, so the chip registers that byte on that same edge.
- ``spi_rx`` (internal): SCLK rising edge, asynchronously reset while CS is high. Bit
  and byte counters: a transfer aborted mid-byte is forgotten the moment CS rises.
- ``spi_tx`` (internal): SCLK falling edge, asynchronously reset while CS is high. The
  SDO shift register, loaded from ``tx_data`` on the falling edge that starts a data
  byte (after the byte-0 command/address byte). In mode 3 the leading falling edge
  after CS falls comes before any rising edge and shifts nothing.

During the first (command) byte SDO sends zeros: no chip defines SDO there. A chip
whose transfers hold several commands (the PMW3901's address/data pairs) asks for zeros
before another command byte with ``tx_skip``.
"""

from amaranth.build import Platform
from amaranth.hdl import Assert, Cat, ClockDomain, Module, Mux, ResetSignal, Signal
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.signatures import BUS_FAULT, SPI

__all__ = [
    "CS_SYNC_STAGES",
    "SpiTarget",
    "SpiTargetChecker",
    "add_spi_engine",
    "check_sys_clk_for_spi",
]

#: Flip-flops between CS and the ``sync`` domain's ``busy`` (see :func:`check_sys_clk_for_spi`).
CS_SYNC_STAGES = 2


def check_sys_clk_for_spi(sys_clk_hz: float, sclk_max_hz: float) -> None:
    """Reject a system clock too slow to see CS before the first data byte is loaded.

    A chip copies a new sample into its visible registers only while ``busy`` is low.
    ``busy`` follows CS through :data:`CS_SYNC_STAGES` flip-flops, so it can lag CS by
    ``CS_SYNC_STAGES + 1`` system-clock periods. The first register byte is loaded into
    SDO 7.5 SCLK periods after the first edge, so that lag must be shorter, or a copy
    could land while a read has already begun.
    """
    if not sys_clk_hz > 0:
        raise ValueError(f"sys_clk_hz must be positive, not {sys_clk_hz!r}")
    lag_s = (CS_SYNC_STAGES + 1) / sys_clk_hz
    first_load_s = 7.5 / sclk_max_hz
    if lag_s >= first_load_s:
        min_hz = (CS_SYNC_STAGES + 1) * sclk_max_hz / 7.5
        raise ValueError(
            f"sys_clk_hz {sys_clk_hz:.6g} is too slow for SCLK up to {sclk_max_hz:.6g} Hz: "
            f"CS reaches the sync domain after {lag_s * 1e9:.1f} ns but the first data byte "
            f"is loaded after {first_load_s * 1e9:.1f} ns; use more than {min_hz:.6g} Hz"
        )


class SpiTarget(wiring.Component):
    """SPI target shift engine, modes 0 and 3, MSB first.

    Instantiate it inside a chip core that defines a local ``spi`` clock domain driven
    by SCLK (rising edge, chip reset); the engine adds its own CS-reset domains.

    Parameters
    ----------
    assertions : bool
        Bind a :class:`SpiTargetChecker`: the protocol properties below as ``Assert``
        statements, which ``amaranth.sim`` raises on and a formal tool can prove. Off by
        default: an ``Assert`` becomes a ``$check`` cell, and the product's Verilog must
        not change.

        - SDO is driven only while CS is low (sampled by the ``sync`` clock);
        - at each rising SCLK edge of a data byte, SDO shows bit ``7 - n`` of the byte
          loaded at that byte's start, ``n`` the bits already received.

    Attributes
    ----------
    spi : In(SPI)
        The bus pins (:data:`~fpga_hdl.buses.signatures.SPI`). CS high resets the bit and
        byte counters at once; ``miso_oe`` is high while selected and not muted.
    fault : In(BUS_FAULT)
        ``mute`` never drives SDO (the chip looks absent); ``flip`` is XORed into every
        data byte sent.
    rx_data : Out(8)
        The byte completing at this rising SCLK edge (combinational).
    rx_stb : Out(1)
        High when this rising edge completes a byte (combinational, ``spi`` domain).
    rx_first : Out(1)
        High while the byte being received is the transfer's first (command) byte.
    tx_data : In(8)
        The next byte to send; sampled on the falling edge after each completed byte.
    tx_skip : In(1)
        Sampled with ``tx_data``: the next byte is another command (or a byte the chip
        only receives), so SDO sends zeros, unflipped, as during the first byte.
    busy : Out(1)
        CS asserted, synchronised into the ``sync`` domain (lags CS by 2..3 cycles).
    """

    spi: In(SPI)
    fault: In(BUS_FAULT)
    rx_data: Out(8)
    rx_stb: Out(1)
    rx_first: Out(1)
    tx_data: In(8)
    tx_skip: In(1)
    busy: Out(1)

    def __init__(self, *, assertions: bool = False) -> None:
        self.assertions = assertions
        super().__init__()

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        pins = self.spi
        for name, edge in (("spi_rx", "pos"), ("spi_tx", "neg")):
            domain = ClockDomain(name, clk_edge=edge, async_reset=True, local=True)
            m.domains += domain
            m.d.comb += [domain.clk.eq(pins.sclk), domain.rst.eq(pins.cs_n)]

        bit_count = Signal(3)
        shift_in = Signal(7)
        first_byte = Signal(init=1)
        m.d.spi_rx += [shift_in.eq(Cat(pins.mosi, shift_in[:6])), bit_count.eq(bit_count + 1)]
        with m.If(bit_count == 7):
            m.d.spi_rx += first_byte.eq(0)
        m.d.comb += [
            self.rx_data.eq(Cat(pins.mosi, shift_in)),
            self.rx_stb.eq((bit_count == 7) & ~pins.cs_n),
            self.rx_first.eq(first_byte),
        ]

        shift_out = Signal(8)
        loaded = Signal(8)  # what a data byte starts with
        m.d.comb += loaded.eq(Mux(self.tx_skip, 0, self.tx_data ^ self.fault.flip))
        with m.If(bit_count != 0):
            m.d.spi_tx += shift_out.eq(shift_out << 1)
        with m.Elif(~first_byte):  # a byte boundary has passed: start the next data byte
            m.d.spi_tx += shift_out.eq(loaded)
        m.d.comb += [
            pins.miso.eq(shift_out[7]),
            pins.miso_oe.eq(~pins.cs_n & ~self.fault.mute),
        ]

        m.submodules.cs_sync = FFSynchronizer(
            ~pins.cs_n, self.busy, o_domain="sync", stages=CS_SYNC_STAGES
        )

        if self.assertions:
            m.submodules.checker = checker = SpiTargetChecker()
            m.d.comb += [
                checker.cs_n.eq(pins.cs_n),
                checker.miso.eq(pins.miso),
                checker.miso_oe.eq(pins.miso_oe),
                checker.bit_count.eq(bit_count),
                checker.first_byte.eq(first_byte),
                checker.loaded.eq(loaded),
            ]
        return m


class SpiTargetChecker(wiring.Component):
    """:class:`SpiTarget`'s protocol properties as ``Assert`` statements, on its signals.

    Why a component of its own: the engine binds it only with ``assertions`` on, and a
    test can drive it alone with a sequence no engine produces, to show each property
    fires. It runs in the engine's ``sync``, ``spi_rx`` and ``spi_tx`` domains.

    Attributes
    ----------
    cs_n, miso, miso_oe : In(1)
        The engine's pins.
    bit_count : In(3)
        Bits of the current byte received so far.
    first_byte : In(1)
        The current byte is the command byte.
    loaded : In(8)
        The byte the engine loads into SDO at a data byte's start.
    """

    cs_n: In(1)
    miso: In(1)
    miso_oe: In(1)
    bit_count: In(3)
    first_byte: In(1)
    loaded: In(8)

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        m.d.sync += Assert(~self.miso_oe | ~self.cs_n, "SPI target drives SDO while CS is high")
        sent = Signal(8)  # the reference: the byte loaded at this data byte's start
        with m.If((self.bit_count == 0) & ~self.first_byte):
            m.d.spi_tx += sent.eq(self.loaded)
        with m.If(~self.first_byte):
            m.d.spi_rx += Assert(
                self.miso == sent.bit_select(~self.bit_count, 1),  # bit 7 - n
                "SPI target's SDO is not the loaded byte's next bit, MSB first",
            )
        return m


def add_spi_engine(m: Module, chip: wiring.Component) -> SpiTarget:
    """Give a chip core its SPI engine: the local ``spi`` domain (SCLK rising edge, chip
    reset) and a :class:`SpiTarget` on the chip's ``spi`` pins and ``fault`` inputs."""
    spi = ClockDomain("spi", async_reset=True, local=True)
    m.domains += spi
    m.d.comb += [spi.clk.eq(chip.spi.sclk), spi.rst.eq(ResetSignal("sync"))]
    m.submodules.engine = engine = SpiTarget()
    wiring.connect(m, wiring.flipped(chip.spi), engine.spi)
    wiring.connect(m, wiring.flipped(chip.fault), engine.fault)
    return engine
