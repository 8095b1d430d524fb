"""Simulation-credibility indices of Dai et al. computed from logs, with plots and reports.

Typical use is the ``credibility`` command; from Python::

    plan = load_plan("credibility/plans/quad4001_repeatability.toml")
    assessment = assess(plan)
    write_report(assessment, Path("out"))
"""

from credibility.assess import Assessment, assess
from credibility.errors import CredibilityError
from credibility.logs import SignalSpec, open_log
from credibility.paper import paper_comparison
from credibility.plan import Plan, load_plan
from credibility.report import to_dict, write_report
from credibility.spectral import FrequencyResponseEstimate, estimate_response

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
