"""Cubic calibration volumes and the poses to measure in them (seed sections 6.1 and 10).

Motta 2006 calibrated in cubic volumes of 200, 400 and 600 mm: "the external cubes have 12
calibration points (600 mm) and the 3 internal cubes (600, 400 and 200 mm) have 27
positions", the points "distributed on the cubic faces". Two layouts, base frame:

- ``faces``: 12 points on the cube's faces: its 8 corners and the centres of its 4 side
  faces (the faces whose normals are horizontal);
- ``grid``: the 27 points of a 3 x 3 x 3 grid (corners, edge midpoints, face centres and the
  centre).

A point fixes where the measured tool point goes, not how the arm gets there: each point is
reached with one of a set of candidate tool orientations (pointing down, tilted by 30 and 60
degrees in 8 directions, each turned about the tool axis in steps of 90 degrees), solved on
the nominal arm inside the controller's axis ranges
(:func:`olp_compensate.compensation.pose.compensate_poses`). Among the reachable ones the
orientations are chosen together for observability with the pose planner's criterion
(:mod:`olp_compensate.calibration.pose_planning`, D-optimal by default: the largest log det
of the information of the unit-scaled identification Jacobian, at the nominal model): a
greedy start point by point, then exchange passes (each point in turn takes the orientation
that improves the criterion most) until a pass changes nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError
from ..kinematics.conventions import rot_y, rot_z
from ..kinematics.robot import Robot

LAYOUTS = ("faces", "grid")
DEFAULT_TOOL_M = (0.05, 0.0, 0.15)
"""Tool point assumed when none is given, flange frame, m (as the pose planner's)."""
TILTS_DEG = (0.0, 30.0, 60.0)
AZIMUTHS = 8
SPINS_DEG = (0.0, 90.0, 180.0, 270.0)
MAX_PASSES = 10
GREEDY_REGULARIZATION = 1e-6


@dataclass(frozen=True)
class CubeVolume:
    """A cubic volume, base frame: ``centre_m`` (3,), edge ``size_m``, m."""

    name: str
    centre_m: np.ndarray
    size_m: float

    def __post_init__(self):
        centre = np.asarray(self.centre_m, dtype=float)
        if centre.shape != (3,) or not np.all(np.isfinite(centre)):
            raise DataError(f"volume {self.name}: centre: expected 3 finite coordinates, "
                            f"got {self.centre_m!r}")
        if not (self.size_m > 0 and math.isfinite(self.size_m)):
            raise DataError(f"volume {self.name}: size: expected a positive length, got "
                            f"{self.size_m}")
        object.__setattr__(self, "centre_m", centre)

    def contains(self, points_base_m: np.ndarray, margin_m: float = 1e-9) -> np.ndarray:
        """(m,) bool: which points (m, 3), base frame, lie inside the cube (faces included)."""
        half = 0.5 * self.size_m + margin_m
        return np.all(np.abs(np.asarray(points_base_m, float) - self.centre_m) <= half, axis=1)

    def points(self, layout: str = "faces") -> tuple[np.ndarray, list[str]]:
        """The layout's points (k, 3), base frame, m, and their names."""
        return cube_points(self.centre_m, self.size_m, layout)


def cube_points(centre_m, size_m: float, layout: str = "faces") -> tuple[np.ndarray, list[str]]:
    """Points (k, 3) of a cube's ``layout`` (module docstring), base frame, m, and names:
    ``C1..C8`` corners (x fastest, then y, then z, from the low corner), ``F+x``.. face
    centres, ``G1..G27`` grid points."""
    if layout not in LAYOUTS:
        raise DataError(f"layout: expected one of {', '.join(LAYOUTS)}, got {layout!r}")
    volume_centre = np.asarray(centre_m, dtype=float)
    half = 0.5 * float(size_m)
    if layout == "grid":
        steps = (-1.0, 0.0, 1.0)
        unit = np.array([(x, y, z) for z in steps for y in steps for x in steps])
        return volume_centre + half * unit, [f"G{k + 1}" for k in range(27)]
    corners = np.array([(x, y, z) for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float)
    faces = np.array([(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)], float)
    names = [f"C{k + 1}" for k in range(8)] + ["F+x", "F-x", "F+y", "F-y"]
    return volume_centre + half * np.vstack([corners, faces]), names


def candidate_orientations() -> np.ndarray:
    """(c, 3, 3) tool orientations, base frame: pointing down, tilted by :data:`TILTS_DEG`
    towards :data:`AZIMUTHS` directions, each turned about the tool axis by
    :data:`SPINS_DEG`."""
    out = []
    for tilt in TILTS_DEG:
        azimuths = [0.0] if tilt == 0 else [360.0 * k / AZIMUTHS for k in range(AZIMUTHS)]
        for azimuth in azimuths:
            direction = rot_z(math.radians(azimuth)) @ rot_y(math.radians(tilt))
            for spin in SPINS_DEG:
                out.append(direction @ rot_y(np.pi) @ rot_z(math.radians(spin)))
    return np.array(out)


@dataclass(frozen=True)
class CubePoseSet:
    """Poses that bring the tool point to a cube's layout points.

    ``points_m`` (k, 3) base frame; ``joints`` (k, n) controller axes, rad; ``rotations``
    (k, 3, 3) the chosen tool orientations; ``config`` (k, 4) ABB confdata of the joints;
    ``reachable`` (k,) how many candidate orientations reached each point; ``log_det`` and
    ``expected_error`` the planner's measures of the set (:class:`DesignQuality`).
    """

    volume: CubeVolume
    layout: str
    names: list[str]
    points_m: np.ndarray
    joints: np.ndarray
    rotations: np.ndarray
    config: np.ndarray
    tool_m: np.ndarray
    reachable: np.ndarray
    criterion: str
    log_det: float
    expected_error: float
    swaps: int = 0
    frozen: dict[str, str] = field(default_factory=dict)


def _reachable(robot: Robot, points: np.ndarray, rotations: np.ndarray, tool_m: np.ndarray):
    """For every (point, orientation): joints (k, c, n) controller axes, NaN where the
    nominal arm cannot reach it inside the controller's ranges, and confdata (k, c, 4)."""
    from ..compensation.pose import Compensator, compensate_poses
    from .calibration import nominal_calibration

    k, c = len(points), len(rotations)
    targets = np.zeros((k, c, 4, 4))
    targets[:, :, :3, :3] = rotations[None]
    targets[:, :, :3, 3] = points[:, None]
    targets[:, :, 3, 3] = 1.0
    tool = np.eye(4)
    tool[:3, 3] = tool_m
    batch = compensate_poses(Compensator(nominal_calibration(robot)),
                             targets.reshape(-1, 4, 4), tool=tool)
    joints = np.where(batch.success[:, None], batch.joints, np.nan)
    return joints.reshape(k, c, -1), batch.config.reshape(k, c, 4)


def _select(space, owner: np.ndarray, k: int, criterion: str) -> tuple[np.ndarray, int]:
    """One candidate per point (indices into the space's candidates): greedy D-optimal
    start, then exchange passes on the criterion; and the number of swaps."""
    from .pose_planning import design_quality

    blocks = space.blocks
    u = blocks.shape[2]

    def score(chosen) -> float:
        quality = design_quality(space, chosen)
        if criterion == "i":
            return -quality.expected_error if np.isfinite(quality.expected_error) else -np.inf
        return quality.log_det

    info = GREEDY_REGULARIZATION * np.eye(u)
    chosen = []
    for point in range(k):
        options = np.flatnonzero(owner == point)
        gains = [np.linalg.slogdet(info + blocks[j].T @ blocks[j])[1] for j in options]
        pick = int(options[int(np.argmax(gains))])
        chosen.append(pick)
        info = info + blocks[pick].T @ blocks[pick]
    swaps = 0
    best = score(chosen)
    for _ in range(MAX_PASSES):
        changed = False
        for point in range(k):
            for j in np.flatnonzero(owner == point):
                if j == chosen[point]:
                    continue
                trial = list(chosen)
                trial[point] = int(j)
                value = score(trial)
                if value > best + 1e-9 * max(1.0, abs(best)):
                    chosen, best, changed = trial, value, True
                    swaps += 1
        if not changed:
            break
    return np.array(chosen, dtype=int), swaps


def cube_pose_set(robot: Robot, centre_m, size_m: float, layout: str = "faces",
                  tool_m=DEFAULT_TOOL_M, criterion: str = "d", seed: int = 0,
                  name: str = "cube") -> CubePoseSet:
    """Poses that bring the tool point ``tool_m`` (3,), flange frame, m, to the ``layout``
    points of the cube ``centre_m`` (3,), edge ``size_m``, base frame, m, each with the
    orientation chosen for observability (module docstring; ``criterion`` 'd' or 'i' as the
    pose planner's). Raises :class:`DataError` naming a point no candidate orientation
    reaches inside the controller's axis ranges."""
    from .pose_planning import CRITERIA, design_quality, planning_space

    if criterion not in CRITERIA:
        raise DataError(f"criterion: expected one of {', '.join(CRITERIA)}, got {criterion!r}")
    volume = CubeVolume(name=name, centre_m=np.asarray(centre_m, float), size_m=float(size_m))
    points, names = cube_points(volume.centre_m, volume.size_m, layout)
    tool = np.asarray(tool_m, dtype=float)
    rotations = candidate_orientations()
    joints, config = _reachable(robot, points, rotations, tool)
    ok = np.all(np.isfinite(joints), axis=2)
    reachable = ok.sum(axis=1)
    if np.any(reachable == 0):
        bad = int(np.flatnonzero(reachable == 0)[0])
        where = ", ".join(f"{v * 1e3:.1f}" for v in points[bad])
        raise DataError(f"cube point {names[bad]} at ({where}) mm (base frame): none of "
                        f"{len(rotations)} tool orientations reaches it inside the "
                        f"controller's axis ranges; move or shrink the cube")
    point_of, orientation_of = np.nonzero(ok)
    space = planning_space(robot, candidates=joints[point_of, orientation_of], seed=seed,
                           tools={"tcp": tool})
    chosen, swaps = _select(space, point_of, len(points), criterion)
    quality = design_quality(space, chosen)
    which = orientation_of[chosen]
    return CubePoseSet(volume=volume, layout=layout, names=names, points_m=points,
                       joints=joints[np.arange(len(points)), which],
                       rotations=rotations[which], config=config[np.arange(len(points)), which],
                       tool_m=tool, reachable=reachable, criterion=criterion,
                       log_det=quality.log_det, expected_error=quality.expected_error,
                       swaps=swaps, frozen=dict(space.frozen))


# -- programs -----------------------------------------------------------------------------

def _num(value: float, decimals: int = 4) -> str:
    text = f"{round(float(value), decimals) + 0.0:.{decimals}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


def _header(pose_set: CubePoseSet, comment: str) -> list[str]:
    v = pose_set.volume
    centre = ", ".join(_num(x * 1e3, 1) for x in v.centre_m)
    tcp = ", ".join(_num(x * 1e3, 3) for x in pose_set.tool_m)
    return [f"{comment} calibration volume {v.name}: cube centre ({centre}) mm, edge "
            f"{_num(v.size_m * 1e3, 1)} mm, layout {pose_set.layout} ({len(pose_set.names)} "
            f"points), base frame (olp-cal plan --volume cube)",
            f"{comment} tool point ({tcp}) mm in the flange frame; measure it at every pose"]


def rapid_joint_program(pose_set: CubePoseSet, robot: Robot, module: str = "CubePoses",
                        speed: str = "v200", wait_s: float = 2.0) -> str:
    """A RAPID module visiting every pose with MoveAbsJ (jointtargets, controller axes)."""
    degrees = robot.to_degrees_or_mm(pose_set.joints)
    lines = [f"MODULE {module}"] + ["  " + line for line in _header(pose_set, "!")]
    for k, q in enumerate(degrees):
        axes = ",".join(_num(v) for v in q)
        lines.append(f"  CONST jointtarget jCube{k + 1}:=[[{axes}],"
                     f"[9E9,9E9,9E9,9E9,9E9,9E9]];  ! {pose_set.names[k]}")
    lines += ["", "  PROC main()"]
    for k in range(len(degrees)):
        lines += [f"    MoveAbsJ jCube{k + 1}\\NoEOffs,{speed},fine,tool0;",
                  f"    WaitTime {_num(wait_s)};"]
    lines += ["  ENDPROC", "ENDMODULE", ""]
    return "\n".join(lines)


def vplus_joint_program(pose_set: CubePoseSet, robot: Robot, name: str = "cube",
                        wait_s: float = 2.0) -> str:
    """A V+ disk file visiting every pose as a precision point (``#cubeK``, degrees)."""
    degrees = robot.to_degrees_or_mm(pose_set.joints)
    lines = [f".PROGRAM {name}()"] + ["    " + line for line in _header(pose_set, ";")]
    for k in range(len(degrees)):
        lines += [f"    MOVE #cube{k + 1}", "    BREAK", f"    DELAY {_num(wait_s)}"]
    lines += [".END", ".LOCATIONS", ""]
    for k, q in enumerate(degrees):
        lines.append(f"#cube{k + 1:<6}" + "".join(f"{v:10.3f}" for v in q))
    lines += [".END", ""]
    return "\n".join(lines)


def joint_program(pose_set: CubePoseSet, robot: Robot, dialect: str) -> str:
    """The program of ``dialect`` ('rapid' or 'vplus') that visits the poses."""
    if dialect == "rapid":
        return rapid_joint_program(pose_set, robot)
    if dialect == "vplus":
        return vplus_joint_program(pose_set, robot)
    raise DataError(f"dialect: expected 'rapid' or 'vplus', got {dialect!r}")


def pose_set_metadata(pose_set: CubePoseSet) -> list[str]:
    """Metadata lines for the joints file (``io.poses.write_poses``)."""
    return _header(pose_set, "#") + [
        f"# orientations chosen by the planner's {pose_set.criterion.upper()} criterion: "
        f"log det {pose_set.log_det:.2f}, expected model error "
        f"{pose_set.expected_error:.2f}x the noise"]
