"""The binary request/response channel between the rig and the RTL co-simulation process.

The co-simulation runs in its own process (cocotb embeds Python in the simulator), as the
paper's FPGA sits behind the real-time computer. The rig talks to it over a Unix stream
socket whose path the worker finds in ``RIG_COSIM_SOCKET`` (and the PWM capture tick, a
build parameter of the gateware, in ``RIG_COSIM_PWM_TICK_HZ``). Strictly one request,
then one response; the rig waits for each response under a wall-clock bound.

Every message is a frame: ``u32 length`` (little endian, bytes after this field), then
``u8 kind``, then the body. All integers and floats are little endian.

Requests (rig → co-simulation):

- ``START`` (kind 1): reset the chips, run PX4's probe/configure sequences, then start
  the PWM generator and the capture clock; simulated time follows rig time from here.

  | field | type | meaning |
  |---|---|---|
  | pwm_period_us | u32 | the autopilot's PWM period (``1 / pwm_hz``), whole capture ticks |
  | motors | u8 | the vehicle's rotors: the capture channels each readout carries |

- ``FRAME`` (kind 2), one lockstep frame (:class:`rig.chips.layer.ChipFrame`):

  | field | type | meaning |
  |---|---|---|
  | now_us | u64 | simulated time |
  | flags | u8 | bit 0 IMU sample, 1 mag sample, 2 baro sample, 3 read the mag, 4 GPS, |
  |  |  | 5 rangefinder sample, 6 flow camera frame |
  | imu | 7 × i32 | MPU-6000 finest-resolution words: accel x/y/z, temp, gyro x/y/z |
  | mag | 3 × i16 | IST8310 counts x, y, z |
  | baro | 2 × u32 | MS5611 D1, D2 |
  | faults | 6 × (u8 mute, u8 flip, u8 own) | mpu6000, ms5611, ist8310, ublox, lidarlite, |
  |  |  | pmw3901 (``own``: the chip's own fault mask) |
  | gps | NAV-PVT fields | the receiver's solution, as ``ubx.NAV_PVT_LAYOUT``'s loaded fields |
  | range | u16, u8, u8 | LIDAR-Lite distance (cm), signal strength, peak strength |
  | flow | i16, i16, u8, u16, 3 × u8 | PMW3901 frame: delta x/y, SQUAL, shutter, raw data |
  | pulse count | u16 | then per pulse: u8 channel, u64 start_us, u32 width_us |

  The pulses are those starting after the previous frame's ``now_us`` and up to this
  one's, at the PWM period starts (multiples of ``pwm_period_us`` from 0); a period
  without a pulse on a channel means that output was silent (a dropout).

- ``STOP`` (kind 3), no body: end the simulation; the worker answers, then exits.

Responses (co-simulation → rig): kind 128 ``OK`` with an optional body, or kind 129
``ERROR`` with a UTF-8 message (the worker's one-line reason). The ``FRAME`` response body
(:class:`rig.chips.layer.ChipReadout`), decoded by PX4's drivers from the RTL chips'
bytes and read from the RTL PWM capture core:

  | field | type | meaning |
  |---|---|---|
  | accel, gyro | 6 × f64 | m/s², rad/s (sensor axes = FRD) |
  | imu temperature | f64 | °C |
  | flags | u8 | bit 0 mag present, bit 1 baro present |
  | mag | 3 × f64 | gauss |
  | baro | 2 × f64 | Pa, °C |
  | PWM channels | u8 | then per channel: f64 width_us, u8 timed_out |
  | error count | u8 | then per error: u8 chip index, u16 length, UTF-8 text |
  | GPS fix count | u8 | then per fix: u64 time_us, u64 sent_us, then ``GpsFix`` in order |
  | range | u8, f64, i8 | a rangefinder reading collected (0/1), distance m, quality |
  | flow | u8, 2 × f64, u32, u8, u64 | a flow report published (0/1), pixel flow x/y rad, |
  |  |  | integration time µs, quality, timestamp µs |
"""

from __future__ import annotations

import socket
import struct
from dataclasses import astuple

from fpga_hdl.chips.ist8310.regs import Ist8310Sample
from fpga_hdl.chips.lidarlite.driver import Range
from fpga_hdl.chips.lidarlite.regs import LidarLiteSample
from fpga_hdl.chips.mpu6000.regs import Mpu6000Sample
from fpga_hdl.chips.pmw3901.driver import FlowReport
from fpga_hdl.chips.pmw3901.regs import Pmw3901Sample
from fpga_hdl.chips.ublox.driver import GpsFix, ReceivedFix
from fpga_hdl.chips.ublox.ubx import NAV_PVT_LAYOUT, NavPvt
from rig.chips.layer import CHIPS, NO_FAULT, ChipFault, ChipFrame, ChipReadout
from rig.chips.pwm import Pulse
from rig.errors import CosimError

START, FRAME, STOP, OK, ERROR = 1, 2, 3, 128, 129
_LENGTH = struct.Struct("<I")
_START = struct.Struct("<IB")
_NAV_PVT = struct.Struct("<" + "".join(fmt for _, fmt, loaded in NAV_PVT_LAYOUT if loaded))
_RANGE_SAMPLE = struct.Struct("<HBB")
_FLOW_SAMPLE = struct.Struct("<hhBHBBB")
_FRAME_HEAD = struct.Struct(
    f"<QB7i3h2I{3 * len(CHIPS)}B{_NAV_PVT.format[1:]}{_RANGE_SAMPLE.format[1:]}"
    f"{_FLOW_SAMPLE.format[1:]}H"
)
#: ReceivedFix: time_us, sent_us, then GpsFix's fields (two counts, 13 floats, a flag).
_GPS_FIX = struct.Struct("<QQBB13d?")
_PULSE = struct.Struct("<BQI")
_READOUT_HEAD = struct.Struct("<7dB3d2dB")
_PWM_CHANNEL = struct.Struct("<dB")
_ERROR_HEAD = struct.Struct("<BH")
_RANGE = struct.Struct("<?db")
_FLOW = struct.Struct("<?2dIBQ")
_NO_RANGE = LidarLiteSample(0, 0, 0)
_NO_FLOW = Pmw3901Sample(0, 0, 0, 0)


def encode_start(pwm_period_us: int, motors: int) -> bytes:
    return bytes([START]) + _START.pack(pwm_period_us, motors)


def decode_start(body: bytes) -> tuple[int, int]:
    """The PWM period (µs) and the motor count of a ``START`` body."""
    pwm_period_us, motors = _START.unpack(body)
    return pwm_period_us, motors


def encode_frame(frame: ChipFrame) -> bytes:
    imu = frame.imu
    mag = frame.mag
    flags = (imu is not None) | (mag is not None) << 1 | (frame.baro_d1_d2 is not None) << 2
    flags |= frame.read_mag << 3 | (frame.gps is not None) << 4 | (frame.range is not None) << 5
    flags |= (frame.flow is not None) << 6
    imu_words = tuple(imu.fields().values()) if imu is not None else (0,) * 7
    mag_counts = (mag.x_counts, mag.y_counts, mag.z_counts) if mag is not None else (0, 0, 0)
    faults = []
    for chip in CHIPS:
        fault = frame.faults.get(chip, NO_FAULT)
        faults += [int(fault.mute), fault.flip, fault.own]
    gps = astuple(frame.gps or NavPvt())
    body = _FRAME_HEAD.pack(
        frame.now_us, flags, *imu_words, *mag_counts, *(frame.baro_d1_d2 or (0, 0)), *faults,
        *gps, *astuple(frame.range or _NO_RANGE), *astuple(frame.flow or _NO_FLOW),
        len(frame.pulses),
    )  # fmt: skip
    body += b"".join(_PULSE.pack(p.channel, p.start_us, p.width_us) for p in frame.pulses)
    return bytes([FRAME]) + body


def decode_frame(body: bytes) -> ChipFrame:
    values = _FRAME_HEAD.unpack_from(body)
    now_us, flags = values[0], values[1]
    imu, mag, baro = values[2:9], values[9:12], values[12:14]
    fault_end = 14 + 3 * len(CHIPS)
    flow_start = len(values) - 1 - len(_FLOW_SAMPLE.format[1:])
    range_start = flow_start - len(_RANGE_SAMPLE.format[1:])
    fault_bytes, gps, count = values[14:fault_end], values[fault_end:range_start], values[-1]
    ranged, flow = values[range_start:flow_start], values[flow_start:-1]
    faults: dict[str, ChipFault] = {}
    for index, chip in enumerate(CHIPS):
        mute, flip, own = fault_bytes[3 * index : 3 * index + 3]
        if mute or flip or own:
            faults[chip] = ChipFault(bool(mute), flip, own)
    offset = _FRAME_HEAD.size
    pulses = []
    for _ in range(count):
        pulses.append(Pulse(*_PULSE.unpack_from(body, offset)))
        offset += _PULSE.size
    return ChipFrame(
        now_us=now_us,
        imu=Mpu6000Sample(*imu) if flags & 1 else None,
        mag=Ist8310Sample(*mag) if flags & 2 else None,
        baro_d1_d2=tuple(baro) if flags & 4 else None,
        read_mag=bool(flags & 8),
        faults=faults,
        pulses=tuple(pulses),
        gps=NavPvt(*gps) if flags & 16 else None,
        range=LidarLiteSample(*ranged) if flags & 32 else None,
        flow=Pmw3901Sample(*flow) if flags & 64 else None,
    )


def encode_readout(readout: ChipReadout) -> bytes:
    flags = (readout.mag_gauss is not None) | (readout.baro_pa_degc is not None) << 1
    body = _READOUT_HEAD.pack(
        *readout.accel_mps2, *readout.gyro_radps, readout.imu_temperature_degc, flags,
        *(readout.mag_gauss or (0.0, 0.0, 0.0)), *(readout.baro_pa_degc or (0.0, 0.0)),
        len(readout.pwm_widths_us),
    )  # fmt: skip
    for width, timed_out in zip(readout.pwm_widths_us, readout.pwm_timed_out, strict=True):
        body += _PWM_CHANNEL.pack(width, timed_out)
    body += bytes([len(readout.bus_errors)])
    for chip, text in readout.bus_errors:
        encoded = text.encode()
        body += _ERROR_HEAD.pack(CHIPS.index(chip), len(encoded)) + encoded
    body += bytes([len(readout.gps)])
    for received in readout.gps:
        body += _GPS_FIX.pack(received.time_us, received.sent_us, *astuple(received.fix))
    ranged = readout.range
    body += _RANGE.pack(ranged is not None, *astuple(ranged or Range(0.0, 0)))
    flow = readout.flow or FlowReport((0.0, 0.0), 0, 0, 0)
    body += _FLOW.pack(readout.flow is not None, *flow.pixel_flow_rad,
                       flow.integration_timespan_us, flow.quality, flow.timestamp_us)  # fmt: skip
    return bytes([OK]) + body


def decode_readout(body: bytes) -> ChipReadout:
    values = _READOUT_HEAD.unpack_from(body)
    flags, channels = values[7], values[13]
    offset = _READOUT_HEAD.size
    widths, timed_out = [], []
    for _ in range(channels):
        width, out = _PWM_CHANNEL.unpack_from(body, offset)
        widths.append(width)
        timed_out.append(bool(out))
        offset += _PWM_CHANNEL.size
    errors = []
    count, offset = body[offset], offset + 1
    for _ in range(count):
        chip, length = _ERROR_HEAD.unpack_from(body, offset)
        offset += _ERROR_HEAD.size
        errors.append((CHIPS[chip], body[offset : offset + length].decode()))
        offset += length
    gps = []
    count, offset = body[offset], offset + 1
    for _ in range(count):
        time_us, sent_us, *fix = _GPS_FIX.unpack_from(body, offset)
        gps.append(ReceivedFix(time_us, sent_us, GpsFix(*fix)))
        offset += _GPS_FIX.size
    collected, distance_m, quality = _RANGE.unpack_from(body, offset)
    published, flow_x, flow_y, span_us, flow_quality, stamp_us = _FLOW.unpack_from(
        body, offset + _RANGE.size
    )
    return ChipReadout(
        accel_mps2=values[0:3],
        gyro_radps=values[3:6],
        imu_temperature_degc=values[6],
        mag_gauss=values[8:11] if flags & 1 else None,
        baro_pa_degc=values[11:13] if flags & 2 else None,
        pwm_widths_us=tuple(widths),
        pwm_timed_out=tuple(timed_out),
        bus_errors=tuple(errors),
        gps=tuple(gps),
        range=Range(distance_m, quality) if collected else None,
        flow=FlowReport((flow_x, flow_y), span_us, flow_quality, stamp_us) if published else None,
    )


def send_message(sock: socket.socket, payload: bytes) -> None:
    sock.sendall(_LENGTH.pack(len(payload)) + payload)


def receive_message(sock: socket.socket) -> bytes:
    """One whole message (kind byte + body); a closed peer is a :class:`CosimError`."""
    (length,) = _LENGTH.unpack(_receive_exactly(sock, _LENGTH.size))
    return _receive_exactly(sock, length)


def _receive_exactly(sock: socket.socket, count: int) -> bytes:
    chunks, remaining = [], count
    while remaining:
        chunk = sock.recv(remaining)
        if not chunk:
            raise CosimError("the RTL co-simulation closed its channel (see its sim.log)")
        chunks.append(chunk)
        remaining -= len(chunk)
    return b"".join(chunks)
