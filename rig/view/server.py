"""The view's server: the page over HTTP and the flight over a WebSocket, on loopback only,
from a thread of its own.

The loop must never wait for a browser. :meth:`ViewServer.publish` only stores the loop's
latest report in one slot (a newer report replaces one not yet sent: no queue grows); the
server's thread samples that slot at most :data:`PUSH_HZ` times a wall second, turns it
into JSON once and hands it to every page, each of which gets the newest frame whenever
its socket is ready to take one, never a backlog. The view only reads reports, so a run's
logs are the same bytes with or without it.

``websockets`` (a well-kept asyncio library) serves both: its ``process_request`` hook
answers plain HTTP requests with the page, ``/ws`` becomes the WebSocket.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import socket
import threading
from collections import deque
from http import HTTPStatus
from importlib import resources

from websockets.asyncio.server import ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response
from websockets.typing import Origin

from rig.lockstep.loop import Progress
from rig.view.frames import Frame, Recording, ViewError, live_frame

#: The view's port for instance 0 (instance i serves on VIEW_PORT + i).
VIEW_PORT = 8765
#: Only this machine's browsers see the flight: the server binds loopback, nothing else.
LOOPBACK = "127.0.0.1"
#: At most this many frames a wall second leave for the pages (the page draws at 60 Hz).
PUSH_HZ = 25
#: Frames a page opened mid-run gets first, for its traces and track (2 min at PUSH_HZ).
HISTORY_FRAMES = 120 * PUSH_HZ
#: Wall seconds the pages get to take the last frame when a run ends.
LAST_FRAME_GRACE_S = 0.2
_START_TIMEOUT_S = 10.0


class ViewServer:
    """Serves the view of a live run (:meth:`publish` its reports) or of a recording.

    Binds ``127.0.0.1:port`` at once (port 0: any free port; :attr:`url` tells), so a
    taken port is a :class:`ViewError` here, before the run starts.
    """

    def __init__(
        self, port: int = VIEW_PORT, *, name: str = "", recording: Recording | None = None
    ) -> None:
        try:
            self._sock = socket.create_server((LOOPBACK, port))
        except OSError as error:
            reason = str(error) if error.errno is None else os.strerror(error.errno)
            raise ViewError(
                f"cannot serve the view on {LOOPBACK}:{port} ({reason}); "
                "is another view running there? (--view-port picks another port)"
            ) from None
        self.port: int = self._sock.getsockname()[1]
        self.url = f"http://{LOOPBACK}:{self.port}/"
        self._page = (resources.files(__package__) / "static" / "index.html").read_text()
        self._hello: dict[str, object] = {"type": "live", "name": name}
        if recording is not None:
            self._hello = {"type": "recording", "name": recording.name,
                           "duration": recording.duration_s, "frames": recording.frames,
                           "events": recording.events}  # fmt: skip
        self._live = recording is None
        self._latest: Progress | None = None  # the slot: written by the loop, read here
        self._sampled: Progress | None = None
        self._history: deque[Frame] = deque(maxlen=HISTORY_FRAMES)
        self._message = ""
        self._version = 0
        self._closing = False  # the run ended: each page gets its last frame and is let go
        self._loop = asyncio.new_event_loop()
        self._changed = asyncio.Condition()
        self._stop = asyncio.Event()
        self._ready = threading.Event()
        self._failure: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="rig-view", daemon=True)
        self._thread.start()
        if not self._ready.wait(_START_TIMEOUT_S) or self._failure is not None:
            self.close()
            raise ViewError(f"the view server did not start ({self._failure or 'timeout'})")

    def publish(self, progress: Progress) -> None:
        """Called by the loop: store the newest report; returns at once, whoever watches."""
        self._latest = progress

    def close(self) -> None:
        """Push the last report, close the pages' sockets and stop the thread."""
        if self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._stop.set)
            self._thread.join(_START_TIMEOUT_S)
        if not self._thread.is_alive():
            self._loop.close()
        self._sock.close()

    def __enter__(self) -> ViewServer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- the server's thread -------------------------------------------------------------

    def _run(self) -> None:
        try:
            self._loop.run_until_complete(self._serve())
        except BaseException as error:  # reported by the constructor, or lost at the end
            self._failure = error
            self._ready.set()

    async def _serve(self) -> None:
        origins = [
            None,
            Origin(f"http://{LOOPBACK}:{self.port}"),
            Origin(f"http://localhost:{self.port}"),
        ]
        # A page that stopped reading must not hold the end of a run: 1 s for its close.
        async with serve(self._client, sock=self._sock, process_request=self._http,
                         origins=origins, compression=None, close_timeout=1.0):  # fmt: skip
            self._ready.set()
            sampler = asyncio.create_task(self._sample_forever()) if self._live else None
            await self._stop.wait()
            if sampler is not None:
                sampler.cancel()
                self._sample()
                self._closing = True
                await self._notify()
                await asyncio.sleep(LAST_FRAME_GRACE_S)

    def _http(self, connection: ServerConnection, request: Request) -> Response | None:
        """The page for ``/``, the WebSocket handshake for ``/ws``, 404 otherwise."""
        if request.path == "/ws":
            return None
        if request.path not in ("/", "/index.html"):
            return connection.respond(HTTPStatus.NOT_FOUND, "not found\n")
        response = connection.respond(HTTPStatus.OK, self._page)
        del response.headers["Content-Type"]
        response.headers["Content-Type"] = "text/html; charset=utf-8"
        response.headers["Cache-Control"] = "no-store"
        return response

    async def _sample_forever(self) -> None:
        while True:
            if self._sample():
                await self._notify()
            await asyncio.sleep(1 / PUSH_HZ)

    def _sample(self) -> bool:
        """Turn a new report into the message every page gets next; False: nothing new."""
        progress = self._latest
        if progress is None or progress is self._sampled:
            return False
        self._sampled = progress
        frame = live_frame(progress)
        self._history.append(frame)
        self._message = json.dumps({"type": "frame", "frame": frame, "duration":
                                    progress.duration_s})  # fmt: skip
        self._version += 1
        return True

    async def _notify(self) -> None:
        async with self._changed:
            self._changed.notify_all()

    async def _client(self, connection: ServerConnection) -> None:
        """One page: the hello (recording, or the history so far), then the newest frames."""
        with contextlib.suppress(ConnectionClosed):
            hello = dict(self._hello)
            if self._live:
                hello["frames"] = list(self._history)
                hello["duration"] = None if self._sampled is None else self._sampled.duration_s
            sent = self._version

            def moved_on() -> bool:  # a frame newer than the page's, or the end of the run
                return self._version != sent or self._closing

            await connection.send(json.dumps(hello))
            if not self._live:
                await connection.wait_closed()
                return
            while not self._closing:
                async with self._changed:
                    await self._changed.wait_for(moved_on)
                if self._version != sent:
                    sent = self._version
                    await connection.send(self._message)
