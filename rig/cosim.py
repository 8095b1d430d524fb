"""``sensor_layer = "rtl"``: the generated Verilog under cocotb, in its own process.

:class:`RtlSensorLayer` builds SensorTop's Verilog (cached by content hash under
``build/``), starts the simulator through fpga_hdl's cocotb runner with
``rig/cosim_worker.py`` as the cocotb module, and talks to it over the binary channel
of :mod:`rig.cosim_channel` (one request, one response per frame). Inside the simulator
the very same :class:`rig.sensor_layer.SensorEngine` runs over pin-level bus masters, so
the RTL and the TLM layers differ only in the buses underneath.

Every wait is bounded: the first build of the Verilator model takes a minute or two
(``build_timeout_s``); each frame must come back within ``frame_timeout_s`` of wall time,
else the co-simulation is reported as the stalled side.
"""

from __future__ import annotations

import contextlib
import os
import socket
import tempfile
import threading
from pathlib import Path

from rig.cosim_channel import (
    ERROR,
    START,
    STOP,
    decode_readout,
    encode_frame,
    receive_message,
    send_message,
)
from rig.errors import CosimError
from rig.sensor_layer import ChipFrame, ChipReadout

WORKER_MODULE = "cosim_worker"
WORKER_DIR = Path(__file__).resolve().parent
DEFAULT_SIMULATOR = "verilator"


class RtlSensorLayer:
    """The chips as RTL in a cocotb simulator process, behind the binary channel."""

    def __init__(
        self,
        simulator: str = DEFAULT_SIMULATOR,
        *,
        build_timeout_s: float = 600.0,
        frame_timeout_s: float = 10.0,
    ) -> None:
        self.simulator = simulator
        self.frame_timeout_s = frame_timeout_s
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
        from fpga_hdl.cosim.runner import run_cocotb  # the simulator toolchain, on demand
        from fpga_hdl.top import SensorTop

        try:
            run_cocotb(
                SensorTop(), "sensor_top", WORKER_MODULE, module_dir=WORKER_DIR,
                simulator=self.simulator, extra_env={"RIG_COSIM_SOCKET": path},
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

    def _request(self, payload: bytes) -> bytes:
        try:
            send_message(self._conn, payload)
            answer = receive_message(self._conn)
        except TimeoutError:
            raise CosimError(
                f"the RTL co-simulation stalled: no answer within {self.frame_timeout_s:g} s "
                "of wall time (the rig is waiting for it)"
            ) from None
        except OSError as error:
            raise CosimError(self._ended(f"mid-run ({error})")) from None
        if answer[0] == ERROR:
            raise CosimError(f"the RTL co-simulation failed: {answer[1:].decode()}")
        return answer[1:]

    def start(self) -> None:
        self._request(bytes([START]))

    def frame(self, frame: ChipFrame) -> ChipReadout:
        return decode_readout(self._request(encode_frame(frame)))

    def close(self) -> None:
        """Ask the simulator to finish (it writes its results), then release everything."""
        if self._thread.is_alive():
            with contextlib.suppress(CosimError):  # already gone: the run's error says why
                self._request(bytes([STOP]))
            self._thread.join(timeout=30.0)
        self._conn.close()
        self._server.close()
        self._folder.cleanup()
