"""``compensate_poses``: a batch of poses of a request, solved together.

Each request pose is ``target`` (wobj_T_target), ``tool`` (flange_T_tool) and ``wobj``
(base_T_wobj), 4x4 row-major in the request's length unit; ``config`` the configuration
numbers of the dialect (RAPID confdata ``[cf1, cf4, cf6, cfx]``). The answer per pose: the
target to write (4x4, same frame and unit; the target as given where not compensated, with
the status saying so), the controller axes the real arm takes (degrees; mm for a prismatic
axis; None where no solution was found), the status ('ok', 'singular' or why not), the
note olp-fix writes for it, and ``config``: the RAPID confdata of those joints, to write
with the pose (None where not compensated).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import chain

import numpy as np

from ..compensation.explained import compensate_explained
from ..compensation.pose import Compensator
from .calls import DIALECTS, INVALID_PARAMS, ORTHONORMAL_TOL, ServiceError, matrix

MAX_POSES = 100_000
"""Poses accepted in one request (the request size limit comes first in practice)."""
CONFIG_DIALECTS = ("rapid",)
"""Dialects whose ``config`` numbers compensate_poses reads (others: whole programs)."""
KEYS = ("target", "tool", "wobj", "config", "dialect")
_KEYS = frozenset(KEYS)
_DIALECT_SET = frozenset(DIALECTS)
_HAS_TARGET = frozenset(["target"]).issubset
IDENTITY = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0]]
_NUMBER = {int, float}


@dataclass(frozen=True)
class PoseRequests:
    """The poses of one request, in metres: ``targets``, ``tools``, ``wobjs`` (m, 4, 4);
    ``confdata`` (m, 4) int and ``has_config`` (m,) bool (rows without one: any
    configuration, the branch nearest zero)."""

    targets: np.ndarray
    tools: np.ndarray
    wobjs: np.ndarray
    confdata: np.ndarray
    has_config: np.ndarray


def read_requests(poses, scale: float) -> PoseRequests:
    """The request's ``poses`` list checked and in metres (``scale``: m per unit)."""
    if not isinstance(poses, list) or not poses:
        raise ServiceError(INVALID_PARAMS, "poses: expected a non-empty list of objects "
                                           "with a 'target' 4x4 matrix")
    if len(poses) > MAX_POSES:
        raise ServiceError(INVALID_PARAMS, f"poses: {len(poses)} poses in one request; send "
                                           f"at most {MAX_POSES}")
    if set(map(type, poses)) != {dict}:
        i = next(i for i, p in enumerate(poses) if not isinstance(p, dict))
        raise ServiceError(INVALID_PARAMS, f"poses[{i}]: expected an object with 'target'")
    if not all(map(_KEYS.issuperset, poses)) or not all(map(_HAS_TARGET, poses)):
        _name_bad_keys(poses)
    dialects = [p.get("dialect", "rapid") for p in poses]
    configs = [p.get("config") for p in poses]
    if not (set(map(type, dialects)) == {str} and set(dialects) <= _DIALECT_SET):
        i = next(i for i, d in enumerate(dialects)
                 if not isinstance(d, str) or d not in _DIALECT_SET)
        raise ServiceError(INVALID_PARAMS, f"poses[{i}].dialect: expected one of "
                                           f"{', '.join(DIALECTS)}")
    has_config = np.array([c is not None for c in configs], dtype=bool)
    confdata = _confdata_all(configs, dialects, has_config)
    targets, tools, wobjs = (_matrices(poses, key, scale) for key in ("target", "tool", "wobj"))
    return PoseRequests(targets, tools, wobjs, confdata, has_config)


def _matrices(poses: list[dict], key: str, scale: float) -> np.ndarray:
    """The ``key`` matrices of every pose (identity where absent) as (m, 4, 4) m, checked
    all at once; a bad one is named by :func:`~.calls.matrix`."""
    values = [p.get(key, IDENTITY) for p in poses]
    values = [IDENTITY if v is None else v for v in values]
    rows = list(chain.from_iterable(values)) if set(map(type, values)) == {list} else []
    plain = len(rows) == 4 * len(values) and set(map(type, rows)) == {list}
    if plain:      # 4 lists of numbers each: read in one pass (bools and strings refused)
        numbers = list(chain.from_iterable(rows))
        plain = len(numbers) == 16 * len(values) and set(map(type, numbers)) <= _NUMBER
    if plain:
        a = np.fromiter(numbers, dtype=float, count=len(numbers)).reshape(-1, 4, 4)
        plain = set(map(len, rows)) == {4}
    if plain:
        rotation = a[:, :3, :3]
        gram = np.einsum("mji,mjk->mik", rotation, rotation) - np.eye(3)
        plain = (np.all(np.isfinite(a)) and np.all(a[:, 3] == (0, 0, 0, 1))
                 and np.max(np.abs(gram)) <= ORTHONORMAL_TOL
                 and np.all(np.linalg.det(rotation) > 0))
    if not plain:     # one of them is not a rigid transform: say which and why
        for i, v in enumerate(values):
            matrix(v, f"poses[{i}].{key}", scale)
    a[:, :3, 3] *= scale
    return a


def _name_bad_keys(poses: list[dict]) -> None:
    """ServiceError for the first pose with an unknown key or without a target."""
    for i, pose in enumerate(poses):
        unknown = sorted(set(pose) - _KEYS)
        if unknown:
            raise ServiceError(INVALID_PARAMS, f"poses[{i}]: unknown key(s) "
                                               f"{', '.join(unknown)}; expected "
                                               f"{', '.join(KEYS)}")
        if "target" not in pose:
            raise ServiceError(INVALID_PARAMS, f"poses[{i}].target: missing (4x4 matrix)")


def _confdata_all(configs: list, dialects: list[str], has_config: np.ndarray) -> np.ndarray:
    """(m, 4) int confdata of the poses that give one (zeros elsewhere)."""
    rows = [c if c is not None else [0, 0, 0, 0] for c in configs]
    numbers = list(chain.from_iterable(rows)) if set(map(type, rows)) == {list} else []
    fine = (len(numbers) == 4 * len(rows) and set(map(len, rows)) == {4}
            and set(map(type, numbers)) == {int} and all(-1000 < v < 1000 for v in numbers)
            and all(d in CONFIG_DIALECTS for d, c in zip(dialects, configs) if c is not None))
    if fine:
        return np.array(numbers, dtype=int).reshape(-1, 4)
    for i, (config, dialect) in enumerate(zip(configs, dialects)):   # name the bad one
        if config is None:
            continue
        if dialect not in CONFIG_DIALECTS:
            raise ServiceError(INVALID_PARAMS, f"poses[{i}].config: the configuration "
                                               f"numbers of {dialect} are read only in "
                                               f"whole programs (compensate_program); leave "
                                               f"config out for the branch nearest zero")
        _confdata(config, f"poses[{i}].config")
    raise AssertionError("unreachable: a bad config was not named")   # pragma: no cover


def _confdata(value, name: str) -> np.ndarray:
    if (not isinstance(value, list) or len(value) != 4
            or not all(isinstance(v, int) and not isinstance(v, bool) and abs(v) < 1000
                       for v in value)):
        raise ServiceError(INVALID_PARAMS, f"{name}: expected RAPID confdata, 4 integers "
                                           f"[cf1, cf4, cf6, cfx]")
    return np.array(value, dtype=int)


def compensate_requests(comp: Compensator, req: PoseRequests, scale: float) -> list[dict]:
    """The answer of each pose of ``req`` in its order (see the module docstring)."""
    m = len(req.targets)
    answers: list[dict | None] = [None] * m
    for with_config in (True, False):
        rows = np.flatnonzero(req.has_config == with_config)
        if len(rows):
            part = _solve(comp, req.targets[rows], req.tools[rows], req.wobjs[rows],
                          req.confdata[rows] if with_config else None, scale)
            for row, answer in zip(rows.tolist(), part):
                answers[row] = answer
    return answers   # type: ignore[return-value]


def _solve(comp: Compensator, targets, tools, wobjs, confdata, scale: float) -> list[dict]:
    """Solve rows sharing whether a configuration was given; their answers."""
    batch = compensate_explained(comp, targets, tools, wobjs, confdata)
    shown = batch.poses.copy()
    shown[:, :3, 3] /= scale
    finite = np.all(np.isfinite(batch.joints_deg), axis=1).tolist()
    return [{"pose": pose, "joints_deg": joints if fine else None, "status": status,
             "note": note, "config": config if ok else None}
            for pose, joints, fine, status, note, config, ok in zip(
                shown.tolist(), batch.joints_deg.tolist(), finite, batch.status,
                batch.notes, batch.config.tolist(), batch.ok.tolist())]
