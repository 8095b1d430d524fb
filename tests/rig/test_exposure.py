"""Nothing the rig starts listens beyond this machine: every socket of the rig and of its
autopilot is bound to loopback (a UDP socket that sends without binding would listen on
every interface for answers, so those count too)."""

import os
import socket
import struct
from pathlib import Path

import pytest

from rig.lockstep.loop import Progress, RunOptions, run_scenario
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import scenario_from_dict

pytestmark = pytest.mark.closed_loop


def _socket_addresses() -> dict[int, tuple[str, str, int]]:
    """Every inet socket on the machine: inode → (protocol, local address, port)."""
    found = {}
    for protocol, family in (("tcp", socket.AF_INET), ("udp", socket.AF_INET),
                             ("tcp6", socket.AF_INET6), ("udp6", socket.AF_INET6)):  # fmt: skip
        lines = Path(f"/proc/net/{protocol}").read_text().splitlines()[1:]
        for line in lines:
            fields = line.split()
            address, port = fields[1].split(":")
            raw = bytes.fromhex(address)
            # /proc prints each 32-bit word of the address in host (little-endian) order
            words = struct.unpack(f"<{len(raw) // 4}I", raw)
            host = socket.inet_ntop(family, struct.pack(f">{len(words)}I", *words))
            found[int(fields[9])] = (protocol, host, int(port, 16))
    return found


def _socket_inodes(pid: int) -> set[int]:
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = fd.readlink().as_posix()
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(int(target[8:-1]))
    return inodes


def _children(pid: int) -> list[int]:
    pids = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        pids += [int(child) for child in (task / "children").read_text().split()]
    return pids


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="reads Linux's /proc")
def test_every_socket_of_a_run_is_on_loopback(tmp_path, free_instance):
    seen: dict[int, tuple[str, str, int]] = {}

    def snapshot(progress: Progress) -> None:
        if progress.time_s < 3.0 or seen:  # armed and flying: every link is open by now
            return
        addresses = _socket_addresses()
        for pid in (os.getpid(), *_children(os.getpid())):
            for inode in _socket_inodes(pid):
                if inode in addresses:
                    seen[inode] = addresses[inode]

    scenario = scenario_from_dict({
        "name": "exposure", "vehicle": "f450_high_precision", "duration_s": 4.0, "seed": 1,
        "rates": {"imu_hz": 250},
        "commands": [{"at_s": 0.5, "action": "arm"},
                     {"at_s": 0.6, "action": "takeoff", "altitude_m": 2.0}],
    })  # fmt: skip
    options = RunOptions(instance=free_instance(), out_dir=tmp_path / "run",
                         timeouts=LinkTimeouts(connect_s=60, answer_s=30))  # fmt: skip
    run_scenario(scenario, options, snapshot)
    assert len(seen) >= 5  # simulator link (both ends), onboard link, the autopilot's two ports
    exposed = {inode: where for inode, where in seen.items()
               if where[1] not in ("127.0.0.1", "::1")}  # fmt: skip
    assert not exposed, exposed
