"""``compensate_poses``: a batch of poses of a request, solved together.

Each request pose is ``target`` (wobj_T_target), ``tool`` (flange_T_tool) and ``wobj``
(base_T_wobj), 4x4 row-major in the request's length unit; ``config`` the configuration
numbers of the dialect (RAPID confdata ``[cf1, cf4, cf6, cfx]``). The answer per pose: the
target to write (4x4, same frame and unit; the target as given where not compensated, with
the status saying so), the controller axes the real arm takes (degrees; mm for a prismatic
axis; None where no solution was found), the status ('ok', 'singular' or why not) and the
note olp-fix writes for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..compensation.explained import compensate_explained
from ..compensation.pose import Compensator
from .calls import DIALECTS, INVALID_PARAMS, ServiceError, matrix

MAX_POSES = 100_000
"""Poses accepted in one request (the request size limit comes first in practice)."""
CONFIG_DIALECTS = ("rapid",)
"""Dialects whose ``config`` numbers compensate_poses reads (others: whole programs)."""
_KEYS = ("target", "tool", "wobj", "config", "dialect")


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
    m = len(poses)
    targets, tools, wobjs = (np.empty((m, 4, 4)) for _ in range(3))
    confdata = np.zeros((m, 4), dtype=int)
    has_config = np.zeros(m, dtype=bool)
    for i, pose in enumerate(poses):
        where = f"poses[{i}]"
        if not isinstance(pose, dict):
            raise ServiceError(INVALID_PARAMS, f"{where}: expected an object with 'target'")
        unknown = sorted(set(pose) - set(_KEYS))
        if unknown:
            raise ServiceError(INVALID_PARAMS, f"{where}: unknown key(s) {', '.join(unknown)}; "
                                               f"expected {', '.join(_KEYS)}")
        if "target" not in pose:
            raise ServiceError(INVALID_PARAMS, f"{where}.target: missing (4x4 matrix)")
        targets[i] = matrix(pose["target"], f"{where}.target", scale)
        tools[i] = _optional(pose.get("tool"), f"{where}.tool", scale)
        wobjs[i] = _optional(pose.get("wobj"), f"{where}.wobj", scale)
        dialect = pose.get("dialect", "rapid")
        if dialect not in DIALECTS:
            raise ServiceError(INVALID_PARAMS, f"{where}.dialect: expected one of "
                                               f"{', '.join(DIALECTS)}")
        config = pose.get("config")
        if config is not None:
            if dialect not in CONFIG_DIALECTS:
                raise ServiceError(INVALID_PARAMS, f"{where}.config: the configuration "
                                                   f"numbers of {dialect} are read only in "
                                                   f"whole programs (compensate_program); "
                                                   f"leave config out for the branch nearest "
                                                   f"zero")
            confdata[i] = _confdata(config, f"{where}.config")
            has_config[i] = True
    return PoseRequests(targets, tools, wobjs, confdata, has_config)


def _optional(value, name: str, scale: float) -> np.ndarray:
    return np.eye(4) if value is None else matrix(value, name, scale)


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
    out = []
    for i, status in enumerate(batch.status):
        shown = batch.poses[i].copy()
        shown[:3, 3] /= scale
        joints = batch.joints_deg[i]
        finite = bool(np.all(np.isfinite(joints)))
        out.append({"pose": shown.tolist(),
                    "joints_deg": [float(v) for v in joints] if finite else None,
                    "status": status, "note": batch.notes[i]})
    return out
