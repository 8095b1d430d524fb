"""The scoreboard for every "RTL equals its TLM twin" check, and the paired buses that feed it.

Each chip has a transaction-level twin (``chips/*/model.py``), and the tests demand that
the gateware answer every transaction with the twin's bytes. A :class:`Scoreboard` is
that check written once: it records each transaction's expected (TLM) and observed (RTL)
result in order and fails at the first mismatch with one line naming its index, the
request, both results and, for bytes, the first byte that differs.

:class:`ScoredSpiBus` and :class:`ScoredI2cBus` put the RTL bus and the TLM bus behind
one ``SpiBus``/``I2cBus``, so a driver written for one bus checks every transaction it
makes; :meth:`Scoreboard.check_transcript` compares two recorded transcripts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from fpga_hdl.buses.transactions import I2cBus, I2cNack, SpiBus

__all__ = ["Scoreboard", "ScoreboardMismatch", "ScoredI2cBus", "ScoredSpiBus", "Transaction"]


class ScoreboardMismatch(AssertionError):
    """The RTL answered a transaction differently from its TLM twin."""


@dataclass(frozen=True)
class Transaction:
    """One scored transaction: the request, the twin's result and the RTL's."""

    request: str
    expected: object
    observed: object


def _show(value: object) -> str:
    return value.hex() if isinstance(value, bytes) else str(value)


def _first_difference(expected: object, observed: object) -> str:
    if not (isinstance(expected, bytes) and isinstance(observed, bytes)):
        return ""
    index = next(
        (i for i, (a, b) in enumerate(zip(expected, observed, strict=False)) if a != b),
        min(len(expected), len(observed)),
    )
    return f"; first difference at byte {index}"


class Scoreboard:
    """Expected (TLM) against observed (RTL) transactions, in order; the first mismatch fails.

    ``name`` says which two sides are compared ("RTL vs TLM", "compiled RTL vs TLM" ...).
    """

    def __init__(self, name: str = "RTL vs TLM") -> None:
        self.name = name
        self.transactions: list[Transaction] = []

    def __len__(self) -> int:
        return len(self.transactions)

    def check(self, request: str, expected: object, observed: object) -> None:
        """Record one transaction; raise :class:`ScoreboardMismatch` if the results differ."""
        index = len(self.transactions)
        self.transactions.append(Transaction(request, expected, observed))
        if expected != observed:
            raise ScoreboardMismatch(
                f"{self.name}: transaction {index} ({request}): expected {_show(expected)}, "
                f"got {_show(observed)}{_first_difference(expected, observed)}"
            )

    def check_transcript(
        self, expected: Sequence[Sequence[str]], observed: Sequence[Sequence[str]]
    ) -> None:
        """Score two transcripts of ``(bus, request, response)`` rows (hex or ``nack<i>``)."""
        for want, got in zip(expected, observed, strict=False):
            request = " ".join(want[:-1])
            if list(got[:-1]) != list(want[:-1]):  # the scripts diverged: show whole rows
                self.check(request, " ".join(want), " ".join(got))
            else:
                self.check(request, _from_hex(want[-1]), _from_hex(got[-1]))
        if len(expected) != len(observed):
            raise ScoreboardMismatch(
                f"{self.name}: expected {len(expected)} transactions, got {len(observed)}"
            )


def _from_hex(response: str) -> bytes | str:
    try:
        return bytes.fromhex(response)
    except ValueError:
        return response


async def _attempt(
    bus: I2cBus, address: int, write: bytes, read_len: int, scl_hz: float
) -> bytes | I2cNack:
    try:
        return await bus.write_read(address, write, read_len, scl_hz=scl_hz)
    except I2cNack as nack:
        return nack


def _result(outcome: bytes | I2cNack) -> bytes | str:
    return outcome if isinstance(outcome, bytes) else f"NACK of byte {outcome.byte_index}"


class ScoredSpiBus:
    """A ``SpiBus`` that runs each transfer on ``rtl`` then ``tlm`` and scores the pair."""

    def __init__(self, rtl: SpiBus, tlm: SpiBus, scoreboard: Scoreboard | None = None) -> None:
        self.rtl, self.tlm = rtl, tlm
        self.scoreboard = Scoreboard() if scoreboard is None else scoreboard

    async def transfer(self, device: str, tx: bytes, *, sclk_hz: float) -> bytes:
        """The RTL's answer, once the TLM twin's equals it."""
        rx = await self.rtl.transfer(device, tx, sclk_hz=sclk_hz)
        expected = await self.tlm.transfer(device, tx, sclk_hz=sclk_hz)
        self.scoreboard.check(f"spi {device} {tx.hex()} at {sclk_hz:g} Hz", expected, rx)
        return rx


class ScoredI2cBus:
    """An ``I2cBus`` that runs each transfer on ``rtl`` then ``tlm`` and scores the pair.

    A NACK is an outcome too: both sides must refuse the same byte, and the RTL's
    :class:`~fpga_hdl.buses.transactions.I2cNack` is then raised to the caller.
    """

    def __init__(self, rtl: I2cBus, tlm: I2cBus, scoreboard: Scoreboard | None = None) -> None:
        self.rtl, self.tlm = rtl, tlm
        self.scoreboard = Scoreboard() if scoreboard is None else scoreboard

    async def write_read(
        self, address: int, write: bytes, read_len: int, *, scl_hz: float
    ) -> bytes:
        """The RTL's answer (or NACK), once the TLM twin's equals it."""
        observed = await _attempt(self.rtl, address, write, read_len, scl_hz)
        expected = await _attempt(self.tlm, address, write, read_len, scl_hz)
        request = f"i2c 0x{address:02X} write {write.hex() or '-'} read {read_len}"
        self.scoreboard.check(f"{request} at {scl_hz:g} Hz", _result(expected), _result(observed))
        if isinstance(observed, I2cNack):
            raise observed
        return observed
