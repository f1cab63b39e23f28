"""A plain HTTP server with Range support on loopback for the tests (127.0.0.1 only, a
random port, stopped by the tests); moto's S3 server is benchmarks/loopback_s3.py.

The HTTP server serves ``root``; it answers ``Range: bytes=a-b`` with 206 and records
every request (method, path, range) so tests can see that readers use ranged reads.
Paths under ``/forbidden/`` answer 403, paths under ``/slow/`` wait ``slow_s`` first.
"""

from __future__ import annotations

import contextlib
import re
import socket
import threading
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from benchmarks.loopback_s3 import LOOPBACK

_RANGE = re.compile(r"bytes=(\d+)-(\d*)")


class RangeServer(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, root: Path, slow_s: float = 0.0) -> None:
        self.root = root
        self.slow_s = slow_s
        self.requests: list[tuple[str, str, str | None]] = []
        super().__init__((LOOPBACK, 0), _Handler)

    def handle_error(self, request: object, client_address: object) -> None:
        pass  # a client that gave up (a timeout test) breaks the pipe: not the test's output

    @property
    def url(self) -> str:
        return f"http://{LOOPBACK}:{self.server_address[1]}"


class _Handler(BaseHTTPRequestHandler):
    server: RangeServer
    protocol_version = "HTTP/1.1"

    def log_message(self, format: str, *args: object) -> None:
        pass

    def _target(self) -> Path | None:
        rel = self.path.split("?", 1)[0].lstrip("/")
        for special in ("forbidden/", "slow/"):
            if rel.startswith(special):
                rel = rel[len(special):]
        p = (self.server.root / rel).resolve()
        return p if p.is_file() and p.is_relative_to(self.server.root.resolve()) else None

    def _answer(self, body: bool) -> None:
        self.server.requests.append((self.command, self.path, self.headers.get("Range")))
        if self.path.startswith("/slow/"):
            time.sleep(self.server.slow_s)
        if self.path.startswith("/forbidden/"):
            self._empty(403)
            return
        p = self._target()
        if p is None:
            self._empty(404)
            return
        size = p.stat().st_size
        start, end, status = 0, size - 1, 200
        m = _RANGE.fullmatch(self.headers.get("Range") or "")
        if m:
            start = int(m[1])
            end = min(int(m[2]) if m[2] else size - 1, size - 1)
            if start >= size:
                self._empty(416)
                return
            status = 206
        self.send_response(status)
        self.send_header("Content-Type", "application/octet-stream")
        self.send_header("Accept-Ranges", "bytes")
        self.send_header("Content-Length", str(end - start + 1))
        if status == 206:
            self.send_header("Content-Range", f"bytes {start}-{end}/{size}")
        self.end_headers()
        if body:
            with p.open("rb") as f:
                f.seek(start)
                self.wfile.write(f.read(end - start + 1))

    def _empty(self, status: int) -> None:
        self.send_response(status)
        self.send_header("Content-Length", "0")
        self.end_headers()

    def do_HEAD(self) -> None:
        self._answer(body=False)

    def do_GET(self) -> None:
        self._answer(body=True)


@contextlib.contextmanager
def http_server(root: Path, slow_s: float = 0.0) -> Iterator[RangeServer]:
    server = RangeServer(root, slow_s)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.shutdown()
        server.server_close()
        thread.join(5)


def closed_port() -> int:
    """A loopback port nothing listens on (bound, then closed)."""
    with socket.socket() as s:
        s.bind((LOOPBACK, 0))
        return int(s.getsockname()[1])
