"""The shared PX4 simulator-API facts match PX4's numbers (PX4_SIM_CONTRACT.md)."""

import socket

import pytest

from rig.mavlink.px4_api import HilSensorFields, Ports, free_instance, mavlink
from tests.instances import free_test_instance


def test_fields_updated_masks_are_px4s():
    assert HilSensorFields.ACCEL == 0x007
    assert HilSensorFields.GYRO == 0x038
    assert HilSensorFields.MAG == 0x1C0
    assert HilSensorFields.BARO == 0x1A00
    assert HilSensorFields.DIFF_PRESSURE == 0x400


@pytest.mark.parametrize(
    ("instance", "sim", "gcs", "api", "onboard", "sysid"),
    [(0, 4560, 18570, (14580, 14540), (14280, 14030), 1),
     (3, 4563, 18573, (14583, 14543), (14283, 14033), 4)],
)  # fmt: skip
def test_ports_per_instance(instance, sim, gcs, api, onboard, sysid):
    """PX4's px4-rc.mavlink: GCS, API (MAVSDK) and onboard payload links, all +i."""
    ports = Ports(instance)
    assert (ports.simulator_tcp, ports.gcs_local_udp, ports.gcs_remote_udp) == (sim, gcs, 14550)
    assert (ports.api_local_udp, ports.api_remote_udp) == api
    assert (ports.onboard_local_udp, ports.onboard_remote_udp) == onboard
    assert ports.system_id == sysid


def test_bad_instance_is_rejected():
    with pytest.raises(ValueError, match=r"instance must be in 0\.\.99, got -1"):
        Ports(-1)


def test_dialect_is_mavlink2_with_hil_sensor_id_extension():
    assert mavlink.WIRE_PROTOCOL_VERSION == "2.0"
    link = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    msg = link.hil_sensor_encode(
        1, 0, 0, -9.81, 0, 0, 0, 0.2, 0, 0.4, 955.0, 0, 0, 15.0, 0x1FFF, id=2
    )
    (decoded,) = mavlink.MAVLink(None).parse_buffer(msg.pack(link))
    assert decoded.id == 2
    assert decoded.zacc == pytest.approx(-9.81)


@pytest.mark.parametrize("port", ["simulator_tcp", "onboard_remote_udp", "gcs_local_udp",
                                  "api_local_udp", "onboard_local_udp"])  # fmt: skip
def test_free_instance_skips_an_instance_whose_port_is_taken(port):
    """The rig's ports and the autopilot's: an autopilot still shutting down holds its own."""
    first = free_test_instance()
    kind = socket.SOCK_STREAM if port.endswith("tcp") else socket.SOCK_DGRAM
    with socket.socket(socket.AF_INET, kind) as held:
        held.bind(("127.0.0.1", getattr(Ports(first), port)))
        assert free_instance(first, 2) == first + 1
        with pytest.raises(OSError, match=rf"no free SITL instance in {first}\.\.{first}"):
            free_instance(first, 1)
