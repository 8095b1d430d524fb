"""The buses as Amaranth ``wiring.Signature``s: one definition of each bus's pins.

Each signature is written from the side that drives the bus (the controller, the host),
so a chip declares ``In(...)``: ``spi: In(SPI)`` gives it ``spi.sclk``, ``spi.cs_n``,
``spi.mosi`` as inputs and ``spi.miso``, ``spi.miso_oe`` as outputs. A chip core hands
its bus to its shift engine with ``wiring.connect(m, wiring.flipped(self.spi), engine.spi)``.
In generated Verilog the members are ``spi__sclk`` and so on.
"""

from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

#: SPI to one target, mode 0 or 3. The target drives SDO (``miso``) only while selected
#: and not muted, and says so in ``miso_oe`` (a shared MISO line is the wired OR of the
#: driving targets).
SPI = wiring.Signature(
    {
        "sclk": Out(1),
        "cs_n": Out(1, init=1),
        "mosi": Out(1),
        "miso": In(1),
        "miso_oe": In(1),
    }
)

#: I2C as a target sees it: SCL and the resolved (wired-AND) SDA level come in; the
#: target pulls SDA low with ``sda_oe`` (open drain). No clock stretching.
I2C = wiring.Signature(
    {
        "scl": Out(1, init=1),
        "sda_i": Out(1, init=1),
        "sda_oe": In(1),
    }
)

#: Faults the host injects into a chip's bus side: ``mute`` never drives the data line
#: (the chip looks absent), ``flip`` is XORed into every data byte the chip sends.
BUS_FAULT = wiring.Signature({"mute": Out(1), "flip": Out(8)})

#: PWM lines from the autopilot's outputs to the capture core, one bit per channel.
PWM_CHANNELS = 8
PWM = wiring.Signature({"pulses": Out(PWM_CHANNELS)})
