"""``compensate_poses``: a batch of poses of a request, solved together.

Each request pose is ``target`` (wobj_T_target), ``tool`` (flange_T_tool) and ``wobj``
(base_T_wobj), 4x4 row-major in the request's length unit; ``config`` the configuration
numbers of the dialect (RAPID confdata ``[cf1, cf4, cf6, cfx]``; the other dialects'
in :mod:`.dialect_poses`), solved as olp-fix reads them in a program. The answer per pose: the
target to write (4x4, same frame and unit; the target as given where not compensated, with
the status saying so), the controller axes the real arm takes (degrees; mm for a prismatic
axis; None where no solution was found), the status ('ok', 'singular' or why not), the
note olp-fix writes for it, ``config``: the dialect's configuration of those joints,
to write with the pose (None where not compensated), and ``model_note``: where
compensated, which fitted-in-a-range parts of the calibration did not apply or did (the
geometric model outside the named effects' fitted ranges, the residual map; the note
olp-fix adds to the row), '' where all of it applied.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import chain

import numpy as np

from ..compensation.explained import compensate_explained
from ..compensation.pose import Compensator
from .requests import DIALECTS, INVALID_PARAMS, ORTHONORMAL_TOL, ServiceError, matrix

MAX_POSES = 100_000
"""Poses accepted in one request (the request size limit comes first in practice)."""
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
    dialects: list
    configs: list
    """Each pose's dialect and its ``config`` as sent (read by :mod:`.dialect_poses` for
    the dialects other than RAPID)."""


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
    rapid = [c if d == "rapid" else None for c, d in zip(configs, dialects)]
    has_config = np.array([c is not None for c in rapid], dtype=bool)
    confdata = _confdata_all(rapid)
    targets, tools, wobjs = (_matrices(poses, key, scale) for key in ("target", "tool", "wobj"))
    return PoseRequests(targets, tools, wobjs, confdata, has_config, dialects, configs)


def _matrices(poses: list[dict], key: str, scale: float) -> np.ndarray:
    """The ``key`` matrices of every pose (identity where absent) as (m, 4, 4) m, checked
    all at once; a bad one is named by :func:`~.requests.matrix`."""
    values = [p.get(key) for p in poses]
    if values.count(None) == len(values):          # none given: the identity for every pose
        return np.broadcast_to(np.eye(4), (len(values), 4, 4)).copy()
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


def _confdata_all(configs: list) -> np.ndarray:
    """(m, 4) int confdata of the RAPID poses that give one (zeros elsewhere)."""
    rows = [c if c is not None else [0, 0, 0, 0] for c in configs]
    numbers = list(chain.from_iterable(rows)) if set(map(type, rows)) == {list} else []
    fine = (len(numbers) == 4 * len(rows) and set(map(len, rows)) == {4}
            and set(map(type, numbers)) == {int} and all(-1000 < v < 1000 for v in numbers))
    if not fine:                                             # name the bad one
        for i, config in enumerate(configs):
            if config is not None:
                _confdata(config, f"poses[{i}].config")
    return np.array(numbers, dtype=int).reshape(-1, 4)


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
    confdata, has_config = req.confdata.copy(), req.has_config.copy()
    others = np.flatnonzero([d != "rapid" for d in req.dialects])
    chosen = None
    if len(others):
        from .dialect_poses import choose_branches, requested_flanges

        chosen = choose_branches(comp, others, req.dialects, req.configs, requested_flanges(
            req.targets[others], req.tools[others], req.wobjs[others]))
        confdata[others] = chosen.confdata
        has_config[others] = True
        for row, (status, note) in chosen.failed.items():
            answers[row] = {"pose": _shown(req.targets[row], scale), "joints_deg": None,
                            "status": status, "note": note, "config": None,
                            "model_note": ""}
    for with_config in (True, False):
        rows = np.flatnonzero((has_config == with_config)
                              & np.array([a is None for a in answers]))
        if len(rows):
            part = _solve(comp, req.targets[rows], req.tools[rows], req.wobjs[rows],
                          confdata[rows] if with_config else None, scale)
            for row, answer in zip(rows.tolist(), part):
                answers[row] = answer
    if chosen is not None:
        _dialect_answers(comp, req, chosen, answers)
    return answers   # type: ignore[return-value]


def _dialect_answers(comp: Compensator, req: PoseRequests, chosen, answers: list) -> None:
    """Answers of the dialect poses in their dialect's configuration, with the rules'
    notes."""
    from .dialect_poses import answer_config

    for row, target in chosen.targets.items():
        answer = answers[row]
        if row in chosen.failed:
            continue
        answer["config"] = (answer_config(comp, req.dialects[row], target,
                                          answer["joints_deg"])
                            if answer["status"] in ("ok", "singular") else None)
        note = chosen.notes.get(row)
        if note:
            answer["note"] = "; ".join(x for x in (answer["note"], note) if x)


def _shown(pose: np.ndarray, scale: float) -> list:
    shown = pose.copy()
    shown[:3, 3] /= scale
    return shown.tolist()


def _solve(comp: Compensator, targets, tools, wobjs, confdata, scale: float) -> list[dict]:
    """Solve rows sharing whether a configuration was given; their answers."""
    batch = compensate_explained(comp, targets, tools, wobjs, confdata)
    shown = batch.poses.copy()
    shown[:, :3, 3] /= scale
    finite = np.all(np.isfinite(batch.joints_deg), axis=1).tolist()
    return [{"pose": pose, "joints_deg": joints if fine else None, "status": status,
             "note": note, "config": config if ok else None, "model_note": model_note}
            for pose, joints, fine, status, note, config, ok, model_note in zip(
                shown.tolist(), batch.joints_deg.tolist(), finite, batch.status,
                batch.notes, batch.config.tolist(), batch.ok.tolist(), batch.model_notes)]
