"""What every service call shares: JSON-RPC error codes, units, the dialects and file names
of requests, :class:`ServiceError`, and the check of a request's pose matrix."""

from __future__ import annotations

import numpy as np

INVALID_PARAMS = -32602
OUTSIDE_ROOT = -32001
"""A path outside the folders the service was started with."""
BAD_INPUT = -32002
"""A file or value the library refused (an :class:`~olp_compensate.errors.OlpError`)."""
UNITS = {"mm": 1e-3, "m": 1.0}
"""Length unit of a request -> metres per unit."""
DIALECTS = ("rapid", "vplus", "krl", "fanuc", "val3", "urscript")
DEFAULT_NAMES = {"rapid": "program.mod", "vplus": "program.pg", "krl": "program.src",
                 "fanuc": "program.ls", "val3": "program.dtx", "urscript": "program.script"}
"""The file name a program text is reported under when the request gives none."""
ORTHONORMAL_TOL = 1e-6
"""Largest |R^T R - I| entry accepted in a request's rotation (a pose rounded to about 7
significant digits passes; a scaled or sheared matrix does not)."""


class ServiceError(Exception):
    """A refused request: ``code`` (JSON-RPC error code) and ``message`` (one line)."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


def matrix(value, name: str, scale: float) -> np.ndarray:
    """A 4x4 row-major pose of a request as (4, 4) m; ServiceError naming ``name``."""
    rows_ok = (isinstance(value, list) and len(value) == 4
               and all(isinstance(r, list) and len(r) == 4 for r in value)
               and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       for r in value for v in r))
    a = np.array(value, dtype=float) if rows_ok else None
    if a is None:
        raise ServiceError(INVALID_PARAMS, f"{name}: expected a 4x4 matrix as 4 rows of 4 "
                                           f"numbers")
    if not np.all(np.isfinite(a)):
        raise ServiceError(INVALID_PARAMS, f"{name}: every number must be finite")
    rotation = a[:3, :3]
    if (np.max(np.abs(a[3] - (0, 0, 0, 1))) > 0
            or np.max(np.abs(rotation.T @ rotation - np.eye(3))) > ORTHONORMAL_TOL
            or np.linalg.det(rotation) < 0):
        raise ServiceError(INVALID_PARAMS, f"{name}: not a rigid transform (the rotation "
                                           f"part must be orthonormal with determinant +1 "
                                           f"to {ORTHONORMAL_TOL:g}, the last row 0 0 0 1)")
    a[:3, 3] *= scale
    return a
