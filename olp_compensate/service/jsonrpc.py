"""JSON-RPC 2.0 framing: one request (or a batch) as bytes in, the answer as bytes out.

Errors follow the specification's codes (-32700 parse error, -32600 invalid request,
-32601 method not found, -32602 invalid params, -32603 internal error) and the service's
own (-32001 a path outside the served folders, -32002 a file or value the library refused,
-32003 a request over the size limit); every message is one line a person can act on.
"""

from __future__ import annotations

import logging

from . import codec
from .calls import Service, ServiceError

PARSE_ERROR = -32700
INVALID_REQUEST = -32600
METHOD_NOT_FOUND = -32601
INTERNAL_ERROR = -32603
TOO_LARGE = -32003
METHODS = ("compensate_poses", "compensate_program")
MAX_BATCH = 1000
"""Requests accepted in one JSON-RPC batch."""

log = logging.getLogger(__name__)


def error(code: int, message: str, id_=None) -> dict:
    """A JSON-RPC error response."""
    return {"jsonrpc": "2.0", "error": {"code": code, "message": message}, "id": id_}


def encode(response) -> bytes:
    """A response (or batch) as one line of JSON (:mod:`.codec`)."""
    return codec.dumps(response)


def too_large(limit: int) -> bytes:
    """The answer to a request over ``limit`` bytes."""
    return encode(error(TOO_LARGE, f"request larger than {limit} bytes refused; send fewer "
                                   f"poses per request or start the service with a larger "
                                   f"--max-request-bytes"))


def handle(service: Service, data: bytes) -> bytes | None:
    """The answer to one JSON-RPC message ``data`` (None for notifications only)."""
    try:
        message = codec.loads(data)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        return encode(error(PARSE_ERROR, f"not valid JSON in UTF-8 ({_short(exc)})"))
    if isinstance(message, list):
        if not message:
            return encode(error(INVALID_REQUEST, "an empty batch: send at least one request"))
        if len(message) > MAX_BATCH:
            return encode(error(INVALID_REQUEST, f"a batch of {len(message)} requests; send "
                                                 f"at most {MAX_BATCH}"))
        answers = [a for a in (_one(service, m) for m in message) if a is not None]
        return _encoded(answers) if answers else None
    answer = _one(service, message)
    return None if answer is None else _encoded(answer)


def _encoded(answer) -> bytes:
    """``answer`` as bytes, or an internal error where it cannot be JSON (a bug)."""
    try:
        return encode(answer)
    except (TypeError, ValueError) as exc:
        log.exception("answer not JSON")
        id_ = answer.get("id") if isinstance(answer, dict) else None
        return encode(error(INTERNAL_ERROR, f"internal error (the answer is not JSON: "
                                            f"{_short(exc)}); please report it", id_))


def _one(service: Service, message) -> dict | None:
    if not isinstance(message, dict):
        return error(INVALID_REQUEST, "expected a JSON-RPC 2.0 request object")
    id_ = message.get("id")
    if not (id_ is None or isinstance(id_, (str, int)) and not isinstance(id_, bool)):
        return error(INVALID_REQUEST, "id: expected a string or an integer")
    if message.get("jsonrpc") != "2.0":
        return error(INVALID_REQUEST, 'jsonrpc: expected "2.0"', id_)
    method = message.get("method")
    if not isinstance(method, str):
        return error(INVALID_REQUEST, "method: expected the method name (string)", id_)
    notification = "id" not in message
    if method not in METHODS:
        answer = error(METHOD_NOT_FOUND, f"method {method!r} unknown; the methods are "
                                         f"{', '.join(METHODS)}", id_)
    else:
        try:
            result = service.call(method, message.get("params", {}))
            answer = {"jsonrpc": "2.0", "result": result, "id": id_}
        except ServiceError as exc:
            answer = error(exc.code, exc.message, id_)
        except (MemoryError, RecursionError) as exc:
            answer = error(INTERNAL_ERROR, f"request too large or deep to compute "
                                           f"({type(exc).__name__})", id_)
        except Exception as exc:   # a bug: answered, logged, and the service goes on
            log.exception("internal error in %s", method)
            answer = error(INTERNAL_ERROR, f"internal error ({type(exc).__name__}: "
                                           f"{_short(exc)}); please report it", id_)
    return None if notification else answer


def _short(exc: Exception) -> str:
    return " ".join(str(exc).split())[:200]
