"""Clocking by event in the compiled co-simulation: what every skippable component shares.

A skippable component (built so only for the compiled harness, never for synthesis) says in
``quiet`` how many coming edges of its clock move nothing but its own counters, and takes
``skip``: its next edge stands for ``1 + skip`` cycles (``skip < quiet``), which its
counters add. The harness lets one edge stand for the least ``quiet`` of every part on
that clock (``fpga_hdl.cosim.native_harness.cpp``), so a stretch in which only counters
move costs one edge, and every count and output is the same as cycle by cycle.
"""

import functools

from amaranth.hdl import Mux, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

__all__ = ["least", "skip_members"]


def skip_members(bits: int) -> dict[str, wiring.Member]:
    """A skippable component's ``skip`` and ``quiet`` ports, ``bits`` wide."""
    return {"skip": In(bits), "quiet": Out(bits)}


def least(*values: Value) -> Value:
    """The smallest of ``values`` (unsigned), as a mux tree: the parts' common quiet."""
    return functools.reduce(lambda a, b: Mux(a < b, a, b), values)
