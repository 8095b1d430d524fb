"""``rig schema``: the JSON Schema of every configuration file, for editors.

TOML maps onto JSON one to one, so a TOML editor that reads JSON Schema (Taplo, "Even Better
TOML" in VS Code) completes and checks a file that starts with a ``#:schema PATH`` line
pointing at one of these. The schemas come from the very tables the loaders check
(:mod:`hil_config`), so an editor and ``rig`` never disagree.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rich.console import Console

from credibility.plan import PlanFile
from hil_config import json_schema
from quad_model.vehicle import Vehicle
from rig.campaign.schema import CampaignFile
from rig.cli.command import Command
from rig.errors import RigError
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


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out", type=Path, default=Path("schemas"), help="folder (default schemas/)"
    )


def _schema(args: argparse.Namespace, console: Console) -> int:
    try:
        written = write_schemas(args.out)
    except OSError as error:
        raise RigError(f"{args.out}: cannot write the schemas ({error.strerror})") from None
    for path in written:
        console.print(str(path), highlight=False)
    return 0


COMMAND = Command(
    "schema",
    "write the JSON Schema of each configuration file (for TOML editors)",
    "Write <kind>.schema.json for the scenario, vehicle, campaign and plan files; a TOML file "
    "starting with '#:schema PATH' is then checked by its editor.",
    _add_arguments,
    _schema,
)
