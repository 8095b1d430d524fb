"""A scenario flown for a test: the known-answer flights the identification, the vehicle
file and the study are checked against."""

from pathlib import Path
from typing import Any

from rig.lockstep.loop import RunOptions, RunResult, run_scenario
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import Scenario, scenario_from_dict
from tests.instances import free_test_instance


def fly(scenario: dict[str, Any] | Scenario, out_dir: Path, **run_options: Any) -> RunResult:
    """Fly ``scenario`` (loaded, or a scenario file's keys) on a free instance into
    ``out_dir``, with the reference autopilot unless ``run_options`` say otherwise; the link's
    timeouts are wide, for a test machine loaded by the other tests."""
    options = RunOptions(instance=free_test_instance(), out_dir=out_dir,
                         timeouts=LinkTimeouts(connect_s=60, answer_s=30),
                         **run_options)  # fmt: skip
    if isinstance(scenario, dict):
        scenario = scenario_from_dict(scenario)
    return run_scenario(scenario, options)
