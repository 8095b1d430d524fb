"""Shared pytest fixtures: where the real flight logs are; hypothesis's profiles."""

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

#: Property tests (tests/fuzz): a few dozen inputs each in `make test`, no per-input
#: deadline (a log parse takes tens of ms on a busy machine); `make fuzz` runs them longer.
settings.register_profile(
    "test", max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "test"))

REPO = Path(__file__).resolve().parent.parent
#: Real flight logs carried with the project (MIT, see data/flight_logs/README.md).
FLIGHT_LOGS = REPO / "data" / "flight_logs"
#: Logs not carried here (other licences): $HIL_FLIGHT_LOGS or the workspace's shared folder.
EXTERNAL_FLIGHT_LOGS = Path(
    os.environ.get("HIL_FLIGHT_LOGS", REPO.parent / "shared" / "flight_logs")
)


@pytest.fixture
def x500_log() -> Path:
    """Holybro X500 V2 outdoor flight (airframe 4019): hover, mission, manoeuvres, land."""
    return FLIGHT_LOGS / "px4_x500v2_v6xrt_flight_2026-03-20.ulg"


@pytest.fixture
def quad4001_log() -> Path:
    """Generic quad X (airframe 4001), Stabilized hover, motors-stopped noise floor first."""
    return FLIGHT_LOGS / "px4_quad4001_v6c_stab_hover_2026-03-09.ulg"


@pytest.fixture
def auriol_log() -> Path:
    """The GPL-licensed X8 high-rate log; the test skips when it is not on this machine."""
    path = EXTERNAL_FLIGHT_LOGS / "px4_octoX8_auriol_v6xrt_highrate_groundrun_2024-10-29.ulg"
    if not path.is_file():
        pytest.skip(f"external flight log not found: {path}")
    return path
