"""``rig schema``: the JSON Schema of every configuration file, for editors.

TOML maps onto JSON one to one, so a TOML editor that reads JSON Schema (Taplo, "Even Better
TOML" in VS Code) completes and checks a file that starts with a ``#:schema PATH`` line
pointing at one of these. The schemas come from the very tables the loaders check
(:mod:`hil_config`), so an editor and ``rig`` never disagree.
"""

from __future__ import annotations

import json
from pathlib import Path

from credibility.plan import PlanFile
from hil_config import json_schema
from quad_model.vehicle import Vehicle
from rig.apps.campaign import CampaignFile
from rig.scenarios.scenario import Scenario

#: Each configuration file's kind → its top table.
FILE_KINDS: dict[str, type] = {
    "scenario": Scenario,
    "vehicle": Vehicle,
    "campaign": CampaignFile,
    "plan": PlanFile,
}


def write_schemas(out_dir: Path) -> list[Path]:
    """Write ``<kind>.schema.json`` for every kind of configuration file into ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for kind, schema in FILE_KINDS.items():
        document = {
            "$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": f"hil-rig {kind} file",
            **json_schema(schema),
        }
        path = out_dir / f"{kind}.schema.json"
        path.write_text(json.dumps(document, indent=2, ensure_ascii=False) + "\n", "utf-8")
        written.append(path)
    return written
