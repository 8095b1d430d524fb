"""cocotb bench for the fast path: the harness's SPI/I2C/PWM peripherals around SensorTop.

Run from ``test_cosim_harness.py`` on every simulator. Byte equality with the TLM (and,
through the pytest side, with the pin-level masters); the pins the peripherals drive
checked against the MPU-6000 datasheet and UM10204 by monitors on the harness's bus
outputs; the PWM capture read through the host port against its tick-exact model.
"""

import json
import math
import os

import cocotb
import pytest
from cocotb.handle import HierarchyArrayObject, HierarchyObject, LogicArrayObject, LogicObject
from cocotb.utils import get_sim_time
from transcript import run_script, tlm_transcript_now

from fpga_hdl.buses.i2c_target import FAST_MODE, STANDARD_MODE
from fpga_hdl.buses.transactions import I2cNack
from fpga_hdl.chips.ist8310 import regs as ist
from fpga_hdl.chips.mpu6000 import regs as mpu
from fpga_hdl.chips.pwm_capture.model import PwmCaptureModel
from fpga_hdl.cosim.peripherals import PWM_PHASE_PS, Harness
from fpga_hdl.top import PWM_RESULT_LATENCY_TICKS, PWM_TICK_HZ, PWM_TIMEOUT_S
from fpga_hdl.verification.scoreboard import Scoreboard

#: PS-MPU-6000A-00 §6.8: CS setup/hold, SDI setup/hold (ns); the controller's CS idle.
T_SU_CS_NS, T_HD_CS_NS, T_SU_SDI_NS, T_HD_SDI_NS, T_CS_IDLE_NS = 8, 500, 5, 7, 100


class HarnessChips:
    def __init__(self, harness: Harness) -> None:
        self.harness = harness

    async def load(self, samples, now_us):
        await self.harness.host.load(samples, now_us=now_us)


class PinMonitor:
    """Records (time ps, pin, level) for every change of the watched harness outputs."""

    def __init__(self, dut, names) -> None:
        self.events = []
        self._tasks = [cocotb.start_soon(self._watch(name, getattr(dut, name))) for name in names]

    async def _watch(self, name, handle):
        while True:
            await handle.value_change
            self.events.append((get_sim_time("ps"), name, int(handle.value)))

    def stop(self) -> list:
        """The events in time order; within a time step clocks and selects come first, so
        data changing *with* an edge is seen after it."""
        for task in self._tasks:
            task.cancel()
        first = ("spi_sclk", "imu_cs_n", "baro_cs_n", "i2c_scl")
        return sorted(self.events, key=lambda e: (e[0], e[1] not in first, e[1]))


async def started(dut, spi_mode=0) -> Harness:
    harness = Harness(dut, spi_mode=spi_mode)
    await harness.reset()
    return harness


def unknown_nets(handle) -> list[str]:
    """Every net under ``handle`` holding X or Z. Icarus shows the whole hierarchy and four
    states; Verilator is two-state and shows only the top level's ports (so finds none)."""
    if isinstance(handle, (LogicObject, LogicArrayObject)):
        return [] if handle.value.is_resolvable else [f"{handle._path}={handle.value}"]
    if isinstance(handle, (HierarchyObject, HierarchyArrayObject)):
        return [net for child in handle for net in unknown_nets(child)]
    return []  # parameters


@cocotb.test()
async def no_net_is_unknown_after_reset(dut):
    """After the reset, before any traffic, every net of the design (gateware and gated
    clocks) is 0 or 1. The Icarus-only X on the MPU-6000's SDO began here: combinational
    ``always @*`` blocks that never ran at time 0 gave the SPI-clocked registers X
    next-state values, taken at the first SCLK edge (see ``fpga_hdl.build``)."""
    await started(dut)
    assert unknown_nets(dut) == []


@cocotb.test()
async def transcript_equals_tlm_in_modes_0_and_3(dut):
    """The shared script over the fast peripherals: identical bytes to the TLM in both
    SPI modes; the mode-0 transcript goes to the pytest side for the pin-level check."""
    expected = tlm_transcript_now()
    for mode in (0, 3):
        harness = await started(dut, mode)
        log = await run_script(harness.spi, harness.i2c, HarnessChips(harness))
        Scoreboard(f"fast path in mode {mode} vs TLM").check_transcript(expected, log)
        if mode == 0 and "TRANSCRIPT_OUT" in os.environ:
            with open(os.environ["TRANSCRIPT_OUT"], "w") as out:
                json.dump(log, out)
        assert unknown_nets(dut) == [], f"mode {mode}: unknown nets after the script"


def check_spi_pins(events, sclk_hz: float, mode: int) -> int:
    """Datasheet checks on one monitored stretch; returns the SCLK rising edges seen."""
    half_ps = round(0.5e12 / sclk_hz)
    cs_low_since = cs_high_since = None
    last_sclk = last_rise = last_mosi = None
    rises = 0
    sclk = 1 if mode == 3 else 0
    for t, pin, level in events:
        if pin in ("imu_cs_n", "baro_cs_n"):
            if level == 0:
                assert cs_high_since is None or t - cs_high_since >= T_CS_IDLE_NS * 1000
                cs_low_since, last_sclk = t, None
            else:
                assert t - last_sclk >= T_HD_CS_NS * 1000, "t_HD.CS"
                cs_high_since = t
        elif pin == "spi_sclk":
            if last_sclk is None:
                assert t - cs_low_since >= T_SU_CS_NS * 1000, "t_SU.CS"
            else:
                assert t - last_sclk >= half_ps, f"SCLK half period {t - last_sclk} ps"
            last_sclk, sclk = t, level
            if level == 1:
                rises += 1
                assert last_mosi is None or t - last_mosi >= T_SU_SDI_NS * 1000, "t_SU.SDI"
                last_rise = t
        elif pin == "spi_mosi":
            assert last_rise is None or t - last_rise >= T_HD_SDI_NS * 1000, "t_HD.SDI"
            assert sclk == 0, "MOSI changed while SCLK high"
            last_mosi = t
        elif pin == "spi_miso" and cs_low_since is not None and cs_high_since is None:
            assert t == last_sclk, f"MISO changed away from an SCLK edge at {t} ps"
            assert sclk == 0, f"MISO changed at a rising SCLK edge at {t} ps"
    return rises


@cocotb.test()
async def spi_pins_meet_the_mpu6000_timing(dut):
    """A monitor on the harness's SPI wires: CS setup/hold/idle, SCLK never above the
    request, MOSI set up and held around rising edges, MISO only at falling edges."""
    pins = ("spi_sclk", "spi_mosi", "spi_miso", "imu_cs_n", "baro_cs_n")
    for mode in (0, 3):
        harness = await started(dut, mode)
        await harness.host.load(
            {"imu": mpu.Mpu6000Sample(0x5A5A5, -3, 77, -9, 0x3C3C3, 5, -1).fields()}
        )
        await harness.spi.transfer("imu", bytes([0x6B, 0x01]), sclk_hz=1e6)
        for sclk_hz, device, tx in (
            (1e6, "imu", bytes([0x75 | 0x80, 0])),
            (5e6, "imu", bytes([0x3B | 0x80]) + bytes(14)),
            (20e6, "imu", bytes([0x3B | 0x80]) + bytes(14)),
            (20e6, "baro", bytes([0xA2, 0, 0])),
        ):
            monitor = PinMonitor(dut, pins)
            await harness.spi.transfer(device, tx, sclk_hz=sclk_hz)
            await harness.spi.transfer(device, tx, sclk_hz=sclk_hz)  # back to back
            events = monitor.stop()
            assert check_spi_pins(events, sclk_hz, mode) == 2 * 8 * len(tx)
            assert not int(dut.spi_contention.value)


def check_i2c_pins(events, t, scl_hz: float) -> dict[str, int]:
    """UM10204 table 10 on monitored SCL/SDA; returns counts of STARTs, repeated STARTs
    and STOPs so the caller can check the framing too."""
    ps = 1000  # per ns
    scl = sda = 1
    scl_since = sda_since = 0
    last_scl_rise = last_stop = None
    counts = {"start": 0, "restart": 0, "stop": 0}
    for time, pin, level in events:
        if pin == "i2c_scl":
            if level == 1:
                if scl_since and counts["start"]:
                    assert time - scl_since >= t.t_low_ns * ps, "t_LOW"
                assert time - sda_since >= t.t_su_dat_ns * ps, "t_SU;DAT"
                if last_scl_rise is not None and counts["start"] and not sda_since > last_scl_rise:
                    assert time - last_scl_rise >= 1e12 / scl_hz - 1, "SCL above the rate"
                last_scl_rise = time
            else:
                assert time - scl_since >= (t.t_high_ns if sda else t.t_hd_sta_ns) * ps
            scl, scl_since = level, time
        else:
            if scl:  # SDA moves with SCL high: a START (falling) or a STOP (rising)
                if level == 0:
                    restart = last_stop is None or last_stop < scl_since
                    if last_stop is not None and not restart:
                        assert time - last_stop >= t.t_buf_ns * ps, "t_BUF"
                    key = "restart" if restart and counts["start"] > counts["stop"] else "start"
                    counts[key] += 1
                    if key == "restart":
                        assert time - scl_since >= t.t_su_sta_ns * ps, "t_SU;STA"
                else:
                    assert time - scl_since >= t.t_su_sto_ns * ps, "t_SU;STO"
                    counts["stop"] += 1
                    last_stop = time
            sda, sda_since = level, time
    return counts


@cocotb.test()
async def i2c_pins_meet_um10204_at_100_and_400_khz(dut):
    """A monitor on the harness's I2C wires during PX4's magnetometer transactions."""
    harness = await started(dut)
    await harness.host.load({"mag": {"x": -1, "y": 0x00FF, "z": 0x5555}}, now_us=10)
    for scl_hz, spec in ((100e3, STANDARD_MODE), (400e3, FAST_MODE)):
        monitor = PinMonitor(dut, ("i2c_scl", "i2c_sda"))
        await harness.i2c.write_read(ist.DEFAULT_ADDRESS, bytes([0x02]), 7, scl_hz=scl_hz)
        await harness.i2c.write_read(ist.DEFAULT_ADDRESS, bytes([0x0A, 0x01]), 0, scl_hz=scl_hz)
        counts = check_i2c_pins(monitor.stop(), spec, scl_hz)
        assert counts == {"start": 2, "restart": 1, "stop": 2}, counts


@cocotb.test()
async def i2c_nacks_are_reported_with_the_byte_index(dut):
    harness = await started(dut)
    absent = ist.DEFAULT_ADDRESS ^ 0x01
    with pytest.raises(I2cNack) as absent_nack:
        await harness.i2c.write_read(absent, bytes([0]), 1, scl_hz=400e3)
    assert (absent_nack.value.address, absent_nack.value.byte_index) == (absent, 0)
    await harness.host.load({}, faults={"mag": (True, 0)})
    with pytest.raises(I2cNack) as muted_nack:
        await harness.i2c.write_read(ist.DEFAULT_ADDRESS, bytes([0]), 1, scl_hz=400e3)
    assert muted_nack.value.byte_index == 0
    await harness.host.load({}, faults={"mag": (False, 0)})
    assert await harness.i2c.write_read(ist.DEFAULT_ADDRESS, bytes([0]), 1, scl_hz=400e3) == b"\x10"


@cocotb.test()
async def pwm_capture_through_the_host_port_equals_the_model(dut):
    """The PWM generator drives SensorTop's capture; new widths every period take effect
    at the next one; a channel set to 0 stops and times out. Reads start, as the rig's
    do, on the grid just before a capture tick, at ticks around the moment channel 0's
    fall becomes readable: each must equal the tick-exact model with SensorTop's
    documented result latency, and many land where one tick less or more of latency
    would read otherwise."""
    harness = await started(dut)
    monitor = PinMonitor(dut, ("pwm",))
    tick_s, phase_s = 1 / PWM_TICK_HZ, PWM_PHASE_PS / 1e12
    period_ticks = 2500  # 400 Hz
    steps = [
        ([1000, 1100, 1200, 1300, 0, 0, 0, 0], 12),
        ([1500, 1100, 1900, 1301, 0, 0, 0, 2000], 12),
        ([2000, 0, 1000, 1302, 0, 0, 0, 2000], 50),  # channel 1 stops: 125 ms > timeout
    ]
    plan = [  # widths per period: channels 0 and 3 change every period
        [base[0] + n % 2, *base[1:3], base[3] + n % 3, *base[4:]]
        for base, count in steps
        for n in range(count)
    ]
    models = {
        latency: PwmCaptureModel(
            tick_hz=PWM_TICK_HZ, timeout_s=PWM_TIMEOUT_S, latency_ticks=latency
        )
        for latency in (PWM_RESULT_LATENCY_TICKS - 1, PWM_RESULT_LATENCY_TICKS,
                        PWM_RESULT_LATENCY_TICKS + 1)
    }  # fmt: skip
    scoreboard = Scoreboard("PWM capture vs model")
    harness.pwm.write(plan[0], period_ticks=period_ticks)
    first_tick = cocotb.start_soon(dut.pwm_clk.rising_edge)
    await harness.pwm.run()
    await first_tick
    first_edge_s = get_sim_time("ps") / 1e12
    await harness.wait_until_s(first_edge_s + 10 * tick_s)
    boundary = 0
    for index, widths in enumerate(plan):
        if index + 1 < len(plan):
            harness.pwm.write(plan[index + 1], period_ticks=period_ticks)  # next period's
        rise_s = _pulses(monitor.events)[0][-1][0]  # channel 0's pulse of this period
        # The capture edge that samples channel 0's fall, then a tick around the one at
        # which the fall becomes readable.
        fall_tick = math.ceil((rise_s + widths[0] * tick_s - first_edge_s) / tick_s)
        tick = fall_tick + PWM_RESULT_LATENCY_TICKS + index % 6 - 3
        await harness.wait_until_s(first_edge_s + tick * tick_s - phase_s)
        got = await harness.host.pwm_capture()
        pulses, at_s = _pulses(monitor.events), first_edge_s + tick * tick_s
        expected = {
            latency: [
                model.capture(pulses[ch], at_s=at_s, first_edge_s=first_edge_s) for ch in range(8)
            ]
            for latency, model in models.items()
        }
        scoreboard.check(f"period {index}, tick {tick}", expected[PWM_RESULT_LATENCY_TICKS], got)
        boundary += len({str(e) for e in expected.values()}) > 1
        await harness.wait_until_s(rise_s + (period_ticks + 10) * tick_s)
    final = await harness.host.pwm_capture()
    assert [capture.timeout for capture in final] == [False, True, False, False] + [True] * 3 + [
        False
    ]
    assert (final[0].width_ticks, final[0].period_ticks) == (plan[-1][0], period_ticks)
    assert boundary >= len(plan) // 4, f"only {boundary} of {len(plan)} probes at a change"
    # Preload: a width written mid-period never cuts or stretches the running pulse.
    widths_us = [round((fall - rise) * 1e6) for rise, fall in _pulses(monitor.stop())[0]]
    assert widths_us[: len(plan)] == [widths[0] for widths in plan]
    dut._log.info("%d probes, %d at a change, all equal to the model", len(plan), boundary)


def _pulses(events) -> list[list[tuple[float, float]]]:
    """(rise, fall) per channel from the monitored PWM vector, edges 1 ps after the clock
    edge that made them (the model counts an edge on a clock edge as already there)."""
    previous, rise_at = 0, [None] * 8
    pulses = [[] for _ in range(8)]
    for t, _, value in events:
        for ch in range(8):
            bit = value >> ch & 1
            if bit != (previous >> ch & 1):
                if bit:
                    rise_at[ch] = (t + 1) / 1e12
                else:
                    pulses[ch].append((rise_at[ch], (t + 1) / 1e12))
        previous = value
    for ch in range(8):
        if previous >> ch & 1:  # high now: a pulse still running
            pulses[ch].append((rise_at[ch], 1e9))
    return pulses
