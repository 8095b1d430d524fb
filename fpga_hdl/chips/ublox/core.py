"""u-blox NEO-M8N GNSS receiver on UART1, as PX4's GPS driver sees it (UBX protocol 18)."""

from __future__ import annotations

from amaranth.build import Platform
from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.by_event import least, skip_members
from fpga_hdl.buses.signatures import BUS_FAULT
from fpga_hdl.buses.uart import DIVIDER_BITS, UartRx, UartTx, divider_for
from fpga_hdl.chips.ublox import ubx
from fpga_hdl.chips.ublox.ubx import Source
from fpga_hdl.host.host_port import chip_sample_latch

__all__ = [
    "BAUD_RATES",
    "EPOCH_DECISION_CYCLES",
    "MIN_MEAS_RATE_MS",
    "RESET_BAUD",
    "RESET_MEAS_RATE_MS",
    "UbloxM8Core",
]

#: Baud rates the core switches to on a CFG-PRT for UART1: PX4's auto-detection list
#: (38400, 57600, 9600, 115200, 230400, 460800, 921600) and 19200, except 921600: on
#: SensorTop's 3.6864 MHz UART clock its divider would be 4, below ``MIN_DIVIDER`` (and a
#: 16 MHz clock's 17 is 2.1 % fast), and PX4 asks for it only in moving-base heading setups.
BAUD_RATES = (9600, 19200, 38400, 57600, 115200, 230400, 460800)
#: UART1's power-on rate on a u-blox M8.
RESET_BAUD = 9600
#: CFG-RATE measRate at power-on: one navigation epoch a second (u-blox M8 default).
RESET_MEAS_RATE_MS = 1000
#: The shortest measRate CFG-RATE takes; a shorter one (or 0) is NAKed and the rate kept.
#: u-blox's CFG-RATE description: "Measurement rate should be greater than or equal to
#: 25 ms". A rate between this and the receiver's maximum navigation rate is ACKed; the
#: epochs then come at most as fast as the rig loads them (the vehicle's ``fix_rate_hz``).
MIN_MEAS_RATE_MS = 25
#: Cycles from a fix's strobe until the core knows whether it is a navigation epoch: one
#: bit of the 32-bit iTOW a cycle (:meth:`UbloxM8Core._navigation_epoch`).
EPOCH_DECISION_CYCLES = 32

#: The frames the sequencer can send, by number.
FRAMES: dict[str, tuple[Source, ...]] = {
    "ack": ubx.ACK_SOURCES,
    "nak": ubx.NAK_SOURCES,
    "mon_ver": ubx.MON_VER_SOURCES,
    "nav_pvt": ubx.NAV_PVT_SOURCES,
}


class UbloxM8Core(wiring.Component):
    """A NEO-M8N's UBX side: NAV-PVT per loaded fix, ACKs for configuration, MON-VER.

    Behaviour emulated:

    - **Output.** Each fix the host loads (``sample_stb``) is a measurement of the rig's
      GNSS model (at the receiver's maximum rate); the ones whose iTOW is a whole multiple
      of CFG-RATE's measRate are navigation epochs, aligned to GPS time as on a u-blox
      (power on: 1000 ms; navRate is taken as 1, as PX4 sends it, and timeRef's UTC and
      GPS seconds differ by whole leap seconds, which a measRate dividing 1000 ms ignores).
      Each epoch sends one NAV-PVT (92-byte M8 payload) once CFG-MSG has enabled it on
      this port (off at power on unless ``nav_pvt_at_reset``; a nonzero rate sends every
      epoch). Whether an iTOW is an epoch takes :data:`EPOCH_DECISION_CYCLES` to find,
      so fixes come at most one per that many cycles. A fix loaded while a frame is on
      the line is used after it (latest wins).
    - **Input.** UBX frames are parsed as PX4's own decoder does (sync, class, id, length,
      payload, CK_A, CK_B). A bad checksum or a framing error drops the frame silently, as
      a receiver does. Valid CFG-class frames are answered with ACK-ACK (class, id);
      CFG-VALSET (protocol 27+, unknown to protocol 18), CFG polls (length <= 1), a
      CFG-PRT for UART1 at a rate outside :data:`BAUD_RATES` and a CFG-RATE below
      :data:`MIN_MEAS_RATE_MS` get ACK-NAK. An empty
      MON-VER poll is answered with MON-VER.
    - **Baud.** UART1 starts at ``baud``. A CFG-PRT for UART1 switches both directions to
      its baudRate once its ACK has left at the old rate.
    - **Order.** At each frame boundary: a pending ACK/NAK, then a rate switch, then
      MON-VER, then NAV-PVT. One ACK is held; a newer one replaces it (PX4 waits for
      each ACK before it sends the next CFG).

    Parameters
    ----------
    sys_clk_hz : float
        Frequency of the core's ``sync`` (SensorTop's ``uart`` domain); every rate in
        :data:`BAUD_RATES` must fit its divider.
    baud : int
        Power-on rate of UART1 (u-blox default 9600).
    nav_pvt_at_reset : bool
        NAV-PVT output enabled at reset (as if stored in the receiver's flash).

    Attributes
    ----------
    tx : Out(1)
        UART1 TXD, receiver to autopilot (idle high).
    rx : In(1)
        UART1 RXD, autopilot to receiver.
    sample : In(ubx.SAMPLE_LAYOUT), sample_stb : In(1)
        A fix and its strobe (the host port's staging register and commit).
    sample_pending : Out(1)
        A loaded fix waits for the frame on the line to end.
    baud : Out(20)
        UART1's current rate.
    meas_rate_ms : Out(16)
        CFG-RATE's measRate in force.
    fault : In(BUS_FAULT)
        ``mute`` holds TXD idle (bytes are lost); ``flip`` is XORed into every byte after
        a frame's 6-byte header (payload and checksum), so the driver finds the frame and
        drops it for its checksum, as after noise on a real line.
    skip : In(DIVIDER_BITS), quiet : Out(DIVIDER_BITS)
        ``skippable`` only (the compiled co-simulation, never synthesis): the coming edges
        that move nothing but the UART's bit timers, and the cycles the next edge stands
        for (:data:`fpga_hdl.buses.uart.QUIET_MAX`). Its inputs must hold still meanwhile.
    """

    def __init__(
        self,
        *,
        sys_clk_hz: float,
        baud: int = RESET_BAUD,
        nav_pvt_at_reset: bool = False,
        skippable: bool = False,
    ) -> None:
        self.dividers = {rate: divider_for(sys_clk_hz, rate) for rate in BAUD_RATES}
        if baud not in self.dividers:
            raise ValueError(f"baud must be one of {BAUD_RATES}, not {baud!r}")
        self.sys_clk_hz = sys_clk_hz
        self.reset_baud = baud
        self.nav_pvt_at_reset = nav_pvt_at_reset
        self.skippable = skippable
        members = {
            "tx": Out(1, init=1),
            "rx": In(1, init=1),
            "sample": In(ubx.SAMPLE_LAYOUT),
            "sample_stb": In(1),
            "sample_pending": Out(1),
            "baud": Out(20, init=baud),
            "meas_rate_ms": Out(16, init=RESET_MEAS_RATE_MS),
            "fault": In(BUS_FAULT),
        }
        if skippable:
            members |= skip_members(DIVIDER_BITS)
        super().__init__(members)

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        m.submodules.uart_tx = uart_tx = UartTx(skippable=self.skippable)
        m.submodules.uart_rx = uart_rx = UartRx(skippable=self.skippable)
        divider = Signal(DIVIDER_BITS, init=self.dividers[self.reset_baud])
        m.d.comb += [
            uart_tx.divider.eq(divider),
            uart_rx.divider.eq(divider),
            uart_rx.rx.eq(self.rx),
            self.tx.eq(uart_tx.tx | self.fault.mute),
        ]

        sending = Signal()
        latch = chip_sample_latch(m, self, ubx.SAMPLE_LAYOUT, busy=sending)

        # --- input: PX4's UBX decoder, in gateware ---------------------------------------
        state = Signal(range(9))
        SYNC1, SYNC2, CLASS, ID, LEN1, LEN2, PAYLOAD, CKA, CKB = range(9)
        rx_class, rx_id, rx_len, rx_count = Signal(8), Signal(8), Signal(16), Signal(16)
        rx_ck_a, rx_ck_b = Signal(8), Signal(8)
        p0, p1, p2, p_baud = Signal(8), Signal(8), Signal(8), Signal(32)
        byte = uart_rx.data

        ack_pending, ack_is_ack = Signal(), Signal()
        ack_class, ack_id = Signal(8), Signal(8)
        mon_ver_pending = Signal()
        pvt_enabled = Signal(init=int(self.nav_pvt_at_reset))
        pvt_pending = Signal()
        switch_pending, new_divider, new_baud = Signal(), Signal(DIVIDER_BITS), Signal(20)

        def add(b: Value) -> list:
            return [rx_ck_a.eq(rx_ck_a + b), rx_ck_b.eq(rx_ck_b + rx_ck_a + b)]

        with m.If(uart_rx.frame_error):
            m.d.sync += state.eq(SYNC1)
        with m.Elif(uart_rx.stb), m.Switch(state):
            with m.Case(SYNC1), m.If(byte == ubx.SYNC1):
                m.d.sync += state.eq(SYNC2)
            with m.Case(SYNC2):
                m.d.sync += [rx_ck_a.eq(0), rx_ck_b.eq(0)]
                m.d.sync += state.eq(Mux(byte == ubx.SYNC2, CLASS, SYNC1))
            with m.Case(CLASS):
                m.d.sync += [rx_class.eq(byte), state.eq(ID), *add(byte)]
            with m.Case(ID):
                m.d.sync += [rx_id.eq(byte), state.eq(LEN1), *add(byte)]
            with m.Case(LEN1):
                m.d.sync += [rx_len[:8].eq(byte), state.eq(LEN2), *add(byte)]
            with m.Case(LEN2):
                empty = (rx_len[:8] == 0) & (byte == 0)
                m.d.sync += [rx_len[8:].eq(byte), rx_count.eq(0), *add(byte)]
                m.d.sync += state.eq(Mux(empty, CKA, PAYLOAD))
            with m.Case(PAYLOAD):
                m.d.sync += [rx_count.eq(rx_count + 1), *add(byte)]
                with m.Switch(rx_count):
                    for index, reg in ((0, p0), (1, p1), (2, p2)):
                        with m.Case(index):
                            m.d.sync += reg.eq(byte)
                    for k in range(4):
                        with m.Case(ubx.CFG_PRT_BAUD_OFFSET + k):
                            m.d.sync += p_baud.word_select(k, 8).eq(byte)
                with m.If(rx_count + 1 == rx_len):
                    m.d.sync += state.eq(CKA)
            with m.Case(CKA):
                m.d.sync += state.eq(Mux(byte == rx_ck_a, CKB, SYNC1))
            with m.Case(CKB):
                m.d.sync += state.eq(SYNC1)
                with m.If(byte == rx_ck_b):
                    self._act(
                        m,
                        rx_class,
                        rx_id,
                        rx_len,
                        (p0, p1, p2, p_baud),
                        ack=(ack_pending, ack_is_ack, ack_class, ack_id),
                        mon_ver_pending=mon_ver_pending,
                        pvt_enabled=pvt_enabled,
                        switch=(switch_pending, new_divider, new_baud),
                    )
        epoch, deciding = self._navigation_epoch(m)

        # --- output: the frame sequencer -------------------------------------------------
        frame = Signal(range(len(FRAMES)))
        index = Signal(range(max(len(s) for s in FRAMES.values())))
        ck_a, ck_b = Signal(8), Signal(8)
        values = {
            "ack_class": ack_class,
            "ack_id": ack_id,
            **{name: latch.visible[name].as_unsigned() for name, _ in ubx.SAMPLE_LAYOUT},
        }
        out_byte, last, summed = Signal(8), Signal(), Signal()
        with m.Switch(frame):
            for number, sources in enumerate(FRAMES.values()):
                # The frame's bytes as one value, byte `index` selected by a shift: a case
                # per position was a priority chain over every byte, which a simulator
                # evaluates in every UART cycle (a tenth of the UART domain's instructions
                # while PX4 configures the receiver, measured).
                image = Cat(*(_source_value(source, values, ck_a, ck_b) for source in sources))
                with m.Case(number):
                    m.d.comb += [
                        out_byte.eq(image.word_select(index, 8)),
                        last.eq(index == len(sources) - 1),
                        # class..payload, as the checksum (the frame's last two bytes) covers
                        summed.eq((index >= 2) & (index < len(sources) - 2)),
                    ]
        m.d.comb += [
            # The header passes intact, so the driver finds the frame and fails its checksum.
            uart_tx.data.eq(out_byte ^ Mux(index >= ubx.HEADER_LEN, self.fault.flip, 0)),
            uart_tx.valid.eq(sending),
        ]
        frame_number = {name: number for number, name in enumerate(FRAMES)}

        def start(name: str) -> list:
            return [
                frame.eq(frame_number[name]),
                index.eq(0),
                sending.eq(1),
                ck_a.eq(0),
                ck_b.eq(0),
            ]

        with m.If(sending), m.If(uart_tx.ready):
            m.d.sync += index.eq(index + 1)
            with m.If(summed):  # class..payload, as the checksum covers
                m.d.sync += [ck_a.eq(ck_a + out_byte), ck_b.eq(ck_b + ck_a + out_byte)]
            with m.If(last):
                m.d.sync += sending.eq(0)
        with m.Elif(ack_pending):
            m.d.sync += [*start("ack"), ack_pending.eq(0)]
            with m.If(~ack_is_ack):
                m.d.sync += frame.eq(frame_number["nak"])
        with m.Elif(switch_pending), m.If(~uart_tx.busy):
            m.d.sync += [divider.eq(new_divider), self.baud.eq(new_baud)]
            m.d.sync += switch_pending.eq(0)
        with m.Elif(mon_ver_pending):
            m.d.sync += [*start("mon_ver"), mon_ver_pending.eq(0)]
        with m.Elif(pvt_pending & ~latch.pending):
            m.d.sync += [*start("nav_pvt"), pvt_pending.eq(0)]
        # After the sequencer: an epoch in the cycle a NAV-PVT starts is not lost.
        with m.If(epoch & pvt_enabled):
            m.d.sync += pvt_pending.eq(1)
        if self.skippable:
            # Quiet while only the bit timers move: no byte or fix to take, no epoch being
            # decided, no copy of a fix, and no frame or rate switch waiting to start.
            waiting = ack_pending | switch_pending | mon_ver_pending | pvt_pending
            acting = Cat(
                uart_rx.stb, uart_rx.frame_error, self.sample_stb, deciding, epoch,
                latch.copying, ~sending & waiting,
            ).any()  # fmt: skip
            m.d.comb += [
                uart_tx.skip.eq(self.skip),
                uart_rx.skip.eq(self.skip),
                self.quiet.eq(Mux(acting, 0, least(uart_tx.quiet, uart_rx.quiet))),
            ]
        return m

    def _navigation_epoch(self, m: Module) -> tuple[Value, Value]:
        """1 for a cycle when the last loaded fix's iTOW is a whole multiple of measRate,
        and whether that is being decided.

        Hand-written restoring division (Amaranth's library has no divider, and a
        combinational 32-by-16-bit remainder would be a large, slow block for a question
        asked ten times a second): the remainder takes one dividend bit a cycle.
        """
        dividend = Signal(EPOCH_DECISION_CYCLES)
        remainder = Signal(16)
        bits_left = Signal(range(EPOCH_DECISION_CYCLES + 1))
        shifted = Signal(17)  # remainder · 2 + the next dividend bit
        reduced = Signal(17)
        epoch = Signal()
        m.d.comb += [
            shifted.eq(Cat(dividend[-1], remainder)),
            reduced.eq(Mux(shifted >= self.meas_rate_ms, shifted - self.meas_rate_ms, shifted)),
        ]
        m.d.sync += epoch.eq(0)
        with m.If(self.sample_stb):
            m.d.sync += [
                dividend.eq(self.sample.iTOW),
                remainder.eq(0),
                bits_left.eq(EPOCH_DECISION_CYCLES),
            ]
        with m.Elif(bits_left != 0):
            m.d.sync += [
                dividend.eq(dividend << 1),
                remainder.eq(reduced),
                bits_left.eq(bits_left - 1),
            ]
            with m.If(bits_left == 1):
                m.d.sync += epoch.eq(reduced == 0)
        return epoch, bits_left != 0

    def _act(
        self,
        m: Module,
        rx_class: Signal,
        rx_id: Signal,
        rx_len: Signal,
        captured: tuple[Signal, Signal, Signal, Signal],
        *,
        ack: tuple[Signal, Signal, Signal, Signal],
        mon_ver_pending: Signal,
        pvt_enabled: Signal,
        switch: tuple[Signal, Signal, Signal],
    ) -> None:
        """A valid frame arrived: queue its ACK/NAK, MON-VER, a rate switch, enable NAV-PVT."""
        p0, p1, p2, p_baud = captured
        ack_pending, ack_is_ack, ack_class, ack_id = ack
        switch_pending, new_divider, new_baud = switch
        with m.If(rx_class == ubx.CLASS_CFG):
            m.d.sync += [ack_pending.eq(1), ack_class.eq(rx_class), ack_id.eq(rx_id)]
            accepted = Signal()
            m.d.comb += accepted.eq((rx_id != ubx.ID_CFG_VALSET) & (rx_len > 1))
            with m.If(rx_id == ubx.ID_CFG_PRT):
                with m.If((p0 == ubx.PORT_UART1) & (rx_len >= ubx.CFG_PRT_BLOCK_LEN)):
                    supported = Signal()
                    with m.Switch(p_baud):
                        for rate, divider in self.dividers.items():
                            with m.Case(rate):
                                m.d.comb += supported.eq(1)
                                m.d.sync += [new_divider.eq(divider), new_baud.eq(rate)]
                    with m.If(supported & accepted):
                        m.d.sync += switch_pending.eq(1)
                    m.d.sync += ack_is_ack.eq(supported & accepted)
                with m.Else():
                    m.d.sync += ack_is_ack.eq(accepted)
            with m.Elif(rx_id == ubx.ID_CFG_RATE):
                meas_rate = Cat(p0, p1)
                supported = (rx_len == ubx.CFG_RATE_LEN) & (meas_rate >= MIN_MEAS_RATE_MS)
                m.d.sync += ack_is_ack.eq(accepted & supported)
                with m.If(accepted & supported):
                    m.d.sync += self.meas_rate_ms.eq(meas_rate)
            with m.Elif(rx_id == ubx.ID_CFG_MSG):
                m.d.sync += ack_is_ack.eq(accepted)
                is_pvt = (p0 == ubx.CLASS_NAV) & (p1 == ubx.ID_NAV_PVT) & (rx_len == 3)
                with m.If(is_pvt):
                    m.d.sync += pvt_enabled.eq(p2 != 0)
            with m.Else():
                m.d.sync += ack_is_ack.eq(accepted)
        with m.Elif((rx_class == ubx.CLASS_MON) & (rx_id == ubx.ID_MON_VER) & (rx_len == 0)):
            m.d.sync += mon_ver_pending.eq(1)


def _source_value(source: Source, values: dict[str, Value], ck_a: Value, ck_b: Value) -> Value:
    if source == ubx.CK_A:
        return ck_a
    if source == ubx.CK_B:
        return ck_b
    if isinstance(source, tuple):
        name, byte = source
        return values[name].word_select(byte, 8)
    return Const(source, 8)
