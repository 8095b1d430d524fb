"""SensorTop: every emulated chip behind one host port, as the rig's FPGA.

Buses, as on a Pixhawk FMU (e.g. FMUv2/v3, where the MPU-6000 and MS5611 share SPI1):

- one SPI bus, SCLK/MOSI/MISO shared, a chip select per chip (``imu_cs_n``,
  ``baro_cs_n``, ``flow_cs_n``): the MPU-6000, the MS5611 and the PMW3901 optical-flow
  chip. Shared because that is how the boards PX4 runs on wire such chips (a flow chip
  on a Pixhawk's external SPI), and because a deselected chip must then really release
  SDO (``miso_oe``): the top drives ``spi_miso`` from the selected chip and flags
  contention if two drive;
- one I2C bus shared by the IST8310 (0x0E) and the LIDAR-Lite v3 rangefinder (0x62), as
  on a Pixhawk's external I2C port: open drain, ``i2c_sda_oe`` = 1 when either target
  pulls SDA low (the wired-AND inside the FPGA); the testbench resolves it with its own
  driver;
- one UART for the u-blox M8 GNSS receiver (``gps_tx`` receiver to autopilot, ``gps_rx``
  the autopilot's configuration), as on a Pixhawk's GPS port. The receiver runs in its
  own ``uart`` domain on a UART crystal (:data:`UART_CLK_HZ`), as real UARTs do: every
  rate divides it exactly, and a simulation pays 32 cycles of the receiver alone per bit
  at 115200 baud instead of ~100 cycles of the whole design. The host's fix and its
  strobe cross into ``uart`` through a
  :class:`~fpga_hdl.host.snapshot_cdc.SampleSynchronizer` (the host's offered register is
  the only copy in ``sync``), the fault word through a ``SnapshotSynchronizer``; the pins
  are asynchronous already (``UartRx`` synchronises RXD).

- eight PWM inputs (``pwm``) into the PWM capture core, which runs in its own slow
  ``pwm`` domain at ``pwm_tick_hz`` (one tick per cycle, so a simulation pays the tick
  rate, not the system clock, to watch the motors). Its width, period and timeout
  results cross into ``sync`` through a :class:`~fpga_hdl.host.snapshot_cdc.SnapshotSynchronizer`;
  a one-cycle ``read_latch`` freezes all of them at once in a result register file,
  which the host then reads word by word (:data:`HOST_MAP`): a read never mixes two
  result sets however long it takes.

PWM result latency, fixed so that a read has a known age (the TLM models it): an input
edge first sampled at capture tick ``k`` changes the core's results at tick
``k + 2`` (``pwm_capture.core.LATENCY_TICKS``), the synchroniser publishes them at tick
``k + 3`` (:data:`PWM_RESULT_LATENCY_TICKS`), they are in its ``sync`` output after the
third system clock edge that follows (:data:`PWM_RESULT_COPY_CYCLES`: two synchroniser
flip-flops, then the copy), and a ``read_latch`` asserted in any later cycle takes them.
At the 16 MHz default that is 3 µs plus at most 4 system cycles (250 ns).

The host port (``fpga_hdl.host.host_port``) loads samples, time and faults; ``now_us`` goes
to every chip with a conversion time. ``pending`` tells a simulation that gates the
system clock that a chip in ``sync`` still waits to take a sample at a transfer's end. The
GPS receiver is not in it: it takes its fix on its own clock (the sample synchroniser's
``copy_cycles`` after the commit's strobe) and holds it until the frame on its line ends,
so a simulation runs the ``uart`` clock whenever it exchanges bytes with the receiver.
"""

from amaranth.build import Platform
from amaranth.hdl import (
    Cat,
    ClockDomain,
    ClockSignal,
    DomainRenamer,
    Module,
    Mux,
    ResetSignal,
    Signal,
)
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from fpga_hdl.chips.ist8310 import regs as ist8310_regs
from fpga_hdl.chips.ist8310.core import Ist8310Core
from fpga_hdl.chips.lidarlite import regs as lidarlite_regs
from fpga_hdl.chips.lidarlite.core import LidarLiteCore
from fpga_hdl.chips.mpu6000 import regs as mpu6000_regs
from fpga_hdl.chips.mpu6000.core import Mpu6000
from fpga_hdl.chips.ms5611 import regs as ms5611_regs
from fpga_hdl.chips.ms5611.core import Ms5611
from fpga_hdl.chips.pmw3901 import regs as pmw3901_regs
from fpga_hdl.chips.pmw3901.core import Pmw3901
from fpga_hdl.chips.pwm_capture.core import CHANNELS, LATENCY_TICKS, PwmCapture, timeout_ticks
from fpga_hdl.chips.ublox import ubx
from fpga_hdl.chips.ublox.core import UbloxM8Core
from fpga_hdl.host.host_port import HostPort, HostPortMap, host_port_map
from fpga_hdl.host.snapshot_cdc import PUBLISH_TICKS, SampleSynchronizer, SnapshotSynchronizer

#: Default system clock: above the SPI chips' 8 MHz floor (see ``spi_target``) and fast
#: enough for the I2C target's Fast-mode timing, as slow as possible because the system
#: clock ticks through every I2C transfer and every host-port write in simulation.
SYS_CLK_HZ = 16e6

SAMPLE_CHANNELS = {
    "imu": mpu6000_regs.SAMPLE_LAYOUT,
    "baro": ms5611_regs.SAMPLE_LAYOUT,
    "mag": ist8310_regs.SAMPLE_LAYOUT,
    "gps": ubx.SAMPLE_LAYOUT,
    "range": lidarlite_regs.SAMPLE_LAYOUT,
    "flow": pmw3901_regs.SAMPLE_LAYOUT,
}
#: The chips with a fault word, and each one's own faults beyond mute and flip.
FAULT_CHIPS: dict[str, tuple[str, ...]] = {
    "imu": (), "baro": (), "mag": (), "gps": (), "range": (), "flow": pmw3901_regs.OWN_FAULTS,
}  # fmt: skip
#: The GPS receiver's ``uart`` clock: a UART crystal, 2 × 1.8432 MHz. Every rate of
#: ``ublox.core.BAUD_RATES`` divides it exactly (no baud error at all; the divider is 32
#: at 115200 and 8, ``buses.uart``'s minimum, at 460800), where 1.8432 MHz itself would
#: give 460800 a divider of 4.
UART_CLK_HZ = 3.6864e6
#: Synchroniser flip-flops of the GPS receiver's inputs into ``uart`` (fix, fault word).
UART_SYNC_STAGES = 2
#: PWM capture tick: 1 µs, the unit PX4 uses for PWM (``fpga_hdl.chips.pwm_capture``).
PWM_TICK_HZ = 1e6
#: No rising edge for this long and a channel is flagged (and reads zero): a usual ESC
#: signal-loss time.
PWM_TIMEOUT_S = 0.1


#: Synchroniser flip-flops of the PWM results' change count.
PWM_RESULT_SYNC_STAGES = 2
#: Capture ticks from the one that first samples a PWM input edge to the publication of
#: the results it changes, which the host can then read (module docstring).
PWM_RESULT_LATENCY_TICKS = LATENCY_TICKS + PUBLISH_TICKS
#: System clock edges after that publication until the results are in ``sync``; a
#: ``read_latch`` in the cycle after the last of them, or later, takes them.
PWM_RESULT_COPY_CYCLES = PWM_RESULT_SYNC_STAGES + 1


def pwm_result_words(tick_hz: float, timeout_s: float) -> dict[str, dict[str, int]]:
    """The capture results as host-port read words: width and period per channel, timeouts."""
    bits = timeout_ticks(tick_hz, timeout_s).bit_length()
    fields = {f"width_ticks_{ch}": bits for ch in range(CHANNELS)}
    fields |= {f"period_ticks_{ch}": bits for ch in range(CHANNELS)}
    return {"pwm": fields | {"timeout": CHANNELS}}


def sensor_top_host_map(
    pwm_tick_hz: float = PWM_TICK_HZ, pwm_timeout_s: float = PWM_TIMEOUT_S
) -> HostPortMap:
    """The host port's word map of a SensorTop built with this PWM tick and timeout (the
    result words' widths depend on them), for the rig side without building the gateware."""
    return host_port_map(SAMPLE_CHANNELS, FAULT_CHIPS, pwm_result_words(pwm_tick_hz, pwm_timeout_s))


#: The host port's word map at the default PWM tick and timeout.
HOST_MAP = sensor_top_host_map()


class SensorTop(wiring.Component):
    """All emulated sensor chips and the host port.

    Parameters
    ----------
    sys_clk_hz : float
        Frequency of the ``sync`` domain, passed to every chip (which checks it).
    pwm_tick_hz, pwm_timeout_s : float
        Frequency of the ``pwm`` domain (one capture tick per cycle) and the capture's
        signal-loss timeout.
    uart_clk_hz : float
        Frequency of the ``uart`` domain (the GPS receiver).
    pwm_skippable : bool
        Build the capture core with its simulation ports (``PwmCapture``'s ``skip`` and
        ``quiet``, reached as ``capture.skip``): for the compiled co-simulation,
        never for synthesis.
    uart_skippable : bool
        The same for the GPS receiver (``UbloxM8Core``'s ``skip`` and ``quiet``, reached as
        ``gps.skip``).
    i2c_skippable : bool
        The same for the I2C chips: each says when it is ``settled`` (``mag.settled``,
        ``range.settled``), so the harness's I2C clock can skip the edges between bus
        events.
    i2c_domain : str
        The clock domain of the I2C chips (the IST8310 and the LIDAR-Lite, targets and
        registers): ``sync`` on the FPGA. The co-simulation harness names one of its own,
        clocked by the system clock while the host writer runs (the chips take their
        samples then) and alone during an I2C transfer, so a transfer's cycles clock the
        I2C bus and nothing else (``fpga_hdl.cosim.harness``).
    spi_idle_sclk : int or None
        None (the FPGA): SCLK reaches every SPI chip. 0 or 1: SCLK's level between
        transfers (CPOL) in a co-simulation whose controller runs one SPI mode; each chip
        then sees SCLK only while its chip select is low, and this level otherwise. The
        chips read the same: a deselected chip's SCLK domains are held in reset by its
        chip select, and its registers change only on a byte it receives. A transfer then
        clocks only the chip it selects (``fpga_hdl.cosim.native``).

    Attributes
    ----------
    write_addr : In(8), write_data : In(32), write_en : In(1), commit : In(1)
        Host port writes and commit (word map: :attr:`host_map`).
    read_latch : In(1)
        One cycle: freeze every result word at once for the host's reads (the PWM
        results as they stand in ``sync``; see the module docstring for their age).
    read_addr : In(8), read_data : Out(32)
        Host port result reads, from the words frozen by the last ``read_latch``.
    pending : Out(1)
        A chip still waits to take an offered sample (keep the clock running).
    spi_sclk, spi_mosi : In(1)
        Shared SPI clock and controller data.
    spi_miso, spi_miso_oe : Out(1)
        Shared SPI target data and whether any chip drives it.
    spi_contention : Out(1)
        More than one chip drives SDO (two chip selects low at once).
    imu_cs_n, baro_cs_n, flow_cs_n : In(1)
        Chip selects of the MPU-6000, the MS5611 and the PMW3901.
    i2c_scl, i2c_sda_i : In(1), i2c_sda_oe : Out(1)
        I2C bus of the IST8310 and the LIDAR-Lite (``i2c_sda_oe`` = 1: one pulls SDA low).
    gps_tx : Out(1), gps_rx : In(1)
        UART1 of the u-blox receiver: its TXD (idle high) and RXD.
    pwm : In(8)
        PWM inputs from the autopilot, one per channel (asynchronous).
    pwm_clk, pwm_rst : In(1)
        Clock and reset of the ``pwm`` domain (the system clock is ``clk``/``rst``).
    uart_clk, uart_rst : In(1)
        Clock and reset of the ``uart`` domain.
    """

    write_addr: In(8)
    write_data: In(32)
    write_en: In(1)
    commit: In(1)
    read_latch: In(1)
    read_addr: In(8)
    read_data: Out(32)
    pending: Out(1)
    spi_sclk: In(1)
    spi_mosi: In(1)
    spi_miso: Out(1)
    spi_miso_oe: Out(1)
    spi_contention: Out(1)
    imu_cs_n: In(1, init=1)
    baro_cs_n: In(1, init=1)
    flow_cs_n: In(1, init=1)
    i2c_scl: In(1, init=1)
    i2c_sda_i: In(1, init=1)
    i2c_sda_oe: Out(1)
    gps_tx: Out(1, init=1)
    gps_rx: In(1, init=1)
    pwm: In(CHANNELS)
    pwm_clk: In(1)
    pwm_rst: In(1)
    uart_clk: In(1)
    uart_rst: In(1)

    def __init__(
        self,
        *,
        sys_clk_hz: float = SYS_CLK_HZ,
        pwm_tick_hz: float = PWM_TICK_HZ,
        pwm_timeout_s: float = PWM_TIMEOUT_S,
        uart_clk_hz: float = UART_CLK_HZ,
        pwm_skippable: bool = False,
        uart_skippable: bool = False,
        i2c_skippable: bool = False,
        i2c_domain: str = "sync",
        spi_idle_sclk: int | None = None,
    ) -> None:
        if spi_idle_sclk not in (None, 0, 1):
            raise ValueError(f"spi_idle_sclk must be None, 0 or 1, not {spi_idle_sclk!r}")
        self.sys_clk_hz = sys_clk_hz
        self.i2c_domain = i2c_domain
        self.spi_idle_sclk = spi_idle_sclk
        self.pwm_tick_hz = pwm_tick_hz
        self.uart_clk_hz = uart_clk_hz
        self.imu = Mpu6000(sys_clk_hz=sys_clk_hz)
        self.baro = Ms5611(sys_clk_hz=sys_clk_hz)
        self.mag = Ist8310Core(sys_clk_hz=sys_clk_hz, skippable=i2c_skippable)
        self.gps = UbloxM8Core(sys_clk_hz=uart_clk_hz, skippable=uart_skippable)
        self.range = LidarLiteCore(sys_clk_hz=sys_clk_hz, skippable=i2c_skippable)
        self.flow = Pmw3901(sys_clk_hz=sys_clk_hz)
        self.capture = PwmCapture(
            tick_hz=pwm_tick_hz, timeout_s=pwm_timeout_s, skippable=pwm_skippable
        )
        # The synchroniser copies a published result within its stages + 1 system
        # cycles, before the next publication (at most one per tick) replaces it.
        ratio = PWM_RESULT_SYNC_STAGES + 2
        if not sys_clk_hz >= ratio * pwm_tick_hz:
            raise ValueError(
                f"sys_clk_hz {sys_clk_hz:g} must be at least {ratio} × pwm_tick_hz "
                f"({pwm_tick_hz:g}) for the capture results to cross into sync whole"
            )
        results = pwm_result_words(pwm_tick_hz, pwm_timeout_s)
        self.host = HostPort(SAMPLE_CHANNELS, FAULT_CHIPS, results)
        super().__init__()

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        host, imu, baro, mag, gps = self.host, self.imu, self.baro, self.mag, self.gps
        rangefinder, flow = self.range, self.flow
        m.submodules.host = host
        m.submodules.imu = imu
        m.submodules.baro = baro
        m.submodules.mag = DomainRenamer(self.i2c_domain)(mag)
        m.submodules.range = DomainRenamer(self.i2c_domain)(rangefinder)
        m.submodules.flow = flow
        m.domains.pwm = ClockDomain(local=True)
        m.d.comb += [ClockSignal("pwm").eq(self.pwm_clk), ResetSignal("pwm").eq(self.pwm_rst)]
        m.submodules.capture = capture = DomainRenamer("pwm")(self.capture)
        m.domains.uart = ClockDomain(local=True)
        m.d.comb += [ClockSignal("uart").eq(self.uart_clk), ResetSignal("uart").eq(self.uart_rst)]
        m.submodules.gps = DomainRenamer("uart")(gps)
        m.d.comb += [
            host.write_addr.eq(self.write_addr),
            host.write_data.eq(self.write_data),
            host.write_en.eq(self.write_en),
            host.commit.eq(self.commit),
            host.read_addr.eq(self.read_addr),
            self.read_data.eq(host.read_data),
        ]
        chips = (("imu", imu), ("baro", baro), ("mag", mag), ("range", rangefinder), ("flow", flow))
        for name, chip in chips:
            m.d.comb += [
                chip.sample.eq(getattr(host, name)),
                chip.sample_stb.eq(getattr(host, f"{name}_stb")),
                chip.fault.mute.eq(getattr(host, f"{name}_fault_mute")),
                chip.fault.flip.eq(getattr(host, f"{name}_fault_flip")),
            ]
        m.d.comb += [
            getattr(flow.own_fault, name).eq(getattr(host, f"flow_fault_{name}"))
            for name in pmw3901_regs.OWN_FAULTS
        ]
        m.d.comb += [chip.now_us.eq(host.now_us) for chip in (baro, mag, rangefinder)]
        m.d.comb += self.pending.eq(Cat(chip.sample_pending for _, chip in chips).any())

        spi_chips = ((imu, self.imu_cs_n), (baro, self.baro_cs_n), (flow, self.flow_cs_n))
        for chip, cs_n in spi_chips:
            sclk = self.spi_sclk
            if self.spi_idle_sclk is not None:
                sclk = Mux(cs_n, self.spi_idle_sclk, self.spi_sclk)
            m.d.comb += [chip.spi.sclk.eq(sclk), chip.spi.mosi.eq(self.spi_mosi)]
            m.d.comb += chip.spi.cs_n.eq(cs_n)
        drives = Cat(chip.spi.miso_oe for chip, _ in spi_chips)
        m.d.comb += [
            self.spi_miso.eq(Cat(chip.spi.miso & chip.spi.miso_oe for chip, _ in spi_chips).any()),
            self.spi_miso_oe.eq(drives.any()),
            # More than one drives: clearing the lowest set bit leaves another.
            self.spi_contention.eq((drives & (drives - 1)[: len(drives)]).any()),
        ]
        for chip in (mag, rangefinder):
            m.d.comb += [chip.i2c.scl.eq(self.i2c_scl), chip.i2c.sda_i.eq(self.i2c_sda_i)]
        m.d.comb += self.i2c_sda_oe.eq(mag.i2c.sda_oe | rangefinder.i2c.sda_oe)
        m.d.comb += [self.gps_tx.eq(gps.tx), gps.rx.eq(self.gps_rx)]
        self._gps_inputs(m, gps)
        self._capture_results(m, capture)
        return m

    def _gps_inputs(self, m: Module, gps: UbloxM8Core) -> None:
        """The host's fix, its strobe and the GPS fault word, ``sync`` → ``uart``.

        The fix: the host's offered register holds it until the next commit of a fix, an
        epoch later, long after the copy (``copy_cycles`` uart edges). The fault word: it
        changes only at a commit, one per rig frame, so it crosses whole into the slower
        domain though a ``SnapshotSynchronizer`` may publish into it only that rarely.
        """
        host = self.host
        m.submodules.gps_sample_cdc = sample = SampleSynchronizer(
            ubx.SAMPLE_LAYOUT, i_domain="sync", o_domain="uart", stages=UART_SYNC_STAGES
        )
        m.submodules.gps_fault_cdc = fault = SnapshotSynchronizer(
            data.StructLayout({"mute": 1, "flip": 8}),
            i_domain="sync",
            o_domain="uart",
            stages=UART_SYNC_STAGES,
        )
        m.d.comb += [
            sample.data_i.eq(host.gps),
            sample.stb_i.eq(host.gps_stb),
            gps.sample.eq(sample.data_o),
            gps.sample_stb.eq(sample.stb_o),
            fault.data_i.mute.eq(host.gps_fault_mute),
            fault.data_i.flip.eq(host.gps_fault_flip),
            gps.fault.mute.eq(fault.data_o.mute),
            gps.fault.flip.eq(fault.data_o.flip),
        ]

    def _capture_results(self, m: Module, capture: PwmCapture) -> None:
        """PWM pins → capture (``pwm``) → snapshot synchroniser → ``read_latch`` → host words."""
        layout = data.StructLayout(
            {
                "width": capture.width_ticks.shape(),
                "period": capture.period_ticks.shape(),
                "timeout": CHANNELS,
            }
        )
        init = {"timeout": capture.timeout.init}  # no pulse yet: every channel timed out
        m.submodules.capture_cdc = cdc = SnapshotSynchronizer(
            layout, i_domain="pwm", o_domain="sync", stages=PWM_RESULT_SYNC_STAGES, init=init
        )
        m.d.comb += [
            capture.pwm.pulses.eq(self.pwm),
            cdc.data_i.width.eq(capture.width_ticks),
            cdc.data_i.period.eq(capture.period_ticks),
            cdc.data_i.timeout.eq(capture.timeout),
        ]
        # The register file the host reads: written whole in one cycle, so the words
        # read one by one afterwards all belong to the same result set.
        frozen = Signal(layout, init=init)
        with m.If(self.read_latch):
            m.d.sync += frozen.eq(cdc.data_o)
        m.d.comb += self.host.pwm_timeout.eq(frozen.timeout)
        for ch in range(CHANNELS):
            m.d.comb += [
                getattr(self.host, f"pwm_width_ticks_{ch}").eq(frozen.width[ch]),
                getattr(self.host, f"pwm_period_ticks_{ch}").eq(frozen.period[ch]),
            ]
