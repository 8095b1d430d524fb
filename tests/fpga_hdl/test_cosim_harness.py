"""The fast path on generated Verilog, on every simulator: the harness's peripherals
against the TLM and the pin-level masters, bus timing, PWM capture through the host port."""

import asyncio
import json
from pathlib import Path

import pytest

from fpga_hdl.cosim.harness import GATED_CLOCK_VERILOG, HARNESS_TOPLEVEL, CosimHarness
from fpga_hdl.cosim.runner import SIMULATOR_PARAMS, run_cocotb
from fpga_hdl.top import SensorTop
from fpga_hdl.verification.scoreboard import Scoreboard
from tests.fpga_hdl.transcript import tlm_transcript

HERE = Path(__file__).parent


@pytest.mark.parametrize("simulator", SIMULATOR_PARAMS)
def test_fast_path_equals_pin_level_and_tlm(simulator, tmp_path):
    fast_out, pins_out = tmp_path / "fast.json", tmp_path / "pins.json"
    run_cocotb(
        CosimHarness(),
        HARNESS_TOPLEVEL,
        "cocotb_harness",
        module_dir=HERE,
        simulator=simulator,
        extra_env={"TRANSCRIPT_OUT": str(fast_out)},
        extra_verilog={"cosim_gated_clock": GATED_CLOCK_VERILOG},
    )
    run_cocotb(
        SensorTop(),
        "sensor_top",
        "cocotb_transcript_pins",
        module_dir=HERE,
        simulator=simulator,
        extra_env={"TRANSCRIPT_OUT": str(pins_out)},
    )
    tlm = json.loads(json.dumps(asyncio.run(tlm_transcript())))
    fast, pins = json.loads(fast_out.read_text()), json.loads(pins_out.read_text())
    assert len(tlm) == 50
    Scoreboard("fast path vs TLM").check_transcript(tlm, fast)
    Scoreboard("pin-level masters vs TLM").check_transcript(tlm, pins)
