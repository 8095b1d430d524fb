"""Carry a slowly changing multi-bit value into another clock domain, whole and coherent.

Why not an ``FFSynchronizer`` per bit: a multi-bit value sampled while it changes can
arrive with some bits old and some new. The usual cure, used here, is to send a *change
count* beside a *published* copy of the value. The source domain publishes in one edge:
``held`` takes the new value and the count steps, in Gray code (one bit flips per step,
so a sample is always the old or the new count). The count crosses through an
``amaranth.lib.cdc.FFSynchronizer``; the destination copies ``held`` whenever the count
it sees moves. The destination therefore only ever shows published values, never the
source's live registers, and a value's age is fixed:

- it is published :data:`PUBLISH_TICKS` source edge after ``data_i`` changed;
- it is in ``data_o`` after the ``stages + 1``-th destination edge that follows the
  publication (:attr:`SnapshotSynchronizer.copy_cycles`: the synchroniser's flip-flops,
  then the copy).

``held`` must stay put while the destination copies it: publications at least
``stages + 1`` destination periods apart. A source that may publish every source cycle
therefore needs a destination clock at least ``stages + 2`` times as fast as its own; a
value that changes only now and then (a fault word set by the host) may cross into a
slower domain.

:class:`SampleSynchronizer` is the same crossing for a value whose *strobe* matters, not
its change (a GPS epoch whose fix equals the last is still an epoch): the strobe steps
the count, and the source's own register is copied, so the source pays no copy of its
own (a 624-bit fix stays one register in the fast domain).

A stopped destination clock (a gated simulation clock) loses nothing as long as the
count does not come round to the value last copied: up to ``2**COUNT_BITS - 1``
publications while it is stopped, and then the destination copies the latest once it
runs again.
"""

from __future__ import annotations

from amaranth.build import Platform
from amaranth.hdl import Module, ShapeLike, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

__all__ = ["COUNT_BITS", "PUBLISH_TICKS", "SampleSynchronizer", "SnapshotSynchronizer"]

#: Bits of the Gray change counter: publications a stopped destination may miss without
#: aliasing. With 3 bits, 8 PWM result changes between two host reads (one 4 ms rig
#: frame at 400 Hz PWM) left the host a whole frame stale; 16 bits allow 65535.
COUNT_BITS = 16
#: Source edges from a change of ``data_i`` to its publication (``held`` and the count).
PUBLISH_TICKS = 1


def _gray(value: Value) -> Value:
    return value ^ (value >> 1)


class SnapshotSynchronizer(wiring.Component):
    """``data_i`` in ``i_domain`` → ``data_o`` in ``o_domain``, copied whole after a change.

    Parameters
    ----------
    shape : shape-castable
        Shape of the value.
    i_domain, o_domain : str
        Source and destination clock domains.
    stages : int
        Synchroniser flip-flops for the change count.
    init : value or mapping, optional
        Reset value of ``data_i``, of its published copy and of ``data_o``: a source whose
        registers reset to it publishes nothing until they change.

    Attributes
    ----------
    data_i : In(shape)
        The value, in ``i_domain``.
    data_o : Out(shape)
        The last published value, in ``o_domain`` (see the module docstring for its age).
    copy_cycles : int
        Destination edges after a publication until ``data_o`` holds it: ``stages + 1``.
    """

    def __init__(
        self,
        shape: ShapeLike,
        *,
        i_domain: str,
        o_domain: str,
        stages: int = 2,
        init: object = None,  # as the shape takes it (a layout's: a dict of its fields)
    ) -> None:
        self._i_domain, self._o_domain, self._stages = i_domain, o_domain, stages
        self.copy_cycles = stages + 1
        super().__init__({"data_i": In(shape, init=init), "data_o": Out(shape, init=init)})

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        held = Signal.like(self.data_i, name="held")
        publish = Value.cast(held) != Value.cast(self.data_i)
        with m.If(publish):
            m.d[self._i_domain] += held.eq(self.data_i)
        moved = _counted_crossing(m, publish, self._i_domain, self._o_domain, self._stages)
        with m.If(moved):
            m.d[self._o_domain] += self.data_o.eq(held)
        return m


class SampleSynchronizer(wiring.Component):
    """``data_i`` with its strobe ``stb_i`` in ``i_domain`` → ``data_o`` with ``stb_o`` in
    ``o_domain``: each strobe copies ``data_i`` once, strobes while the destination clock
    stands still give one copy of the latest (latest wins).

    ``data_i`` must hold still from its strobe until the copy, ``stages + 1`` destination
    edges after the strobe's source edge: in the rig, a register the host rewrites only at
    its next commit of the same channel.

    Parameters
    ----------
    shape : shape-castable
        Shape of the value.
    i_domain, o_domain : str
        Source and destination clock domains.
    stages : int
        Synchroniser flip-flops for the strobe count.

    Attributes
    ----------
    data_i : In(shape), stb_i : In(1)
        The value and its one-cycle strobe, in ``i_domain``.
    data_o : Out(shape), stb_o : Out(1)
        The copy and its one-cycle strobe (the cycle after the copy), in ``o_domain``.
    copy_cycles : int
        Destination edges after the strobe's source edge until ``data_o`` holds the
        value: ``stages + 1``.
    """

    def __init__(self, shape: ShapeLike, *, i_domain: str, o_domain: str, stages: int = 2) -> None:
        self._i_domain, self._o_domain, self._stages = i_domain, o_domain, stages
        self.copy_cycles = stages + 1
        super().__init__(
            {"data_i": In(shape), "stb_i": In(1), "data_o": Out(shape), "stb_o": Out(1)}
        )

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        moved = _counted_crossing(m, self.stb_i, self._i_domain, self._o_domain, self._stages)
        m.d[self._o_domain] += self.stb_o.eq(moved)
        with m.If(moved):
            m.d[self._o_domain] += self.data_o.eq(self.data_i)
        return m


def _counted_crossing(
    m: Module, publish: Value, i_domain: str, o_domain: str, stages: int
) -> Signal:
    """The change count of both synchronisers: steps (Gray coded) in an ``i_domain`` cycle
    with ``publish``, crosses through an ``FFSynchronizer``; the ``o_domain`` signal
    returned is 1 in the destination cycle that sees it move (and takes the copy)."""
    count = Signal(COUNT_BITS)
    next_count = Signal(COUNT_BITS)  # wraps, so the Gray code wraps by one bit too
    gray = Signal(COUNT_BITS)
    m.d.comb += next_count.eq(count + 1)
    with m.If(publish):
        m.d[i_domain] += [count.eq(next_count), gray.eq(_gray(next_count))]
    seen_gray = Signal(COUNT_BITS)
    m.submodules.count_sync = FFSynchronizer(gray, seen_gray, o_domain=o_domain, stages=stages)
    copied_gray = Signal(COUNT_BITS)
    moved = Signal()
    m.d.comb += moved.eq(seen_gray != copied_gray)
    with m.If(moved):
        m.d[o_domain] += copied_gray.eq(seen_gray)
    return moved
