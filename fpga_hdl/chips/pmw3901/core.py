"""PixArt PMW3901MB optical-flow chip on SPI, as an Amaranth component (register map and
sources in ``regs``; the TLM twin is ``model.Pmw3901Model``).

The bus (SPI mode 3, up to 2 MHz, MSB first, on :class:`~fpga_hdl.buses.spi_target.SpiTarget`):
a transfer is a run of address/data pairs under one chip select. An address byte with
bit 7 set writes the next byte to that register; with bit 7 clear the chip answers the
register in the next byte. SDO sends 0x00 during address bytes and a write's data byte.
Motion_Burst (0x16) is the exception: after its address every byte is the next of the 12
burst bytes (``regs.BURST_ORDER``), then 0x00, until the chip select rises.

Motion, the rules emulated:

- Every loaded sample is one camera frame. A frame the chip takes adds its delta X/Y to
  the motion accumulators, saturating at int16, and sets MOT when it moved; its SQUAL,
  shutter and raw-data statistics become the image registers.
- Reading Motion (its address byte, bank 0) moves the accumulated motion into the Delta
  registers (frozen for the reads that follow) and MOT into the Motion byte, and starts
  the accumulators from zero: motion since the last report. A Delta register reads 0
  once it has been read (each byte on its own, so Delta_X_L then Delta_X_H both answer),
  until the next Motion read freezes new values; a second Motion read before the Delta
  reads loses the first values, as the datasheet warns. Motion_Burst freezes the same
  way at its address and its Delta bytes clear as they are sent.
- The chip takes frames only once it tracks: after a power-up reset (0x5A to 0x3A, which
  also restores every register, bank 0, empty accumulators) the performance-optimisation
  sequence must end with its last write (bank 0, 0x40 = 0x80); until then frames are
  not taken and SQUAL, the shutter, the raw data and Observation read 0. Shutdown (0xB6
  to 0x3B) stops tracking until the next power-up reset.
- The banked registers the optimisation sequence writes are stored and read back
  (``regs.STORED_REGISTERS``); bank 0x0E registers 0x67 and 0x73 read fixed trim values;
  every other banked register reads 0 and ignores writes, and so do the read-only ones.

Faults: ``fault.mute`` (the chip never drives SDO) and ``fault.flip`` (XOR on every byte
read) as every chip has them, and the chip's own (``own_fault``):

- ``stuck``: the image freezes. Frames are not taken: no motion accumulates and SQUAL,
  shutter and raw data keep the values of the last frame taken, so the chip reports
  "no motion" with its old quality; motion accumulated before the fault is still
  reported.
- ``zero_quality``: SQUAL reads 0 (motion is tracked and reported as usual).
- ``drop_frames``: the frames are lost before the chip: none is taken and the motion not
  yet reported is discarded, so MOT reads clear and the Delta registers 0 while it lasts.

Clocks: the registers the bus reads and writes live in the ``spi`` domain (SCLK); the
host's frames arrive in ``sync``. The accumulators live in ``sync`` and change only while
no transfer runs (like the sample latch), so a transfer reads them stable. A Motion read
cannot clear them from ``spi``: it raises a *take* request (a toggle, raised only when
none is outstanding); while one is outstanding the bus sees empty accumulators, and
``sync`` empties them at its first cycle without a transfer, before it adds any new frame.
"""

from amaranth.build import Platform
from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal, Value, signed
from amaranth.lib import data, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.signatures import BUS_FAULT, SPI
from fpga_hdl.buses.spi_target import CS_SYNC_STAGES, add_spi_engine, check_sys_clk_for_spi
from fpga_hdl.chips.pmw3901 import regs
from fpga_hdl.chips.pmw3901.regs import Reg
from fpga_hdl.host.host_port import chip_sample_latch

__all__ = ["OWN_FAULT_LAYOUT", "Pmw3901"]

#: The chip's own fault inputs, one bit each (``regs.OWN_FAULTS``).
OWN_FAULT_LAYOUT = data.StructLayout({name: 1 for name in regs.OWN_FAULTS})


def _saturated_int16(value: Value) -> Value:
    return Mux(value > 32767, 32767, Mux(value < -32768, -32768, value))[:16]


def _register_key(bank: int, register: int) -> int:
    """A register's case value of ``Cat(address, bank)``."""
    return register | bank << 7


class Pmw3901(wiring.Component):
    """PMW3901MB registers, motion accumulators and faults behind an SPI target.

    Parameters
    ----------
    sys_clk_hz : float
        Frequency of the ``sync`` domain; checked against the 2 MHz SCLK so a frame never
        lands inside a read (see ``spi_target``).

    Attributes
    ----------
    spi : In(SPI)
        SCLK, NCS, MOSI, MISO and MISO's driver enable (high-Z while deselected or muted).
    sample : In(regs.SAMPLE_LAYOUT)
        One camera frame; stable from ``sample_stb`` until taken.
    sample_stb : In(1)
        One ``sync`` cycle: a frame is offered. The chip takes it (if it tracks and no
        fault stops it) at the first cycle with no transfer running.
    fault : In(BUS_FAULT)
        ``mute``: SDO never driven; ``flip``: XOR mask on every byte read.
    own_fault : In(OWN_FAULT_LAYOUT)
        ``stuck``, ``zero_quality``, ``drop_frames`` (module docstring).
    sample_pending : Out(1)
        A frame waits for the running transfer's end (keep the clock running).
    """

    spi: In(SPI)
    sample: In(regs.SAMPLE_LAYOUT)
    sample_stb: In(1)
    fault: In(BUS_FAULT)
    own_fault: In(OWN_FAULT_LAYOUT)
    sample_pending: Out(1)

    def __init__(self, *, sys_clk_hz: float) -> None:
        check_sys_clk_for_spi(sys_clk_hz, regs.SPI_TIMING.sclk_max_hz)
        self.sys_clk_hz = sys_clk_hz
        super().__init__()

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        engine = add_spi_engine(m, self)
        own = self.own_fault

        tracking = Signal()  # spi: power-up reset and the sequence's last write seen
        reset_seen = Signal()
        tracking_sync = Signal()
        m.submodules.tracking_sync = FFSynchronizer(tracking, tracking_sync, o_domain="sync")
        taken = self.sample_stb & tracking_sync & ~own.stuck & ~own.drop_frames
        latch = chip_sample_latch(m, self, regs.SAMPLE_LAYOUT, busy=engine.busy, offered_stb=taken)

        # Accumulators (sync) and the take handshake (module docstring).
        acc_x, acc_y = Signal(signed(16)), Signal(signed(16))
        moved = Signal()
        take_request, take_request_sync, take_acknowledge = Signal(), Signal(), Signal()
        m.submodules.take_sync = FFSynchronizer(
            take_request, take_request_sync, o_domain="sync", stages=CS_SYNC_STAGES
        )
        with m.If(~engine.busy):
            cleared = (take_request_sync != take_acknowledge) | own.drop_frames
            m.d.sync += take_acknowledge.eq(take_request_sync)
            offered = latch.offered
            with m.If(latch.copying & ~own.drop_frames):
                m.d.sync += [
                    acc_x.eq(_saturated_int16(Mux(cleared, 0, acc_x) + offered.delta_x)),
                    acc_y.eq(_saturated_int16(Mux(cleared, 0, acc_y) + offered.delta_y)),
                    moved.eq((moved & ~cleared) | (offered.delta_x != 0) | (offered.delta_y != 0)),
                ]
            with m.Elif(cleared):
                m.d.sync += [acc_x.eq(0), acc_y.eq(0), moved.eq(0)]
        outstanding = take_request != take_acknowledge  # the bus sees empty accumulators

        # The bus side (spi).
        address, writing = Signal(7), Signal()
        data_next = Signal()  # the next byte is an address/data pair's data byte
        in_burst = Signal()
        burst_index = Signal(range(regs.BURST_LENGTH + 1))
        bank = Signal(8)
        frozen = Array(Signal(8, name=f"frozen_{r.name.lower()}") for r in regs.DELTA_REGISTERS)
        frozen_mot = Signal()
        stored = {
            key: Signal(8, init=init, name=f"bank{key[0]:02x}_{key[1]:02x}")
            for key, init in regs.STORED_REGISTERS.items()
        }

        def take() -> None:
            """Freeze the accumulated motion into the Delta registers and clear it."""
            eff_x = Mux(outstanding, 0, acc_x)
            eff_y = Mux(outstanding, 0, acc_y)
            m.d.spi += [
                frozen[0].eq(eff_x[:8]), frozen[1].eq(eff_x[8:]),
                frozen[2].eq(eff_y[:8]), frozen[3].eq(eff_y[8:]),
                frozen_mot.eq(moved & ~outstanding),
            ]  # fmt: skip
            with m.If(~outstanding):
                m.d.spi += take_request.eq(~take_request)

        rx = engine.rx_data
        is_address = engine.rx_first | (~data_next & ~in_burst)
        with m.If(engine.rx_stb):
            with m.If(is_address):
                m.d.spi += [address.eq(rx[:7]), writing.eq(rx[7]), data_next.eq(1),
                            in_burst.eq(0)]  # fmt: skip
                bank0_read = ~rx[7] & (bank == 0)
                with m.If(bank0_read & ((rx[:7] == Reg.MOTION) | (rx[:7] == Reg.MOTION_BURST))):
                    take()
                with m.If(bank0_read & (rx[:7] == Reg.MOTION_BURST)):
                    m.d.spi += [in_burst.eq(1), burst_index.eq(0)]
            with m.Elif(in_burst):
                with m.If(burst_index != regs.BURST_LENGTH):
                    m.d.spi += burst_index.eq(burst_index + 1)
                for position, register in enumerate(regs.BURST_ORDER):
                    if register in regs.DELTA_REGISTERS:
                        with m.If(burst_index == position):
                            m.d.spi += frozen[register - Reg.DELTA_X_L].eq(0)
            with m.Else():
                m.d.spi += data_next.eq(0)
                with m.If(writing):
                    self._write(m, address, bank, rx, stored, tracking, reset_seen)
                    # The power-up reset's motion part (``_write`` does its registers).
                    with m.If((bank == 0) & (address == Reg.POWER_UP_RESET)
                              & (rx == regs.POWER_UP_RESET_VALUE)):  # fmt: skip
                        take()  # empties the accumulators
                        m.d.spi += [f.eq(0) for f in frozen]
                        m.d.spi += frozen_mot.eq(0)
                with m.Elif((bank == 0) & (address >= Reg.DELTA_X_L) & (address <= Reg.DELTA_Y_H)):
                    m.d.spi += frozen[(address - Reg.DELTA_X_L)[:2]].eq(0)

        # The byte SDO sends next.
        visible = latch.visible
        motion = {
            Reg.MOTION: Cat(Const(0, 7), frozen_mot),
            **{r: frozen[r - Reg.DELTA_X_L] for r in regs.DELTA_REGISTERS},
        }
        image = {  # the last frame taken; 0 until the chip tracks
            Reg.SQUAL: Mux(own.zero_quality, 0, visible.squal),
            Reg.RAW_DATA_SUM: visible.raw_sum,
            Reg.MAXIMUM_RAW_DATA: visible.raw_max,
            Reg.MINIMUM_RAW_DATA: visible.raw_min,
            Reg.SHUTTER_LOWER: visible.shutter[:8],
            Reg.SHUTTER_UPPER: visible.shutter[8:],
            Reg.OBSERVATION: Const(regs.OBSERVATION_TRACKING, 8),
        }
        bank0 = {
            Reg.PRODUCT_ID: Const(regs.PRODUCT_ID_VALUE, 8),
            Reg.REVISION_ID: Const(regs.REVISION_ID_VALUE, 8),
            Reg.INVERSE_PRODUCT_ID: Const(regs.INVERSE_PRODUCT_ID_VALUE, 8),
            **motion,
            **{register: Mux(tracking, value, 0) for register, value in image.items()},
        }
        register_value = Signal(8)
        with m.If(address == Reg.BANK_SELECT):
            m.d.comb += register_value.eq(bank)
        with m.Else(), m.Switch(Cat(address, bank)):
            for register, value in bank0.items():
                with m.Case(_register_key(0, register)):
                    m.d.comb += register_value.eq(value)
            for trim, fixed in regs.TRIM_READ_ONLY.items():
                with m.Case(_register_key(regs.TRIM_BANK, trim)):
                    m.d.comb += register_value.eq(fixed)
            for key, signal in stored.items():
                with m.Case(_register_key(*key)):
                    m.d.comb += register_value.eq(signal)
        burst_value = Signal(8)
        with m.Switch(burst_index):
            for position, register in enumerate(regs.BURST_ORDER):
                with m.Case(position):
                    m.d.comb += burst_value.eq(bank0[register])
        m.d.comb += [
            engine.tx_data.eq(Mux(in_burst, burst_value, register_value)),
            engine.tx_skip.eq(~in_burst & (~data_next | writing)),
        ]
        return m

    @staticmethod
    def _write(
        m: Module,
        address: Signal,
        bank: Signal,
        value: Value,
        stored: dict[tuple[int, int], Signal],
        tracking: Signal,
        reset_seen: Signal,
    ) -> None:
        """A data byte written to ``address`` in ``bank`` (bank select in every bank)."""
        bank0 = bank == 0
        with m.If(address == Reg.BANK_SELECT):
            m.d.spi += bank.eq(value)
        with (
            m.Elif(bank0 & (address == Reg.POWER_UP_RESET)),
            m.If(value == regs.POWER_UP_RESET_VALUE),
        ):
            m.d.spi += [bank.eq(0), reset_seen.eq(1), tracking.eq(0)]
            m.d.spi += [signal.eq(regs.STORED_REGISTERS[key]) for key, signal in stored.items()]
        with m.Elif(bank0 & (address == Reg.SHUTDOWN)), m.If(value == regs.SHUTDOWN_VALUE):
            m.d.spi += [reset_seen.eq(0), tracking.eq(0)]
        with m.Else(), m.Switch(Cat(address, bank)):
            for key, signal in stored.items():
                with m.Case(_register_key(*key)):
                    m.d.spi += signal.eq(value)
                    if key == regs.TRACKING_WRITE[:2]:
                        with m.If((value == regs.TRACKING_WRITE[2]) & reset_seen):
                            m.d.spi += tracking.eq(1)
