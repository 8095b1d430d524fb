"""InvenSense MPU-6000 on SPI, as an Amaranth component (PS-MPU-6000A-00, RM-MPU-6000A-00).

Emulated: SPI modes 0 and 3, read flag 0x80, burst reads and writes with address
auto-increment, WHO_AM_I = 0x68, PWR_MGMT_1 with DEVICE_RESET (all registers back to
their reset values) and SLEEP (data registers frozen while asleep, as after power-up),
CONFIG / SMPLRT_DIV / FIFO_EN / INT_* / USER_CTRL / PWR_MGMT_2 stored and read back,
GYRO_CONFIG.FS_SEL and ACCEL_CONFIG.AFS_SEL scaling the data registers (shift and
saturate), 16-bit big-endian ACCEL/TEMP/GYRO registers, writes to read-only registers
ignored.

Not emulated: the FIFO (FIFO_COUNTH/L read 0, FIFO_R_W reads 0; PX4's current driver
therefore sees "FIFO empty" and our driver model reads the data registers instead), the
digital low-pass filter and sample-rate divider (the rig's model supplies filtered
samples at its own rate), interrupts and INT_STATUS, self-test, the I2C auxiliary bus.
"""

from amaranth.build import Platform
from amaranth.hdl import Const, Module, Mux, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.signatures import BUS_FAULT, SPI
from fpga_hdl.buses.spi_target import add_spi_engine, check_sys_clk_for_spi
from fpga_hdl.chips.mpu6000 import regs
from fpga_hdl.host.host_port import chip_sample_latch


def _saturate_int16(value: Value) -> Value:
    return Mux(value > 32767, 32767, Mux(value < -32768, -32768, value))


class Mpu6000(wiring.Component):
    """MPU-6000 six-axis IMU with its SPI interface.

    Parameters
    ----------
    sys_clk_hz : float
        Frequency of the ``sync`` domain; checked against the 20 MHz SCLK limit so the
        sample copy can never land inside a read (see ``spi_target``).

    Attributes
    ----------
    spi : In(SPI)
        SPI pins (the datasheet's SCLK, /CS, SDI, SDO) and SDO's driver enable
        (high-Z while deselected or muted).
    sample : In(regs.SAMPLE_LAYOUT)
        Raw accel/gyro at the finest resolution (±2 g, ±250 °/s scale, 20-bit signed)
        and raw TEMP_OUT; must stay stable from ``sample_stb`` until copied.
    sample_stb : In(1)
        One ``sync`` cycle: a new sample is offered. It becomes visible at the first
        cycle with no transfer in progress, else when the transfer ends.
    fault : In(BUS_FAULT)
        ``mute``: the chip stops driving SDO; ``flip``: XOR mask on every data byte sent.
    sample_pending : Out(1)
        A sample waits for the current transfer to end; a simulation that gates the
        system clock keeps it running until this falls.
    """

    spi: In(SPI)
    sample: In(regs.SAMPLE_LAYOUT)
    sample_stb: In(1)
    fault: In(BUS_FAULT)
    sample_pending: Out(1)

    def __init__(self, *, sys_clk_hz: float) -> None:
        check_sys_clk_for_spi(sys_clk_hz, regs.SPI_TIMING.sclk_max_sensor_registers_hz)
        self.sys_clk_hz = sys_clk_hz
        super().__init__()

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        engine = add_spi_engine(m, self)

        config = {
            r.address: Signal(8, init=r.reset_value, name=f"reg_{regs.Reg(r.address).name}")
            for r in regs.CONFIG_REGISTERS
        }
        sleeping = Signal()
        m.submodules.sleep_sync = FFSynchronizer(
            config[regs.Reg.PWR_MGMT_1][6], sleeping, o_domain="sync", init=1
        )
        latch = chip_sample_latch(
            m, self, regs.SAMPLE_LAYOUT, busy=engine.busy, offered_stb=self.sample_stb & ~sleeping
        )

        address = Signal(7)
        writing = Signal()
        with m.If(engine.rx_stb):
            with m.If(engine.rx_first):
                m.d.spi += [address.eq(engine.rx_data[:7]), writing.eq(~engine.rx_data[7])]
            with m.Else():
                m.d.spi += address.eq(address + 1)
                with m.If(writing):
                    self._write(m, config, address, engine.rx_data)

        # The byte to send next is register[address] after the increment above.
        read_value = Signal(8)
        with m.Switch(address):
            for r in regs.CONFIG_REGISTERS:
                with m.Case(r.address):
                    m.d.comb += read_value.eq(config[r.address])
            with m.Case(regs.Reg.WHO_AM_I):
                m.d.comb += read_value.eq(regs.WHO_AM_I_VALUE)
            for index, name in enumerate(regs.DATA_FIELDS):
                value = self._data_register(latch.visible[name], name, config)
                with m.Case(regs.Reg.ACCEL_XOUT_H + 2 * index):
                    m.d.comb += read_value.eq(value[8:16])
                with m.Case(regs.Reg.ACCEL_XOUT_H + 2 * index + 1):
                    m.d.comb += read_value.eq(value[:8])
        m.d.comb += engine.tx_data.eq(read_value)
        return m

    @staticmethod
    def _write(m: Module, config: dict[int, Signal], address: Signal, value: Value) -> None:
        with m.Switch(address):
            for r in regs.CONFIG_REGISTERS:
                with m.Case(r.address):
                    m.d.spi += config[r.address].eq(value & ~Const(r.self_clearing, 8))
                    if r.address == regs.Reg.PWR_MGMT_1:
                        with m.If(value & regs.PWR_MGMT_1_DEVICE_RESET):
                            m.d.spi += [
                                config[c.address].eq(c.reset_value) for c in regs.CONFIG_REGISTERS
                            ]

    @staticmethod
    def _data_register(raw: Value, name: str, config: dict[int, Signal]) -> Value:
        if name == "temp":
            return raw
        selector = config[regs.Reg.ACCEL_CONFIG if "accel" in name else regs.Reg.GYRO_CONFIG]
        full_scale = selector[regs.FULL_SCALE_SHIFT : regs.FULL_SCALE_SHIFT + 2]
        return _saturate_int16(raw >> full_scale)[:16]
