"""How the rig loads samples, time and faults into the chips, and reads results back.

Double buffering, in two halves:

1. :class:`HostPort` (rig side). The rig writes 32-bit words into *staging* registers,
   one word per sample field, in any order and over as many cycles as it likes. Nothing
   a chip shows changes until ``commit``: in that one cycle every channel written since
   the last commit is copied to its *offered* register and strobed, and ``now_us`` and
   the fault words take their new values.
2. :class:`CoherentLatch` (chip side, inside each chip core). An offered sample becomes
   *visible* (readable over the bus) only in a cycle with no bus transaction running;
   one offered during a transaction waits for the transaction's end.

A bus read therefore sees one committed sample from its first byte to its last: the
rig cannot tear it (staging is invisible) and neither can a commit (the latch defers).

The word map (which address holds which field) is built once by :func:`host_port_map`
and used by the gateware and by the Python side that drives the port.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from amaranth.build import Platform
from amaranth.hdl import Module, Shape, Signal, Value
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

WORD_BITS = 32
#: Fault word layout: bits 0..7 XOR mask on sent bytes, bit 8 mute, then the chip's own
#: faults (if it has any, e.g. the PMW3901's), one bit each from :data:`FAULT_OWN_SHIFT`.
FAULT_MUTE_BIT = 8
FAULT_OWN_SHIFT = FAULT_MUTE_BIT + 1


#: A chip's fault inputs as the rig gives them: ``(mute, flip)`` or ``(mute, flip, own)``.
FaultInputs = tuple[bool, int] | tuple[bool, int, int]


def fault_word(mute: bool, flip: int, own: int = 0) -> int:
    """A chip's fault word: ``own`` is the mask of its own faults, bit 0 the first named."""
    return own << FAULT_OWN_SHIFT | int(mute) << FAULT_MUTE_BIT | flip


class CoherentLatch(wiring.Component):
    """Chip-side half of the double buffer: offered sample → visible when the bus is idle.

    Attributes
    ----------
    offered : In(layout)
        The sample on offer; must stay stable from ``offered_stb`` until copied.
    offered_stb : In(1)
        One cycle: ``offered`` holds a new sample.
    busy : In(1)
        A bus transaction with this chip is in progress (synchronised to ``sync``).
    visible : Out(layout)
        The sample the bus reads; changes only while ``busy`` is low.
    pending : Out(1)
        A sample is waiting to become visible.
    copying : Out(1)
        The edge ending this cycle copies ``offered`` into ``visible`` (a chip that
        acts on each new sample, the PMW3901's motion accumulators, acts on it then).
    """

    def __init__(self, layout: data.Layout) -> None:
        super().__init__(
            {
                "offered": In(layout),
                "offered_stb": In(1),
                "busy": In(1),
                "visible": Out(layout),
                "pending": Out(1),
                "copying": Out(1),
            }
        )

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        m.d.comb += self.copying.eq(self.pending & ~self.busy)
        with m.If(self.copying):
            m.d.sync += [self.visible.eq(self.offered), self.pending.eq(0)]
        with m.If(self.offered_stb):  # a strobe in the copy cycle re-arms: latest wins
            m.d.sync += self.pending.eq(1)
        return m


def chip_sample_latch(
    m: Module,
    chip: wiring.Component,
    layout: data.Layout,
    *,
    busy: Value,
    offered_stb: Value | None = None,
) -> CoherentLatch:
    """A chip core's double buffer (submodule ``latch``), wired as every core has it: the
    core's ``sample``/``sample_stb`` offered (``offered_stb`` instead of the strobe when the
    core gates it), ``busy`` while its bus is in a transaction, ``sample_pending`` out."""
    m.submodules.latch = latch = CoherentLatch(layout)
    m.d.comb += [
        latch.offered.eq(chip.sample),
        latch.offered_stb.eq(chip.sample_stb if offered_stb is None else offered_stb),
        latch.busy.eq(busy),
        chip.sample_pending.eq(latch.pending),
    ]
    return latch


@dataclass(frozen=True)
class HostWord:
    """One word of the host port: a staged sample field, time, a fault word or a result."""

    address: int
    channel: str
    field: str
    width: int
    signed: bool

    @property
    def limits(self) -> tuple[int, int]:
        """The lowest and highest value the word holds."""
        low = -(1 << (self.width - 1)) if self.signed else 0
        return low, low + (1 << self.width) - 1


@dataclass(frozen=True)
class HostPortMap:
    """Addresses of every host-port word; built once by :func:`host_port_map`."""

    writes: tuple[HostWord, ...]
    reads: tuple[HostWord, ...]

    def write_address(self, channel: str, field: str) -> int:
        return self._find(self.writes, channel, field).address

    def read_address(self, channel: str, field: str) -> int:
        return self._find(self.reads, channel, field).address

    @staticmethod
    def _find(words: tuple[HostWord, ...], channel: str, field: str) -> HostWord:
        for word in words:
            if (word.channel, word.field) == (channel, field):
                return word
        known = ", ".join(f"{w.channel}.{w.field}" for w in words)
        raise KeyError(f"no host-port word {channel}.{field}; known: {known}")

    def encode(self, channel: str, field: str, value: int) -> tuple[int, int]:
        """(address, 32-bit data) writing ``value`` into a staged field, range-checked."""
        word = self._find(self.writes, channel, field)
        low, high = word.limits
        if not low <= value <= high:
            raise ValueError(
                f"host-port value {channel}.{field}={value} outside {low}..{high} "
                f"({word.width}-bit {'signed' if word.signed else 'unsigned'})"
            )
        return word.address, value & ((1 << WORD_BITS) - 1)

    def encode_frame(
        self,
        samples: Mapping[str, Mapping[str, int]],
        *,
        now_us: int | None = None,
        faults: Mapping[str, FaultInputs] | None = None,
    ) -> list[tuple[int, int]]:
        """The (address, data) writes that stage one frame: sample fields, the time
        (wrapped to 32 bits) and each chip's fault word from ``(mute, flip)`` or
        ``(mute, flip, own)`` (:func:`fault_word`)."""
        words = [
            self.encode(channel, field, value)
            for channel, fields in samples.items()
            for field, value in fields.items()
        ]
        if now_us is not None:
            words.append(self.encode("time", "now_us", now_us % (1 << 32)))
        for chip, fault in (faults or {}).items():
            words.append(self.encode(chip, "fault", fault_word(*fault)))
        return words


def host_port_map(
    samples: Mapping[str, data.StructLayout],
    faults: Mapping[str, tuple[str, ...]],
    results: Mapping[str, Mapping[str, Shape]],
) -> HostPortMap:
    """Assign word addresses: ``now_us`` first, then sample fields, faults, results.
    ``faults`` names each chip with a fault word and its own faults (often none)."""
    writes = [HostWord(0, "time", "now_us", 32, False)]
    for channel, layout in samples.items():
        for name, field in layout:
            shape = Shape.cast(field.shape)
            if shape.width > WORD_BITS:
                raise ValueError(f"{channel}.{name} is {shape.width} bits; words hold 32")
            writes.append(HostWord(len(writes), channel, name, shape.width, shape.signed))
    for chip, own in faults.items():
        writes.append(HostWord(len(writes), chip, "fault", FAULT_OWN_SHIFT + len(own), False))
    reads: list[HostWord] = []
    for channel, fields in results.items():
        for name, shape in fields.items():
            shape = Shape.cast(shape)
            reads.append(HostWord(len(reads), channel, name, shape.width, shape.signed))
    return HostPortMap(tuple(writes), tuple(reads))


class HostPort(wiring.Component):
    """Rig-side half of the double buffer: staged word writes, one atomic commit.

    Parameters
    ----------
    samples : mapping of channel name to ``StructLayout``
        One sample channel per chip (``"imu"``, ``"baro"``, ``"mag"``).
    faults : mapping of chip name to the names of its own faults
        Chips with fault inputs (``fault_mute``, ``fault_flip`` and ``fault_<own>``).
    results : mapping of channel name to {field: shape}
        Values the rig reads back (PWM capture results), one word each.

    Attributes
    ----------
    write_addr : In(8), write_data : In(32), write_en : In(1)
        One staged word per cycle; addresses from :attr:`map`.
    commit : In(1)
        One cycle: publish every written channel, ``now_us`` and the fault words.
    read_addr : In(8)
        Result word to show on ``read_data``.
    read_data : Out(32)
        The addressed result word (combinational), sign-extended when signed.
    now_us : Out(32)
        Simulated time in microseconds, as last committed.
    <channel> : Out(layout), <channel>_stb : Out(1)
        Offered sample per channel and its one-cycle strobe at commit.
    <chip>_fault_mute : Out(1), <chip>_fault_flip : Out(8), <chip>_fault_<own> : Out(1)
        Fault inputs per chip, as last committed.
    <channel>_<field> : In(shape)
        Result inputs, readable through ``read_addr``/``read_data``.
    """

    def __init__(
        self,
        samples: Mapping[str, data.StructLayout],
        faults: Mapping[str, tuple[str, ...]],
        results: Mapping[str, Mapping[str, Shape]],
    ) -> None:
        self.map = host_port_map(samples, faults, results)
        if len(self.map.writes) > 256 or len(self.map.reads) > 256:
            raise ValueError("the host port addresses at most 256 words each way")
        self._samples = dict(samples)
        self._faults = dict(faults)
        members = {
            "write_addr": In(8),
            "write_data": In(WORD_BITS),
            "write_en": In(1),
            "commit": In(1),
            "read_addr": In(8),
            "read_data": Out(WORD_BITS),
            "now_us": Out(32),
        }
        for channel, layout in samples.items():
            members[channel] = Out(layout)
            members[f"{channel}_stb"] = Out(1)
        for chip, own in faults.items():
            members[f"{chip}_fault_mute"] = Out(1)
            members[f"{chip}_fault_flip"] = Out(8)
            members |= {f"{chip}_fault_{name}": Out(1) for name in own}
        for word in self.map.reads:
            members[f"{word.channel}_{word.field}"] = In(word.width)
        super().__init__(members)

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        staged = {
            w.address: Signal(w.width, name=f"staged_{w.channel}_{w.field}")
            for w in self.map.writes
        }
        dirty = {channel: Signal(name=f"dirty_{channel}") for channel in self._samples}
        stb_signals = [getattr(self, f"{c}_stb") for c in self._samples]
        m.d.sync += [stb.eq(0) for stb in stb_signals]
        with m.If(self.commit):
            for word in self.map.writes:
                value = staged[word.address]
                if word.channel == "time":
                    m.d.sync += self.now_us.eq(value)
                elif word.field == "fault":
                    m.d.sync += [
                        getattr(self, f"{word.channel}_fault_flip").eq(value[:8]),
                        getattr(self, f"{word.channel}_fault_mute").eq(value[FAULT_MUTE_BIT]),
                    ]
                    for bit, name in enumerate(self._faults[word.channel], FAULT_OWN_SHIFT):
                        m.d.sync += getattr(self, f"{word.channel}_fault_{name}").eq(value[bit])
                else:
                    offered = getattr(self, word.channel)[word.field]
                    m.d.sync += offered.eq(value)
            for channel, flag in dirty.items():
                m.d.sync += [getattr(self, f"{channel}_stb").eq(flag), flag.eq(0)]
        # After the commit block: a word written in the commit cycle stays staged and dirty.
        with m.If(self.write_en), m.Switch(self.write_addr):
            for word in self.map.writes:
                with m.Case(word.address):
                    m.d.sync += staged[word.address].eq(self.write_data[: word.width])
                    # A chip's fault word is not its sample: writing it offers nothing new
                    # (the rig writes every fault word every frame; a GPS receiver would
                    # take each re-offered fix for a new epoch).
                    if word.channel in dirty and word.field != "fault":
                        m.d.sync += dirty[word.channel].eq(1)

        with m.Switch(self.read_addr):
            for word in self.map.reads:
                with m.Case(word.address):
                    value = getattr(self, f"{word.channel}_{word.field}")
                    m.d.comb += self.read_data.eq(value.as_signed() if word.signed else value)
        return m
