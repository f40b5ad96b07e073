"""The service on a pipe: one JSON-RPC message per line in, one answer per line out.

For a parent process that starts ``olp-fix serve`` and keeps it: each line of standard
input is a request (or a batch), each answer one line on standard output, in order;
notifications get no line. A line over the size limit is answered with an error and
skipped; an empty line is ignored. End of input ends the service.
"""

from __future__ import annotations

from typing import BinaryIO

from .calls import Service
from .jsonrpc import handle, too_large

READ_CHUNK = 1 << 16


def serve_lines(service: Service, stdin: BinaryIO, stdout: BinaryIO, limit: int) -> int:
    """Answer the lines of ``stdin`` on ``stdout`` until end of input; the number of
    messages answered."""
    answered = 0
    while True:
        line = stdin.readline(limit + 1)
        if not line:
            return answered
        if len(line) > limit and not line.endswith(b"\n"):
            _skip_line(stdin)
            answer = too_large(limit)
        elif not line.strip():
            continue
        else:
            answer = handle(service, line)
        if answer is not None:
            stdout.write(answer + b"\n")
            stdout.flush()
            answered += 1


def _skip_line(stdin: BinaryIO) -> None:
    """Read and drop the rest of an over-long line (kept out of memory)."""
    while True:
        chunk = stdin.readline(READ_CHUNK)
        if not chunk or chunk.endswith(b"\n"):
            return
