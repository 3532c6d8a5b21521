"""A live meshcat server for one scene: start it, send the commands, serve until stopped.

The server is meshcat's own ``ZMQWebSocketBridge`` in a child process (it keeps the scene
tree and replays it to every browser that connects); we talk to it over a zmq REQ
socket with timeouts, so nothing here can hang on a dead server.

It listens on ``host`` only (default 127.0.0.1, this machine), for HTTP and websocket alike
as for zmq: meshcat 0.3.2 passes its ``host`` to the zmq socket but lets tornado listen
on every interface, which the server script below corrects.
"""

from __future__ import annotations

import os
import selectors
import subprocess
import sys
import tempfile
import time

import umsgpack
import zmq

from ..errors import ContactdynError
from .writer import ViewerScene

__all__ = ["LiveViewer", "LOOPBACK"]

START_TIMEOUT = 20.0  #: [s] for the server to print its URLs
REPLY_TIMEOUT = 20.0  #: [s] for the server to acknowledge one command

LOOPBACK = "127.0.0.1"

_SERVER = """
import os, sys
from meshcat.servers.zmqserver import ZMQWebSocketBridge

class Bridge(ZMQWebSocketBridge):
    def make_app(self):  # HTTP and websocket on self.host only (meshcat's own listens on all interfaces)
        app = super().make_app()
        listen = app.listen
        app.listen = lambda port, **kwargs: listen(port, address=self.host, **kwargs)
        return app

port = int(sys.argv[2]) if sys.argv[2] else None
bridge = Bridge(zmq_url=sys.argv[1] or None, host=sys.argv[3], port=port)
print("zmq_url=" + bridge.zmq_url, flush=True)
print("web_url=" + bridge.web_url, flush=True)
sys.stdout = open(os.devnull, "w")
bridge.run()
"""


class LiveViewer:
    """meshcat server child process + a client socket. Use as a context manager."""

    def __init__(self, port: int | None = None, zmq_url: str | None = None, host: str = LOOPBACK):
        self._stderr = tempfile.TemporaryFile()
        args = [sys.executable, "-u", "-c", _SERVER, zmq_url or "", str(port) if port else "", host]
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=self._stderr, stdin=subprocess.DEVNULL)
        self.socket = None
        try:
            lines = self._read_lines(2)
            self.zmq_url = lines[0].removeprefix("zmq_url=")
            self.url = lines[1].removeprefix("web_url=")
            self.socket = zmq.Context.instance().socket(zmq.REQ)
            for option, value in ((zmq.RCVTIMEO, int(REPLY_TIMEOUT * 1000)), (zmq.SNDTIMEO, int(REPLY_TIMEOUT * 1000)),
                                  (zmq.LINGER, 0)):
                self.socket.setsockopt(option, value)
            self.socket.connect(self.zmq_url)
        except BaseException:
            self.close()
            raise

    def _read_lines(self, n: int) -> list[str]:
        """The server's first n stdout lines, read unbuffered from the pipe with a deadline."""
        fd = self.proc.stdout.fileno()
        buffer = b""
        deadline = time.monotonic() + START_TIMEOUT
        with selectors.DefaultSelector() as sel:
            sel.register(fd, selectors.EVENT_READ)
            while buffer.count(b"\n") < n:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise ContactdynError(f"meshcat server did not start: {self._reason()}")
                if sel.select(min(left, 0.5)):
                    chunk = os.read(fd, 4096)
                    if not chunk:  # the server exited
                        self.proc.wait(timeout=5.0)
                        raise ContactdynError(f"meshcat server did not start: {self._reason()}")
                    buffer += chunk
        return [line.strip() for line in buffer.decode(errors="replace").splitlines()[:n]]

    def _reason(self) -> str:
        code = self.proc.poll()
        self._stderr.seek(0)
        err = self._stderr.read().decode(errors="replace").strip().splitlines()
        last = err[-1] if err else "no message"
        return f"exit code {code}: {last}" if code is not None else f"no URL within {START_TIMEOUT:g} s"

    def show(self, scene: ViewerScene) -> None:
        """Send every command of the scene (the server keeps them for browsers connecting later)."""
        for cmd in scene.commands:
            self.socket.send_multipart([cmd["type"].encode(), cmd["path"].encode(), umsgpack.packb(cmd)])
            try:
                reply = self.socket.recv()
            except zmq.Again:
                raise ContactdynError(f"meshcat server at {self.zmq_url} did not answer within "
                                      f"{REPLY_TIMEOUT:g} s") from None
            if reply != b"ok":
                raise ContactdynError(f"meshcat server refused a {cmd['type']} command: {reply[:200]!r}")

    def alive(self) -> bool:
        return self.proc.poll() is None

    def wait(self) -> None:
        """Serve until the server exits or the user interrupts (Ctrl+C)."""
        try:
            while self.alive():
                time.sleep(0.5)
        except KeyboardInterrupt:
            pass

    def close(self) -> None:
        if self.socket is not None:
            self.socket.close(linger=0)
            self.socket = None
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5.0)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        self._stderr.close()

    def __enter__(self) -> LiveViewer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
