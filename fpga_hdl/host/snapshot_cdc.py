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

The source may publish at most once per source cycle, and ``held`` must then stay put
while the destination copies it: the destination clock must run at least
``stages + 2`` times as fast as the source's (the copy lands ``stages + 1`` destination
edges after a publication, before the next one can).

A stopped destination clock (a gated simulation clock) loses nothing as long as the
count does not come round to the value last copied: up to ``2**COUNT_BITS - 1``
publications while it is stopped, and then the destination copies the latest once it
runs again.
"""

from __future__ import annotations

from amaranth.hdl import Module, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

__all__ = ["COUNT_BITS", "PUBLISH_TICKS", "SnapshotSynchronizer"]

#: Bits of the Gray change counter: publications a stopped destination may miss without
#: aliasing. With 3 bits, 8 PWM result changes between two host reads (one 4 ms rig
#: frame at 400 Hz PWM) left the host a whole frame stale; 16 bits allow 65535.
COUNT_BITS = 16
#: Source edges from a change of ``data_i`` to its publication (``held`` and the count).
PUBLISH_TICKS = 1


def _gray(value):
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

    def __init__(self, shape, *, i_domain: str, o_domain: str, stages: int = 2, init=None) -> None:
        self._i_domain, self._o_domain, self._stages = i_domain, o_domain, stages
        self.copy_cycles = stages + 1
        super().__init__({"data_i": In(shape, init=init), "data_o": Out(shape, init=init)})

    def elaborate(self, platform) -> Module:
        m = Module()
        held = Signal.like(self.data_i, name="held")
        count = Signal(COUNT_BITS)
        next_count = Signal(COUNT_BITS)  # wraps, so the Gray code wraps by one bit too
        gray = Signal(COUNT_BITS)
        m.d.comb += next_count.eq(count + 1)
        with m.If(Value.cast(held) != Value.cast(self.data_i)):
            m.d[self._i_domain] += [
                held.eq(self.data_i),
                count.eq(next_count),
                gray.eq(_gray(next_count)),
            ]

        seen_gray = Signal(COUNT_BITS)
        m.submodules.count_sync = FFSynchronizer(
            gray, seen_gray, o_domain=self._o_domain, stages=self._stages
        )
        copied_gray = Signal(COUNT_BITS)
        with m.If(seen_gray != copied_gray):
            m.d[self._o_domain] += [self.data_o.eq(held), copied_gray.eq(seen_gray)]
        return m
