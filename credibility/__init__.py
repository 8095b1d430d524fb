"""Simulation-credibility indices of Dai et al. computed from logs, with plots and reports.

Typical use is the ``credibility`` command; from Python::

    plan = load_plan("credibility/plans/quad4001_repeatability.toml")
    assessment = assess(plan)
    write_report(assessment, Path("out"))

The names below load their modules on first use (PEP 562): the signal processing brings
scipy.signal and python-control (which loads matplotlib's pyplot), about 4 s, which a
process that only needs ``CredibilityError`` or a plan (``rig --help``, a campaign case)
should not pay. A hand-written table rather than a lazy-import library: ten names.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from credibility.assess import Assessment, assess
    from credibility.errors import CredibilityError
    from credibility.logs import SignalSpec, open_log
    from credibility.paper import paper_comparison
    from credibility.plan import Plan, load_plan
    from credibility.report import to_dict, write_report
    from credibility.spectral import FrequencyResponseEstimate, estimate_response

#: Each public name's module.
_HOMES = {
    "Assessment": "assess",
    "assess": "assess",
    "CredibilityError": "errors",
    "SignalSpec": "logs",
    "open_log": "logs",
    "paper_comparison": "paper",
    "Plan": "plan",
    "load_plan": "plan",
    "to_dict": "report",
    "write_report": "report",
    "FrequencyResponseEstimate": "spectral",
    "estimate_response": "spectral",
}

__all__ = [
    "Assessment",
    "CredibilityError",
    "FrequencyResponseEstimate",
    "Plan",
    "SignalSpec",
    "assess",
    "estimate_response",
    "load_plan",
    "open_log",
    "paper_comparison",
    "to_dict",
    "write_report",
]


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'credibility' has no attribute {name!r}")
    return getattr(importlib.import_module(f"credibility.{home}"), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *_HOMES])
