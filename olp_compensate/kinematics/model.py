"""The calibration model: a chain of elementary transforms with named parameters.

Frames are assigned automatically from the nominal chain at its zero position (Motta 2006,
sections 3-4, after Schroer): each pair of consecutive joint axes is classified, and the link
between them gets the parameterization that has no singularity there:

- axes more than 45 degrees apart (perpendicular or general): Denavit-Hartenberg,
  ``Rz(q_i + theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`` (eq. 16);
- axes less than 45 degrees apart (parallel): Hayati,
  ``Rz(q_i + theta_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)`` (eq. 17), singular only where D-H is
  regular;
- a prismatic joint moves along z instead: ``Tz(q_i + d_i)`` then the same link terms.

The first joint frame is fixed to the base: z along axis 1, origin where axis 1 is closest to
the base origin, x from the base x. The last joint carries only its zero offset; a constant
transform then reaches the flange. Parameters are named ``j<joint>.<name>`` (``j3.beta``),
joints counted from 1; values are SI (m, rad). The link values themselves come from
:mod:`olp_compensate.kinematics.frame_assignment`.

:func:`forward` evaluates the chain for a batch of joint vectors and returns positions, the
flange frames and, on request, the analytic derivatives with respect to every parameter and
every joint (the geometric Jacobian), all from one pass. :func:`fixed_chain` is the same
chain at fixed parameter values, fused per joint, for fast batches of poses and joint
Jacobians (inverse kinematics).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .buffers import reusable_array
from .conventions import invert_pose
from .frame_assignment import dh_link, first_frame, hayati_link
from .robot import Robot

if TYPE_CHECKING:
    from .fixed_chain import FixedChain

PARALLEL_BELOW_DEG = 45.0
"""Consecutive axes closer than this angle get Hayati's parameterization, others D-H."""


@dataclass(frozen=True)
class Parameter:
    """A named model parameter: ``unit`` is ``'m'`` or ``'rad'``; ``nominal`` in that unit."""

    name: str
    unit: str
    nominal: float
    joint: int  # 0-based joint the parameter belongs to

    @property
    def display_unit(self) -> str:
        return "mm" if self.unit == "m" else "deg"

    @property
    def display_scale(self) -> float:
        """Factor from SI to the display unit (mm or deg)."""
        return 1e3 if self.unit == "m" else 180.0 / np.pi


@dataclass(frozen=True)
class Step:
    """One elementary transform: rotation about / translation along local ``axis`` (0, 1, 2
    for x, y, z) by ``parameter value (+ joint value)``."""

    rotation: bool
    axis: int
    parameter: int
    joint: int | None = None


@dataclass(frozen=True)
class KinematicModel:
    """The parameterized chain of one robot (constant; values live outside).

    ``base_T_first``: base frame to the first joint frame (4, 4); ``last_T_flange``: the last
    joint frame (after its motion) to the flange (4, 4); ``conventions[i]`` is ``'dh'`` or
    ``'hayati'`` for the link from joint i to joint i+1.
    """

    robot_name: str
    fingerprint: str
    joint_kinds: tuple[str, ...]
    base_T_first: np.ndarray
    steps: tuple[Step, ...]
    last_T_flange: np.ndarray
    parameters: tuple[Parameter, ...]
    conventions: tuple[str, ...]
    convention: str = "auto"

    @property
    def n_joints(self) -> int:
        return len(self.joint_kinds)

    @property
    def n_parameters(self) -> int:
        return len(self.parameters)

    @property
    def nominal(self) -> np.ndarray:
        """Nominal parameter values, shape (P,), SI."""
        return np.array([p.nominal for p in self.parameters])

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    def index(self, name: str) -> int:
        """Position of a parameter by its exact name."""
        for k, p in enumerate(self.parameters):
            if p.name == name:
                return k
        raise KeyError(name)


@dataclass(frozen=True)
class ChainResult:
    """What :func:`forward` computes for m joint vectors (base frame, SI).

    ``points``: (m, 3) positions of the tool points; ``flange``: (m, 4, 4) flange poses;
    with ``jacobian=True`` also ``dpoint_dparam`` (m, 3, P), ``drot_dparam`` (m, 3, P)
    (angular velocity per unit parameter), ``dpoint_dq`` (m, 3, n) and ``drot_dq`` (m, 3, n).
    The derivative arrays are views that may share memory (a joint's columns are those of
    its zero offset's step): read them, do not write into them.
    """

    points: np.ndarray
    flange: np.ndarray
    dpoint_dparam: np.ndarray | None = None
    drot_dparam: np.ndarray | None = None
    dpoint_dq: np.ndarray | None = None
    drot_dq: np.ndarray | None = None


class _ChainBuilder:
    """Collects steps and parameters while walking the nominal axes."""

    def __init__(self):
        self.steps: list[Step] = []
        self.parameters: list[Parameter] = []

    def add(self, rotation: bool, axis: int, name: str, joint: int, value: float,
            moves_with: int | None = None) -> None:
        self.parameters.append(Parameter(name=f"j{joint + 1}.{name}",
                                         unit="rad" if rotation else "m",
                                         nominal=float(value), joint=joint))
        self.steps.append(Step(rotation, axis, len(self.parameters) - 1, moves_with))


def build_model(robot: Robot, convention: str = "auto") -> KinematicModel:
    """Assign frames to ``robot`` and return its calibration model.

    ``convention='auto'`` picks D-H or Hayati per link (singularity-free); ``'dh'`` uses D-H
    everywhere (singular for parallel axes; kept to show why 'auto' exists).
    """
    if convention not in ("auto", "dh"):
        raise ValueError(f"convention must be 'auto' or 'dh', got {convention!r}")
    points, directions = robot.joint_axes_at_zero()
    kinds = tuple(j.kind for j in robot.joints)
    n = len(kinds)

    first = first_frame(points[0], directions[0])

    chain = _ChainBuilder()
    frame = first
    conventions = []
    cos_limit = np.cos(np.radians(PARALLEL_BELOW_DEG))
    for i in range(n - 1):
        revolute = kinds[i] == "revolute"
        parallel = abs(np.dot(frame[:3, 2], directions[i + 1])) > cos_limit
        if parallel and convention == "auto":
            (theta, a, alpha, beta), frame = hayati_link(frame, points[i + 1], directions[i + 1])
            if revolute:
                chain.add(True, 2, "theta", i, theta, moves_with=i)
            else:
                chain.add(False, 2, "d", i, 0.0, moves_with=i)
                chain.add(True, 2, "theta", i, theta)
            chain.add(False, 0, "a", i, a)
            chain.add(True, 0, "alpha", i, alpha)
            chain.add(True, 1, "beta", i, beta)
            conventions.append("hayati")
        else:
            (theta, d, a, alpha), frame = dh_link(frame, points[i + 1], directions[i + 1])
            chain.add(True, 2, "theta", i, theta,
                      moves_with=i if revolute else None)
            chain.add(False, 2, "d", i, d, moves_with=None if revolute else i)
            chain.add(False, 0, "a", i, a)
            chain.add(True, 0, "alpha", i, alpha)
            conventions.append("dh")
    last = n - 1
    if kinds[last] == "revolute":
        chain.add(True, 2, "theta", last, 0.0, moves_with=last)
    else:
        chain.add(False, 2, "d", last, 0.0, moves_with=last)
    frame_inv = np.eye(4)  # frame is rigid: its inverse is (R^T, -R^T t)
    frame_inv[:3, :3] = frame[:3, :3].T
    frame_inv[:3, 3] = -frame[:3, :3].T @ frame[:3, 3]
    last_T_flange = frame_inv @ robot.flange_at_zero()
    return KinematicModel(robot_name=robot.name, fingerprint=robot.fingerprint, joint_kinds=kinds,
                          base_T_first=first, steps=tuple(chain.steps),
                          last_T_flange=last_T_flange, parameters=tuple(chain.parameters),
                          conventions=tuple(conventions), convention=convention)


def forward(model: KinematicModel, values: np.ndarray, q: np.ndarray,
            tool_points: np.ndarray | None = None, jacobian: bool = False) -> ChainResult:
    """Forward kinematics of the model for m joint vectors.

    Parameters
    ----------
    values : (P,) parameter values, SI.
    q : (m, n) joint values, rad or m.
    tool_points : (m, 3) points in the flange frame (m); default the flange origin.
    jacobian : also return the analytic derivatives (see :class:`ChainResult`).

    The derivatives are twists: a step turning about the unit axis w through the point o
    moves the tool point p by ``w x (p - o)`` and turns the flange by ``w`` per unit of its
    value; a step translating along w moves p by ``w``. One pass through the chain records
    w and o of every step straight into the output arrays; the cross products with the
    final p are then taken for all steps at once.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    m = q.shape[0]
    scalars = np.asarray(values, dtype=float).tolist()  # constant steps in float arithmetic
    steps = model.steps
    n_par, n_q = model.n_parameters, model.n_joints
    moving = [s for s, step in enumerate(steps) if step.joint is not None]
    if moving:  # the values of the moving steps, (k, m), with cosines and sines, at once
        moved = q.T[[steps[s].joint for s in moving]]
        moved += np.array([scalars[steps[s].parameter] for s in moving])[:, None]
        cosines, sines = np.cos(moved), np.sin(moved)
        slot = dict(zip(moving, range(len(moving))))
    if jacobian:
        by_parameter = [step.parameter for step in steps]
        direct = sorted(by_parameter) == list(range(n_par))  # one step per parameter
        n_rows = n_par if direct else len(steps)
        # One block for the derivatives, (k, 3, m) each: [dp/dpar | dr/dpar | scratch]; the
        # joints' are views of their steps' rows.
        block = reusable_array("forward", (3 * n_rows, 3, m), slots=2)
        dpoint, drot, scratch = block[:n_rows], block[n_rows:2 * n_rows], block[2 * n_rows:]
        row_of = by_parameter if direct else list(range(len(steps)))
    # Frame columns and origin as (3, m) arrays (contiguous per component, cheap to update);
    # they start as (3, 1) and broadcast to m at the first step that moves.
    bt = model.base_T_first
    cols = [bt[:3, k, None].copy() for k in range(3)]
    origin = bt[:3, 3, None].copy()
    for s, step in enumerate(steps):
        value = scalars[step.parameter] if step.joint is None else moved[slot[s]]
        if jacobian:
            # the axis w, and for rotations the origin o in the dpoint row (replaced below)
            drot[row_of[s]] = cols[step.axis]
            if step.rotation:
                dpoint[row_of[s]] = origin
        if step.rotation:
            if step.joint is None:
                c, s_ = math.cos(value), math.sin(value)
            else:
                c, s_ = cosines[slot[s]], sines[slot[s]]
            j, k = (step.axis + 1) % 3, (step.axis + 2) % 3
            cols[j], cols[k] = c * cols[j] + s_ * cols[k], c * cols[k] - s_ * cols[j]
        else:
            origin = origin + value * cols[step.axis]
    spare = scratch[:8] if jacobian and n_rows >= 8 else None  # free until the cross products
    flange, p = _flange_and_point(model.last_T_flange, cols, origin, tool_points, m, spare)
    points = np.ascontiguousarray(p.T)
    if not jacobian:
        return ChainResult(points=points, flange=flange)

    translations = [row_of[s] for s, step in enumerate(steps) if not step.rotation]
    _twists_to_columns(dpoint, drot, scratch, p, translations)
    if direct:
        dp_dpar, dr_dpar = dpoint, drot
    else:  # several steps share a parameter: sum their columns
        dp_dpar, dr_dpar = (np.zeros((n_par, 3, m)) for _ in range(2))
        np.add.at(dp_dpar, by_parameter, dpoint)
        np.add.at(dr_dpar, by_parameter, drot)
    dp_dq, dr_dq = _joint_columns(dpoint, drot, [steps[s].joint for s in moving],
                                  [row_of[s] for s in moving], n_q)
    # (m, 3, k) views of the (k, 3, m) arrays; ``.transpose(2, 1, 0)`` gives the contiguous
    # (k, 3, m) layout back.
    return ChainResult(points=points, flange=flange,
                       dpoint_dparam=dp_dpar.transpose(2, 1, 0),
                       drot_dparam=dr_dpar.transpose(2, 1, 0),
                       dpoint_dq=dp_dq.transpose(2, 1, 0), drot_dq=dr_dq.transpose(2, 1, 0))


def _flange_and_point(last_T_flange: np.ndarray, cols: list[np.ndarray], origin: np.ndarray,
                      tool_points: np.ndarray | None, m: int, spare: np.ndarray | None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(flange poses (m, 4, 4), tool points (3, m)), base frame: the last joint frame
    (axes ``cols``, ``origin``, (3, m) or (3, 1) each) times the constant ``last_T_flange``, one
    (4, 4) @ (4, 3m) product on the rows (x, y, z axes, origin); ``tool_points`` (m, 3) in
    the flange frame (default its origin); ``spare``: (8, 3, m) free memory or None."""
    if spare is not None:
        last, flange_rows = spare[:4], spare[4:8]
    else:
        last, flange_rows = np.empty((4, 3, m)), np.empty((4, 3, m))
    last[0], last[1], last[2], last[3] = cols[0], cols[1], cols[2], origin
    np.matmul(last_T_flange.T, last.reshape(4, -1), out=flange_rows.reshape(4, -1))
    flange_cols, flange_origin = flange_rows[:3], flange_rows[3]
    flange = np.zeros((m, 4, 4))
    flange[:, :3, :] = flange_rows.transpose(2, 1, 0)
    flange[:, 3, 3] = 1.0
    if tool_points is None:
        return flange, flange_origin.copy()
    tool = np.asarray(tool_points, dtype=float).reshape(-1, 3).T
    return flange, (flange_origin + flange_cols[0] * tool[0] + flange_cols[1] * tool[1]
                    + flange_cols[2] * tool[2])


def _twists_to_columns(dpoint: np.ndarray, drot: np.ndarray, scratch: np.ndarray,
                       p: np.ndarray, translations: list[int]) -> None:
    """In place: rows (k, 3, m) holding each step's axis w (``drot``) and, for rotations,
    its origin o (``dpoint``) become the derivatives of the point p (3, m) and of the
    flange's rotation: ``w x (p - o)`` and w for a rotation, w and 0 for the translations
    (rows ``translations``); ``scratch`` (k, 3, m) holds the intermediate products."""
    if translations:  # o = 0 here; fixed below
        dpoint[translations] = 0.0
    np.subtract(p, dpoint, out=dpoint)
    w0, w1, w2 = drot[:, 0], drot[:, 1], drot[:, 2]
    r0, r1, r2 = dpoint[:, 0], dpoint[:, 1], dpoint[:, 2]
    c0, c1, t = scratch[:, 0], scratch[:, 1], scratch[:, 2]
    np.subtract(np.multiply(w1, r2, out=c0), np.multiply(w2, r1, out=t), out=c0)
    np.subtract(np.multiply(w2, r0, out=c1), np.multiply(w0, r2, out=t), out=c1)
    np.subtract(np.multiply(w0, r1, out=r2), np.multiply(w1, r0, out=t), out=r2)
    r0[...] = c0
    r1[...] = c1
    if translations:  # through the scratch rows: no temporary
        np.take(drot, translations, axis=0, out=scratch[:len(translations)])
        dpoint[translations] = scratch[:len(translations)]
        drot[translations] = 0.0


def _joint_columns(dpoint: np.ndarray, drot: np.ndarray, joints: list[int], rows: list[int],
                   n_q: int) -> tuple[np.ndarray, np.ndarray]:
    """Derivatives (n_q, 3, m) with respect to the joints: the rows of their moving steps
    (``joints[i]`` moves the step in row ``rows[i]``), as strided views when each joint
    moves one step, else summed."""
    m = dpoint.shape[2]
    if sorted(joints) == list(range(n_q)):  # one moving step per joint: its rows, as views
        order = [rows[i] for i in sorted(range(n_q), key=joints.__getitem__)]
        stride = order[1] - order[0] if n_q > 1 else 1
        if stride > 0 and order == list(range(order[0], order[0] + stride * n_q, stride)):
            return (dpoint[order[0]:order[-1] + 1:stride], drot[order[0]:order[-1] + 1:stride])
        return dpoint[order], drot[order]
    dp_dq, dr_dq = (np.zeros((n_q, 3, m)) for _ in range(2))
    np.add.at(dp_dq, joints, dpoint[rows])
    np.add.at(dr_dq, joints, drot[rows])
    return dp_dq, dr_dq


def joint_frames(model: KinematicModel, values: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Frame of each joint (z on its axis) just before its own motion, base frame, for one
    joint vector ``q`` (n,); shape (n, 4, 4)."""
    current = model.base_T_first.copy()
    frames = np.empty((model.n_joints, 4, 4))
    seen = set()
    for step in model.steps:
        if step.joint is not None and step.joint not in seen:
            frames[step.joint] = current
            seen.add(step.joint)
        value = values[step.parameter] + (q[step.joint] if step.joint is not None else 0.0)
        elementary = np.eye(4)
        if step.rotation:
            c, s = np.cos(value), np.sin(value)
            j, k = (step.axis + 1) % 3, (step.axis + 2) % 3
            elementary[j, j], elementary[j, k], elementary[k, j], elementary[k, k] = c, -s, s, c
        else:
            elementary[step.axis, 3] = value
        current = current @ elementary
    return frames


def joint_frames_batch(model: KinematicModel, values: np.ndarray, q: np.ndarray) -> np.ndarray:
    """:func:`joint_frames` for joint vectors ``q`` (m, n) at once; shape (m, n, 4, 4)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    m = len(q)
    current = np.broadcast_to(model.base_T_first, (m, 4, 4)).copy()
    frames = np.empty((m, model.n_joints, 4, 4))
    seen = set()
    for step in model.steps:
        if step.joint is not None and step.joint not in seen:
            frames[:, step.joint] = current
            seen.add(step.joint)
        value = values[step.parameter] + (q[:, step.joint] if step.joint is not None
                                          else np.zeros(m))
        elementary = np.broadcast_to(np.eye(4), (m, 4, 4)).copy()
        if step.rotation:
            c, s = np.cos(value), np.sin(value)
            j, k = (step.axis + 1) % 3, (step.axis + 2) % 3
            elementary[:, j, j], elementary[:, j, k] = c, -s
            elementary[:, k, j], elementary[:, k, k] = s, c
        else:
            elementary[:, step.axis, 3] = value
        current = current @ elementary
    return frames


def fixed_chain(model: KinematicModel, values: np.ndarray) -> FixedChain | None:
    """The chain of the model with parameter ``values``, or None unless the model is six
    revolute joints each turning its frame about z (checked at a few joint vectors)."""
    if model.joint_kinds != ("revolute",) * 6:
        return None
    frames = joint_frames(model, values, np.zeros(6))
    flange = forward(model, values, np.zeros((1, 6))).flange[0]
    links = [invert_pose(frames[k]) @ frames[k + 1] for k in range(5)]
    links.append(invert_pose(frames[5]) @ flange)
    from .fixed_chain import FixedChain

    chain = FixedChain(first=frames[0], links=np.array(links))
    q = spread_joints(8, 6)
    pose, jac = chain.flange_and_jacobian(q)
    expected = forward(model, values, q, jacobian=True)
    expected_jac = np.concatenate([expected.dpoint_dq, expected.drot_dq], axis=1)
    if not (np.allclose(pose, expected.flange, rtol=0.0, atol=1e-12)
            and np.allclose(jac, expected_jac, rtol=0.0, atol=1e-12)):
        return None
    return chain


def spread_joints(m: int, n: int, seed: int = 0) -> np.ndarray:
    """(m, n) joint values (rad) spread over [-pi, pi] on every axis, the same for a
    ``seed``: pi sin(k phi) for k = seed m n + 1, ... with phi the golden angle, whose
    multiples modulo 2 pi fill the circle evenly (numpy.random would take 6 ms to import
    in every olp-fix)."""
    k = np.arange(seed * m * n + 1, (seed + 1) * m * n + 1, dtype=float)
    return np.pi * np.sin(GOLDEN_ANGLE * k).reshape(m, n)


GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))
"""rad, about 2.39996."""


def __getattr__(name: str):
    """``FixedChain`` is still importable from here (PEP 562), loaded when first asked for:
    identification never uses it (issue 32)."""
    if name == "FixedChain":
        from .fixed_chain import FixedChain

        return FixedChain
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
