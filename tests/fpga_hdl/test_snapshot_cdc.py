# amaranth: UnusedElaboratable=no
"""amaranth.sim tests of the PWM results' path into ``sync``: the snapshot synchroniser
alone (whole values, their age, a stopped destination clock), and SensorTop's result
words as the harness's reader takes them (one result set per read, of a known age); the
sample synchroniser that carries the GPS fix and its strobe into the slower ``uart``."""

import numpy as np
import pytest
from amaranth.hdl import ClockDomain, ClockSignal, Module, Signal
from amaranth.sim import Simulator

from fpga_hdl.chips.pwm_capture.core import CHANNELS
from fpga_hdl.cosim.harness import HostReader
from fpga_hdl.host.snapshot_cdc import (
    COUNT_BITS,
    PUBLISH_TICKS,
    SampleSynchronizer,
    SnapshotSynchronizer,
)
from fpga_hdl.top import PWM_RESULT_COPY_CYCLES, SensorTop

SYS_CLK_HZ = 10e6


def _source_and_destination(width: int = 24):
    m = Module()
    m.domains.src = src = ClockDomain()
    m.domains.dst = dst = ClockDomain()
    m.submodules.cdc = cdc = SnapshotSynchronizer(width, i_domain="src", o_domain="dst")
    return m, cdc, src, dst


def test_whole_values_only_at_coprime_clock_rates():
    """A 24-bit value changing every 37 source cycles (two halves that always differ);
    the destination at a coprime rate must only ever show whole values, and all of them."""
    m, cdc, _, _ = _source_and_destination()
    sim = Simulator(m)
    sim.add_clock(1 / SYS_CLK_HZ, domain="dst")
    sim.add_clock(1 / 1.3e6, domain="src")
    seen = set()

    async def source(ctx):
        for k in range(1, 40):
            ctx.set(cdc.data_i, k << 12 | (0xFFF - k))
            await ctx.tick("src").repeat(37)

    async def sink(ctx):
        for _ in range(11_500):  # 1.15 ms: past the source's last change
            await ctx.tick("dst")
            seen.add(ctx.get(cdc.data_o))

    sim.add_testbench(source)
    sim.add_testbench(sink)
    sim.run()
    values = {k << 12 | (0xFFF - k) for k in range(1, 40)}
    assert seen - {0} <= values
    assert len(seen & values) == len(values)


def test_a_change_reaches_the_destination_after_the_documented_edges():
    """Source edge ``e`` takes a new value; it is published at ``e + PUBLISH_TICKS`` and
    in ``data_o`` after exactly ``copy_cycles`` destination edges that follow (clocks
    driven by hand, so the order of every edge is known)."""
    m, cdc, src, dst = _source_and_destination()
    history = []

    async def bench(ctx):
        async def edge(clk):
            ctx.set(clk, 1)
            await ctx.delay(1e-9)
            ctx.set(clk, 0)
            await ctx.delay(1e-9)

        ctx.set(cdc.data_i, 0xABCDEF)
        for _ in range(PUBLISH_TICKS):
            await edge(src.clk)
        for _ in range(cdc.copy_cycles):
            history.append(ctx.get(cdc.data_o))
            await edge(dst.clk)
        history.append(ctx.get(cdc.data_o))

    sim = Simulator(m)
    sim.add_testbench(bench)
    sim.run()
    assert cdc.copy_cycles == 3
    assert history == [0] * cdc.copy_cycles + [0xABCDEF]


@pytest.mark.parametrize("changes", [7, 8, 9, 64, 1001, 2**COUNT_BITS - 1])
def test_changes_while_the_destination_clock_is_stopped_arrive_when_it_runs(changes):
    """The gated simulation clock stops the destination between host reads. However many
    changes the source makes meanwhile (a 3-bit count aliased at 8, the bug this fixed;
    the documented limit is 2**COUNT_BITS - 1), the destination first shows the value it
    copied before the stop and, ``copy_cycles`` edges after restarting, the latest."""
    m, cdc, _, dst = _source_and_destination(32)
    sim = Simulator(m)
    sim.add_clock(1e-6, domain="src")
    shown = []

    def value(k):  # halves that always differ: a mixed value would not be one of these
        return (k & 0xFFFF) << 16 | (0xFFFF - (k & 0xFFFF))

    async def bench(ctx):
        async def dst_edges(count):
            for _ in range(count):
                ctx.set(dst.clk, 1)
                await ctx.delay(0.1e-6)
                ctx.set(dst.clk, 0)
                await ctx.delay(0.1e-6)
                shown.append(ctx.get(cdc.data_o))

        ctx.set(cdc.data_i, value(1))
        await ctx.tick("src").repeat(2)
        await dst_edges(4)  # copied value(1); the destination clock then stops
        for k in range(2, changes + 2):
            ctx.set(cdc.data_i, value(k))
            await ctx.tick("src")
        await ctx.tick("src").repeat(2)  # the last change published
        shown.clear()
        await dst_edges(cdc.copy_cycles + 2)

    sim.add_testbench(bench)
    sim.run()
    latest = value(changes + 1)
    assert shown == [value(1)] * (cdc.copy_cycles - 1) + [latest] * 3


def test_a_strobed_sample_crosses_once_per_strobe_into_a_slower_domain():
    """The GPS fix's crossing: the source (16 MHz) strobes a value, the destination runs at
    the UART clock's 3.6864 MHz. Each strobe gives exactly one ``stb_o`` with the value in
    ``data_o`` (an equal value too: an epoch is the strobe), ``copy_cycles`` destination
    edges after the strobe's source edge; three strobes while the destination stands still
    give one, with the latest."""
    m = Module()
    m.domains.src = ClockDomain()
    m.domains.dst = dst = ClockDomain()
    m.submodules.cdc = cdc = SampleSynchronizer(24, i_domain="src", o_domain="dst")
    sim = Simulator(m)
    sim.add_clock(1 / 16e6, domain="src")
    got = []  # (destination edges since the strobe, data_o) at each stb_o

    async def bench(ctx):
        async def dst_edges(count, since):
            for k in range(1, count + 1):
                ctx.set(dst.clk, 1)
                await ctx.delay(0.5 / 3.6864e6)
                ctx.set(dst.clk, 0)
                await ctx.delay(0.5 / 3.6864e6)
                if ctx.get(cdc.stb_o):
                    got.append((k - since, ctx.get(cdc.data_o)))

        async def strobe(value):
            ctx.set(cdc.data_i, value)
            ctx.set(cdc.stb_i, 1)
            await ctx.tick("src")
            ctx.set(cdc.stb_i, 0)

        for value in (0x123456, 0x123456, 0xABCDEF):
            await strobe(value)
            await dst_edges(8, 0)
        for value in (1, 2, 3):  # the destination clock stands still
            await strobe(value)
            await ctx.tick("src").repeat(5)
        await dst_edges(8, 0)

    sim.add_testbench(bench)
    sim.run()
    assert cdc.copy_cycles == 3
    # stb_o is registered with the copy: high after edge copy_cycles, seen at the next one.
    expected_edge = cdc.copy_cycles
    assert got == [(expected_edge, v) for v in (0x123456, 0x123456, 0xABCDEF, 3)]


def _read_words(reader: HostReader, words) -> tuple[tuple[int, ...], tuple[int, ...], int]:
    """(widths, periods, timeout flags) from the reader's words (``top.HOST_MAP`` order)."""
    return tuple(words[:CHANNELS]), tuple(words[CHANNELS : 2 * CHANNELS]), words[2 * CHANNELS]


def test_every_host_read_is_one_result_set_of_the_documented_age():
    """SensorTop with the harness's reader, both clocks free-running at an irrational-like
    ratio (no two edges coincide), eight channels of random short pulses so the results
    change at nearly every tick, reads back to back. Each read must equal the core's
    results after one tick edge, exactly: the one before the last tick edge that came
    before the system edge ``PWM_RESULT_COPY_CYCLES`` edges ahead of the latch (publication,
    two synchroniser flip-flops, copy). A read that mixed two sets, or read them a cycle
    early or late, would differ."""
    rng = np.random.default_rng(17)
    tick_hz = SYS_CLK_HZ / 4.3  # the harness allows down to 4 system cycles per tick
    m = Module()
    m.submodules.top = top = SensorTop(sys_clk_hz=SYS_CLK_HZ, pwm_tick_hz=tick_hz)
    m.submodules.reader = reader = HostReader(top.host.map)
    m.domains.sync = ClockDomain()
    m.domains.tick = ClockDomain()
    ticks = Signal(32)  # capture clock edges so far, seen from sync
    m.d.tick += ticks.eq(ticks + 1)
    m.d.comb += [
        top.pwm_clk.eq(ClockSignal("tick")),
        top.read_latch.eq(reader.read_latch),
        top.read_addr.eq(reader.read_addr),
        reader.read_data.eq(top.read_data),
    ]
    capture = top.capture
    sim = Simulator(m)
    sim.add_clock(1 / SYS_CLK_HZ)
    sim.add_clock(1 / tick_hz, domain="tick", phase=0.25 / SYS_CLK_HZ)
    core_sets = {}  # tick edges so far -> the core's results after the last of them
    ticks_at_sync_edge = []  # per system edge: tick edges before it
    latch_edges, reads = [], []

    async def pulses(ctx):
        next_rise = [int(t) for t in rng.integers(1, 13, CHANNELS)]
        fall, levels = [0] * CHANNELS, 0
        for tick in range(1, 4000):
            for ch in range(CHANNELS):
                if tick == next_rise[ch]:
                    period = int(rng.integers(5, 13))
                    fall[ch], next_rise[ch] = tick + int(rng.integers(1, period)), tick + period
                    levels |= 1 << ch
                elif tick == fall[ch]:
                    levels &= ~(1 << ch)
            ctx.set(top.pwm, levels)
            await ctx.tick("tick")
            core_sets[ctx.get(ticks)] = (
                tuple(int(w) for w in ctx.get(capture.width_ticks)),
                tuple(int(p) for p in ctx.get(capture.period_ticks)),
                int(ctx.get(capture.timeout)),
            )

    async def sync_edges(ctx):
        while True:
            await ctx.tick()
            ticks_at_sync_edge.append(ctx.get(ticks))
            if ctx.get(reader.read_latch):  # sampled at the next system edge
                latch_edges.append(len(ticks_at_sync_edge) + 1)

    async def host(ctx):
        await ctx.tick().repeat(40)
        for _ in range(60):
            ctx.set(reader.request, 1 - ctx.get(reader.request))
            await ctx.tick().until(reader.acknowledge == reader.request)
            reads.append(_read_words(reader, [int(w) for w in ctx.get(reader.words)]))
            await ctx.tick().repeat(int(rng.integers(1, 10)))

    sim.add_testbench(pulses, background=True)
    sim.add_testbench(sync_edges, background=True)
    sim.add_testbench(host)
    sim.run()

    assert len(reads) == len(latch_edges) == 60
    changed_during_read = 0
    for latch, read in zip(latch_edges, reads, strict=True):
        # System edges are numbered from 1; the latch is edge `latch`.
        published = ticks_at_sync_edge[latch - 1 - PWM_RESULT_COPY_CYCLES]
        assert read == core_sets[published - PUBLISH_TICKS], f"read latched at edge {latch}"
        words_read = latch + len(top.host.map.reads)
        changed_during_read += core_sets[ticks_at_sync_edge[words_read]] != read
    assert changed_during_read >= 30  # most reads overlapped result changes
