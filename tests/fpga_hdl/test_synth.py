# amaranth: UnusedElaboratable=no
"""SensorTop still elaborates and synthesizes for the ECP5 (issue 18): the whole top and each
core alone through Yosys's ``synth_ecp5``, without place and route (that is ``make synth``);
and the verdict on a nextpnr report, on made-up reports."""

import pytest

from fpga_hdl.chips.ist8310 import regs as ist8310_regs
from fpga_hdl.chips.lidarlite import regs as lidarlite_regs
from fpga_hdl.chips.mpu6000 import regs as mpu6000_regs
from fpga_hdl.chips.ms5611 import regs as ms5611_regs
from fpga_hdl.chips.pmw3901 import regs as pmw3901_regs
from fpga_hdl.chips.pwm_capture.core import CHANNELS
from fpga_hdl.chips.ublox import ubx
from fpga_hdl.synth import (
    CORES,
    ECP5_85F,
    TOP_NAME,
    SynthesisError,
    clock_requirements,
    clock_results,
    crossing_budgets,
    crossing_results,
    ecp5_resources,
    over_capacity,
    synth_ecp5,
    timing_failures,
    xc7_resources,
)
from fpga_hdl.top import SensorTop


@pytest.fixture(scope="module")
def synthesized(tmp_path_factory) -> tuple[SensorTop, dict[str, dict[str, int]]]:
    """The top, and the ECP5 resources of the whole top and of each of its cores alone."""
    workdir = tmp_path_factory.mktemp("synth")
    top = SensorTop()
    used = {TOP_NAME: ecp5_resources(synth_ecp5(top, TOP_NAME, workdir))}
    for core in CORES:
        used[core] = ecp5_resources(synth_ecp5(getattr(top, core), core, workdir))
    return top, used


def state_bits(top: SensorTop) -> dict[str, int]:
    """Bits each core must hold in flip-flops, a floor for its count: the chips' visible
    samples (the GPS receiver's fix), the capture's three counters per channel, the host
    port's staged words."""
    return {
        "imu": mpu6000_regs.SAMPLE_LAYOUT.size,
        "baro": ms5611_regs.SAMPLE_LAYOUT.size,
        "mag": ist8310_regs.SAMPLE_LAYOUT.size,
        "gps": ubx.SAMPLE_LAYOUT.size,
        "range": lidarlite_regs.SAMPLE_LAYOUT.size,
        "flow": pmw3901_regs.SAMPLE_LAYOUT.size,
        "capture": 3 * CHANNELS * top.capture.counter_bits,
        "host": sum(word.width for word in top.host.map.writes),
    }


@pytest.mark.synth
def test_the_whole_top_fits_the_ecp5_85f(synthesized):
    _, used = synthesized
    assert used[TOP_NAME]["LUT4"] > 0
    assert used[TOP_NAME]["FF"] > 0
    assert over_capacity(used[TOP_NAME], ECP5_85F) == []
    # Every core is inside, with the PWM results' crossing on top.
    assert used[TOP_NAME]["FF"] >= sum(used[core]["FF"] for core in CORES)


@pytest.mark.synth
@pytest.mark.parametrize("core", CORES)
def test_each_core_synthesizes_to_plausible_logic(synthesized, core):
    top, used = synthesized
    floor = state_bits(top)[core]
    assert floor <= used[core]["FF"] < 10 * floor
    assert 0 < used[core]["LUT4"] < ECP5_85F["LUT4"] // 10
    assert used[core]["DP16KD"] == used[core]["MULT18X18D"] == 0  # no memories, multipliers


def report(fmax: dict[str, float], paths: list[tuple[str, str, float]]) -> dict:
    """A nextpnr report as ``--report`` writes it, with only the keys the verdict reads."""

    def end(name: str) -> str:
        edge, _, port = name.partition(" ")
        return f"{edge} $glbnet${port}$TRELLIS_IO_IN" if port else name

    return {
        "fmax": {f"$glbnet${p}$TRELLIS_IO_IN": {"achieved": f} for p, f in fmax.items()},
        "critical_paths": [
            {"from": end(a), "to": end(b), "path": [{"delay": d / 2}, {"delay": d / 2}]}
            for a, b, d in paths
        ],
    }


def test_a_slow_clock_and_a_late_crossing_are_named():
    clocks, budgets = clock_requirements(), crossing_budgets()
    sample_budget = next(b for b in budgets if b.target == "negedge spi_sclk").budget_ns
    gps_budget = next(b for b in budgets if b.target == "posedge uart_clk").budget_ns
    assert gps_budget == pytest.approx(2 / 3.6864e6 * 1e9)  # two UART periods: 542.5 ns
    made_up = report(
        {"clk": 50.0, "pwm_clk": 50.0, "uart_clk": 3.5, "spi_sclk": 19.5},
        [
            ("posedge spi_sclk", "negedge spi_sclk", 20.0),  # inside the spi clock's Fmax
            ("posedge clk", "negedge spi_sclk", sample_budget + 1),
            ("posedge pwm_clk", "posedge clk", 2.0),
            ("posedge clk", "posedge uart_clk", gps_budget + 1),
            ("<async>", "posedge clk", 1e3),  # a pin: no budget, never a failure
        ],
    )
    crossings = crossing_results(made_up, budgets)
    assert [(x.source, x.target) for x in crossings] == [
        ("posedge clk", "negedge spi_sclk"),
        ("posedge pwm_clk", "posedge clk"),
        ("posedge clk", "posedge uart_clk"),
        ("<async>", "posedge clk"),
    ]
    failures = timing_failures(clock_results(made_up, clocks), crossings)
    assert len(failures) == 4
    assert failures[0].startswith("uart_clk (uart) reaches 3.5 MHz of 3.6864 MHz")
    assert failures[1].startswith("spi_sclk (spi) reaches 19.5 MHz of 20 MHz")
    assert failures[2].startswith("posedge clk → negedge spi_sclk takes")
    assert failures[3].startswith("posedge clk → posedge uart_clk takes")


def test_a_clock_nextpnr_did_not_time_is_an_error():
    clocks = clock_requirements()
    with pytest.raises(SynthesisError, match="pwm_clk"):
        clock_results(report({"clk": 50.0, "uart_clk": 50.0, "spi_sclk": 50.0}, []), clocks)


def test_xilinx_cells_count_as_device_resources():
    cells = {"LUT2": 3, "LUT6": 4, "SRL16E": 1, "MUXF7": 5, "CARRY4": 2}
    cells |= {"FDRE": 10, "FDCE_1": 2, "RAMB18E1": 3, "RAMB36E1": 1, "DSP48E1": 2, "BUFG": 3}
    assert xc7_resources(cells) == {"LUT": 8, "FF": 12, "RAMB36": 3, "DSP48E1": 2}
