"""``olp-fix serve``: the compensation service for tools that are not Python.

Without ``--http`` it answers JSON-RPC 2.0 lines on standard input, one line each on
standard output, until the input ends (for a parent process that starts it). With
``--http HOST:PORT`` it answers ``POST /rpc`` and describes itself at ``GET /openapi.json``
(port 0: any free port, printed). Files are read only under ``--root``. Exit codes: 0 input
ended or stopped; 1 bad arguments (a remote address without --allow-remote, a port in use).
Ctrl-C and SIGTERM stop it (exit 0).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import DataError
from .common import run_guarded

DEFAULT_LIMIT = 16 * 1024 * 1024


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="olp-fix serve", description=__doc__.splitlines()[0],
                                epilog="Methods: compensate_poses, compensate_program (see "
                                       "the README and GET /openapi.json).")
    p.add_argument("--http", metavar="HOST:PORT",
                   help="answer HTTP on this address (default: JSON lines on stdin/stdout)")
    p.add_argument("--root", default=".", metavar="DIR",
                   help="the folder whose files requests may name (default: the current one)")
    p.add_argument("--max-request-bytes", type=int, default=DEFAULT_LIMIT, metavar="N",
                   help=f"refuse a request (line or body) larger than this (default "
                        f"{DEFAULT_LIMIT})")
    p.add_argument("--allow-remote", action="store_true",
                   help="listen on an address other machines reach (default: loopback only)")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="more logging on stderr; -v also shows tracebacks")
    return p


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[::1]:PORT`` for IPv6) -> (host, port); DataError when malformed."""
    host, sep, port = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise DataError(f"--http: expected HOST:PORT (for example 127.0.0.1:8765), got "
                        f"{text!r}")
    return host, int(port)


def run(args) -> int:
    from ..service.calls import Service

    root = Path(args.root)
    if not root.is_dir():
        raise DataError(f"--root: {args.root} is not a folder")
    if args.max_request_bytes < 1024:
        raise DataError(f"--max-request-bytes: at least 1024, got {args.max_request_bytes}")
    service = Service(root)
    if args.http is None:
        from ..service.stdio import serve_lines

        print(f"olp-fix serve: JSON-RPC lines on standard input, files under "
              f"{service.root}", file=sys.stderr, flush=True)
        try:
            serve_lines(service, sys.stdin.buffer, sys.stdout.buffer, args.max_request_bytes)
        except KeyboardInterrupt:       # Ctrl-C or SIGTERM: the way a service is stopped
            print("olp-fix serve: stopped", file=sys.stderr)
        return 0
    return _serve_http(args, service)


def _serve_http(args, service) -> int:
    from ..service.http import RpcServer, is_loopback

    host, port = parse_address(args.http)
    loopback = is_loopback(host)
    if not loopback and not args.allow_remote:
        raise DataError(f"--http {args.http}: not a loopback address; other machines could "
                        f"send requests. Use 127.0.0.1, or add --allow-remote to mean it")
    try:
        server = RpcServer((host, port), service, args.max_request_bytes)
    except OSError as exc:
        raise DataError(f"--http {args.http}: cannot listen ({exc.strerror or exc})") from None
    bound_host, bound_port = server.server_address[:2]
    reach = ("loopback only" if loopback else
             "REACHABLE FROM OTHER MACHINES (--allow-remote): no authentication")
    print(f"olp-fix serve: listening on http://{_url_host(bound_host)}:{bound_port}/rpc "
          f"({reach}), files under {service.root}", file=sys.stderr, flush=True)
    with server:
        try:
            server.serve_forever(poll_interval=0.2)
        except KeyboardInterrupt:       # Ctrl-C or SIGTERM: the way a service is stopped
            print("olp-fix serve: stopped", file=sys.stderr)
    return 0


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def main(argv: list[str] | None = None) -> int:
    """``olp-fix serve`` as a function (argv after ``serve``); returns the exit code."""
    args = build_parser().parse_args(argv)
    return run_guarded(lambda: run(args), args.verbose, "olp-fix serve")
