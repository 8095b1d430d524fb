"""The generated Verilog under cocotb, in its own process: the RTL layer's reference path.

``sensor_layer = "rtl"`` runs the same Verilog compiled in the rig's process
(:mod:`rig.chips.native`, several times faster); this layer stays for the identity tests
(the two give the same readouts as ``tlm``) and for comparisons, where the loop makes it
for the name :data:`COCOTB_LAYER` (``RunOptions.sensor_layer``, not a scenario's).

:class:`RtlSensorLayer` builds fpga_hdl's co-simulation harness (SensorTop, every chip
and the PWM capture core as RTL, with the flight controller's SPI/I2C controllers and
PWM timer around it as gateware; cached by content hash under ``build/``), starts the
simulator through fpga_hdl's cocotb runner with ``rig/chips/cosim_worker.py`` as the cocotb
module, and talks to it over the binary channel of :mod:`rig.chips.channel` (one
request, one response per frame). Inside the simulator the very same
:class:`rig.chips.layer.SensorEngine` runs over the harness's buses, so the RTL and the
TLM layers differ only in what is underneath, and give the same readouts.

The PWM capture tick (``pwm_tick_hz``) is a build parameter of the gateware: a coarser
tick costs fewer simulated cycles (the capture clock runs all the time, one cycle per
tick) and measures widths in coarser steps. ``benchmarks/bench_rig.py`` has the figures.

Every wait is bounded: the first build of the Verilator model takes a minute or two
(``build_timeout_s``); the start-up within ``start_timeout_s`` and each frame within
``frame_timeout_s`` of wall time, else the co-simulation is reported as the stalled side.
"""

from __future__ import annotations

import contextlib
import os
import socket
import tempfile
import threading
from pathlib import Path

from rig.chips.channel import (
    ERROR,
    STOP,
    decode_readout,
    encode_frame,
    encode_start,
    receive_message,
    send_message,
)
from rig.chips.layer import ChipFrame, ChipReadout, SensorLayer
from rig.chips.pwm import PWM_TICK_HZ, Pulse
from rig.errors import CosimError

#: ``RunOptions.sensor_layer`` that selects this layer instead of the compiled one.
COCOTB_LAYER = "rtl-cocotb"
WORKER_MODULE = "cosim_worker"
WORKER_DIR = Path(__file__).resolve().parent
DEFAULT_SIMULATOR = "verilator"


class RtlSensorLayer(SensorLayer):
    """The chips as RTL in a cocotb simulator process, behind the binary channel.

    ``motors`` is the vehicle's rotor count: the capture channels read. ``pwm_hz`` is the
    autopilot's PWM rate (its timer period is replayed by the harness's
    PWM generator); ``pwm_tick_hz`` the capture core's tick.
    """

    def __init__(
        self,
        simulator: str = DEFAULT_SIMULATOR,
        *,
        motors: int,
        pwm_hz: int,
        pwm_tick_hz: float = PWM_TICK_HZ,
        build_timeout_s: float = 600.0,
        frame_timeout_s: float = 10.0,
        start_timeout_s: float = 120.0,
    ) -> None:
        self.simulator = simulator
        self.motors = motors
        self.pwm_period_us = round(1e6 / pwm_hz)
        self.pwm_tick_hz = pwm_tick_hz
        self.frame_timeout_s = frame_timeout_s
        self.start_timeout_s = start_timeout_s
        self._sensed: ChipFrame | None = None  # sense() keeps the frame for finish()
        self._folder = tempfile.TemporaryDirectory(prefix="rig-cosim-")
        path = os.path.join(self._folder.name, "channel.sock")
        self._server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._server.bind(path)
        self._server.listen(1)
        self._failure: BaseException | None = None
        self._thread = threading.Thread(
            target=self._simulate, args=(path,), name="rtl-cosim", daemon=True
        )
        self._thread.start()
        self._conn = self._accept(build_timeout_s)

    def _simulate(self, path: str) -> None:
        """Runs in a thread: cocotb's runner blocks until the simulator process exits."""
        # The simulator toolchain, on demand.
        from fpga_hdl.cosim.harness import GATED_CLOCK_VERILOG, HARNESS_TOPLEVEL, CosimHarness
        from fpga_hdl.cosim.runner import run_cocotb

        env = {"RIG_COSIM_SOCKET": path, "RIG_COSIM_PWM_TICK_HZ": repr(self.pwm_tick_hz)}
        try:
            run_cocotb(
                CosimHarness(pwm_tick_hz=self.pwm_tick_hz), HARNESS_TOPLEVEL, WORKER_MODULE,
                module_dir=WORKER_DIR, simulator=self.simulator, extra_env=env,
                extra_verilog={"cosim_gated_clock": GATED_CLOCK_VERILOG},
            )  # fmt: skip
        except BaseException as error:  # reported by the rig's thread, with its message
            self._failure = error

    def _accept(self, timeout_s: float) -> socket.socket:
        self._server.settimeout(0.5)
        waited = 0.0
        while waited < timeout_s:
            try:
                conn, _ = self._server.accept()
            except TimeoutError:
                waited += 0.5
                if not self._thread.is_alive():
                    raise CosimError(self._ended("before it connected")) from None
                continue
            conn.settimeout(self.frame_timeout_s)
            return conn
        raise CosimError(
            f"the RTL co-simulation did not connect within {timeout_s:g} s (building "
            f"SensorTop for {self.simulator}?)"
        )

    def _ended(self, when: str) -> str:
        reason = str(self._failure).splitlines()[0] if self._failure else "no reason given"
        return f"the RTL co-simulation ({self.simulator}) ended {when}: {reason}"

    def _request(self, payload: bytes, timeout_s: float | None = None) -> bytes:
        timeout_s = timeout_s or self.frame_timeout_s
        self._conn.settimeout(timeout_s)
        try:
            send_message(self._conn, payload)
            answer = receive_message(self._conn)
        except TimeoutError:
            raise CosimError(
                f"the RTL co-simulation stalled: no answer within {timeout_s:g} s "
                "of wall time (the rig is waiting for it)"
            ) from None
        except OSError as error:
            raise CosimError(self._ended(f"mid-run ({error})")) from None
        if answer[0] == ERROR:
            raise CosimError(f"the RTL co-simulation failed: {answer[1:].decode()}")
        return answer[1:]

    def start(self) -> None:
        """PX4's start-up sequences; the GPS handshake alone runs about 2.4 million system
        cycles (its first steps at 9600 baud), hence its own, longer bound."""
        self._request(encode_start(self.pwm_period_us, self.motors), self.start_timeout_s)

    def sense(self, frame: ChipFrame) -> None:
        """Kept for :meth:`finish`: under cocotb the capture clock runs through the bus
        transfers, so the worker needs the frame's pulses before its first transfer."""
        self._sensed = frame

    def finish(self, pulses: tuple[Pulse, ...]) -> ChipReadout:
        frame, self._sensed = self._sensed, None
        if frame is None:
            raise CosimError("finish() without a sensed frame: call sense() first")
        return decode_readout(self._request(encode_frame(frame._replace(pulses=pulses))))

    def close(self) -> None:
        """Ask the simulator to finish (it writes its results), then release everything."""
        if self._thread.is_alive():
            with contextlib.suppress(CosimError):  # already gone: the run's error says why
                self._request(bytes([STOP]))
            self._thread.join(timeout=30.0)
        self._conn.close()
        self._server.close()
        self._folder.cleanup()
