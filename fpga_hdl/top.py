"""SensorTop: every emulated chip behind one host port, as the rig's FPGA.

Buses, as on a Pixhawk FMU (e.g. FMUv2/v3, where the MPU-6000 and MS5611 share SPI1):

- one SPI bus, SCLK/MOSI/MISO shared, a chip select per chip (``imu_cs_n``,
  ``baro_cs_n``). Shared because that is how the boards PX4 runs on wire these two
  chips, and because a deselected chip must then really release SDO (``miso_oe``): the
  top drives ``spi_miso`` from the selected chip and flags contention if two drive;
- one I2C bus for the IST8310 (open drain: ``i2c_sda_oe`` = 1 pulls SDA low; the
  testbench resolves the wired-AND with its own driver).

The host port (``fpga_hdl.host_port``) loads samples, time and faults; ``now_us`` goes
to every chip with a conversion time. ``pending`` tells a simulation that gates the
system clock that a chip still waits to take a sample at a transfer's end.
"""

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from fpga_hdl.host_port import HostPort, host_port_map
from fpga_hdl.ist8310 import regs as ist8310_regs
from fpga_hdl.ist8310.core import Ist8310Core
from fpga_hdl.mpu6000 import regs as mpu6000_regs
from fpga_hdl.mpu6000.core import Mpu6000
from fpga_hdl.ms5611 import regs as ms5611_regs
from fpga_hdl.ms5611.core import Ms5611

#: Default system clock: above the SPI chips' 8 MHz floor (see ``spi_target``) and fast
#: enough for the I2C target's Fast-mode timing, as slow as possible because the system
#: clock ticks through every I2C transfer and every host-port write in simulation.
SYS_CLK_HZ = 16e6

SAMPLE_CHANNELS = {
    "imu": mpu6000_regs.SAMPLE_LAYOUT,
    "baro": ms5611_regs.SAMPLE_LAYOUT,
    "mag": ist8310_regs.SAMPLE_LAYOUT,
}
FAULT_CHIPS = ("imu", "baro", "mag")
#: The host port's word map, for the rig side (no need to build the gateware for it).
HOST_MAP = host_port_map(SAMPLE_CHANNELS, FAULT_CHIPS, {})


class SensorTop(wiring.Component):
    """All emulated sensor chips and the host port.

    Parameters
    ----------
    sys_clk_hz : float
        Frequency of the ``sync`` domain, passed to every chip (which checks it).

    Attributes
    ----------
    write_addr : In(8), write_data : In(32), write_en : In(1), commit : In(1)
        Host port writes and commit (word map: :attr:`host_map`).
    read_addr : In(8), read_data : Out(32)
        Host port result reads.
    pending : Out(1)
        A chip still waits to take an offered sample (keep the clock running).
    spi_sclk, spi_mosi : In(1)
        Shared SPI clock and controller data.
    spi_miso, spi_miso_oe : Out(1)
        Shared SPI target data and whether any chip drives it.
    spi_contention : Out(1)
        More than one chip drives SDO (two chip selects low at once).
    imu_cs_n, baro_cs_n : In(1)
        Chip selects of the MPU-6000 and the MS5611.
    i2c_scl, i2c_sda_i : In(1), i2c_sda_oe : Out(1)
        I2C bus of the IST8310 (``i2c_sda_oe`` = 1 pulls SDA low).
    """

    write_addr: In(8)
    write_data: In(32)
    write_en: In(1)
    commit: In(1)
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
    i2c_scl: In(1, init=1)
    i2c_sda_i: In(1, init=1)
    i2c_sda_oe: Out(1)

    def __init__(self, *, sys_clk_hz: float = SYS_CLK_HZ) -> None:
        self.sys_clk_hz = sys_clk_hz
        self.imu = Mpu6000(sys_clk_hz=sys_clk_hz)
        self.baro = Ms5611(sys_clk_hz=sys_clk_hz)
        self.mag = Ist8310Core(sys_clk_hz=sys_clk_hz)
        self.host = HostPort(SAMPLE_CHANNELS, FAULT_CHIPS, {})
        super().__init__()

    def elaborate(self, platform) -> Module:
        m = Module()
        host, imu, baro, mag = self.host, self.imu, self.baro, self.mag
        m.submodules.host = host
        m.submodules.imu = imu
        m.submodules.baro = baro
        m.submodules.mag = mag
        m.d.comb += [
            host.write_addr.eq(self.write_addr),
            host.write_data.eq(self.write_data),
            host.write_en.eq(self.write_en),
            host.commit.eq(self.commit),
            host.read_addr.eq(self.read_addr),
            self.read_data.eq(host.read_data),
        ]
        for name, chip in (("imu", imu), ("baro", baro), ("mag", mag)):
            m.d.comb += [
                chip.sample.eq(getattr(host, name)),
                chip.sample_stb.eq(getattr(host, f"{name}_stb")),
                chip.fault_mute.eq(getattr(host, f"{name}_fault_mute")),
                chip.fault_flip.eq(getattr(host, f"{name}_fault_flip")),
            ]
        m.d.comb += [baro.now_us.eq(host.now_us), mag.now_us.eq(host.now_us)]
        m.d.comb += self.pending.eq(imu.sample_pending | baro.sample_pending)

        for chip, cs_n in ((imu, self.imu_cs_n), (baro, self.baro_cs_n)):
            m.d.comb += [chip.sclk.eq(self.spi_sclk), chip.mosi.eq(self.spi_mosi)]
            m.d.comb += chip.cs_n.eq(cs_n)
        m.d.comb += [
            self.spi_miso.eq((imu.miso & imu.miso_oe) | (baro.miso & baro.miso_oe)),
            self.spi_miso_oe.eq(imu.miso_oe | baro.miso_oe),
            self.spi_contention.eq(imu.miso_oe & baro.miso_oe),
        ]
        m.d.comb += [
            mag.scl.eq(self.i2c_scl),
            mag.sda_i.eq(self.i2c_sda_i),
            self.i2c_sda_oe.eq(mag.sda_oe),
        ]
        return m
