"""Transaction-level model of the MS5611 core, and the host-side inverse compensation.

:class:`Ms5611Model` answers the same bytes as ``core.Ms5611``. :func:`raw_from_si`
inverts the datasheet's first- and second-order compensation: for a pressure and a
temperature it finds the D1/D2 whose compensated result is nearest, so the autopilot's
driver, running the datasheet formulas, reads back the values the rig intended.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

from fpga_hdl.chips.ms5611 import regs

IDLE_BYTE = 0xFF  # an undriven SDO reads as the pull-up
ADC_MAX = (1 << 24) - 1


class Ms5611Model:
    """MS5611 behind an SPI transfer (:class:`fpga_hdl.buses.transactions.SpiDeviceModel`).

    ``now_us`` is the simulated time, set by the rig as it advances.
    """

    def __init__(self, prom: tuple[int, ...] = regs.DEFAULT_PROM) -> None:
        self.prom = tuple(prom)
        self.d1 = 0
        self.d2 = 0
        self.now_us = 0
        self.fault_mute = False
        self.fault_flip = 0
        self._conversion: tuple[int, int, int] | None = None  # value, start, duration
        self._adc_result = 0

    def load_sample(self, d1: int, d2: int) -> None:
        if not (0 <= d1 <= ADC_MAX and 0 <= d2 <= ADC_MAX):
            raise ValueError(f"MS5611 D1/D2 must be 24-bit, not {d1}/{d2}")
        self.d1, self.d2 = d1, d2

    def _command(self, command: int) -> bytes:
        """Act on the command byte; return the data bytes the chip then sends."""
        high, low = command >> 4, command & 0xF
        if command == regs.CMD_RESET:
            self._conversion, self._adc_result = None, 0
        elif high in (0x4, 0x5) and low <= regs.Osr.OSR_4096 and not low & 1:
            value = self.d2 if high == 0x5 else self.d1
            self._conversion = (value, self.now_us, regs.CONVERSION_TIME_US[regs.Osr(low)])
        elif command == regs.CMD_ADC_READ:
            conversion, self._conversion = self._conversion, None
            self._adc_result = 0  # read before the conversion is done (or without one): 0
            if conversion is not None:
                value, start_us, duration_us = conversion
                if (self.now_us - start_us) % (1 << 32) >= duration_us:
                    self._adc_result = value
        if command == regs.CMD_ADC_READ:
            return self._adc_result.to_bytes(3, "big")
        if high == regs.CMD_PROM_READ >> 4 and not low & 1:
            return self.prom[low >> 1].to_bytes(2, "big")
        return b""

    def transfer(self, tx: bytes) -> bytes:
        if not tx:
            return b""
        count = len(tx) - 1
        payload = self._command(tx[0])[:count].ljust(count, b"\x00")  # then zeros
        if self.fault_mute:
            return bytes([IDLE_BYTE]) * len(tx)
        if self.fault_flip:
            payload = bytes(byte ^ self.fault_flip for byte in payload)
        return b"\x00" + payload


def _nearest(
    target: int, evaluate: Callable[[int], int], name: str, guess: int | None = None
) -> int:
    """The 24-bit input whose non-decreasing ``evaluate`` is nearest ``target``.

    The answer is the smallest input reaching ``target`` (or the one below it, when that
    one is nearer). A ``guess`` that is exactly that smallest input is accepted after two
    evaluations; otherwise bisection finds it, because the compensation has no
    closed-form inverse once the second-order terms and integer shifts are in.
    """
    if guess is not None and 0 < guess <= ADC_MAX:
        below, at = evaluate(guess - 1), evaluate(guess)
        if below < target <= at:
            return guess - 1 if target - below < at - target else guess
    low, high = 0, ADC_MAX
    if not evaluate(low) <= target <= evaluate(high):
        raise ValueError(
            f"MS5611 {name} {target} is outside what a 24-bit ADC value can produce "
            f"({evaluate(low)}..{evaluate(high)}) with this PROM"
        )
    while low < high:  # smallest input with evaluate(input) >= target
        middle = (low + high) // 2
        if evaluate(middle) < target:
            low = middle + 1
        else:
            high = middle
    if low > 0 and target - evaluate(low - 1) < evaluate(low) - target:
        return low - 1
    return low


@functools.lru_cache(maxsize=4096)
def _d2_for(temp_target: int, prom: tuple[int, ...]) -> int:
    """D2 for a temperature in 0.01 °C: cached, as the air temperature changes slowly."""
    return _nearest(
        temp_target, lambda d: regs.compensate(0, d, prom).temp, "temperature (0.01 °C)"
    )


def raw_from_si(
    pressure_pa: float, temperature_c: float, prom: tuple[int, ...] = regs.DEFAULT_PROM
) -> tuple[int, int]:
    """(D1, D2) that the datasheet compensation turns into these values, to 1 Pa / 0.01 °C.

    Given D2, the pressure P = ((D1·SENS >> 21) − OFF) >> 15 first reaches a target at
    D1 = ⌈(target·2¹⁵ + OFF)·2²¹ / SENS⌉ (floor shifts); that guess is checked against the
    datasheet formula before it is used, so a PROM or formula it does not fit only costs
    the bisection.
    """
    d2 = _d2_for(round(temperature_c * 100), tuple(prom))
    pressure_target = round(pressure_pa)
    at_d2 = regs.compensate(0, d2, prom)
    guess = None
    if at_d2.sens > 0:
        guess = -(-(((pressure_target << 15) + at_d2.off) << 21) // at_d2.sens)
    d1 = _nearest(
        pressure_target, lambda d: regs.compensate(d, d2, prom).pressure, "pressure (Pa)", guess
    )
    return d1, d2
