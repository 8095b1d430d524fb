"""The emulated sensor chips in the loop: SI samples in, what PX4's drivers read out.

Per lockstep frame the rig hands the chips a :class:`ChipFrame` (new samples as the
chips' raw words, simulated time, bus faults, the PWM pulses that ended) and gets back a
:class:`ChipReadout` decoded by fpga_hdl's autopilot-side drivers, which issue PX4's own
transactions: an MPU-6000 burst every frame, an IST8310 read + single-measurement trigger
at the mag rate (PX4's driver: every 20 ms, the default), the MS5611 convert/read cycle
every 10 ms (D2 then D1, so a pressure every 20 ms), and the PWM capture's widths.
Quantization, full-scale saturation, conversion latency and bus faults therefore reach the
autopilot as on the real rig.

Optical flow: the PMW3901 shares the SPI bus. Each frame that carries a camera frame
(``ChipFrame.flow``) loads it; PX4's pmw3901 cycle runs every 10 ms of simulated time on a
grid from start-up (the 12-byte motion read, a report every second cycle), as
``ChipReadout.flow``, from the first camera frame on: PX4 runs the driver only on a vehicle
configured with the chip (``SENS_EN_PMW3901``), and a run without the camera loads none.

Rangefinder: the LIDAR-Lite v3 shares the IST8310's I2C bus. PX4's ll40ls driver runs on
the frames that carry a rangefinder sample (the loop samples the physics at the driver's
20 Hz): the sample is loaded, the acquisition started one cycle before is collected and
the next one started, so each reading is the scene of 50 ms before, as on a vehicle.

GPS: at start-up PX4's u-blox driver configures the receiver over its UART (every step
ACKed, at the rates it switches through); each navigation epoch's solution is loaded
into the receiver, which sends NAV-PVT over the UART at 115200 baud, and PX4's decoder
hands the fix to the loop only once its last byte has arrived (about 8.7 ms later), as
:class:`~fpga_hdl.chips.ublox.driver.ReceivedFix`.

:class:`SensorEngine` is written once against fpga_hdl's async bus protocols and a
:class:`ChipHost` (how samples reach the chips). It runs in three places:

- ``sensor_layer = "tlm"``: here, over the pure-Python register models
  (:class:`TlmChips`); the coroutines never suspend, so :func:`run_now` drives them
  without an event loop;
- ``sensor_layer = "rtl"``: here too (``rig.chips.native``), over the co-simulation
  harness's SPI/I2C controllers, PWM generator and the generated Verilog of every chip
  and the PWM capture, compiled by Verilator and called once per transaction;
- the same RTL under cocotb (``rig.chips.rtl``, the loop's ``rtl-cocotb``): inside the
  simulator's process, behind the binary channel of ``rig.chips.channel``.
"""

from __future__ import annotations

import math
from collections.abc import Coroutine, Iterable, Mapping
from dataclasses import dataclass
from enum import StrEnum
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol, TypeVar

from fpga_hdl.buses.transactions import (
    BusError,
    I2cBus,
    SpiBus,
    TlmI2cBus,
    TlmSpiBus,
    UartPort,
)
from fpga_hdl.chips.ist8310 import regs as ist_regs
from fpga_hdl.chips.ist8310.driver import Ist8310Driver
from fpga_hdl.chips.ist8310.model import Ist8310Model
from fpga_hdl.chips.lidarlite.driver import LidarLiteDriver, LidarLiteVersion, Range
from fpga_hdl.chips.lidarlite.model import LidarLiteModel
from fpga_hdl.chips.lidarlite.regs import LidarLiteSample
from fpga_hdl.chips.mpu6000 import regs as mpu_regs
from fpga_hdl.chips.mpu6000.driver import Mpu6000Driver, decode
from fpga_hdl.chips.mpu6000.model import Mpu6000Model
from fpga_hdl.chips.ms5611 import regs as ms_regs
from fpga_hdl.chips.ms5611.driver import CONVERSION_INTERVAL_US, Ms5611Driver
from fpga_hdl.chips.ms5611.model import Ms5611Model
from fpga_hdl.chips.pmw3901.driver import (
    COUNTS_PER_RAD,
    SAMPLE_INTERVAL_US,
    FlowReport,
    Pmw3901Driver,
)
from fpga_hdl.chips.pmw3901.model import Pmw3901Model
from fpga_hdl.chips.pmw3901.regs import Pmw3901Sample
from fpga_hdl.chips.ublox.driver import GpsFix, ReceivedFix, UbloxDriver
from fpga_hdl.chips.ublox.link import TlmUbloxUart
from fpga_hdl.chips.ublox.model import UbloxM8Model
from fpga_hdl.chips.ublox.ubx import NavPvt
from fpga_hdl.top import UART_CLK_HZ
from quad_model.sensors import GpsSample, SensorReadings
from rig.chips.pwm import PWM_TICK_HZ, Pulse, PwmCapture

if TYPE_CHECKING:  # the compiled harness's module: imported only where a layer builds it
    from fpga_hdl.cosim.native import CallCost


class Chip(StrEnum):
    """The emulated chips, in the order the co-simulation channel numbers them."""

    MPU6000 = "mpu6000"
    MS5611 = "ms5611"
    IST8310 = "ist8310"
    UBLOX = "ublox"
    LIDARLITE = "lidarlite"
    PMW3901 = "pmw3901"


CHIPS = tuple(Chip)

_T = TypeVar("_T")


class SensorLayerError(RuntimeError):
    """A driver could not bring a chip up (wrong WHO_AM_I, PROM CRC, configuration)."""


@dataclass(frozen=True)
class ChipFault:
    """Bus fault of one chip: ``mute`` (stops answering), ``flip`` (XOR on sent bytes), and
    ``own``: the mask of the chip's own faults (the PMW3901's ``regs.FAULT_*``)."""

    mute: bool = False
    flip: int = 0
    own: int = 0


NO_FAULT = ChipFault()


#: No chip faulted: the frames' default fault map (read-only: every frame shares it).
NO_FAULTS: Mapping[str, ChipFault] = MappingProxyType({})


class ChipFrame(NamedTuple):
    """What the rig gives the chips for one frame; ``None`` where nothing new is loaded.

    A named tuple, as :class:`ChipReadout`: the rig builds one each frame, and a frozen
    dataclass's initialiser cost four times as much.
    """

    now_us: int
    imu: mpu_regs.Mpu6000Sample | None
    mag: ist_regs.Ist8310Sample | None
    baro_d1_d2: tuple[int, int] | None
    read_mag: bool
    faults: Mapping[str, ChipFault] = NO_FAULTS
    #: PWM pulses that started since the previous frame (the autopilot's outputs).
    pulses: tuple[Pulse, ...] = ()
    #: The SI samples the words came from; only :class:`BypassSensorLayer` reads them.
    si: SensorReadings | None = None
    #: The GPS receiver's solution of a navigation epoch output now (receiver faults in).
    gps: NavPvt | None = None
    #: The rangefinder's scene for this frame's driver cycle (None: no cycle this frame).
    range: LidarLiteSample | None = None
    #: One camera frame of the flow chip to load this frame (None: no new frame).
    flow: Pmw3901Sample | None = None


class ChipReadout(NamedTuple):
    """What the autopilot-side drivers decoded this frame (SI, sensor axes = body FRD)."""

    accel_mps2: tuple[float, float, float]
    gyro_radps: tuple[float, float, float]
    imu_temperature_degc: float
    mag_gauss: tuple[float, float, float] | None
    baro_pa_degc: tuple[float, float] | None
    #: What the PWM capture measured per motor channel (µs) and whether it timed out.
    pwm_widths_us: tuple[float, ...]
    pwm_timed_out: tuple[bool, ...]
    #: ``(chip, message)`` for each failed transfer this frame.
    bus_errors: tuple[tuple[str, str], ...] = ()
    #: The GPS fixes PX4's driver decoded by this frame's time, oldest first.
    gps: tuple[ReceivedFix, ...] = ()
    #: The rangefinder reading PX4's driver collected this frame, if it collected one.
    range: Range | None = None
    #: What PX4's pmw3901 driver published this frame, if it published.
    flow: FlowReport | None = None


#: SensorTop's host-port channel and fault names for the rig's chip names.
HOST_CHIP = {Chip.MPU6000: "imu", Chip.MS5611: "baro", Chip.IST8310: "mag", Chip.UBLOX: "gps",
             Chip.LIDARLITE: "range", Chip.PMW3901: "flow"}  # fmt: skip


def gps_fix(sample: GpsSample) -> GpsFix:
    """The model's GPS sample in PX4's ``sensor_gps`` terms (what the receiver reports)."""
    vn, ve, vd = (float(v) for v in sample.vel_ned_mps)
    return GpsFix(
        fix_type=sample.fix_type,
        satellites_used=sample.satellites_visible,
        latitude_deg=sample.lat_deg,
        longitude_deg=sample.lon_deg,
        altitude_msl_m=sample.alt_amsl_m,
        altitude_ellipsoid_m=sample.alt_amsl_m,
        eph=sample.eph_m,
        epv=sample.epv_m,
        vel_n_m_s=vn,
        vel_e_m_s=ve,
        vel_d_m_s=vd,
        vel_m_s=math.hypot(vn, ve),
        cog_rad=math.atan2(ve, vn),
        s_variance_m_s=0.0,
        c_variance_rad=0.0,
        vel_ned_valid=sample.fix_type >= 2,
    )


def host_port_inputs(
    frame: ChipFrame, held_faults: Mapping[str, ChipFault] | None = None
) -> tuple[dict[str, dict[str, int]], dict[str, tuple[bool, int, int]]]:
    """The frame's sample fields and fault words as the RTL's host port takes them (the
    compiled and the cocotb layer load the same).

    ``held_faults``: the faults the chips were last loaded with. The host port keeps each
    fault word until it is written again, so when the frame's faults equal them no fault
    word is written (six of the twenty words a frame loads, on every frame without a change).
    """
    samples: dict[str, dict[str, int]] = {}
    if frame.imu is not None:
        samples["imu"] = frame.imu.fields()
    if frame.mag is not None:
        samples["mag"] = {"x": frame.mag.x_counts, "y": frame.mag.y_counts,
                          "z": frame.mag.z_counts}  # fmt: skip
    if frame.baro_d1_d2 is not None:
        samples["baro"] = {"d1": frame.baro_d1_d2[0], "d2": frame.baro_d1_d2[1]}
    if frame.gps is not None:
        samples["gps"] = frame.gps.fields()
    if frame.range is not None:
        samples["range"] = frame.range.fields()
    if frame.flow is not None:
        samples["flow"] = frame.flow.fields()
    faults = {}
    if held_faults is None or frame.faults != held_faults:
        for chip in CHIPS:
            fault = frame.faults.get(chip, NO_FAULT)
            faults[HOST_CHIP[chip]] = (fault.mute, fault.flip, fault.own)
    return samples, faults


class ChipHost(Protocol):
    """How samples, time and faults reach the chips (TLM: models; RTL: the host port)."""

    async def load(self, frame: ChipFrame) -> None:
        """Load the frame's samples, time and faults. A host whose capture clock runs
        during the bus transfers (the cocotb worker's) preloads the frame's PWM widths here
        too, so it is only ever given whole frames."""
        ...

    async def capture(
        self, pulses: tuple[Pulse, ...], now_us: int
    ) -> tuple[tuple[float, ...], tuple[bool, ...]]:
        """Feed the PWM pulses; return each motor channel's captured width and timeout (one
        channel per rotor of the vehicle)."""
        ...


class SensorLayer(Protocol):
    """What the loop needs of a sensor layer (:class:`TlmSensorLayer`, ``NativeSensorLayer``,
    ``RtlSensorLayer``, :class:`BypassSensorLayer`).

    A frame comes in two calls: :meth:`sense` with the samples (the loop makes it while
    the autopilot computes its answer to the previous frame), then :meth:`finish` with the
    PWM pulses that answer started. :meth:`frame` makes both at once.
    """

    def start(self) -> None: ...

    def sense(self, frame: ChipFrame) -> None:
        """Load the frame's samples and run the drivers' sensor reads (``frame.pulses``
        is not used: they come with :meth:`finish`)."""
        ...

    def finish(self, pulses: tuple[Pulse, ...]) -> ChipReadout:
        """Feed the pulses that started since the previous frame, capture them: the
        sensed frame's whole readout."""
        ...

    def frame(self, frame: ChipFrame) -> ChipReadout:
        """One whole frame, pulses included (:meth:`sense`, then :meth:`finish`)."""
        self.sense(frame)
        return self.finish(frame.pulses)

    def close(self) -> None: ...

    def costs(self) -> tuple[CallCost, ...]:
        """What each kind of call into a compiled simulator has cost so far (none here)."""
        return ()


def run_now(coroutine: Coroutine[Any, Any, _T]) -> _T:
    """Run a coroutine that never suspends (TLM buses) to its result, without an event loop.

    An asyncio loop would cost tens of µs per frame for nothing: the TLM buses return at
    once. A coroutine that does suspend is a bug here and is reported as one.
    """
    try:
        coroutine.send(None)
    except StopIteration as done:
        return done.value
    coroutine.close()
    raise SensorLayerError("a TLM bus transaction suspended; TLM buses must return at once")


class SensorEngine:
    """PX4's sensor drivers on one SPI bus, one I2C bus and the GPS UART, frame by frame."""

    def __init__(self, spi: SpiBus, i2c: I2cBus, uart: UartPort, host: ChipHost) -> None:
        self.host = host
        self.imu = Mpu6000Driver(spi, "imu")
        self.baro = Ms5611Driver(spi, self._boot_sleep, "baro")
        self.mag = Ist8310Driver(i2c)
        self.gps = UbloxDriver(uart)
        self.range = LidarLiteDriver(i2c)
        self.flow = Pmw3901Driver(spi, "flow")
        self._next_flow_us = 0  # PX4 ScheduleOnInterval: a fixed 10 ms grid from start-up
        self._flow_flown = False  # a camera frame was loaded: the vehicle has the chip
        self._range_collect = False  # PX4 ``_collect_phase``: an acquisition is running
        self._next_baro_us = 0
        self._baro_phase_d1 = False  # False: a D2 (temperature) conversion is running
        self._d2 = 0
        self._baro_started = False
        #: (now_us, the readout's sensor fields) from sense() until finish()
        self._sensed: tuple[int, dict[str, Any]] | None = None

    @staticmethod
    async def _boot_sleep(duration_us: int) -> None:
        """Start-up runs before simulated time begins; the chips are ready at once."""

    async def start(self) -> None:
        """PX4's probe/reset/configure sequences, before the first frame."""
        try:
            await self.imu.start()
            await self.baro.start()
            if not await self.mag.probe():
                raise SensorLayerError("IST8310 WHO_AM_I does not read 0x10")
            await self.mag.reset()
            if not (await self.mag.reset_done() and await self.mag.configure()):
                raise SensorLayerError("IST8310 configuration registers do not hold")
            await self.gps.configure()
            if await self.range.probe() is not LidarLiteVersion.V1_V3:
                raise SensorLayerError("LIDAR-Lite probe: not the v1/v3 PX4 expects at 0x62")
            await self.range.reset()
            if not await self.flow.probe():
                raise SensorLayerError("PMW3901 Product_ID does not read 0x49")
            await self.flow.init()
        except BusError as error:
            raise SensorLayerError(f"sensor start-up failed: {error}") from None

    async def frame(self, frame: ChipFrame) -> ChipReadout:
        """One whole frame: :meth:`sense`, then :meth:`finish` with the frame's pulses."""
        await self.sense(frame)
        return await self.finish(frame.pulses)

    async def sense(self, frame: ChipFrame) -> None:
        """Load the frame's samples, then read as PX4's drivers would at this time; the
        readout waits in the engine for :meth:`finish`.

        The sensor transfers never touch the PWM capture, so the loop runs them while the
        autopilot computes the previous frame's answer (which sets this frame's pulses).
        """
        await self.host.load(frame)
        if frame.gps is not None:
            await self.gps.receive(frame.now_us)
        errors: list[tuple[str, str]] = []
        imu = decode(await self.imu.read_raw(), self.imu.gyro_config, self.imu.accel_config)
        mag = None
        if frame.read_mag:
            try:
                mag = await self.mag.read_field_gauss()
                await self.mag.start_measurement()
            except BusError as error:
                errors.append(("ist8310", str(error)))
        ranged = None
        if frame.range is not None:
            try:
                ranged = await self._range_cycle()
            except BusError as error:
                errors.append(("lidarlite", str(error)))
        flow = None
        self._flow_flown |= frame.flow is not None
        if self._flow_flown and frame.now_us >= self._next_flow_us:
            while self._next_flow_us <= frame.now_us:
                self._next_flow_us += SAMPLE_INTERVAL_US
            try:
                flow = await self.flow.cycle(frame.now_us)
            except BusError as error:
                errors.append(("pmw3901", str(error)))
        baro = None
        if frame.now_us >= self._next_baro_us:
            self._next_baro_us = frame.now_us + CONVERSION_INTERVAL_US
            try:
                baro = await self._baro_cycle()
            except BusError as error:
                errors.append(("ms5611", str(error)))
        sensed = {
            "accel_mps2": imu.accel_mps2,
            "gyro_radps": imu.gyro_rads,
            "imu_temperature_degc": imu.temperature_c,
            "mag_gauss": mag,
            "baro_pa_degc": baro,
            "bus_errors": tuple(errors),
            "gps": self.gps.poll(frame.now_us),
            "range": ranged,
            "flow": flow,
        }
        self._sensed = (frame.now_us, sensed)

    async def finish(self, pulses: tuple[Pulse, ...]) -> ChipReadout:
        """Feed the PWM pulses that started since the previous frame and read the capture
        at the sensed frame's time: that frame's whole readout."""
        if self._sensed is None:
            raise SensorLayerError("finish() without a sensed frame: call sense() first")
        (now_us, sensed), self._sensed = self._sensed, None
        widths_us, timed_out = await self.host.capture(pulses, now_us)
        return ChipReadout(**sensed, pwm_widths_us=widths_us, pwm_timed_out=timed_out)

    async def _range_cycle(self) -> Range | None:
        """PX4's ll40ls ``RunImpl``: collect the acquisition started one cycle ago (none on
        the first cycle), then start the next. A failed transfer leaves the collect due,
        as in PX4."""
        result = await self.range.collect() if self._range_collect else None
        await self.range.measure()
        self._range_collect = True
        return result

    async def _baro_cycle(self) -> tuple[float, float] | None:
        """PX4's MS5611 cycle: collect the running conversion, start the next one."""
        if not self._baro_started:
            self._baro_started = True
            await self.baro.convert(ms_regs.CMD_CONVERT_D2)
            return None
        result = await self.baro.read_adc()
        self._baro_phase_d1 = not self._baro_phase_d1
        if self._baro_phase_d1:  # the D2 just read: start the pressure conversion
            self._d2 = result
            await self.baro.convert(ms_regs.CMD_CONVERT_D1)
            return None
        await self.baro.convert(ms_regs.CMD_CONVERT_D2)
        if result == 0 or self._d2 == 0:  # PX4 ms5611.cpp: zero means read too early
            raise BusError(f"MS5611 conversion not ready (D1={result}, D2={self._d2})")
        compensated = ms_regs.compensate(result, self._d2, self.baro.prom)
        return compensated.pressure_pa, compensated.temperature_c


class TlmChips:
    """The chips as fpga_hdl's Python register models, behind TLM buses.

    The GPS UART's line time is the RTL's (on SensorTop's UART clock), so fixes arrive at
    the same frames as through the RTL. The PWM capture measures ``motors`` channels, one
    per rotor of the vehicle.
    """

    def __init__(self, *, motors: int, pwm_tick_hz: float = PWM_TICK_HZ) -> None:
        self.mpu6000 = Mpu6000Model()
        self.ms5611 = Ms5611Model()
        self.ist8310 = Ist8310Model()
        self.ublox = UbloxM8Model()
        self.lidarlite = LidarLiteModel()
        self.pmw3901 = Pmw3901Model()
        self.spi = TlmSpiBus({"imu": self.mpu6000, "baro": self.ms5611, "flow": self.pmw3901})
        self.i2c = TlmI2cBus({chip.address: chip for chip in (self.ist8310, self.lidarlite)})
        self.uart = TlmUbloxUart(self.ublox, clk_hz=UART_CLK_HZ)
        self.pwm = PwmCapture(motors, tick_hz=pwm_tick_hz)
        self._faults: Mapping[str, ChipFault] | None = None  # the fault inputs set last

    async def load(self, frame: ChipFrame) -> None:
        # Faults first: the host port commits them with the samples, and the flow chip's
        # own faults decide whether it takes the frame committed with them.
        if frame.faults is not self._faults:  # the injector hands the same map until it changes
            self._faults = frame.faults
            for name in CHIPS:
                fault = frame.faults.get(name, NO_FAULT)
                chip = getattr(self, name)
                chip.fault_mute, chip.fault_flip = fault.mute, fault.flip
            self.pmw3901.fault_own = frame.faults.get(Chip.PMW3901, NO_FAULT).own
        self.ms5611.now_us = self.ist8310.now_us = self.lidarlite.now_us = frame.now_us
        if frame.imu is not None:
            self.mpu6000.load_sample(frame.imu)
        if frame.mag is not None:
            self.ist8310.load_sample(frame.mag)
        if frame.baro_d1_d2 is not None:
            self.ms5611.load_sample(*frame.baro_d1_d2)
        if frame.gps is not None:
            self.ublox.load_fix(frame.gps)
        if frame.range is not None:
            self.lidarlite.load_sample(frame.range)
        if frame.flow is not None:
            self.pmw3901.load_sample(frame.flow)

    async def capture(
        self, pulses: tuple[Pulse, ...], now_us: int
    ) -> tuple[tuple[float, ...], tuple[bool, ...]]:
        return self.pwm.capture(pulses, now_us)


class TlmSensorLayer(SensorLayer):
    """``sensor_layer = "tlm"``: the engine in this process over :class:`TlmChips`."""

    def __init__(self, *, motors: int, pwm_tick_hz: float = PWM_TICK_HZ) -> None:
        self.chips = TlmChips(motors=motors, pwm_tick_hz=pwm_tick_hz)
        self.engine = SensorEngine(self.chips.spi, self.chips.i2c, self.chips.uart, self.chips)

    def start(self) -> None:
        run_now(self.engine.start())

    def sense(self, frame: ChipFrame) -> None:
        run_now(self.engine.sense(frame))

    def finish(self, pulses: tuple[Pulse, ...]) -> ChipReadout:
        return run_now(self.engine.finish(pulses))

    def close(self) -> None:
        """Nothing to release: the models live in this process."""


def _xyz(vector: Iterable[float]) -> tuple[float, float, float]:
    """A 3-vector sample as the readout's floats."""
    x, y, z = vector
    return float(x), float(y), float(z)


class BypassSensorLayer(SensorLayer):
    """No chips: the SI samples go straight into HIL_SENSOR and HIL_GPS (no receiver, no
    UART time) and the commanded pulse widths straight to the motors, as a bare simulator
    (Gazebo's) feeds PX4. Each camera frame's flow is reported as it comes (its angle,
    ``ChipFrame.flow``'s counts over PX4's 385 per radian, integrated since the previous
    camera frame), as Gazebo's flow plugin sends it. For measuring what the chips cost
    (``make bench``); the credible rig is ``tlm`` or ``rtl``."""

    def __init__(self, *, motors: int) -> None:
        self._widths_us = [0.0] * motors
        self._healthy = (False,) * motors
        self._sensed: ChipFrame | None = None
        self._flow_us = 0  # the previous camera frame's time

    def start(self) -> None:
        """Nothing to bring up."""

    def sense(self, frame: ChipFrame) -> None:
        self._sensed = frame

    def finish(self, pulses: tuple[Pulse, ...]) -> ChipReadout:
        frame, self._sensed = self._sensed, None
        assert frame is not None, "the loop senses the frame first"
        assert frame.si is not None, "the loop passes the samples"
        readings = frame.si
        assert readings.imu is not None, "the IMU is due every frame"
        for pulse in pulses:
            self._widths_us[pulse.channel] = float(pulse.width_us)
        imu, mag, baro, gps = readings.imu, readings.mag, readings.baro, readings.gps
        ranged = readings.range
        now_us = frame.now_us
        flow = None
        if frame.flow is not None:
            angles = (frame.flow.delta_x / COUNTS_PER_RAD, frame.flow.delta_y / COUNTS_PER_RAD)
            flow = FlowReport(angles, now_us - self._flow_us, frame.flow.squal, now_us)
            self._flow_us = now_us
        return ChipReadout(
            accel_mps2=_xyz(imu.accel_mps2),
            gyro_radps=_xyz(imu.gyro_radps),
            imu_temperature_degc=imu.temperature_degc,
            mag_gauss=None if mag is None else _xyz(mag.field_gauss),
            baro_pa_degc=None if baro is None else (baro.pressure_pa, baro.temperature_degc),
            pwm_widths_us=tuple(self._widths_us),
            pwm_timed_out=self._healthy,
            gps=() if gps is None else (ReceivedFix(now_us, now_us, gps_fix(gps)),),
            range=None if ranged is None or ranged.distance_m is None
            else Range(ranged.distance_m, 100),
            flow=flow,
        )  # fmt: skip

    def close(self) -> None:
        """Nothing to release."""
