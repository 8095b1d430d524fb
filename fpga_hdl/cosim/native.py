"""The co-simulation harness driven from compiled code: one call per bus transaction.

Why: in the closed loop at PX4's rates (IMU 1 kHz, PWM capture tick 1 µs) a frame needs
about 1,000 capture-clock cycles and 600 system cycles (an MPU-6000 burst at 5 MHz SCLK,
every 20 ms an IST8310 read at 400 kHz). Under cocotb the harness's gated Verilog clocks
run as Verilator ``--timing`` coroutines and every transaction wakes Python twice through
the VPI: 1.8 ms of wall time per 1 ms frame. Here the same generated Verilog of
:class:`~fpga_hdl.cosim.harness.CosimHarness` is Verilated to C++ without ``--timing`` and
linked with ``native_harness.cpp`` (a C ABI: reset, one SPI transfer, one I2C write/read,
one host-port burst write or read, one GPS UART exchange on the UART clock, N
capture-clock cycles) into a
shared library under ``build/native/``, keyed by the hash of everything that goes into it.

Python loads it with :mod:`ctypes` (standard library): the ABI is a dozen functions of
integers and byte buffers, so a binding generator (pybind11, nanobind, cffi) would add a
dependency and a compile step for nothing; each call costs about a microsecond.

Clocks. The harness instantiates ``cosim_gated_clock`` for its system, capture and UART
clocks. This build replaces that module with :data:`NATIVE_CLOCK_VERILOG`: a register the
C++ sets to 1 and which clears itself on its own rising edge, so one ``eval()`` is one
whole cycle (nothing in the design uses a falling clock edge). That halves the cost
of a cycle against a rising and a falling ``eval()`` (measured on the harness: about 100
instead of 270 ns per capture tick, 230 instead of 520 ns per system cycle). The system
clock keeps the gated clock's rule, whole cycles while its ``enable`` is high, and so do
the SPI controller's clock, which only an SPI transfer enables, the I2C bus's, which only
an I2C transfer enables, and the UART clock, which only a UART exchange enables (nothing
else runs meanwhile), so
each transaction sees the same edges as under cocotb, where the design sees no time but
its clock edges and the ``now_us`` the host port loads. The capture clock runs only when the
caller asks (:meth:`NativePwm.cycles`), and by event: one edge for each stretch of ticks in
which nothing but counters move (``native_harness.cpp``), so a 400 Hz PWM period costs a
few dozen edges. A UART exchange's clock likewise: a byte costs a few dozen edges.

:class:`NativeHarness` bundles the buses like :class:`fpga_hdl.cosim.peripherals.Harness`
(whose cocotb classes this mirrors): ``spi`` and ``i2c`` implement the
:mod:`fpga_hdl.buses.transactions` protocols with coroutines that never suspend, so the
same PX4-like drivers run over them without an event loop.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import struct
import subprocess
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from fpga_hdl.build import BUILD_DIR, verilog_by_inputs
from fpga_hdl.buses.i2c_controller import RATES_HZ, controller_rate_hz
from fpga_hdl.buses.spi_controller import divider_for
from fpga_hdl.buses.transactions import (
    I2cNack,
    UartTransfer,
    check_clock_hz,
    check_i2c_request,
    check_spi_mode,
    check_spi_request,
)
from fpga_hdl.buses.uart import cycles_to_us
from fpga_hdl.buses.uart import divider_for as uart_divider
from fpga_hdl.chips.pwm_capture.core import CHANNELS
from fpga_hdl.chips.pwm_capture.model import ChannelCapture, channel_captures
from fpga_hdl.cosim.harness import (
    HARNESS_SYS_CLK_HZ,
    HARNESS_TOPLEVEL,
    I2C_READ_DEPTH,
    I2C_WRITE_DEPTH,
    PWM_COUNTER_BITS,
    SPI_DEPTH,
    SPI_DEVICES,
    UART_RX_DEPTH,
    UART_TX_DEPTH,
    CosimHarness,
)
from fpga_hdl.cosim.runner import missing_simulator_reason, simulator_environment, verilator_root
from fpga_hdl.host.host_port import WORD_BITS, FaultInputs, HostPortMap, fault_word
from fpga_hdl.top import PWM_TICK_HZ, UART_CLK_HZ, sensor_top_host_map

__all__ = [
    "NATIVE_CLOCK_VERILOG",
    "CallCost",
    "NativeHarness",
    "NativeHarnessError",
    "NativeHost",
    "NativeI2cBus",
    "NativePwm",
    "NativeSpiBus",
    "NativeUart",
    "build_native_harness",
]

SOURCE = Path(__file__).with_name("native_harness.cpp")
#: The harness's clock instances (``CosimHarness.elaborate``: ``m.submodules.sync_clock``,
#: ``spi_clock``, ``i2c_clock``, ``pwm_clock``, ``uart_clock``); the C++ reaches their
#: registers through Verilator's root members.
_SYNC_CLOCK, _SPI_CLOCK, _I2C_CLOCK = "sync_clock", "spi_clock", "i2c_clock"
_PWM_CLOCK, _UART_CLOCK = "pwm_clock", "uart_clock"
#: ``cosim_gated_clock`` for this build: the C++ writes 1, the rising edge clears it. The
#: ports and parameter are the gated clock's; ``enable`` is read by the C++ only.
NATIVE_CLOCK_VERILOG = """\
// Clock of the compiled co-simulation (fpga_hdl.cosim.native), in place of the gated
// simulation clock: C++ sets `clk`, its own rising edge clears it (one eval, one cycle).
module cosim_gated_clock #(parameter integer HALF_PERIOD_PS = 1) (
    input wire enable /*verilator public_flat_rd*/,
    output reg clk /*verilator public_flat_rw*/
);
    initial clk = 1'b0;
    always @(posedge clk) clk <= 1'b0;
endmodule
"""
#: Verilator: ``-O3``, ``--x-assign fast``/``--x-initial fast`` (Amaranth initialises every
#: register) as for the cocotb builds (``fpga_hdl.cosim.runner``), one C++ file
#: (``--output-split 0``: the wheel's ``verilated.mk`` cannot use precompiled headers),
#: ``-O2`` for g++ instead of the makefile's ``-Os``, and position-independent code linked
#: as a shared library (``--exe`` names our C++ file as the program, ``-shared`` makes it
#: a library; no ``main`` is needed).
VERILATOR_ARGS = (
    *("--cc", "--exe", "--build", "-j", "2", "--prefix", "Vharness", "-Wno-fatal", "-O3"),
    *("--x-assign", "fast", "--x-initial", "fast", "--output-split", "0"),
    *("-MAKEFLAGS", "OPT_FAST=-O2 OPT_GLOBAL=-O2", "-LDFLAGS", "-shared"),
)
#: g++: ``-fno-semantic-interposition`` lets the library call its own functions directly,
#: not through the PLT (15 % per cycle, measured); hidden visibility exports only the
#: ``nh_*`` functions, so two harness libraries (two capture ticks) in one process never
#: bind to each other's Verilator runtime. (Profile-guided optimisation gained 5 %: not
#: worth a second compile and a training run.)
CXXFLAGS = "-fPIC -fno-semantic-interposition -fvisibility=hidden"
_LIBRARY = "libcosim_harness.so"
_BUILD_DONE = "native_build.done"


class NativeHarnessError(RuntimeError):
    """The compiled harness could not be built, or a transaction failed inside it."""


def _root_member(*path: str) -> str:
    """Verilator's root member for a signal of the hierarchy under the harness's top."""
    return "__DOT__".join((HARNESS_TOPLEVEL, *path))


def build_native_harness(
    *, pwm_tick_hz: float = PWM_TICK_HZ, spi_mode: int = 0, build_dir: Path = BUILD_DIR
) -> Path:
    """The shared library of the :class:`CosimHarness` of these parameters (Verilated with
    ``native_harness.cpp``); built once per content under ``build_dir/native/``, then
    reused."""
    reason = missing_simulator_reason("verilator")
    if reason is not None:
        raise NativeHarnessError(f"cannot build the compiled harness: {reason}")
    generated = verilog_by_inputs(CosimHarness, HARNESS_TOPLEVEL,
                                  {"pwm_tick_hz": pwm_tick_hz, "spi_mode": spi_mode},
                                  build_dir=build_dir)  # fmt: skip
    defines = {
        "SYNC_CLOCK": _root_member(_SYNC_CLOCK, "clk"),
        "SYNC_ENABLE": _root_member(_SYNC_CLOCK, "enable"),
        "SPI_CLOCK": _root_member(_SPI_CLOCK, "clk"),
        "SPI_ENABLE": _root_member(_SPI_CLOCK, "enable"),
        "I2C_CLOCK": _root_member(_I2C_CLOCK, "clk"),
        "I2C_ENABLE": _root_member(_I2C_CLOCK, "enable"),
        "PWM_CLOCK": _root_member(_PWM_CLOCK, "clk"),
        "UART_CLOCK": _root_member(_UART_CLOCK, "clk"),
        "UART_ENABLE": _root_member(_UART_CLOCK, "enable"),
    }
    cflags = " ".join([CXXFLAGS, *(f"-D{name}={value}" for name, value in defines.items())])
    args = [*VERILATOR_ARGS, "-CFLAGS", cflags, "--top-module", HARNESS_TOPLEVEL]
    version = (verilator_root() / "include" / "verilated_config.h").read_bytes()
    key = hashlib.sha256(
        b"\0".join(
            [generated.digest.encode(), NATIVE_CLOCK_VERILOG.encode(), SOURCE.read_bytes(),
             "\n".join(args).encode(), version]
        )
    ).hexdigest()[:16]  # fmt: skip
    folder = build_dir / "native" / f"{HARNESS_TOPLEVEL}-{key}"
    if (folder / _BUILD_DONE).is_file():
        return folder / _LIBRARY
    simulator_environment("verilator")
    folder.parent.mkdir(parents=True, exist_ok=True)
    # Built in a fresh folder, then renamed into place: a parallel build never sees half.
    work = Path(tempfile.mkdtemp(prefix=f"{folder.name}.", dir=folder.parent))
    try:
        clock = work / "cosim_gated_clock.v"
        clock.write_text(NATIVE_CLOCK_VERILOG)
        command = ["verilator", *args, "--Mdir", str(work / "obj"), "-o", f"../{_LIBRARY}",
                   str(generated.path), str(clock), str(SOURCE)]  # fmt: skip
        log = work / "build.log"
        with log.open("w") as out:
            done = subprocess.run(command, stdout=out, stderr=subprocess.STDOUT, check=False)
        if done.returncode != 0:
            tail = log.read_text(errors="replace")[-4000:]
            raise NativeHarnessError(f"Verilator build of the compiled harness failed:\n{tail}")
        shutil.rmtree(work / "obj")  # objects only; the library and its log stay
        (work / _BUILD_DONE).write_text(f"{generated.path}\n")
        try:
            os.replace(work, folder)
        except OSError:  # another process finished the same build first
            if not (folder / _BUILD_DONE).is_file():
                raise
    finally:
        if work.exists():
            shutil.rmtree(work, ignore_errors=True)
    return folder / _LIBRARY


_u8p = ctypes.POINTER(ctypes.c_uint8)
_SIGNATURES = {
    "nh_create": ([], ctypes.c_void_p),
    "nh_destroy": ([ctypes.c_void_p], None),
    "nh_error": ([ctypes.c_void_p], ctypes.c_char_p),
    "nh_cycles": ([ctypes.c_void_p, *[ctypes.POINTER(ctypes.c_uint64)] * 3], ctypes.c_int),
    "nh_costs": ([ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint64), ctypes.c_size_t],
                 ctypes.c_int),
    "nh_reset": ([ctypes.c_void_p, *[ctypes.c_uint32] * 3], ctypes.c_int),
    "nh_spi": ([ctypes.c_void_p, *[ctypes.c_uint32] * 4, ctypes.c_char_p, _u8p, ctypes.c_size_t],
               ctypes.c_int),
    "nh_i2c": ([ctypes.c_void_p, *[ctypes.c_uint32] * 4, ctypes.c_char_p, ctypes.c_size_t, _u8p,
                ctypes.c_size_t, ctypes.POINTER(ctypes.c_int32)], ctypes.c_int),
    "nh_host_write": ([ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint32],
                      ctypes.c_int),
    "nh_host_read": ([ctypes.c_void_p, _u8p, ctypes.c_size_t], ctypes.c_int),
    "nh_pwm_set": ([ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint32],
                   ctypes.c_int),
    "nh_pwm_cycles": ([ctypes.c_void_p, ctypes.c_uint64], ctypes.c_int),
    "nh_pwm_by_event": ([ctypes.c_void_p, ctypes.c_int], ctypes.c_int),
    "nh_uart_by_event": ([ctypes.c_void_p, ctypes.c_int], ctypes.c_int),
    "nh_i2c_by_event": ([ctypes.c_void_p, ctypes.c_int], ctypes.c_int),
    "nh_uart": ([ctypes.c_void_p, ctypes.c_uint32, ctypes.c_char_p, ctypes.c_size_t,
                 ctypes.c_uint32, _u8p, ctypes.c_size_t, ctypes.POINTER(ctypes.c_uint32),
                 ctypes.POINTER(ctypes.c_uint32)], ctypes.c_int),
}  # fmt: skip


def _load(path: Path) -> ctypes.CDLL:
    library = ctypes.CDLL(str(path))
    for name, (argtypes, restype) in _SIGNATURES.items():
        function = getattr(library, name)
        function.argtypes, function.restype = argtypes, restype
    return library


#: ``native_harness.cpp``'s cost slots: one per SPI device index, one per 7-bit I2C
#: address, then these, each with the clock its cycles are counted on.
_SPI_SLOTS = 8
_I2C_SLOT = _SPI_SLOTS
_OTHER_SLOTS = (
    ("host-port write", "system"),
    ("host-port read", "system"),
    ("GPS UART exchange", "UART"),
    ("PWM capture clock", "capture"),
)
_COST_SLOTS = _I2C_SLOT + 128 + len(_OTHER_SLOTS)


@dataclass(frozen=True)
class CallCost:
    """What one kind of call into the compiled harness has cost so far.

    ``what`` names it (``SPI imu``, ``I2C 0x0e``, ``host-port write`` ...); ``cycles`` are
    of ``clock`` (system, UART or capture); ``seconds`` is wall time, measured inside the
    library.
    """

    what: str
    calls: int
    cycles: int
    clock: str
    seconds: float

    def since(self, earlier: CallCost | None) -> CallCost:
        """This cost less ``earlier``'s (the same kind, read before): what came between."""
        if earlier is None:
            return self
        return CallCost(self.what, self.calls - earlier.calls, self.cycles - earlier.cycles,
                        self.clock, self.seconds - earlier.seconds)  # fmt: skip


class _Model:
    """One Verilated harness in the library: its handle, and its failures as exceptions."""

    def __init__(self, library: ctypes.CDLL) -> None:
        self.lib = library
        self.handle = library.nh_create()

    def call(self, name: str, *args: object) -> None:
        """``name(handle, *args)``; a failure inside the simulator is raised here."""
        if getattr(self.lib, name)(self.handle, *args) != 0:
            raise NativeHarnessError(f"{name}: {self.lib.nh_error(self.handle).decode()}")

    def close(self) -> None:
        if self.handle is not None:
            self.lib.nh_destroy(self.handle)
            self.handle = None


#: One word of the host writer's input (``HostWriter.words``: the address byte, then the
#: data), little-endian as every wide port: packed by ``struct``, at a third of the cost of
#: shifting the words into one integer.
_HOST_WORD = struct.Struct("<BI")
_WORD_MASK = (1 << WORD_BITS) - 1
assert _HOST_WORD.size * 8 == 8 + WORD_BITS, "the struct holds one host-port word"
assert struct.calcsize("<I") * 8 == WORD_BITS, "a result word reads as one uint32"


def _bytes_of(bits: int) -> int:
    return (bits + 7) // 8


def _pack(values: Sequence[int], bits: int, size: int) -> bytes:
    """Values into one wide port's little-endian bytes, element ``i`` at bit ``i * bits``."""
    mask = (1 << bits) - 1
    packed = 0
    for i, value in enumerate(values):
        packed |= (value & mask) << (i * bits)
    return packed.to_bytes(size, "little")


class NativeSpiBus:
    """:class:`~fpga_hdl.buses.transactions.SpiBus` over the harness's SPI controller (mode 0
    or 3), as :class:`fpga_hdl.cosim.peripherals.HarnessSpiBus` under cocotb."""

    def __init__(self, model: _Model, depth: int, *, mode: int = 0,
                 sys_clk_hz: float = HARNESS_SYS_CLK_HZ) -> None:  # fmt: skip
        check_spi_mode(mode)
        self._model = model
        self.depth = depth
        self.mode3 = int(mode == 3)
        self.sys_clk_hz = sys_clk_hz
        self.transfers = 0
        self._rx = (ctypes.c_uint8 * depth)()

    async def transfer(self, device: str, tx: bytes, *, sclk_hz: float) -> bytes:
        check_clock_hz("sclk_hz", sclk_hz)
        check_spi_request(device, tx, SPI_DEVICES, depth=self.depth)
        self._model.call(
            "nh_spi", SPI_DEVICES.index(device), len(tx), divider_for(self.sys_clk_hz, sclk_hz),
            self.mode3, tx, self._rx, len(tx),
        )  # fmt: skip
        self.transfers += 1
        return ctypes.string_at(self._rx, len(tx))


class NativeI2cBus:
    """:class:`~fpga_hdl.buses.transactions.I2cBus` over the harness's I2C controller
    (100/400 kHz; a requested rate is rounded down to :data:`RATES_HZ`)."""

    def __init__(self, model: _Model, write_depth: int, read_depth: int) -> None:
        self._model = model
        self.write_depth = write_depth
        self.read_depth = read_depth
        self.transfers = 0
        self._rx = (ctypes.c_uint8 * read_depth)()
        self._nack_index = ctypes.c_int32()

    async def write_read(
        self, address: int, write: bytes, read_len: int, *, scl_hz: float
    ) -> bytes:
        rate_hz = controller_rate_hz(scl_hz)
        check_i2c_request(
            address, write, read_len, write_depth=self.write_depth, read_depth=self.read_depth
        )
        self._model.call(
            "nh_i2c", address, len(write), read_len, int(rate_hz == RATES_HZ[1]), write,
            len(write), self._rx, read_len, ctypes.byref(self._nack_index),
        )  # fmt: skip
        self.transfers += 1
        if self._nack_index.value >= 0:
            raise I2cNack(address, self._nack_index.value)
        return ctypes.string_at(self._rx, read_len)


class NativeHost:
    """The rig's side of SensorTop's host port: one burst write per load, one burst read."""

    def __init__(self, model: _Model, host_map: HostPortMap) -> None:
        self._model = model
        self.map = host_map
        self._read = (ctypes.c_uint8 * (WORD_BITS // 8 * len(host_map.reads)))()
        # HostPortMap.encode finds each word by a linear search, 11 times a frame (about
        # 12 µs of the loop's budget): each word's address and range from a table built once.
        self._writes = {(word.channel, word.field): (word.address, *word.limits)
                        for word in host_map.writes}  # fmt: skip
        self._reads = [((word.channel, word.field), word.address, (1 << word.width) - 1,
                        word.width if word.signed else 0) for word in host_map.reads]  # fmt: skip
        self._read_words = struct.Struct(f"<{len(host_map.reads)}I")

    def load(
        self,
        samples: Mapping[str, Mapping[str, int]],
        *,
        now_us: int | None = None,
        faults: Mapping[str, FaultInputs] | None = None,
    ) -> None:
        """Stage the fields (and time, faults), commit, and return once the chips took them.

        The words of :meth:`HostPortMap.encode_frame`, in its order.
        """
        words = [
            self._word(channel, field, value)
            for channel, fields in samples.items()
            for field, value in fields.items()
        ]
        if now_us is not None:
            words.append(self._word("time", "now_us", now_us % (1 << 32)))
        for chip, fault in (faults or {}).items():
            words.append(self._word(chip, "fault", fault_word(*fault)))
        packed = b"".join(words)  # the harness zeroes the rest of its input
        self._model.call("nh_host_write", packed, len(packed), len(words))

    def _word(self, channel: str, field: str, value: int) -> bytes:
        """One staged field as the writer's input bytes (:meth:`HostPortMap.encode`)."""
        found = self._writes.get((channel, field))
        if found is not None:
            address, low, high = found
            if low <= value <= high:
                return _HOST_WORD.pack(address, value & _WORD_MASK)
        return _HOST_WORD.pack(*self.map.encode(channel, field, value))  # raises its one line

    def results(self) -> dict[tuple[str, str], int]:
        """Every result word, keyed by (channel, field), sign-extended where signed."""
        self._model.call("nh_host_read", self._read, len(self._read))
        words = self._read_words.unpack(self._read)
        values = {}
        for key, address, mask, signed_width in self._reads:
            raw = words[address] & mask
            if signed_width and raw >> (signed_width - 1):
                raw -= 1 << signed_width
            values[key] = raw
        return values

    def pwm_capture(self, channels: int = CHANNELS) -> list[ChannelCapture]:
        """The PWM capture's results for the first ``channels``, as the host port shows them."""
        return channel_captures(self.results(), channels)


class NativeUart:
    """:class:`~fpga_hdl.buses.transactions.UartPort` over the harness's GPS UART peer."""

    def __init__(self, model: _Model, tx_depth: int, rx_depth: int, *,
                 clk_hz: float = UART_CLK_HZ) -> None:  # fmt: skip
        self._model = model
        self.tx_depth = tx_depth
        self.clk_hz = clk_hz
        self.exchanges = 0
        self._rx = (ctypes.c_uint8 * rx_depth)()
        self._rx_len = ctypes.c_uint32()
        self._line_cycles = ctypes.c_uint32()

    @property
    def line_cycles(self) -> int:
        """The last exchange's line time in UART cycles (``UartTransfer.line_us`` rounds)."""
        return self._line_cycles.value

    async def exchange(self, tx: bytes, *, baud: int) -> UartTransfer:
        if len(tx) > self.tx_depth:
            raise ValueError(f"UART burst of {len(tx)} bytes exceeds {self.tx_depth}")
        self._model.call(
            "nh_uart", uart_divider(self.clk_hz, baud), tx, len(tx), len(tx), self._rx,
            len(self._rx), ctypes.byref(self._rx_len), ctypes.byref(self._line_cycles),
        )  # fmt: skip
        self.exchanges += 1
        count = self._rx_len.value
        if count > len(self._rx):
            raise NativeHarnessError(
                f"the GPS UART received {count} bytes in one exchange; the peer keeps "
                f"{len(self._rx)}"
            )
        data = bytes(self._rx)[len(self._rx) - count :]  # newest at the top (UartPeer)
        return UartTransfer(data, cycles_to_us(self._line_cycles.value, self.clk_hz))


class NativePwm:
    """The autopilot's PWM outputs (widths and period in ticks) and the capture clock."""

    def __init__(self, model: _Model, counter_bits: int, *, tick_hz: float) -> None:
        self._model = model
        self.counter_bits = counter_bits
        self.tick_hz = tick_hz
        self._bytes = _bytes_of(counter_bits * CHANNELS)

    def write(self, widths_ticks: Sequence[int], *, period_ticks: int) -> None:
        """New widths (0 = no pulse) from the next period start; period 0 stops all."""
        if len(widths_ticks) > CHANNELS:
            raise ValueError(f"at most {CHANNELS} PWM channels, got {len(widths_ticks)}")
        limit = (1 << self.counter_bits) - 1
        for value in (*widths_ticks, period_ticks):
            if not 0 <= value <= limit:
                raise ValueError(f"PWM ticks must be in 0..{limit}, not {value}")
        packed = _pack(widths_ticks, self.counter_bits, self._bytes)
        self._model.call("nh_pwm_set", packed, len(packed), period_ticks)

    def cycles(self, count: int) -> None:
        """Run ``count`` capture-clock ticks (generator and capture core)."""
        if count > 0:
            self._model.call("nh_pwm_cycles", count)


class NativeHarness:
    """Host port, SPI, I2C and PWM of a compiled :class:`~fpga_hdl.cosim.harness.CosimHarness`.

    Builds the library on first use (about half a minute; then cached). ``close`` frees
    the model; the library stays loaded for the process's other harnesses. The capture
    clock, the UART clock and the I2C clock advance by event (one edge for each quiet
    stretch, see ``native_harness.cpp``); ``pwm_by_event=False``, ``uart_by_event=False``
    and ``i2c_by_event=False`` clock every cycle, the reference the tests compare them
    with. ``spi_mode`` is the SPI bus's mode, built in: a transfer clocks only the chip it
    selects (SensorTop's ``spi_idle_sclk``).
    """

    def __init__(
        self,
        *,
        pwm_tick_hz: float = PWM_TICK_HZ,
        spi_mode: int = 0,
        pwm_by_event: bool = True,
        uart_by_event: bool = True,
        i2c_by_event: bool = True,
    ) -> None:
        self.pwm_tick_hz = pwm_tick_hz
        library = build_native_harness(pwm_tick_hz=pwm_tick_hz, spi_mode=spi_mode)
        self._model = _Model(_load(library))
        model = self._model
        self.host = NativeHost(model, sensor_top_host_map(pwm_tick_hz))
        self.spi = NativeSpiBus(model, SPI_DEPTH, mode=spi_mode)
        self.i2c = NativeI2cBus(model, I2C_WRITE_DEPTH, I2C_READ_DEPTH)
        self.pwm = NativePwm(model, PWM_COUNTER_BITS, tick_hz=pwm_tick_hz)
        self.uart = NativeUart(model, UART_TX_DEPTH, UART_RX_DEPTH)
        model.call("nh_pwm_by_event", int(pwm_by_event))
        model.call("nh_uart_by_event", int(uart_by_event))
        model.call("nh_i2c_by_event", int(i2c_by_event))
        # Read once a frame: the counters and their pointers made once (half the call's cost).
        self._counts = [ctypes.c_uint64() for _ in range(3)]
        self._count_refs = [ctypes.byref(count) for count in self._counts]

    def reset(self) -> None:
        """Reset every clock domain for three capture ticks, as the cocotb harness does;
        the generator stopped (period 0), no pulse."""
        self.pwm.write([0] * CHANNELS, period_ticks=0)
        ticks_s = 3 / self.pwm_tick_hz
        self._model.call(
            "nh_reset", round(ticks_s * HARNESS_SYS_CLK_HZ), 3, round(ticks_s * UART_CLK_HZ)
        )

    def costs(self) -> list[CallCost]:
        """Each kind of call made so far (not those never made): the per-frame budget."""
        words = (ctypes.c_uint64 * (3 * _COST_SLOTS))()
        self._model.call("nh_costs", words, len(words))
        names = [
            *(f"SPI {SPI_DEVICES[i]}" if i < len(SPI_DEVICES) else f"SPI device {i}"
              for i in range(_SPI_SLOTS)),
            *(f"I2C 0x{address:02x}" for address in range(128)),
            *(name for name, _ in _OTHER_SLOTS),
        ]  # fmt: skip
        clocks = ["system"] * (_SPI_SLOTS + 128) + [clock for _, clock in _OTHER_SLOTS]
        return [
            CallCost(name, words[3 * slot], words[3 * slot + 1], clock, words[3 * slot + 2] / 1e9)
            for slot, (name, clock) in enumerate(zip(names, clocks, strict=True))
            if words[3 * slot]
        ]

    def cycles(self) -> tuple[int, int, int]:
        """(system, capture, UART) clock cycles so far: what the simulation has cost."""
        self._model.call("nh_cycles", *self._count_refs)
        system, capture, uart = self._counts
        return system.value, capture.value, uart.value

    def close(self) -> None:
        self._model.close()
