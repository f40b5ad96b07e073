"""The service's methods on plain JSON values: ``compensate_poses`` and
``compensate_program``, with the calibrations kept in memory.

Every path a request names is taken relative to the service's root folder and refused when
it leads outside it (through ``..`` or a link). A calibration is read at each call (its
bytes, a few kB) and its solver kept in memory keyed by the SHA-256 of those bytes, so an
edited calib.json is used at the next call and an unchanged one costs no new set-up.
Errors are :class:`ServiceError` (a JSON-RPC code and a message a person can act on).
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

from ..errors import OlpError
from .requests import (BAD_INPUT, DEFAULT_NAMES, DIALECTS, INVALID_PARAMS, OUTSIDE_ROOT, UNITS,
                       ServiceError)

CACHED_CALIBRATIONS = 16


@dataclass(frozen=True)
class Loaded:
    """A calibration in memory: its solver and the SHA-256 of the calib.json bytes."""

    sha256: str
    compensator: object


class Service:
    """The methods of one running service (thread-safe: one call computes at a time).

    root : the folder every path must lie in (resolved through links).
    """

    def __init__(self, root: str | Path = "."):
        self.root = Path(root).resolve()
        self._cache: OrderedDict[str, Loaded] = OrderedDict()
        self._lock = threading.Lock()

    # -- paths and calibrations --------------------------------------------------------

    def path(self, value, name: str) -> Path:
        """The file ``value`` (relative to the root, or absolute) if it lies under the root."""
        if not isinstance(value, str) or not value:
            raise ServiceError(INVALID_PARAMS, f"{name}: expected a file path (string), got "
                                               f"{_kind(value) if value != '' else 'an empty one'}")
        if "\0" in value:
            raise ServiceError(INVALID_PARAMS, f"{name}: a path cannot hold a NUL character")
        try:
            path = (self.root / value).resolve()
            value.encode("utf-8")
        except (OSError, ValueError, RuntimeError):   # a link loop, an unpaired surrogate
            raise ServiceError(INVALID_PARAMS, f"{name}: {value!r} is not a usable path") from None
        if path != self.root and self.root not in path.parents:
            raise ServiceError(OUTSIDE_ROOT, f"{name}: {value} is outside the folder the "
                                             f"service serves ({self.root}); start it with "
                                             f"--root covering that file")
        return path

    def calibration(self, value, name: str = "calibration") -> Loaded:
        """The calibration of file ``value`` (read, hashed, solver kept by hash)."""
        path = self.path(value, name)
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise ServiceError(BAD_INPUT, f"{name}: cannot read {value} "
                                          f"({exc.strerror or exc})") from None
        digest = hashlib.sha256(data).hexdigest()
        loaded = self._cache.get(digest)
        if loaded is not None:
            self._cache.move_to_end(digest)
            return loaded
        loaded = Loaded(digest, _compensator(data, str(value)))
        self._cache[digest] = loaded
        while len(self._cache) > CACHED_CALIBRATIONS:
            self._cache.popitem(last=False)
        return loaded

    # -- methods -----------------------------------------------------------------------

    def call(self, method: str, params) -> dict:
        """Run ``method`` on ``params`` (a dict); the JSON result. Raises ServiceError."""
        if not isinstance(params, dict):
            raise ServiceError(INVALID_PARAMS, f"params: expected an object with named "
                                               f"parameters, got {_kind(params)}")
        handler = {"compensate_poses": self._compensate_poses,
                   "compensate_program": self._compensate_program}[method]
        with self._lock:
            try:
                return handler(params)
            except OlpError as exc:
                raise ServiceError(BAD_INPUT, str(exc)) from None

    def _compensate_poses(self, params: dict) -> dict:
        from .poses import compensate_requests, read_requests

        _only(params, "compensate_poses", ("calibration", "controller", "units", "poses"))
        loaded = self.calibration(params.get("calibration"))
        _refuse_controller(params)
        units = params.get("units", "mm")
        if not isinstance(units, str) or units not in UNITS:
            raise ServiceError(INVALID_PARAMS, f"units: expected 'mm' or 'm', got "
                                               f"{_shown(units)}")
        requests = read_requests(params.get("poses"), UNITS[units])
        return {"poses": compensate_requests(loaded.compensator, requests, UNITS[units])}

    def _compensate_program(self, params: dict) -> dict:
        from .program import compensate_text

        _only(params, "compensate_program",
              ("calibration", "controller", "dialect", "text", "file", "frames", "dat"))
        loaded = self.calibration(params.get("calibration"))
        _refuse_controller(params)
        dialect = params.get("dialect")
        if dialect not in DIALECTS:
            raise ServiceError(INVALID_PARAMS, f"dialect: expected one of "
                                               f"{', '.join(DIALECTS)}, got "
                                               f"{_shown(dialect)}")
        text = params.get("text")
        if not isinstance(text, str):
            raise ServiceError(INVALID_PARAMS, f"text: expected the program as a string, "
                                               f"got {_kind(text)}")
        file = params.get("file", DEFAULT_NAMES[dialect])
        if not isinstance(file, str) or not file or "/" in file or "\\" in file:
            raise ServiceError(INVALID_PARAMS, "file: expected a bare file name (it names the "
                                               "program in the report; nothing is read)")
        dat = params.get("dat")
        if dat is not None and (dialect != "krl" or not isinstance(dat, str)
                                or not file.lower().endswith(".src")):
            raise ServiceError(INVALID_PARAMS, "dat: the text of a KRL .src's data list "
                                               "(a string, with dialect krl and file NAME.src)")
        frames = params.get("frames")
        frames_path = None if frames is None else self.path(frames, "frames")
        return compensate_text(loaded.compensator, dialect, text, file, frames_path, dat)


def _compensator(data: bytes, source: str):
    """The solver of calib.json bytes (the regional one when the calibration has regions,
    as olp-fix takes)."""
    from ..compensation.pose import Compensator
    from ..io.calibration_file import calibration_from_dict, check_numbers

    try:
        doc = json.loads(data.decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise ServiceError(BAD_INPUT, f"calibration: {source} is not valid JSON ({exc})") from None
    try:
        check_numbers(doc, source)
        calibration = calibration_from_dict(doc, source, None)
        if calibration.regions:
            from ..compensation.regions import RegionalCompensator

            return RegionalCompensator(calibration)
        return Compensator(calibration)
    except OlpError as exc:
        raise ServiceError(BAD_INPUT, f"calibration: {exc}") from None


def _refuse_controller(params: dict) -> None:
    if params.get("controller") is not None:
        raise ServiceError(INVALID_PARAMS, "controller: a controller model other than the "
                                           "data sheet is not supported by this version of "
                                           "olp-compensate; leave it out")


def _only(params: dict, method: str, known: tuple[str, ...]) -> None:
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise ServiceError(INVALID_PARAMS, f"{method}: unknown parameter(s) "
                                           f"{', '.join(unknown)}; expected "
                                           f"{', '.join(known)}")


def _shown(value) -> str:
    """A request's value in a message: a short string quoted, else what it is."""
    if isinstance(value, str) and len(value) <= 40:
        return json.dumps(value)
    return _kind(value)


def _kind(value) -> str:
    """How a JSON value is described in a message."""
    if value is None:
        return "nothing"
    names = {bool: "a boolean", int: "a number", float: "a number", str: "a string",
             list: "a list", dict: "an object"}
    return names.get(type(value), type(value).__name__)
