"""What the tests of ``gfimu live`` share: the command's environment, free ports, waiting for the
command's UDP socket, and a one-connection TCP server that sends bytes the way a sensor's server would."""

from __future__ import annotations

import os
import socket
import struct
import threading
import time
from pathlib import Path
from typing import Self

REPO = Path(__file__).resolve().parents[1]


def env() -> dict:
    """The environment of a ``python -m gfimu`` subprocess: this checkout first on the path."""
    return {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}


def free_port(kind=socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until_bound(port: int, proc, timeout_s: float = 120.0) -> None:
    """Wait until a UDP socket on 127.0.0.1:``port`` is bound (read from /proc/net/udp, so a loaded
    machine's slow start-up cannot make the test send before the command listens), or ``proc`` ended."""
    table = Path("/proc/net/udp")
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and proc.poll() is None:
        if not table.exists():  # not Linux: fall back to a fixed wait
            time.sleep(3.0)
            return
        if any(line.split()[1].endswith(f":{port:04X}") for line in table.read_text().splitlines()[1:]):
            time.sleep(0.2)
            return
        time.sleep(0.05)


class OneShotServer:
    """Listens on 127.0.0.1 (:attr:`port`), accepts one connection, sends ``data`` (in pieces of ``chunk``
    bytes, or at once), waits ``hold_s`` and closes it, with a reset (RST) when ``reset``. A context
    manager: the listening socket is closed on exit."""

    def __init__(self, data: bytes, chunk: int | None = None, hold_s: float = 0.5, reset: bool = False) -> None:
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.bind(("127.0.0.1", 0))
        self._server.listen(1)
        self.port = self._server.getsockname()[1]
        self._data, self._chunk, self._hold_s, self._reset = data, chunk or len(data) or 1, hold_s, reset
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        conn, _ = self._server.accept()
        for i in range(0, len(self._data), self._chunk):
            conn.sendall(self._data[i:i + self._chunk])
        threading.Event().wait(self._hold_s)
        if self._reset:
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # close = RST
        conn.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self._server.close()
