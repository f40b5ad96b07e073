"""Clients of ``olp-fix serve`` for the tests: the service as a subprocess, spoken to over
its pipe or over HTTP on 127.0.0.1, every wait bounded. JSON through the service's own
codec (orjson where installed: a client in another language has a fast one too)."""

from __future__ import annotations

import http.client
import os
import re
import select
import subprocess
import sys
import time
from pathlib import Path

from olp_compensate.service.codec import dumps, loads

WAIT_S = 60.0


def command(*args: str) -> list[str]:
    return [sys.executable, "-m", "olp_compensate.cli.fix", "serve", *args]


def _readline(stream, timeout: float = WAIT_S) -> bytes:
    """One line of a pipe, or AssertionError after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    fd = stream.fileno()
    buf = b""
    while not buf.endswith(b"\n"):
        left = deadline - time.monotonic()
        assert left > 0, f"no answer line within {timeout} s (got {buf[:200]!r})"
        ready, _, _ = select.select([fd], [], [], left)
        if ready:
            chunk = os.read(fd, 1 << 20)
            if not chunk:
                return buf
            buf += chunk
    return buf


class PipeService:
    """``olp-fix serve`` on a pipe: :meth:`send` a line, :meth:`receive` the answer."""

    def __init__(self, root: Path, *args: str):
        self.process = subprocess.Popen(command("--root", str(root), *args),
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, cwd=root)
        self.pending = b""

    def send(self, line: bytes) -> None:
        self.process.stdin.write(line + b"\n")
        self.process.stdin.flush()

    def receive(self, timeout: float = WAIT_S) -> dict:
        while b"\n" not in self.pending:
            more = _readline(self.process.stdout, timeout)
            assert more, "the service closed its output"
            self.pending += more
        line, self.pending = self.pending.split(b"\n", 1)
        return loads(line)

    def call(self, method: str, params: dict, id_=1) -> dict:
        self.send(dumps({"jsonrpc": "2.0", "method": method, "params": params, "id": id_}))
        return self.receive()

    def close(self) -> tuple[int, str]:
        self.process.stdin.close()
        code = self.process.wait(timeout=WAIT_S)
        err = self.process.stderr.read().decode()
        self.process.stdout.close()
        self.process.stderr.close()
        return code, err


class HttpService:
    """``olp-fix serve --http 127.0.0.1:0``; ``port`` read from its first stderr line."""

    def __init__(self, root: Path, *args: str):
        self.process = subprocess.Popen(command("--root", str(root), "--http",
                                                "127.0.0.1:0", *args),
                                        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, cwd=root)
        self.banner = _readline(self.process.stderr).decode()
        found = re.search(r"http://127\.0\.0\.1:(\d+)/rpc", self.banner)
        assert found, self.banner
        self.port = int(found.group(1))
        self.base = f"http://127.0.0.1:{self.port}"

    def request(self, method: str, path: str, body: bytes | None = None,
                headers: dict | None = None) -> tuple[int, bytes]:
        connection = http.client.HTTPConnection("127.0.0.1", self.port, timeout=WAIT_S)
        try:
            connection.request(method, path, body=body, headers=headers or {})
            response = connection.getresponse()
            return response.status, response.read()
        finally:
            connection.close()

    def call(self, method: str, params: dict, id_=1) -> dict:
        body = dumps({"jsonrpc": "2.0", "method": method, "params": params, "id": id_})
        status, data = self.request("POST", "/rpc", body,
                                    {"Content-Type": "application/json"})
        assert status == 200, (status, data[:300])
        return loads(data)

    def close(self) -> tuple[int, str]:
        """Stop it as a parent does (SIGTERM); its exit code and what it wrote on stderr."""
        self.process.terminate()
        code = self.process.wait(timeout=WAIT_S)
        err = self.process.stderr.read().decode()
        self.process.stdout.close()
        self.process.stderr.close()
        return code, err
