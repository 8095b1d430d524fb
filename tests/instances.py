"""Rig instances (port sets) for tests, shared out between parallel test workers.

``make test`` runs pytest-xdist workers side by side. A test looks for a free instance
just before its rig binds the ports, so two workers looking at the same moment could both
find the same one; each worker therefore searches only its own slice of a range.
"""

import os

from rig.mavlink.px4_api import free_instance


def worker_instances(first: int, count: int) -> range:
    """This worker's slice of instances ``first .. first + count - 1`` (all of them when
    pytest runs without workers)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")  # "gw0", "gw1", ...
    if worker is None:
        return range(first, first + count)
    workers = int(os.environ["PYTEST_XDIST_WORKER_COUNT"])
    share = count // workers
    if share == 0:
        raise RuntimeError(f"{workers} test workers cannot share {count} instances from {first}")
    # a worker that replaces a crashed one is numbered on (gw2 of 2): it takes a slice again
    start = first + int(worker.removeprefix("gw")) % workers * share
    return range(start, start + share)


def free_test_instance(first: int = 60, count: int = 40) -> int:
    """A free instance in this worker's slice of ``first .. first + count - 1``."""
    instances = worker_instances(first, count)
    return free_instance(instances.start, len(instances))
