"""Fixtures of the rig tests: a free SITL instance and the test-double autopilot process."""

import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from rig.autopilots.px4 import Px4Build, find_px4
from rig.errors import AutopilotNotConnected
from rig.mavlink.px4_api import Ports
from rig.mavlink.simulator_link import LinkTimeouts, SimulatorLink
from tests.instances import free_test_instance, worker_instances
from tests.rig.px4_flights import NO_PX4, every_build

DOUBLE = Path(__file__).with_name("autopilot_double.py")
#: Short bounds so a broken test fails in seconds, not minutes.
TEST_TIMEOUTS = LinkTimeouts(connect_s=10, answer_s=2)
#: The links of these tests carry a quad's four motors.
QUAD_MOTORS = 4


@pytest.fixture
def listening_link() -> Iterator[Callable[..., SimulatorLink]]:
    """Open a SimulatorLink on the first free instance of this worker's 60..99 (other
    suites use low ones)."""
    links: list[SimulatorLink] = []

    def open_link(timeouts: LinkTimeouts = TEST_TIMEOUTS, motors: int = QUAD_MOTORS, **kw):
        instances = worker_instances(60, 40)
        for instance in instances:
            try:
                link = SimulatorLink(Ports(instance), timeouts, motors=motors, **kw)
            except AutopilotNotConnected:
                continue
            links.append(link)
            return link
        raise RuntimeError(f"no free simulator port for instances {instances}")

    yield open_link
    for link in links:
        link.close()


@pytest.fixture
def start_double() -> Iterator[Callable[..., subprocess.Popen]]:
    """Start the test-double autopilot (see autopilot_double.py) against a port."""
    processes: list[subprocess.Popen] = []

    def start(port: int, behaviour: str = "px4", *args: str) -> subprocess.Popen:
        process = subprocess.Popen(
            [sys.executable, str(DOUBLE), "--port", str(port), "--behaviour", behaviour, *args]
        )
        processes.append(process)
        return process

    yield start
    for process in processes:
        process.kill()
        process.wait()


@pytest.fixture
def free_instance() -> Callable[[], int]:
    """Call it for a rig instance whose ports are free (other suites use low instances)."""
    return free_test_instance  # 60..99; campaigns default to 20..59


@pytest.fixture(scope="module")
def px4_dir() -> Path:
    """$PX4_DIR's PX4 SITL build (CI: the newest release it has); the test skips without."""
    build = find_px4()
    if build is None:
        pytest.skip(NO_PX4)
    return build.root


@pytest.fixture(scope="module", params=every_build())
def any_px4(request) -> Px4Build:
    """$PX4_DIR's build, then each of $PX4_OLDER_DIRS' (the short subset's releases)."""
    if request.param is None:
        pytest.skip(NO_PX4)
    build = find_px4(request.param)
    assert build is not None
    return build
