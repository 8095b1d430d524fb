"""TOML files named by a bundled name or by a path, read with one-line errors.

Vehicle sets and rig scenarios are both found this way (``"x500_v2"`` or
``path/to/file.toml``); the rig imports this from here because quad_model cannot
import the rig.
"""

import tomllib
from pathlib import Path
from typing import Any


def read_toml_file(
    name_or_path: str | Path,
    bundled_dir: Path,
    *,
    kind: str,
    error: type[Exception],
    invalid_toml: str = "not valid TOML",
) -> tuple[dict[str, Any], Path]:
    """Parse a bundled file by name or any ``.toml`` path; return the document and its path.

    Every failure raises ``error`` with one line that starts with the path: a missing
    file lists the bundled ``kind`` files; ``invalid_toml`` words a parse error (callers
    keep the wording their users already see).
    """
    path = Path(name_or_path)
    if path.suffix != ".toml":
        path = bundled_dir / f"{name_or_path}.toml"
    try:
        return tomllib.loads(path.read_text(encoding="utf-8")), path
    except FileNotFoundError:
        bundled = ", ".join(sorted(p.stem for p in bundled_dir.glob("*.toml")))
        raise error(f"{path}: no such {kind} file (bundled: {bundled})") from None
    except (OSError, UnicodeDecodeError) as reason:
        raise error(f"{path}: cannot read ({reason})") from None
    except tomllib.TOMLDecodeError as reason:
        raise error(f"{path}: {invalid_toml} ({reason})") from None
