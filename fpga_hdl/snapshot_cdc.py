"""Carry a slowly changing multi-bit value into another clock domain, whole and coherent.

Why not an ``FFSynchronizer`` per bit: a multi-bit value sampled while it changes can
arrive with some bits old and some new. The usual cure, used here, is to send a *change
count* instead: the source domain counts its updates in Gray code (one bit flips per
update, so a sample is always the old or the new count), the count crosses through an
``amaranth.lib.cdc.FFSynchronizer``, and the destination copies the value, which has
been stable since before the count changed, whenever the count it sees moves. Updates
that happen while the destination clock is stopped (a gated simulation clock) are not
lost: the count still differs when the clock runs again, and the latest value is copied.

The value must stay stable for ``stages + 1`` destination cycles after each update;
:class:`SnapshotSynchronizer` is meant for values that change once per event (a PWM
capture result changes once per pulse edge, at most once per microsecond tick).
"""

from __future__ import annotations

from amaranth.hdl import Module, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

__all__ = ["SnapshotSynchronizer"]

#: Bits of the Gray change counter. While the destination clock is stopped (a gated
#: simulation clock) the count must not wrap back to the value last copied, or the
#: destination misses the updates: with 3 bits, 8 PWM result changes between two host
#: reads (one 4 ms rig frame at 400 Hz PWM) left the host port a whole frame stale.
#: 16 bits allow 65535 updates between reads.
COUNT_BITS = 16


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

    Attributes
    ----------
    data_i : In(shape)
        The value, in ``i_domain``.
    data_o : Out(shape)
        Its copy in ``o_domain``, at most ``stages + 2`` destination cycles behind.
    """

    def __init__(self, shape, *, i_domain: str, o_domain: str, stages: int = 2) -> None:
        self._i_domain, self._o_domain, self._stages = i_domain, o_domain, stages
        super().__init__({"data_i": In(shape), "data_o": Out(shape)})

    def elaborate(self, platform) -> Module:
        m = Module()
        previous = Signal.like(self.data_i)
        count = Signal(COUNT_BITS)
        gray = Signal(COUNT_BITS)
        m.d[self._i_domain] += [previous.eq(self.data_i), gray.eq(_gray(count))]
        # The count moves the cycle after the value did, so the value is already stable.
        with m.If(Value.cast(previous) != Value.cast(self.data_i)):
            m.d[self._i_domain] += count.eq(count + 1)

        seen_gray = Signal(COUNT_BITS)
        m.submodules.count_sync = FFSynchronizer(
            gray, seen_gray, o_domain=self._o_domain, stages=self._stages
        )
        copied_gray = Signal(COUNT_BITS)
        primed = Signal()  # the first destination cycle after reset copies the reset value
        with m.If((seen_gray != copied_gray) | ~primed):
            m.d[self._o_domain] += [
                self.data_o.eq(self.data_i),
                copied_gray.eq(seen_gray),
                primed.eq(1),
            ]
        return m
