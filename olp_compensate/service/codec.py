"""JSON bytes in and out of the service: orjson where it is installed (the ``service``
extra: it encodes an answer of 100 poses 50x faster than the standard library, which
otherwise costs about the solve itself), the standard library's json otherwise. Both give
the same values: finite numbers only (NaN and Infinity are refused when read, never
written), UTF-8."""

from __future__ import annotations

import json

try:   # an optional speed-up, not a dependency
    import orjson
except ImportError:   # pragma: no cover - depends on the installation
    orjson = None

NAME = "orjson" if orjson is not None else "json"


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def loads_std(data: bytes):
    """The standard library's reading of ``data`` (ValueError when not JSON)."""
    return json.loads(data.decode("utf-8"), parse_constant=_no_constant)


def dumps_std(value) -> bytes:
    """The standard library's compact writing of ``value`` (ValueError for NaN)."""
    return json.dumps(value, separators=(",", ":"), allow_nan=False).encode("utf-8")


if orjson is not None:
    def loads(data: bytes):
        """``data`` read as JSON (ValueError, a subclass, when it is not)."""
        return orjson.loads(data)

    def dumps(value) -> bytes:
        """``value`` as compact JSON (every value the service answers is finite)."""
        return orjson.dumps(value)
else:   # pragma: no cover - depends on the installation
    loads, dumps = loads_std, dumps_std
