"""Pose planning: which joint vectors to measure, so that few poses identify the model well.

The identification is linearized at the nominal model (never at a fitted or true one): the
unknowns are exactly those :func:`olp_compensate.calibration.identify.identify` will fit -- device
registration (6), the geometric parameters left free by the same structural freezing
(and by the rank test on the candidate set), and 3 per measured tool point. Each candidate
pose contributes a block ``J_k`` (3 rows per tool point) of the column-scaled identification
Jacobian (:class:`olp_compensate.calibration.problem.IdentificationProblem`, device frame = base
frame; the information is invariant to where the device stands). A design (a set of
poses) has the information matrix ``M = sum_k J_k^T J_k``; with noise sigma per axis the
covariance of the unknowns is ``sigma^2 M^-1``.

Criteria (Atkinson & Donev, *Optimum Experimental Designs*, 1992; in robot calibration
Borm & Menq 1991, observability index O1; Sun & Hollerbach 2008, "Observability index
selection for robot calibration"):

- ``d``: D-optimality, maximize ``log det M`` (O1 to the power of the number of unknowns;
  invariant to how the unknowns are scaled);
- ``i``: I-optimality, minimize ``trace(M^-1 A)``, ``A`` the mean of ``G^T G`` over random
  workspace poses ``G`` (their measured-point rows): the mean squared error of a predicted
  point at random poses per unit noise -- what ``benchmarks/identify.py`` measures.

Both are searched the same way: greedy D-optimal selection (each step adds the pose with the
largest ``det(I + J_k M^-1 J_k^T)``, from ``M = eps I``), then Fedorov exchange passes (each
chosen pose in turn is swapped for the candidate that improves the criterion most; passes
repeat until one gains less than :data:`PASS_TOLERANCE`), D first, then I for ``i``.
Every addition or removal is a rank-3 (3 x points) update of ``M^-1`` and of the
per-candidate 3x3 forms ``J_k M^-1 J_k^T`` (and, for ``i``, ``J_k M^-1 A M^-1 J_k^T``), so
a step costs O(candidates x unknowns), never a refactorization. Restarts from random designs
ended within 1-2 % of the same criterion values, so there is one start. An optional minimum
joint distance keeps the chosen poses apart.

The default is ``i``. Measured on virtual IRB 2400s (0.05 mm noise, one tool point unknown
to the planner, RMS error against the truth at 1,000 new poses, in units of the noise;
plans from 5,000 candidates), I-optimal against D-optimal plans: 40 robots (4 planning
seeds) 1.42 vs 1.42 at 15 poses, 0.93 vs 0.95 at 30, 0.71 vs 0.73 at 50 (random poses 2.50,
1.15, 0.82); ``python benchmarks/identify.py`` (5 robots) 1.29 vs 1.35, 0.88 vs 0.92, 0.68
vs 0.66. So I is as good or slightly better, as its own linearized prediction says
(1.40 vs 1.42, 0.93 vs 0.95, 0.71 vs 0.72): D weighs every unknown alike (the registration
and the tool as much as the arm), while what matters is the predicted point over the
workspace, which is the I criterion. D stays available as the classic scale-free index.

Planned poses lie on the boundary of the candidate set (extreme joint values), so candidates
are drawn inside the limits with a margin; what the cell forbids (collisions, the device's
line of sight) is not known here -- give your own candidates (reachable poses) then. The
tool point is a guess (:data:`DEFAULT_TOOL_M` unless given): the plan is for the nominal
model and that guess, never for a fitted or true robot.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import qr

from ..errors import DataError
from .identifiability import RANK_TOLERANCE, structural_freeze
from .problem import IdentificationProblem
from .unknowns import UnknownLayout
from .measurements import Measurements
from ..kinematics.model import build_model
from ..kinematics.robot import Robot
from .simulate import random_joints
from .design_search import PASS_TOLERANCE, REGULARIZATION  # noqa: F401 (named here before)
from .design_search import Design as _Design  # noqa: F401 (tests reach the search state)
from .design_search import Selection, exchange_passes, greedy_selection

CRITERIA = ("d", "i")
DEFAULT_CRITERION = "i"
"""I-optimal: measured as good as or slightly better than D-optimal (module docstring)."""
DEFAULT_CANDIDATES = 5000
DEFAULT_TEST_POSES = 1000
DEFAULT_MARGIN = 0.1
"""Candidates keep this fraction of each joint range away from the limits (half each side)."""
DEFAULT_TOOL_M = (0.05, 0.0, 0.15)
"""Tool point assumed when none is given (flange frame, m): 150 mm out and 50 mm off the
axis of the last joint (a point on that axis hides some of the wrist's parameters)."""
RANDOM_DRAWS = 21
"""Random designs drawn for the comparison (their median is reported)."""


@dataclass(frozen=True)
class PlanningSpace:
    """The linearized identification over candidate poses, at the nominal model.

    ``candidates``: (K, n) controller joint values, rad (m for prismatic joints);
    ``blocks``: (K, r, u) rows of the unit-scaled identification Jacobian per candidate
    (r = 3 x tool points, u unknowns); ``scale``: (u,) the column scale (RMS over the
    candidates of each column's norm per pose; m per unit of the unknown);
    ``test_information``: (u, u) mean over random test poses and tool points of the scaled
    point Jacobian's ``G^T G``; ``frozen``: parameter name -> reason (as identify says it).
    """

    robot: Robot
    candidates: np.ndarray
    blocks: np.ndarray
    scale: np.ndarray
    test_information: np.ndarray
    unknown_names: list[str]
    frozen: dict[str, str]
    tool_names: list[str]
    tools_m: np.ndarray

    @property
    def n_unknowns(self) -> int:
        return self.blocks.shape[2]

    @property
    def rows_per_pose(self) -> int:
        return self.blocks.shape[1]

    @property
    def min_poses(self) -> int:
        """Fewest poses whose equations outnumber the unknowns (what identify requires)."""
        return self.n_unknowns // self.rows_per_pose + 1


@dataclass(frozen=True)
class DesignQuality:
    """How good a set of poses is, linearized at the nominal model.

    ``log_det``: log det of the information matrix of the unit-scaled Jacobian (-inf when
    singular); ``expected_error``: predicted RMS 3-D error of a measured point at random
    poses, in units of the per-axis noise (inf when singular).
    """

    log_det: float
    expected_error: float


@dataclass(frozen=True)
class PosePlan:
    """Planned poses: ``joints`` (N, n) controller values, rad (m), ``indices`` into the
    candidates; ``quality`` of the plan, ``random`` the median quality of random sets of
    the same size drawn from the same candidates; ``swaps`` made by the exchange passes."""

    joints: np.ndarray
    indices: np.ndarray
    criterion: str
    quality: DesignQuality
    random: DesignQuality
    n_unknowns: int
    n_candidates: int
    unknown_names: list[str] = field(default_factory=list)
    frozen: dict[str, str] = field(default_factory=dict)
    swaps: int = 0


def _jacobian_blocks(robot: Robot, model, free: np.ndarray, joints: np.ndarray,
                     tool_names: list[str], tools: np.ndarray
                     ) -> tuple[np.ndarray, UnknownLayout]:
    """(m, 3T, u) identification Jacobian of every tool point at each controller joint
    vector of ``joints`` (m, n), at the nominal model, device frame = base frame; and the
    layout of the u unknowns."""
    m, per = len(joints), len(tool_names)
    q = np.repeat(robot.joints_from_controller(joints), per, axis=0)
    names = np.array(list(tool_names) * m, dtype=object)
    meas = Measurements(joints=q, points=np.zeros((m * per, 3)), pose_ids=np.repeat(
        np.arange(m).astype(str).astype(object), per), point_names=names)
    problem = IdentificationProblem(model, meas, model.nominal, free, list(tool_names), np.eye(4),
                                    urdf_from_controller=robot.urdf_from_controller)
    x = problem.pack(model.nominal, np.eye(4), tools)
    _, jac = problem.residuals_and_jacobian(x)
    return jac.reshape(m, 3 * per, -1), problem.layout


def planning_space(robot: Robot, candidates: np.ndarray | None = None,
                   n_candidates: int = DEFAULT_CANDIDATES, seed: int = 0,
                   tools: dict[str, np.ndarray] | None = None, freeze: tuple[str, ...] = (),
                   convention: str = "auto", margin: float = DEFAULT_MARGIN,
                   n_test: int = DEFAULT_TEST_POSES) -> PlanningSpace:
    """Set up planning for ``robot``.

    ``candidates``: (K, n) controller joint values (rad, m) to choose from, e.g. poses known
    to be reachable in the cell; default ``n_candidates`` random ones inside the limits
    shrunk by ``margin`` (seeded). ``tools``: name -> (3,) measured point in the flange
    frame, m (every point is measured at every pose; default one point 'tcp' at
    :data:`DEFAULT_TOOL_M`). ``freeze``: parameter names held at nominal, as identify's.
    The random test poses of the I criterion come from ``seed`` too.
    """
    rng = np.random.default_rng(seed)
    if candidates is None:
        if n_candidates < 1:
            raise DataError(f"candidates: need at least 1, got {n_candidates}")
        candidates = random_joints(robot, n_candidates, rng, margin)
    candidates = np.atleast_2d(np.asarray(candidates, dtype=float))
    if candidates.shape[1] != robot.n_joints:
        raise DataError(f"candidates: {candidates.shape[1]} joint values per pose, but "
                        f"{robot.name} has {robot.n_joints} joints")
    urdf = robot.joints_from_controller(candidates)
    outside = (urdf < robot.lower_limits - 1e-6) | (urdf > robot.upper_limits + 1e-6)
    if np.any(outside):
        row, joint = np.argwhere(outside)[0]
        raise DataError(f"candidate pose {row + 1}: joint {joint + 1} is outside the joint "
                        f"limits of {robot.name}")
    tools = {"tcp": np.array(DEFAULT_TOOL_M)} if not tools else tools
    tool_names = sorted(tools)
    tool_xyz = np.array([np.asarray(tools[n], dtype=float) for n in tool_names])
    model = build_model(robot, convention)
    probe = Measurements(joints=urdf[:1], points=np.zeros((1, 3)),
                         pose_ids=np.array(["1"], dtype=object),
                         point_names=np.array(tool_names[:1], dtype=object))
    frozen = dict(structural_freeze(model, probe, tool_names, tuple(freeze), option="freeze"))
    free = np.array([k for k, p in enumerate(model.parameters) if p.name not in frozen], int)

    # Geometry that no candidate separates from the rest stays frozen, as identify would
    # freeze it: pivoted QR of the unit-scaled geometric columns once the registration and
    # tool columns (always fitted) are projected out.
    blocks, layout = _jacobian_blocks(robot, model, free, candidates, tool_names, tool_xyz)
    names = layout.names()
    flat = blocks.reshape(-1, blocks.shape[2])
    norms = np.linalg.norm(flat, axis=0)
    geometric = np.zeros(layout.size, dtype=bool)
    geometric[layout.geometry] = True
    dead = geometric & (norms <= 1e-12 * norms.max())
    for k in np.flatnonzero(dead):
        frozen[names[k]] = "has no effect on the measured points at any candidate pose"
    fixed = flat[:, ~geometric] / norms[~geometric]
    basis, r_fixed, _ = qr(fixed, mode="economic", pivoting=True)
    if abs(r_fixed[-1, -1]) <= RANK_TOLERANCE * abs(r_fixed[0, 0]):
        raise DataError("the device registration and the tool points cannot be determined "
                        "from the candidate poses; give candidates that move every joint")
    alive = np.flatnonzero(geometric & ~dead)
    unit = flat[:, alive] / norms[alive]
    _, r, pivots = qr(unit - basis @ (basis.T @ unit), mode="economic", pivoting=True)
    rank = int(np.sum(np.abs(np.diag(r)) > RANK_TOLERANCE))
    for col in pivots[rank:]:
        frozen[names[alive[col]]] = "cannot be separated at any candidate pose"
    drop = set(frozen)
    free = np.array([k for k in free if model.parameters[k].name not in drop], int)
    blocks, layout = _jacobian_blocks(robot, model, free, candidates, tool_names, tool_xyz)

    scale = np.sqrt(np.mean(np.sum(blocks**2, axis=1), axis=0))
    scale[scale == 0] = 1.0
    blocks = blocks / scale
    test = random_joints(robot, n_test, rng, margin)
    rows, _ = _jacobian_blocks(robot, model, free, test, tool_names, tool_xyz)
    rows = rows.reshape(-1, rows.shape[2]) / scale
    information = rows.T @ rows / (n_test * len(tool_names))
    return PlanningSpace(robot=robot, candidates=candidates, blocks=blocks, scale=scale,
                         test_information=information, unknown_names=layout.names(),
                         frozen=frozen,
                         tool_names=tool_names, tools_m=tool_xyz)


def design_quality(space: PlanningSpace, indices) -> DesignQuality:
    """Quality of the candidates ``indices`` as a design (no regularization)."""
    blocks = space.blocks[np.asarray(indices, dtype=int)]
    flat = blocks.reshape(-1, space.n_unknowns)
    info = flat.T @ flat
    sign, log_det = np.linalg.slogdet(info)
    if sign <= 0 or not np.isfinite(log_det):
        return DesignQuality(-np.inf, np.inf)
    # cond of the information, not of J: trust the inverse up to ~1e-14 relative
    s = np.linalg.eigvalsh(info)
    if s[0] <= 1e-13 * s[-1]:
        return DesignQuality(float(log_det), np.inf)
    variance = np.trace(np.linalg.solve(info, space.test_information))
    return DesignQuality(float(log_det), float(np.sqrt(max(variance, 0.0))))


def random_quality(space: PlanningSpace, n_poses: int, draws: int = RANDOM_DRAWS,
                   seed: int = 0) -> DesignQuality:
    """Median quality of ``draws`` random sets of ``n_poses`` candidates."""
    rng = np.random.default_rng(seed + 7_919)
    qualities = [design_quality(space, rng.choice(len(space.candidates), n_poses, replace=False))
                 for _ in range(draws)]
    return DesignQuality(float(np.median([q.log_det for q in qualities])),
                         float(np.median([q.expected_error for q in qualities])))


def plan_poses(space: PlanningSpace, n_poses: int, criterion: str = DEFAULT_CRITERION,
               min_distance_deg: float = 0.0, max_passes: int = 30,
               compare_seed: int = 0) -> PosePlan:
    """Choose ``n_poses`` of the candidates of ``space`` (see module docstring).

    ``min_distance_deg``: two chosen poses differ by at least this much in some joint
    (degrees, mm for a prismatic joint; 0: no constraint). Raises :class:`DataError` when
    ``n_poses`` is too few to identify the unknowns, or more than the candidates allow.
    """
    if criterion not in CRITERIA:
        raise DataError(f"criterion must be one of {', '.join(CRITERIA)}, got '{criterion}'")
    k_total = len(space.candidates)
    if n_poses < space.min_poses:
        raise DataError(
            f"{n_poses} poses give {n_poses * space.rows_per_pose} equations for "
            f"{space.n_unknowns} unknowns; plan at least {space.min_poses} poses")
    if n_poses > k_total:
        raise DataError(f"{n_poses} poses asked for, but only {k_total} candidates")
    selection = Selection([], np.zeros(k_total, dtype=bool),
                           np.zeros((n_poses, k_total), dtype=bool),
                           space.robot.to_degrees_or_mm(space.candidates), min_distance_deg)
    greedy_selection(space.blocks, selection, n_poses)
    # Exchange passes: D first (cheap, from the greedy start), then the asked-for criterion
    # from the D-exchanged design (an I exchange from the greedy start stops in worse optima).
    swaps = sum(exchange_passes(space.blocks, space.test_information, selection, stage,
                                max_passes)
                for stage in (("d",) if criterion == "d" else ("d", criterion)))
    chosen = selection.chosen
    indices = np.array(chosen, dtype=int)
    return PosePlan(joints=space.candidates[indices].copy(), indices=indices, criterion=criterion,
                    quality=design_quality(space, indices),
                    random=random_quality(space, n_poses, seed=compare_seed),
                    n_unknowns=space.n_unknowns, n_candidates=k_total,
                    unknown_names=list(space.unknown_names), frozen=dict(space.frozen),
                    swaps=swaps)


def plan(robot: Robot, n_poses: int, criterion: str = DEFAULT_CRITERION,
         min_distance_deg: float = 0.0, **space_options) -> PosePlan:
    """One call: :func:`planning_space` with ``space_options``, then :func:`plan_poses`."""
    return plan_poses(planning_space(robot, **space_options), n_poses, criterion,
                      min_distance_deg=min_distance_deg)


__all__ = ["PlanningSpace", "DesignQuality", "PosePlan", "planning_space", "plan_poses",
           "design_quality", "random_quality", "plan", "CRITERIA", "DEFAULT_CRITERION"]
