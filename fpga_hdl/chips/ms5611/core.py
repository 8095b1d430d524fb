"""TE MS5611 barometer on SPI, as an Amaranth component (MS5611-01BA03 datasheet).

Emulated: SPI modes 0 and 3; RESET (0x1E: abandons a conversion and clears the ADC
result); PROM READ 0xA0..0xAE (eight 16-bit words, MSB first, CRC4 in word 7);
CONVERT D1 0x40..0x48 and D2 0x50..0x58, which latch the loaded D1 or D2 and the time
``now_us`` at the end of the command byte; ADC READ 0x00, which answers the 24-bit
result only when the OSR's maximum conversion time has elapsed since the CONVERT, and
0 otherwise. As the datasheet says, a read without a finished conversion, or a repeated
read, gives 0: every ADC READ consumes the conversion.

Not emulated: the 2.8 ms PROM reload after RESET (the PROM reads back at once), the
I2C interface, supply-current and self-heating effects.
"""

from amaranth.build import Platform
from amaranth.hdl import Array, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.signatures import BUS_FAULT, SPI
from fpga_hdl.buses.spi_target import add_spi_engine, check_sys_clk_for_spi
from fpga_hdl.chips.ms5611 import regs
from fpga_hdl.host.host_port import chip_sample_latch


class Ms5611(wiring.Component):
    """MS5611 barometer with its SPI interface.

    Parameters
    ----------
    sys_clk_hz : float
        Frequency of the ``sync`` domain; checked against the 20 MHz SCLK limit.
    prom : tuple of 8 ints
        PROM words (default: the datasheet's coefficients with a valid CRC4).

    Attributes
    ----------
    spi : In(SPI)
        SPI pins (SCLK, CSB, SDI, SDO) and SDO's driver enable (high-Z while deselected
        or muted).
    sample : In(regs.SAMPLE_LAYOUT)
        The raw ADC values D1 (pressure) and D2 (temperature) a conversion returns;
        stable from ``sample_stb`` until copied.
    sample_stb : In(1)
        One ``sync`` cycle: a new sample is offered; visible once no transfer runs.
    now_us : In(32)
        Simulated time in microseconds; the chip takes a new value only between
        transfers, and needs no clock in between to let time pass.
    fault : In(BUS_FAULT)
        ``mute``: the chip stops driving SDO; ``flip``: XOR mask on every data byte sent.
    sample_pending : Out(1)
        A sample waits for the current transfer to end; a simulation that gates the
        system clock keeps it running until this falls.
    """

    spi: In(SPI)
    sample: In(regs.SAMPLE_LAYOUT)
    sample_stb: In(1)
    now_us: In(32)
    fault: In(BUS_FAULT)
    sample_pending: Out(1)

    def __init__(self, *, sys_clk_hz: float, prom: tuple[int, ...] = regs.DEFAULT_PROM) -> None:
        check_sys_clk_for_spi(sys_clk_hz, regs.SCLK_MAX_HZ)
        if len(prom) != 8 or not all(0 <= w <= 0xFFFF for w in prom):
            raise ValueError(f"prom must be eight 16-bit words, not {prom!r}")
        self.sys_clk_hz = sys_clk_hz
        self.prom = tuple(prom)
        super().__init__()

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        engine = add_spi_engine(m, self)
        latch = chip_sample_latch(m, self, regs.SAMPLE_LAYOUT, busy=engine.busy)
        time_us = Signal(32)  # ``now_us`` as the bus sees it: frozen during a transfer
        with m.If(~engine.busy):
            m.d.sync += time_us.eq(self.now_us)

        command = Signal(8)
        data_index = Signal(2)  # data byte about to be sent: 0, 1, 2, then 3 = past the end
        adc_result = Signal(24)
        converting = Signal()
        conversion_value = Signal(24)
        conversion_start_us = Signal(32)
        conversion_time_us = Signal(range(max(regs.CONVERSION_TIME_US.values()) + 1))

        rx = engine.rx_data
        is_convert = ((rx[4:8] == 0x4) | (rx[4:8] == 0x5)) & (rx[0:4] <= regs.Osr.OSR_4096)
        times = Array(
            Const(regs.CONVERSION_TIME_US.get(code, 0), conversion_time_us.shape())
            for code in range(16)
        )
        with m.If(engine.rx_stb):
            with m.If(engine.rx_first):
                m.d.spi += [command.eq(rx), data_index.eq(0)]
                with m.If(rx == regs.CMD_RESET):
                    m.d.spi += [converting.eq(0), adc_result.eq(0)]
                with m.Elif(is_convert & ~rx[0]):
                    m.d.spi += [
                        converting.eq(1),
                        conversion_value.eq(Mux(rx[4], latch.visible.d2, latch.visible.d1)),
                        conversion_start_us.eq(time_us),
                        conversion_time_us.eq(times[rx[0:4]]),
                    ]
                with m.Elif(rx == regs.CMD_ADC_READ):
                    elapsed_us = (time_us - conversion_start_us)[:32]
                    done = converting & (elapsed_us >= conversion_time_us)
                    m.d.spi += [adc_result.eq(Mux(done, conversion_value, 0)), converting.eq(0)]
            with m.Elif(data_index != 3):
                m.d.spi += data_index.eq(data_index + 1)

        prom = Array(Const(word, 16) for word in self.prom)
        prom_word = prom[command[1:4]]
        with m.If(command == regs.CMD_ADC_READ):
            m.d.comb += engine.tx_data.eq(
                Array([adc_result[16:24], adc_result[8:16], adc_result[0:8], 0])[data_index]
            )
        with m.Elif((command[4:8] == regs.CMD_PROM_READ >> 4) & ~command[0]):
            m.d.comb += engine.tx_data.eq(
                Array([prom_word[8:16], prom_word[0:8], 0, 0])[data_index]
            )
        return m
