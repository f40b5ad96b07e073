"""The service over HTTP: ``POST /rpc`` with a JSON-RPC body, ``GET /openapi.json``.

The standard library's threading server (one thread per connection; the computations
themselves take turns, see :class:`~.calls.Service`). A request body must state its
``Content-Length`` and stay under the size limit; a client that leaves mid-request costs a
line in the log, never the service.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import socket
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from .calls import Service
from .jsonrpc import INTERNAL_ERROR, INVALID_REQUEST, encode, error, handle, too_large
from .openapi import openapi

log = logging.getLogger(__name__)
IDLE_TIMEOUT_S = 60.0
"""A connection that sends nothing for this long is closed (a stalled client holds no
thread for ever)."""


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address) is this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class RpcServer(ThreadingHTTPServer):
    """An HTTP server of one :class:`Service` with a request size limit (bytes)."""

    daemon_threads = True
    allow_reuse_address = True
    request_queue_size = 128
    """Connections waiting to be accepted (the standard library's 5 refuses a burst of
    clients connecting at once)."""

    def __init__(self, address: tuple[str, int], service: Service, limit: int):
        self.address_family = (socket.AF_INET6 if ":" in address[0] else socket.AF_INET)
        self.service = service
        self.limit = limit
        self.description = encode(openapi())
        super().__init__(address, RpcHandler)


class RpcHandler(BaseHTTPRequestHandler):
    """Answers ``POST /rpc`` and ``GET /openapi.json``; everything else 404/405."""

    server: RpcServer
    protocol_version = "HTTP/1.1"
    timeout = IDLE_TIMEOUT_S
    server_version = "olp-fix-serve"

    def setup(self) -> None:
        super().setup()
        # the headers and the body go out in two writes: without this the client's
        # delayed acknowledgement holds the body back ~40 ms (Nagle's algorithm)
        self.connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def do_GET(self) -> None:  # noqa: N802 (the standard library's name)
        path = self.path.split("?", 1)[0]
        if path == "/openapi.json":
            self._send(HTTPStatus.OK, self.server.description)
        elif path == "/rpc":
            self._send(HTTPStatus.METHOD_NOT_ALLOWED,
                       encode(error(INVALID_REQUEST, "POST a JSON-RPC request to /rpc")),
                       {"Allow": "POST"})
        else:
            self._not_found()

    def do_POST(self) -> None:  # noqa: N802
        if self.path.split("?", 1)[0] != "/rpc":
            self._not_found()
            return
        limit = self.server.limit
        if self.headers.get("Transfer-Encoding", "").lower() not in ("", "identity"):
            self._refuse(HTTPStatus.LENGTH_REQUIRED, "send the body with a Content-Length "
                                                     "(chunked bodies are not read)")
            return
        try:
            length = int(self.headers.get("Content-Length", ""))
        except ValueError:
            self._refuse(HTTPStatus.LENGTH_REQUIRED, "Content-Length: expected the body's "
                                                     "length in bytes")
            return
        if length < 0:
            self._refuse(HTTPStatus.BAD_REQUEST, "Content-Length: negative")
            return
        if length > limit:
            self._send(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, too_large(limit),
                       {"Connection": "close"})
            self.close_connection = True
            return
        try:
            body = self.rfile.read(length)
        except (OSError, TimeoutError):    # reset, or silent past the idle timeout
            body = b""
        if len(body) < length:   # the client left mid-request: nobody to answer
            log.info("client %s left after %d of %d bytes", self.client_address[0],
                     len(body), length)
            self.close_connection = True
            return
        try:
            answer = handle(self.server.service, body)
        except Exception as exc:   # a bug: answered all the same, the service goes on
            log.exception("internal error")
            self._send(HTTPStatus.INTERNAL_SERVER_ERROR, encode(error(
                INTERNAL_ERROR, f"internal error ({type(exc).__name__}); please report it")))
            return
        if answer is None:
            self.send_response(HTTPStatus.NO_CONTENT)
            self.send_header("Content-Length", "0")
            self.end_headers()
        else:
            self._send(HTTPStatus.OK, answer)

    def _refuse(self, status: HTTPStatus, message: str) -> None:
        self._send(status, encode(error(INVALID_REQUEST, message)), {"Connection": "close"})
        self.close_connection = True

    def _not_found(self) -> None:
        self._send(HTTPStatus.NOT_FOUND, json.dumps(
            {"error": f"{self.path} not found; POST /rpc or GET /openapi.json"}).encode())

    def _send(self, status: HTTPStatus, body: bytes, headers: dict | None = None) -> None:
        try:
            self.send_response(status)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(body)))
            for key, value in (headers or {}).items():
                self.send_header(key, value)
            self.end_headers()
            self.wfile.write(body)
        except (BrokenPipeError, ConnectionResetError):
            log.info("client %s left before its answer", self.client_address[0])
            self.close_connection = True

    def log_message(self, format: str, *args) -> None:  # noqa: A002 (the library's name)
        log.debug("%s %s", self.client_address[0], format % args)
