"""The RTL sensor layer: its channel codec, and RTL readouts equal to the TLM's."""

import numpy as np
import pytest

from fpga_hdl.ist8310.driver import sample_from_field_gauss
from fpga_hdl.mpu6000.regs import Mpu6000Sample
from fpga_hdl.ms5611.model import raw_from_si
from rig.cosim_channel import decode_frame, decode_readout, encode_frame, encode_readout
from rig.errors import CosimError
from rig.pwm import Pulse
from rig.sensor_layer import ChipFault, ChipFrame, ChipReadout, TlmSensorLayer


def _frames(rng, count, faults=None):
    d1_d2 = raw_from_si(95_461.0, 21.5)
    for k in range(1, count + 1):
        yield ChipFrame(
            now_us=k * 1000,
            imu=Mpu6000Sample.from_si(rng.normal(0, 20, 3), rng.normal(0, 3, 3), 30.0),
            mag=sample_from_field_gauss(rng.normal(0, 0.4, 3)) if k % 10 == 0 else None,
            baro_d1_d2=d1_d2 if k % 20 == 0 else None,
            read_mag=k % 10 == 0,
            faults=(faults or {}).get(k, {}),
            pulses=(Pulse(0, k * 1000, 1500), Pulse(3, k * 1000, 1100)) if k % 3 == 0 else (),
        )


def test_frame_codec_round_trip():
    rng = np.random.default_rng(3)
    faults = {5: {"mpu6000": ChipFault(flip=0x81), "ist8310": ChipFault(mute=True)}}
    for frame in _frames(rng, 30, faults):
        assert decode_frame(encode_frame(frame)[1:]) == frame


def test_readout_codec_round_trip():
    readout = ChipReadout(
        accel_mps2=(0.1, -0.2, -9.81), gyro_radps=(0.01, 0.02, -0.03), imu_temperature_degc=31.5,
        mag_gauss=(0.2, 0.01, 0.43), baro_pa_degc=None, pwm_widths_us=(1500.0, 0.0, 1000.0, 2000.0),
        pwm_timed_out=(False, True, False, False), bus_errors=(("ms5611", "MS5611 not ready ü"),),
    )  # fmt: skip
    assert decode_readout(encode_readout(readout)[1:]) == readout


@pytest.fixture(scope="module")
def rtl_layer():
    from rig.cosim import RtlSensorLayer  # builds SensorTop once (cached under build/)

    layer = RtlSensorLayer()
    layer.start()
    yield layer
    layer.close()


@pytest.mark.cosim
def test_rtl_readouts_equal_tlm_readouts_with_bus_faults(rtl_layer):
    """The same samples, time, faults and pulses give the same decoded values on both
    layers: the RTL chips behave as the register models (fpga_hdl proves it per byte)."""
    tlm, healthy = TlmSensorLayer(), TlmSensorLayer()
    tlm.start()
    healthy.start()
    faults = {k: {"mpu6000": ChipFault(flip=0x40)} for k in range(50, 55)}
    faults |= {k: {"ms5611": ChipFault(mute=True)} for k in range(100, 141)}
    corrupted = set()
    for frame in _frames(np.random.default_rng(11), 160, faults):
        rtl, reference = rtl_layer.frame(frame), tlm.frame(frame)
        assert rtl == reference, f"frame at {frame.now_us} µs"
        clean = healthy.frame(ChipFrame(**{**frame.__dict__, "faults": {}}))
        if rtl != clean:
            corrupted.add(frame.now_us // 1000)
    # The flip corrupts every IMU burst it covers; the muted MS5611 reads 0xFFFFFF, which
    # the datasheet compensation turns into a wild pressure: only at baro cycles (frames
    # 1, 11, 21, ...: PX4's 10 ms MS5611 cycle) during or just after the mute.
    assert set(range(50, 55)) <= corrupted
    baro_corrupted = corrupted - set(range(50, 55))
    assert baro_corrupted
    assert baro_corrupted <= set(range(101, 160, 10))


@pytest.mark.cosim
def test_a_request_out_of_protocol_is_a_one_line_error(rtl_layer):
    with pytest.raises(CosimError, match=r"^the RTL co-simulation failed: unknown request kind 9$"):
        rtl_layer._request(bytes([9]))
