"""Files a user hands the rig: flight logs (cut short, corrupted, reordered) and TOML
configuration of every kind (any keys, any value types, raw text). Each is read, or
refused with one line that names the problem; nothing else may escape."""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from credibility.errors import CredibilityError
from credibility.logs import open_log
from credibility.plan import load_plan
from px4_logs import FlightLog, LogError
from quad_model.vehicle import VehicleFileError, load_vehicle
from rig.campaign import load_campaign
from rig.errors import RigError
from rig.identify import identify_vehicle
from rig.replay import plan_replay
from rig.scenarios.scenario import load_scenario
from tests.fuzz.inputs import SEED_TOPICS, damaged_logs, one_line, seed_log, toml_documents

#: Each kind of configuration file: its loader, and the one error it may raise.
LOADERS = {
    "scenario": load_scenario,
    "vehicle": load_vehicle,
    "campaign": load_campaign,
    "plan": load_plan,
}
REFUSALS = (RigError, CredibilityError, VehicleFileError, LogError)


@functools.cache
def _x500():
    return load_vehicle("x500_v2")


def test_the_undamaged_seed_is_read_and_planned(tmp_path):
    """The damage starts from a log every reader accepts, so the fuzz reaches past the header."""
    path = tmp_path / "flight.ulg"
    path.write_bytes(seed_log())
    assert {name for name, _ in open_log(path).topics} == set(SEED_TOPICS)
    assert plan_replay(path).drive == "velocity"


@given(damaged_logs())
def test_a_damaged_flight_log_is_read_or_refused_in_one_line(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "flight.ulg"
        path.write_bytes(data)
        for read in (open_log, plan_replay, lambda p: identify_vehicle(FlightLog.read(p), _x500())):
            try:
                read(path)
            except REFUSALS as error:
                one_line(error)


@given(st.sampled_from(sorted(LOADERS)), toml_documents())
def test_any_configuration_file_is_loaded_or_refused_in_one_line(kind: str, text: str) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"{kind}.toml"
        path.write_text(text, encoding="utf-8")
        try:
            LOADERS[kind](path)
        except REFUSALS as error:
            one_line(error)


def test_a_topic_whose_definition_lost_its_timestamp_is_refused_in_one_line(tmp_path):
    """Found by `make fuzz`: a flipped bit in a format message renamed a topic's
    'timestamp' field, and every reader failed with a KeyError traceback."""
    data = seed_log()
    at = data.index(b"vehicle_land_detected:uint64_t timestamp;")
    path = tmp_path / "flight.ulg"
    path.write_bytes(data[:at] + data[at:].replace(b"timestamp;", b"timestamq;", 1))
    for read in (open_log, plan_replay, lambda p: identify_vehicle(FlightLog.read(p), _x500())):
        with pytest.raises(REFUSALS) as refusal:
            read(path)
        one_line(refusal.value)


@pytest.mark.parametrize("field", ["armed_time", "arming_state", "nav_state"])
def test_vehicle_status_without_an_arming_or_mode_field_is_read_or_refused(tmp_path, field):
    """Found by the fuzz above: a flipped byte renamed ``vehicle_status.armed_time`` and
    the replay planner failed with a KeyError. Without ``armed_time`` the arm is the first
    armed sample's time, and the reference autopilot's replay needs no mode; without the
    arming state there are no arming times: one line."""
    data = seed_log()
    at = data.index(b"vehicle_status:")
    renamed = data[at:].replace(f" {field};".encode(), f" {field[:-1]}_;".encode(), 1)
    path = tmp_path / "flight.ulg"
    path.write_bytes(data[:at] + renamed)
    if field != "arming_state":
        assert plan_replay(path).drive == "velocity"
        return
    with pytest.raises(REFUSALS) as refusal:
        plan_replay(path)
    assert str(refusal.value).startswith(f"{path}: topic vehicle_status has no field {field} (")
    one_line(refusal.value)
