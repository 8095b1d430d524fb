"""The RTL sensor layers: the channel codec, and RTL readouts equal to the TLM's.

In ``rtl`` mode every chip and the PWM capture core are RTL on the co-simulation
harness, compiled into the rig's process (``rig.chips.native``); the same Verilog also
runs under cocotb in its own process (``rig.chips.rtl``). The same frames through the
three layers (TLM, cocotb RTL, compiled RTL) must give the same decoded values, bus
errors and captured PWM, frame by frame, at the default 1 µs capture tick on every one of
the capture core's eight channels (an octo's motors) and at a coarser tick on a quad's
four, the same GPS fixes at the same times (through the u-blox core's UART and PX4's
decoder, with receiver and line faults), and the same optical-flow reports (the PMW3901's
camera frames through PX4's pmw3901 cycle, with the chip's own faults). The RTL is read at
the frame time, whatever the pulses do; nothing steers it.
"""

import numpy as np
import pytest

from fpga_hdl.chips.ist8310.driver import sample_from_field_gauss
from fpga_hdl.chips.lidarlite.driver import Range, decode_range, sample_from_range
from fpga_hdl.chips.mpu6000.regs import Mpu6000Sample
from fpga_hdl.chips.ms5611.model import raw_from_si
from fpga_hdl.chips.pmw3901 import regs as flow_regs
from fpga_hdl.chips.pmw3901.driver import FlowReport
from fpga_hdl.chips.pmw3901.regs import Pmw3901Sample
from fpga_hdl.chips.pwm_capture.core import CHANNELS
from fpga_hdl.chips.ublox.driver import GpsFix, ReceivedFix
from fpga_hdl.chips.ublox.link import BAD_CHECKSUM_FLIP, GpsFault, receiver_solution
from fpga_hdl.verification.scoreboard import Scoreboard
from rig.chips.channel import (
    decode_frame,
    decode_readout,
    decode_start,
    encode_frame,
    encode_readout,
    encode_start,
)
from rig.chips.layer import ChipFault, ChipFrame, ChipReadout, TlmSensorLayer
from rig.chips.pwm import Pulse, PwmOutput
from rig.errors import CosimError

PWM_HZ = 400
#: An octo's motors use every channel of the capture core; a quad's the first four.
OCTO, QUAD = CHANNELS, 4
#: The output of motor ``motors - 2`` stops for this span of frames: longer than the
#: capture's 0.1 s timeout at 1 kHz, so the timeout flag and its clearing are compared too.
DROPOUT_FRAMES = range(150, 290)
#: Frames whose PWM periods put the motors' falls 3, 2, 1 and 0 µs before a 1 ms frame
#: time: the documented read latency (an edge is readable 3 ticks after the tick that
#: samples it, ``fpga_hdl.top.PWM_RESULT_LATENCY_TICKS``) splits them.
BOUNDARY_FRAMES = range(340, 400)
#: Widths of those periods (motors 0..3, again 4..7): a period starting 1.5 ms before a
#: frame time ends 3..0 µs before it; the others in between change every width back to
#: 1200 µs.
BOUNDARY_WIDTHS_US, BETWEEN_WIDTH_US = (1497, 1498, 1499, 1500), 1200
#: A GPS measurement every this many frames (40 Hz at 1 kHz), each stamped with 4 × its
#: frame time as time of week, so that a short test holds many of the navigation epochs
#: PX4's 200 ms CFG-RATE selects (every other measurement) and as many that are not; and
#: the receiver faults of some epochs.
GPS_EVERY, GPS_TIME_SCALE = 25, 4
GPS_FAULTS = {100: GpsFault.LOSS_OF_FIX, 150: GpsFault.JAMMED, 200: GpsFault.BAD_CHECKSUM}
#: A LIDAR-Lite driver cycle every this many frames (PX4's 50 ms at 1 kHz), offset from the
#: GPS epochs; the LIDAR-Lite is muted over the cycles at frames 175 and 225.
RANGE_EVERY, RANGE_OFFSET = 50, 25
RANGE_MUTED = range(170, 230)
#: A PMW3901 camera frame every this many frames (125 Hz at 1 kHz, near its 126 fps); its
#: own faults over spans of frames, and a mute.
FLOW_EVERY = 8
FLOW_FAULTS = {
    **{k: ChipFault(own=flow_regs.FAULT_STUCK) for k in range(60, 100)},
    **{k: ChipFault(own=flow_regs.FAULT_ZERO_QUALITY) for k in range(120, 160)},
    **{k: ChipFault(own=flow_regs.FAULT_DROP_FRAMES) for k in range(200, 240)},
    **{k: ChipFault(mute=True) for k in range(265, 285)},
}


def _gps_fix(rng):
    return GpsFix(
        fix_type=3, satellites_used=int(rng.integers(6, 20)),
        latitude_deg=47.3977 + rng.normal(0, 1e-4), longitude_deg=8.5456 + rng.normal(0, 1e-4),
        altitude_msl_m=488.0 + rng.normal(0, 2), altitude_ellipsoid_m=535.0, eph=0.9, epv=1.6,
        vel_n_m_s=rng.normal(0, 2), vel_e_m_s=rng.normal(0, 2), vel_d_m_s=rng.normal(0, 1),
        vel_m_s=1.5, cog_rad=0.5, s_variance_m_s=0.3, c_variance_rad=0.2, vel_ned_valid=True,
    )  # fmt: skip


def _frames(rng, count, *, motors, frame_us=1000, faults=None):
    """Frames as the rig builds them for ``motors`` rotors: new motor commands every frame
    (armed after 20), the autopilot's PWM pulses at 400 Hz, a dropout, mag and baro at
    their rates."""
    d1_d2 = raw_from_si(95_461.0, 21.5)
    outputs = PwmOutput(motors, PWM_HZ)
    for k in range(1, count + 1):
        now_us = k * frame_us
        dropped = {motors - 2} if k in DROPOUT_FRAMES else set()
        gps_fault = GPS_FAULTS.get(k)
        frame_faults = (faults or {}).get(k, {})
        if gps_fault is GpsFault.BAD_CHECKSUM:
            frame_faults = {**frame_faults, "ublox": ChipFault(flip=BAD_CHECKSUM_FLIP)}
        if k in RANGE_MUTED:
            frame_faults = {**frame_faults, "lidarlite": ChipFault(mute=True)}
        if k in FLOW_FAULTS:
            frame_faults = {**frame_faults, "pmw3901": FLOW_FAULTS[k]}
        flow = None
        if k % FLOW_EVERY == 0:
            dx, dy = (int(v) for v in rng.integers(-60, 61, 2))
            flow = Pmw3901Sample(dx, dy, int(rng.integers(20, 200)), int(rng.integers(8192)))
        ranged = None
        if k % RANGE_EVERY == RANGE_OFFSET:
            ranged = sample_from_range(float(rng.uniform(0.1, 30.0)) if k != 325 else None)
        gps = None
        if k % GPS_EVERY == 0:
            gps = receiver_solution(_gps_fix(rng), GPS_TIME_SCALE * now_us, gps_fault)
        yield ChipFrame(
            now_us=now_us,
            imu=Mpu6000Sample.from_si(rng.normal(0, 20, 3), rng.normal(0, 3, 3), 30.0),
            mag=sample_from_field_gauss(rng.normal(0, 0.4, 3)) if k % 10 == 0 else None,
            baro_d1_d2=d1_d2 if k % 20 == 0 else None,
            read_mag=k % 10 == 0,
            faults=frame_faults,
            pulses=tuple(outputs.pulses(now_us + 1, dropped)),
            gps=gps,
            range=ranged,
            flow=flow,
        )
        if frame_us == 1000 and k in BOUNDARY_FRAMES:
            # The periods take the last command before their start: one starting at
            # 2.5 ms mod 5 the command after frames 0, 1, 2 mod 5, one at 0 ms mod 5 the
            # command after frames 3, 4 mod 5.
            widths_us = _boundary(motors) if k % 5 < 3 else (BETWEEN_WIDTH_US,) * motors
            outputs.command([(width - 1000) / 1000 for width in widths_us], armed=True)
            continue
        # Random throttles, then a hover's: the motors within 4 µs of each other, whose
        # falls straddle frame boundaries.
        spread = 1.0 if k < 300 else 0.004
        outputs.command(0.5 + rng.uniform(-spread / 2, spread / 2, motors), armed=k > 20)


def _boundary(motors):
    """The boundary periods' widths, :data:`BOUNDARY_WIDTHS_US` over and over."""
    return (BOUNDARY_WIDTHS_US * motors)[:motors]


def test_frame_codec_round_trip():
    rng = np.random.default_rng(3)
    faults = {5: {"mpu6000": ChipFault(flip=0x81), "ist8310": ChipFault(mute=True)}}
    faults[16] = {"pmw3901": ChipFault(flip=0x0F, own=flow_regs.FAULT_DROP_FRAMES)}
    frames = list(_frames(rng, 30, motors=OCTO, faults=faults))
    assert any(frame.flow for frame in frames)
    for frame in frames:
        assert decode_frame(encode_frame(frame)[1:]) == frame
    assert decode_start(encode_start(2500, OCTO)[1:]) == (2500, OCTO)


def test_readout_codec_round_trip():
    readout = ChipReadout(
        accel_mps2=(0.1, -0.2, -9.81), gyro_radps=(0.01, 0.02, -0.03), imu_temperature_degc=31.5,
        mag_gauss=(0.2, 0.01, 0.43), baro_pa_degc=None, pwm_widths_us=(1500.0, 0.0, 1000.0, 2000.0),
        pwm_timed_out=(False, True, False, False), bus_errors=(("ms5611", "MS5611 not ready ü"),),
        gps=(ReceivedFix(208_697, 200_000, _gps_fix(np.random.default_rng(1))),),
        range=Range(12.34, 100), flow=FlowReport((0.25, -1.5), 20_000, 117, 40_005),
    )  # fmt: skip
    assert decode_readout(encode_readout(readout)[1:]) == readout


def _started(layer):
    layer.start()
    return layer


@pytest.fixture(scope="module")
def rtl_layer():
    from rig.chips.rtl import RtlSensorLayer  # builds the harness once (cached under build/)

    layer = _started(RtlSensorLayer(motors=OCTO, pwm_hz=PWM_HZ))
    yield layer
    layer.close()


@pytest.fixture(scope="module")
def native_layer():
    from rig.chips.native import NativeSensorLayer  # builds the library once (build/native/)

    layer = _started(NativeSensorLayer(motors=OCTO, pwm_hz=PWM_HZ))
    yield layer
    layer.close()


@pytest.mark.cosim
def test_rtl_readouts_equal_tlm_readouts_with_bus_faults_and_pwm(rtl_layer, native_layer):
    """The same samples, time, faults and pulses give the same decoded values, bus errors
    and captured PWM of an octo's eight motors on the three layers, every frame (fpga_hdl
    proves the chips per byte)."""
    tlm, healthy = _started(TlmSensorLayer(motors=OCTO)), _started(TlmSensorLayer(motors=OCTO))
    faults = {k: {"mpu6000": ChipFault(flip=0x40)} for k in range(50, 55)}
    faults |= {k: {"ms5611": ChipFault(mute=True)} for k in range(100, 141)}
    corrupted, widths, timed_out, pwm, boundary, fixes = set(), set(), [], [], 0, []
    loaded, collected, flows = {}, {}, {}
    cocotb_rtl, compiled_rtl = Scoreboard("RTL vs TLM"), Scoreboard("compiled RTL vs TLM")
    for frame in _frames(np.random.default_rng(11), 400, motors=OCTO, faults=faults):
        rtl, reference = rtl_layer.frame(frame), tlm.frame(frame)
        if reference.flow is not None:
            flows[frame.now_us // 1000] = reference.flow
        fixes += [(frame.now_us, received) for received in reference.gps]
        if frame.range is not None:
            k = frame.now_us // 1000
            loaded[k] = frame.range
            nacked = [chip for chip, _ in reference.bus_errors if chip == "lidarlite"]
            collected[k] = "nack" if nacked else reference.range
        cocotb_rtl.check(f"frame at {frame.now_us} µs", reference, rtl)
        compiled_rtl.check(f"frame at {frame.now_us} µs", reference, native_layer.frame(frame))
        pwm.append(rtl.pwm_widths_us)
        if pwm[-1] == _boundary(OCTO) != pwm[-2]:
            # The falls came 3, 2, 1, 0 µs before the previous frame: there, only motors 0
            # and 4 showed their new width, the others still the one of the frame before.
            boundary += 1
            first = BOUNDARY_WIDTHS_US[0]
            shown = tuple(first if new == first else old
                          for new, old in zip(_boundary(OCTO), pwm[-3], strict=True))  # fmt: skip
            assert pwm[-2] == shown, f"frame {len(pwm) - 1}"
        clean = healthy.frame(frame._replace(faults={}))
        if (rtl.accel_mps2, rtl.baro_pa_degc) != (clean.accel_mps2, clean.baro_pa_degc):
            corrupted.add(frame.now_us // 1000)
        assert len(rtl.pwm_widths_us) == OCTO
        widths.add(rtl.pwm_widths_us[7])
        timed_out.append(rtl.pwm_timed_out[OCTO - 2])
    # The flip corrupts every IMU burst it covers; the muted MS5611 reads 0xFFFFFF, which
    # the datasheet compensation turns into a wild pressure: only at baro cycles (frames
    # 1, 11, 21, ...: PX4's 10 ms MS5611 cycle) during or just after the mute.
    assert set(range(50, 55)) <= corrupted
    baro_corrupted = corrupted - set(range(50, 55))
    assert baro_corrupted
    assert baro_corrupted <= set(range(101, 160, 10))
    # The PWM compared is a live signal: new widths each period; motor 6's last pulse
    # before the dropout rose at 147.5 ms, readable 3 ticks later, so it times out 0.1 s
    # on, at 247.503 ms (read at frame 248), and recovers with its first pulse after it.
    assert len(widths) > 100
    assert boundary >= 10  # the latency boundary was read often
    assert timed_out.index(True, 20) + 1 == 248
    assert not any(timed_out[295:])
    # Each epoch's NAV-PVT (100 bytes at 115200 baud: 8.7 ms on the line) is delivered at
    # the first frame after its last byte; the measurements between epochs send nothing;
    # loss of fix and jamming reach PX4's decoder, and the epoch with the bad checksum
    # never arrives.
    assert [received.sent_us // 1000 for _, received in fixes] == [50, 100, 150, 250, 300, 350]
    # The line: 99 bytes of 10 bits and the last one's 9.5 at 32 cycles a bit on the
    # 3.6864 MHz UART clock, plus the receiver's 3 input registers: 31,987 cycles, 8678 µs.
    line_us = -(-(99 * 10 * 32 + 9 * 32 + 16 + 3) * 1_000_000 // 3_686_400)
    assert line_us == 8678
    for delivered_us, received in fixes:
        assert received.time_us - received.sent_us == line_us
        assert delivered_us == received.sent_us + 9000
    # Each LIDAR-Lite cycle collects the acquisition the previous one started (none at the
    # first); muted, the collect is NACKed and stays due, and the first cycle after it
    # collects the acquisition started before the mute; a no return reads 1 cm, quality 0.
    cm = {k: decode_range(loaded[k].distance_cm.to_bytes(2, "big"), 128, 234)
          for k in (25, 75, 125, 275)}  # fmt: skip
    assert collected == {25: None, 75: cm[25], 125: cm[75], 175: "nack", 225: "nack",
                         275: cm[125], 325: cm[275], 375: Range(0.01, 0)}  # fmt: skip
    # PX4's pmw3901 cycle every 10 ms from start-up publishes every second one (20 ms
    # windows); stuck: no flow, the old quality; zero quality: PX4 drops the reads (quality
    # 0, no flow); dropped frames: no flow; muted: 0xFF bytes, -1 counts at quality 255.
    assert sorted(flows) == list(range(20, 401, 20))
    assert {r.integration_timespan_us for r in flows.values()} == {20_000}
    assert any(flows[k].pixel_flow_rad != (0.0, 0.0) for k in (20, 40, 180, 320))
    assert all(flows[k].pixel_flow_rad == (0.0, 0.0) for k in (80, 220))
    assert flows[80].quality > 0
    assert flows[140] == FlowReport((0.0, 0.0), 20_000, 0, 140_000)
    minus_two = float(np.float32(-2) / np.float32(385))  # two reads of -1 counts
    assert flows[280] == FlowReport((minus_two, minus_two), 20_000, 255, 280_000)
    kinds = {r.sent_us // 1000: (r.fix.fix_type, r.fix.satellites_used) for _, r in fixes}
    assert kinds[100] == (0, 0)
    assert kinds[150] == (2, 3)  # jammed: a 2D fix from 3 satellites
    assert kinds[50][0] == kinds[250][0] == 3


@pytest.mark.cosim
def test_a_coarser_pwm_tick_is_the_same_on_every_layer():
    """``rates.pwm_tick_hz`` = 250 kHz (4 µs) reaches SensorTop and the TLM model alike:
    a quad's widths come in whole 4 µs ticks, identical on the three layers at 250 Hz
    frames."""
    from rig.chips.native import NativeSensorLayer
    from rig.chips.rtl import RtlSensorLayer

    rtl = _started(RtlSensorLayer(motors=QUAD, pwm_hz=PWM_HZ, pwm_tick_hz=250e3))
    native = _started(NativeSensorLayer(motors=QUAD, pwm_hz=PWM_HZ, pwm_tick_hz=250e3))
    tlm = _started(TlmSensorLayer(motors=QUAD, pwm_tick_hz=250e3))
    cocotb_rtl, compiled_rtl = Scoreboard("RTL vs TLM"), Scoreboard("compiled RTL vs TLM")
    try:
        for frame in _frames(np.random.default_rng(12), 120, motors=QUAD, frame_us=4000):
            readout, reference = rtl.frame(frame), tlm.frame(frame)
            cocotb_rtl.check(f"frame at {frame.now_us} µs", reference, readout)
            compiled_rtl.check(f"frame at {frame.now_us} µs", reference, native.frame(frame))
            assert len(readout.pwm_widths_us) == QUAD
            assert all(width % 4 == 0 for width in readout.pwm_widths_us)
    finally:
        rtl.close()
        native.close()


@pytest.mark.cosim
def test_the_pwm_capture_is_the_same_on_every_layer_after_a_long_flight():
    """From 32 s of flight on, a time in seconds as a float no longer holds its µs exactly:
    the compiled RTL and the TLM model still capture every pulse alike, each width new
    (the first frame replays the 32 s before, disarmed)."""
    from rig.chips.native import NativeSensorLayer

    native = _started(NativeSensorLayer(motors=QUAD, pwm_hz=PWM_HZ))
    tlm = _started(TlmSensorLayer(motors=QUAD))
    out = PwmOutput(QUAD, PWM_HZ)
    imu = Mpu6000Sample(0, 0, 0, 0, 0, 0, 0)
    scoreboard = Scoreboard("compiled RTL vs TLM")
    try:
        for k in range(400):
            now_us = 32_000_000 + 1000 * k
            out.command([(k * 7 + motor * 13) % 101 / 100 for motor in range(QUAD)], armed=k > 0)
            pulses = tuple(out.pulses(now_us + 1))
            frame = ChipFrame(now_us, imu, mag=None, baro_d1_d2=None, read_mag=False,
                              pulses=pulses)  # fmt: skip
            scoreboard.check(f"frame at {now_us} µs", tlm.frame(frame), native.frame(frame))
    finally:
        native.close()


@pytest.mark.cosim
@pytest.mark.parametrize("layer", ["rtl_layer", "native_layer"])
def test_a_pulse_off_the_pwm_period_is_a_one_line_error(layer, request):
    imu = Mpu6000Sample(0, 0, 0, 0, 0, 0, 0)
    pulses = (Pulse(1, 10**7 - 7, 1500),)
    frame = ChipFrame(10**7, imu, mag=None, baro_d1_d2=None, read_mag=False, pulses=pulses)
    with pytest.raises(CosimError, match=r"^the RTL co-simulation failed: PwmTimingError: "
                       r"PWM pulse on channel 1 at 9999993 µs is not at a period start of this "
                       r"frame \(period 2500 µs from 0\)$"):  # fmt: skip
        request.getfixturevalue(layer).frame(frame)


@pytest.mark.cosim
def test_bus_transfers_longer_than_the_frame_are_a_one_line_error():
    """The compiled layer runs the bus while the capture clock stands still; it still
    refuses a frame whose transfers (here an IST8310 read, 0.3 ms at 400 kHz) cannot fit
    in its time, as the cocotb layer does."""
    from rig.chips.native import NativeSensorLayer

    native = _started(NativeSensorLayer(motors=QUAD, pwm_hz=PWM_HZ))
    try:
        imu = Mpu6000Sample(0, 0, 0, 0, 0, 0, 0)
        native.frame(ChipFrame(1000, imu, mag=None, baro_d1_d2=None, read_mag=True))
        with pytest.raises(CosimError, match=r"^the RTL co-simulation failed: PwmTimingError: "
                           r"the frame's bus transfers ran past its time \(1010 µs\)"):  # fmt: skip
            native.frame(ChipFrame(1010, imu, mag=None, baro_d1_d2=None, read_mag=True))
    finally:
        native.close()


@pytest.mark.cosim
def test_a_request_out_of_protocol_is_a_one_line_error(rtl_layer):
    with pytest.raises(CosimError, match=r"^the RTL co-simulation failed: unknown request kind 9$"):
        rtl_layer._request(bytes([9]))


def test_bypass_layer_passes_the_si_samples_and_commanded_widths():
    """The benchmark's no-chips layer: what the sensor models made, as they made it."""
    from quad_model.sensors import BaroSample, ImuSample, MagSample, SensorReadings
    from rig.chips.layer import BypassSensorLayer

    imu = ImuSample(0.001, np.array([0.1, -0.2, -9.8]), np.array([0.01, 0.0, -0.02]), 30.0)
    readings = SensorReadings(imu, MagSample(0.001, np.array([0.2, 0.0, 0.4])),
                              BaroSample(0.001, 95_500.0, 20.0), None)  # fmt: skip
    hexa = 6
    pulses = tuple(Pulse(channel, 0, 1500 + channel) for channel in range(hexa))
    frame = ChipFrame(now_us=1000, imu=None, mag=None, baro_d1_d2=None, read_mag=True,
                      pulses=pulses, si=readings)  # fmt: skip
    bypass = BypassSensorLayer(motors=hexa)
    out = bypass.frame(frame)
    assert out.flow is None
    assert out.accel_mps2 == (0.1, -0.2, -9.8)
    assert out.gyro_radps == (0.01, 0.0, -0.02)
    assert out.mag_gauss == (0.2, 0.0, 0.4)
    assert out.baro_pa_degc == (95_500.0, 20.0)
    assert out.pwm_widths_us == (1500.0, 1501.0, 1502.0, 1503.0, 1504.0, 1505.0)
    assert out.pwm_timed_out == (False,) * hexa
    camera = Pmw3901Sample(77, -385, 90, 0)
    out = bypass.frame(frame._replace(now_us=9000, flow=camera))
    assert out.flow == FlowReport((0.2, -1.0), 9000, 90, 9000)


def test_a_finish_without_a_sensed_frame_is_a_one_line_error():
    """The loop's two calls per frame come in order; out of order is an error, not a stale
    readout."""
    from rig.chips.layer import SensorLayerError, TlmSensorLayer

    layer = TlmSensorLayer(motors=QUAD)
    layer.start()
    with pytest.raises(SensorLayerError, match=r"^finish\(\) without a sensed frame"):
        layer.finish(())
