"""ISO 9283 pose accuracy (AP) and pose repeatability (RP): the test program and the figures.

ISO 9283:1998, *Manipulating industrial robots -- Performance criteria and related test
methods* (the text itself was not in the reference library searched for this module; the
section numbers and rules below are those of the 1998 edition as usually cited):

- 6.8 (poses to be tested): a cube in the part of the working space used most, with the
  measuring plane C1-C2-C7-C8, the diagonal plane through two opposite edges of the cube.
  P1 is the intersection of the plane's diagonals, the centre of the cube; P2 .. P5 lie on
  the diagonals at (10 +- 2) % of the diagonal's length L from the corners. Here C1, C2 are
  the cube's lower edge at y = -E/2 and C7, C8 the upper edge at y = +E/2 (base frame), so
  the diagonals are space diagonals of the cube (L = sqrt(3) E) and
  ``P_k = centre + 0.8 (C_k - centre)`` for P2 .. P5 near C1, C2, C7, C8.
- 6.9 and 7.2: 30 cycles; each cycle visits P1, P5, P4, P3, P2, each pose approached from
  the same direction (unidirectional approach), with the same tool orientation.
- 7.2.1, pose accuracy: ``AP_P = sqrt((xb - xc)^2 + (yb - yc)^2 + (zb - zc)^2)`` with
  (xb, yb, zb) the barycentre of the n attained positions and (xc, yc, zc) the commanded
  one; ``AP_a = mean(a_j) - a_c`` (likewise b, c: rotations about the x, y, z axes).
- 7.2.2, pose repeatability: ``RP_l = mean(l) + 3 S_l`` with ``l_j`` the distance of
  attained position j from the barycentre and ``S_l = sqrt(sum (l_j - mean l)^2 / (n - 1))``;
  ``RP_a = +- 3 S_a`` with ``S_a`` the sample standard deviation of a_j (likewise b, c).

Angles: ``R = Rz(c) Ry(b) Rx(a)`` (rotations a, b, c about the fixed x, y, z axes of the
measuring frame), degrees at the edges; deviations from the commanded angle are wrapped
into (-180, 180] degrees before averaging, which equals the formulas above away from the wrap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import DataError, UnreachableTarget
from ..kinematics.conventions import (euler_zyz_from_matrix, matrix_from_quat_wxyz,
                                      quat_wxyz_from_matrix, rot_y, rot_z)
from .calibration import Calibration

POSE_NAMES = ("P1", "P2", "P3", "P4", "P5")
CYCLE_ORDER = ("P1", "P5", "P4", "P3", "P2")
"""Order of the poses in one cycle (ISO 9283:1998, 7.2)."""
CORNER_FRACTION = 0.10
"""P2 .. P5 lie this fraction of the diagonal's length from its ends (6.8)."""
PLANE_CORNERS = {"C1": (-1, -1, -1), "C2": (1, -1, -1), "C7": (1, 1, 1), "C8": (-1, 1, 1)}
"""Corners of the measuring plane C1-C2-C7-C8, in half edges from the cube's centre."""
NEAR_CORNER = {"P2": "C1", "P3": "C2", "P4": "C7", "P5": "C8"}
DEFAULT_CYCLES = 30
DEFAULT_APPROACH_M = 0.05
"""Every pose is approached along the tool's z axis from this far back, m."""


def iso_positions(centre_m, edge_m: float) -> np.ndarray:
    """(5, 3) positions of P1 .. P5, m, in the frame of ``centre_m`` (the cube's centre)."""
    centre = np.asarray(centre_m, dtype=float)
    if centre.shape != (3,) or not np.all(np.isfinite(centre)):
        raise DataError(f"cube centre: expected 3 finite coordinates, got {centre_m!r}")
    if not (edge_m > 0 and math.isfinite(edge_m)):
        raise DataError(f"cube edge: expected a positive length, got {edge_m}")
    out = [centre]
    for name in POSE_NAMES[1:]:
        corner = centre + 0.5 * edge_m * np.array(PLANE_CORNERS[NEAR_CORNER[name]], float)
        out.append(corner + CORNER_FRACTION * 2.0 * (centre - corner))
    return np.array(out)


# -- the test program ---------------------------------------------------------------------

@dataclass(frozen=True)
class IsoPlan:
    """The five test poses, solved on the nominal arm.

    ``positions_m`` (5, 3) base frame; ``rotation`` (3, 3) the tool's orientation at every
    pose, base frame; ``joints`` (5, n) controller axes, rad; ``config`` (5, 4) ABB confdata;
    ``tool_m`` (3,) the TCP in the flange frame; ``orientation`` says it in words.
    """

    centre_m: np.ndarray
    edge_m: float
    positions_m: np.ndarray
    rotation: np.ndarray
    orientation: str
    joints: np.ndarray
    config: np.ndarray
    tool_m: np.ndarray
    cycles: int
    approach_m: float


def _orientations(centre_m: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Candidate tool orientations, in the order tried: pointing down; pointing away from
    the base, horizontal; pointing away and down at 45 degrees."""
    heading = math.atan2(centre_m[1], centre_m[0])
    return [("pointing down", rot_y(np.pi)),
            ("horizontal, pointing away from the base", rot_z(heading) @ rot_y(np.pi / 2)),
            ("pointing away from the base and down at 45 deg",
             rot_z(heading) @ rot_y(3 * np.pi / 4))]


def _targets(positions: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    targets = np.zeros((len(positions), 4, 4))
    targets[:, :3, :3], targets[:, :3, 3], targets[:, 3, 3] = rotation, positions, 1.0
    return targets


def plan_iso_test(calibration: Calibration, centre_m, edge_m: float,
                  cycles: int = DEFAULT_CYCLES, tool_m=None, same_branch: bool = False,
                  approach_m: float = DEFAULT_APPROACH_M) -> IsoPlan:
    """Solve the five poses of the cube ``centre_m`` (3,), base frame, edge ``edge_m``, m,
    on ``calibration`` (the nominal one: what the controller does), with one tool
    orientation for all (the first of :func:`_orientations` at which every pose is reached
    inside the controller's axis ranges on P1's configuration). ``same_branch``: also
    require each pose's branch nearest zero to be P1's (V+ locations carry no
    configuration). Raises :class:`UnreachableTarget` naming the pose and the reason."""
    from ..compensation.pose import Compensator, compensate_pose, compensate_poses

    if cycles < 1:
        raise DataError(f"cycles: expected at least 1, got {cycles}")
    positions = iso_positions(centre_m, edge_m)
    tool = np.eye(4)
    tool[:3, 3] = np.zeros(3) if tool_m is None else np.asarray(tool_m, float)
    comp = Compensator(calibration)
    first_failure = None
    for words, rotation in _orientations(positions[0]):
        targets = _targets(positions, rotation)
        free = compensate_poses(comp, targets, tool=tool)
        if not free.success[0]:
            first_failure = first_failure or (0, words, rotation, None)
            continue
        # one arm configuration (branch cfx) for all; each pose keeps its own quadrants
        other = free.config[:, 3] != free.config[0, 3]
        if same_branch and np.any(other | ~free.success):
            bad = int(np.flatnonzero(other | ~free.success)[0])
            first_failure = first_failure or (bad, words, rotation,
                                              "branch" if free.success[bad] else None)
            continue
        config = np.where(free.success[:, None], free.config, free.config[0])
        config[:, 3] = free.config[0, 3]
        batch = compensate_poses(comp, targets, tool=tool, confdata=config)
        if np.all(batch.success):
            return IsoPlan(centre_m=positions[0], edge_m=float(edge_m), positions_m=positions,
                           rotation=rotation, orientation=words, joints=batch.joints,
                           config=batch.config, tool_m=tool[:3, 3].copy(), cycles=int(cycles),
                           approach_m=float(approach_m))
        bad = int(np.flatnonzero(~batch.success)[0])
        first_failure = first_failure or (bad, words, rotation, tuple(config[bad]))
    bad, words, rotation, config = first_failure
    where = ", ".join(f"{v * 1e3:.1f}" for v in positions[bad])
    if config == "branch":
        reason = ("its nominal configuration differs from P1's, and V+ locations carry no "
                  "configuration")
    else:
        result = compensate_pose(comp, _targets(positions[bad:bad + 1], rotation)[0],
                                 tool=tool, config=config)
        reason = f"{result.status}: {result.note}" if result.note else result.status
    raise UnreachableTarget(f"ISO 9283 pose {POSE_NAMES[bad]} at ({where}) mm, tool {words}, "
                            f"is not reachable inside the controller's axis ranges ({reason}); "
                            f"move or shrink the cube")


def _num(value: float, decimals: int = 3) -> str:
    text = f"{round(float(value), decimals) + 0.0:.{decimals}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


def _header(plan: IsoPlan, comment: str) -> list[str]:
    c = ", ".join(_num(v * 1e3) for v in plan.centre_m)
    return [f"{comment} ISO 9283:1998 pose accuracy and repeatability test (olp-cal iso9283 plan)",
            f"{comment} cube centre ({c}) mm, edge {_num(plan.edge_m * 1e3)} mm, measuring "
            f"plane C1-C2-C7-C8; P1 the centre, P2..P5 at 10 % of the diagonal from C1, C2, "
            f"C7, C8",
            f"{comment} {plan.cycles} cycles of P1, P5, P4, P3, P2; tool {plan.orientation}; "
            f"each pose approached along the tool z axis from {_num(plan.approach_m * 1e3)} mm",
            f"{comment} measure the attained pose while the robot waits at each pose"]


def rapid_program(plan: IsoPlan, module: str = "ISO9283", speed: str = "v500",
                  wait_s: float = 2.0) -> str:
    """A RAPID module: robtargets P1..P5 (confdata solved inside the controller's ranges),
    a tool ``tIso``, and ``main`` with the cycles (MoveJ to the approach point, MoveL fine)."""
    tcp = ",".join(_num(v * 1e3) for v in plan.tool_m)
    quat = ",".join(_num(v, 9) for v in quat_wxyz_from_matrix(plan.rotation))
    lines = [f"MODULE {module}"] + ["  " + line for line in _header(plan, "!")]
    lines.append(f"  PERS tooldata tIso:=[TRUE,[[{tcp}],[1,0,0,0]],[1,[0,0,0],[1,0,0,0],0,0,0]];")
    for name, p, conf in zip(POSE_NAMES, plan.positions_m, plan.config):
        xyz = ",".join(_num(v * 1e3) for v in p)
        cf = ",".join(str(int(c)) for c in conf)
        lines.append(f"  CONST robtarget {name}:=[[{xyz}],[{quat}],[{cf}],"
                     f"[9E9,9E9,9E9,9E9,9E9,9E9]];")
    back = _num(-plan.approach_m * 1e3)
    lines += ["", "  PROC main()", f"    FOR cycle FROM 1 TO {plan.cycles} DO"]
    for name in CYCLE_ORDER:
        lines += [f"      MoveJ RelTool({name},0,0,{back}),{speed},z10,tIso;",
                  f"      MoveL {name},{speed},fine,tIso;",
                  f"      WaitTime {_num(wait_s)};"]
    lines += ["    ENDFOR", "  ENDPROC", "ENDMODULE", ""]
    return "\n".join(lines)


def vplus_program(plan: IsoPlan, name: str = "iso9283", speed_percent: float = 50.0,
                  wait_s: float = 2.0) -> str:
    """A V+ disk file: transformations p1..p5 (Z-Y-Z Euler, mm and degrees), the tool
    ``iso.tool`` and the program with the cycles (APPRO then MOVES)."""
    yaw, pitch, roll = (math.degrees(float(v)) for v in euler_zyz_from_matrix(plan.rotation))
    lines = [f".PROGRAM {name}()"] + ["    " + line for line in _header(plan, ";")]
    lines += [f"    SPEED {_num(speed_percent)} ALWAYS", "    TOOL iso.tool",
              f"    FOR cycle = 1 TO {plan.cycles}"]
    for pose in CYCLE_ORDER:
        loc = pose.lower()
        lines += [f"        APPRO {loc}, {_num(plan.approach_m * 1e3)}", f"        MOVES {loc}",
                  "        BREAK", f"        DELAY {_num(wait_s)}"]
    lines += ["    END", ".END", ".LOCATIONS", ""]
    tcp = plan.tool_m * 1e3
    lines.append(f"iso.tool  {tcp[0]:10.3f}{tcp[1]:10.3f}{tcp[2]:10.3f}"
                 f"{0.0:10.3f}{0.0:10.3f}{0.0:10.3f}")
    for pose, p in zip(POSE_NAMES, plan.positions_m * 1e3):
        lines.append(f"{pose.lower():<9} {p[0]:10.3f}{p[1]:10.3f}{p[2]:10.3f}"
                     f"{yaw:10.3f}{pitch:10.3f}{roll:10.3f}")
    lines += [".END", ""]
    return "\n".join(lines)


# -- the figures ----------------------------------------------------------------------------

def abc_from_quat_wxyz(quat) -> np.ndarray:
    """(m, 3) angles a, b, c, rad, of ``R = Rz(c) Ry(b) Rx(a)`` from quaternions (m, 4)."""
    r = matrix_from_quat_wxyz(np.asarray(quat, dtype=float).reshape(-1, 4))
    a = np.arctan2(r[:, 2, 1], r[:, 2, 2])
    b = np.arctan2(-r[:, 2, 0], np.hypot(r[:, 0, 0], r[:, 1, 0]))
    c = np.arctan2(r[:, 1, 0], r[:, 0, 0])
    return np.stack([a, b, c], axis=1)


@dataclass(frozen=True)
class IsoPoseResult:
    """AP and RP of one pose (ISO 9283:1998, 7.2), lengths in m and angles in rad.

    ``ap_xyz_m``: barycentre minus commanded position (3,); ``ap_p_m``: its norm;
    ``rp_l_m``: mean(l) + 3 S_l. ``ap_abc_rad`` and ``rp_abc_rad`` (3,) or None without
    orientations.
    """

    pose: str
    n: int
    commanded_m: np.ndarray
    barycentre_m: np.ndarray
    ap_xyz_m: np.ndarray
    ap_p_m: float
    rp_l_m: float
    ap_abc_rad: np.ndarray | None = None
    rp_abc_rad: np.ndarray | None = None


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def pose_result(pose: str, attained_m, commanded_m, attained_quat=None,
                commanded_quat=None) -> IsoPoseResult:
    """The figures of one pose from its n attained positions (n, 3) and the commanded one
    (3,), and optionally attained (n, 4) and commanded (4,) quaternions (w first)."""
    attained = np.asarray(attained_m, dtype=float).reshape(-1, 3)
    n = len(attained)
    if n < 2:
        raise DataError(f"pose {pose}: {n} cycle(s); repeatability needs at least 2 "
                        f"(the standard asks for 30)")
    commanded = np.asarray(commanded_m, dtype=float).reshape(3)
    barycentre = attained.mean(axis=0)
    l = np.linalg.norm(attained - barycentre, axis=1)
    ap_abc = rp_abc = None
    if attained_quat is not None:
        deviation = _wrap(abc_from_quat_wxyz(attained_quat)
                          - abc_from_quat_wxyz(commanded_quat)[0])
        ap_abc = deviation.mean(axis=0)
        rp_abc = 3.0 * deviation.std(axis=0, ddof=1)
    return IsoPoseResult(pose=pose, n=n, commanded_m=commanded, barycentre_m=barycentre,
                         ap_xyz_m=barycentre - commanded,
                         ap_p_m=float(np.linalg.norm(barycentre - commanded)),
                         rp_l_m=float(l.mean() + 3.0 * l.std(ddof=1)),
                         ap_abc_rad=ap_abc, rp_abc_rad=rp_abc)


def iso_results(poses, attained_m, commanded_m, attained_quat=None,
                commanded_quat=None) -> tuple[IsoPoseResult, ...]:
    """The figures of every pose of a test table: ``poses`` (m,) names, ``attained_m`` and
    ``commanded_m`` (m, 3), optional quaternions (m, 4). Poses in P1 .. P5 order first, then
    others by first appearance. The commanded pose must be the same on every row of a pose."""
    poses = np.asarray(poses, dtype=object)
    commanded = np.asarray(commanded_m, dtype=float)
    order = sorted(dict.fromkeys(poses), key=lambda p: (POSE_NAMES.index(p)
                                                        if p in POSE_NAMES else 99))
    out = []
    for name in order:
        rows = poses == name
        if np.ptp(commanded[rows], axis=0).max() > 1e-9:
            raise DataError(f"pose {name}: the commanded position differs between its cycles "
                            f"(by up to {np.ptp(commanded[rows], axis=0).max() * 1e3:.4f} mm)")
        cq = None
        if commanded_quat is not None:
            cq = np.asarray(commanded_quat, float)[rows]
            if np.ptp(abc_from_quat_wxyz(cq), axis=0).max() > 1e-9:
                raise DataError(f"pose {name}: the commanded orientation differs between "
                                f"its cycles")
            cq = cq[:1]
        aq = None if attained_quat is None else np.asarray(attained_quat, float)[rows]
        out.append(pose_result(str(name), np.asarray(attained_m, float)[rows],
                               commanded[rows][0], aq, cq))
    return tuple(out)


def iso_report_to_dict(results, conditions: dict) -> dict:
    """The JSON document (mm and degrees, unrounded): ``poses``, ``worst``, ``conditions``."""
    poses = []
    for r in results:
        entry = {"pose": r.pose, "n": r.n, "AP_P_mm": r.ap_p_m * 1e3,
                 "AP_x_mm": r.ap_xyz_m[0] * 1e3, "AP_y_mm": r.ap_xyz_m[1] * 1e3,
                 "AP_z_mm": r.ap_xyz_m[2] * 1e3, "RP_l_mm": r.rp_l_m * 1e3,
                 "commanded_mm": (r.commanded_m * 1e3).tolist(),
                 "barycentre_mm": (r.barycentre_m * 1e3).tolist()}
        if r.ap_abc_rad is not None:
            for k, axis in enumerate("abc"):
                entry[f"AP_{axis}_deg"] = math.degrees(r.ap_abc_rad[k])
                entry[f"RP_{axis}_deg"] = math.degrees(r.rp_abc_rad[k])
        poses.append(entry)
    worst_ap = max(results, key=lambda r: r.ap_p_m)
    worst_rp = max(results, key=lambda r: r.rp_l_m)
    return {"standard": "ISO 9283:1998, 7.2.1 (AP) and 7.2.2 (RP)", "poses": poses,
            "worst": {"AP_P": {"pose": worst_ap.pose, "mm": worst_ap.ap_p_m * 1e3},
                      "RP_l": {"pose": worst_rp.pose, "mm": worst_rp.rp_l_m * 1e3}},
            "conditions": dict(conditions)}


def iso_summary(results, conditions: dict) -> list[str]:
    """Printed lines: one per pose, the worst pose, the test conditions (units shown)."""
    lines = ["ISO 9283:1998 pose accuracy (AP) and repeatability (RP):"]
    for r in results:
        text = (f"  {r.pose}: n = {r.n}, AP_P = {r.ap_p_m * 1e3:.4f} mm "
                f"(x {r.ap_xyz_m[0] * 1e3:+.4f}, y {r.ap_xyz_m[1] * 1e3:+.4f}, "
                f"z {r.ap_xyz_m[2] * 1e3:+.4f} mm), RP_l = {r.rp_l_m * 1e3:.4f} mm")
        if r.ap_abc_rad is not None:
            ap = ", ".join(f"{math.degrees(v):+.4f}" for v in r.ap_abc_rad)
            rp = ", ".join(f"{math.degrees(v):.4f}" for v in r.rp_abc_rad)
            text += f"; AP_a,b,c = ({ap}) deg, RP_a,b,c = +-({rp}) deg"
        lines.append(text)
    worst_ap = max(results, key=lambda r: r.ap_p_m)
    worst_rp = max(results, key=lambda r: r.rp_l_m)
    lines.append(f"worst pose: AP_P {worst_ap.ap_p_m * 1e3:.4f} mm at {worst_ap.pose}, "
                 f"RP_l {worst_rp.rp_l_m * 1e3:.4f} mm at {worst_rp.pose}")
    if conditions:
        lines.append("test conditions: " + "; ".join(_condition_words(k, v)
                                                     for k, v in conditions.items()))
    else:
        lines.append("test conditions: none given (the standard asks for load, speed, "
                     "temperature and the measuring instrument)")
    return lines


CONDITION_UNITS = {"load_kg": ("load", "kg"), "speed_mm_s": ("speed", "mm/s"),
                   "temperature_c": ("temperature", "deg C"), "instrument": ("instrument", "")}


def _condition_words(key: str, value) -> str:
    label, unit = CONDITION_UNITS.get(key, (key, ""))
    return f"{label} {value:g} {unit}".strip() if isinstance(value, (int, float)) \
        else f"{label} {value}"
