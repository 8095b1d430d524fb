"""Every TOML the project ships is checked by its loader and by the JSON Schema that
``rig schema`` writes for editors, so the two never disagree on a shipped file."""

import json
import subprocess
import tomllib
from pathlib import Path

import jsonschema
import pytest

from credibility.plan import load_plan
from quad_model.vehicle import load_vehicle
from rig.campaign import load_campaign
from rig.cli.schema import FILE_KINDS, write_schemas
from rig.scenarios.scenario import load_scenario

ROOT = Path(__file__).parents[1]
#: Where each kind of configuration file lives, and its loader.
HOMES = {
    "scenario": ("rig/scenarios", load_scenario),
    "vehicle": ("quad_model/vehicles", load_vehicle),
    "campaign": ("rig/campaign/campaigns", load_campaign),
    "plan": ("credibility/plans", load_plan),
}
EXTRA_PLANS = ("rig/campaign/campaigns/plans",)


def _shipped() -> list[tuple[str, Path]]:
    tracked = subprocess.run(
        ["git", "ls-files", "*.toml"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    files = []
    for name in tracked:
        if name == "pyproject.toml":
            continue
        folder = str(Path(name).parent)
        kind = next((k for k, (home, _) in HOMES.items() if folder == home), None)
        files.append(("plan" if folder in EXTRA_PLANS else kind, ROOT / name))
    return files


SHIPPED = _shipped()


def test_every_shipped_toml_has_a_known_kind():
    assert [str(path) for kind, path in SHIPPED if kind is None] == []
    assert {kind for kind, _ in SHIPPED} == set(FILE_KINDS)


@pytest.fixture(scope="module")
def schemas(tmp_path_factory):
    folder = tmp_path_factory.mktemp("schemas")
    return {
        path.name.removesuffix(".schema.json"): json.loads(path.read_text())
        for path in write_schemas(folder)
    }


@pytest.mark.parametrize(("kind", "path"), SHIPPED, ids=[p.name for _, p in SHIPPED])
def test_a_shipped_file_loads_and_meets_its_json_schema(schemas, kind, path):
    HOMES[kind][1](path)
    jsonschema.validate(tomllib.loads(path.read_text("utf-8")), schemas[kind])


def test_the_json_schema_refuses_what_the_loader_refuses(schemas):
    """An editor flags the same mistakes: a misspelt key, a wrong enum, a bad bound."""
    scenario = tomllib.loads((ROOT / "rig/scenarios/level_step.toml").read_text("utf-8"))
    for change in ({"sensorlayer": "rtl"}, {"sensor_layer": "fpga"}, {"duration_s": -1.0},
                   {"commands": [{"at_s": 1.0, "action": "takeoff"}]}):  # fmt: skip
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(scenario | change, schemas["scenario"])


def test_rig_schema_writes_the_files_and_an_unwritable_folder_is_one_line(tmp_path, capsys):
    from rig.cli import main

    assert main(["schema", "--out", str(tmp_path / "schemas")]) == 0
    assert sorted(p.name for p in (tmp_path / "schemas").iterdir()) == sorted(
        f"{kind}.schema.json" for kind in FILE_KINDS
    )
    capsys.readouterr()  # the written paths
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert main(["schema", "--out", str(blocker / "schemas")]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"rig: error: {blocker / 'schemas'}: cannot write the schemas (")
    assert err.count("\n") == 1
