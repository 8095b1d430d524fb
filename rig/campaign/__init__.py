"""Campaigns: a base scenario swept over axes, every case a real rig run, results in SQLite.

A campaign file (TOML) names a base scenario, the axes to sweep (fault × onset × severity,
wind, mass and inertia, motor constants, IMU noise, seeds, autopilot parameters), the
pass criteria and the run settings. :func:`expand` turns it into the Cartesian product of
cases; :func:`run_campaign` runs them on any ``concurrent.futures.Executor`` (a local
process pool, or Dask's ``Client.get_executor()``) and commits one row per case to
``results.sqlite`` as each finishes, so a rerun skips what is done and Ctrl-C never
leaves a half-written row.

Each case runs in its own ``python -m rig.campaign.case`` process (its own ports, its own
autopilot) under a wall-clock timeout, so a crash or a hang costs that case only: it is
recorded with its reason and the campaign goes on. The case folder holds the scenario
and vehicle files it flew (``rig run CASE/scenario.toml`` replays it) and its logs.
"""

from rig.campaign.executor import campaign_executor, run_campaign
from rig.campaign.expansion import campaign_from_dict, expand, load_campaign
from rig.campaign.report import write_report
from rig.campaign.results import read_provenance, read_results
from rig.campaign.schema import Campaign, CampaignError, Criterion

__all__ = [
    "Campaign",
    "CampaignError",
    "Criterion",
    "campaign_executor",
    "campaign_from_dict",
    "expand",
    "load_campaign",
    "read_provenance",
    "read_results",
    "run_campaign",
    "write_report",
]
