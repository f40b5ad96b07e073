"""How a compensated program's new targets are written: the edits of the numbers (or of
whole targets turned into joint targets with ``--emit joints``), for
:func:`~olp_compensate.programs.object_model.program.compensate_module`."""

from __future__ import annotations

import operator

import numpy as np

from ...errors import DataError
from ...kinematics.conventions import MM, quat_wxyz_from_matrix, rotation_angle_between
from .. import Program
from ..emit import nearest_euler_zyz_deg, target_edits
from ..emit_batch import edits_for_targets
from ..emit_joints import joint_emit_edits

def orientations(targets, rotations: np.ndarray, vplus: bool) -> np.ndarray:
    """Orientation numbers for ``rotations`` (k, 3, 3): unit quaternions (RAPID; the
    emitter leaves a written one alone when it is the same rotation), or Z-Y-Z degrees
    (V+): the written triple when the rotation did not change at its resolution, else the
    equivalent triple nearest to it."""
    if not vplus:
        return quat_wxyz_from_matrix(rotations)
    out = []
    for t, rotation in zip(targets, rotations):
        written = t.orientation_values()
        if rotation_angle_between(rotation, t.rotation()) < 1e-7:
            out.append(written)
        else:
            out.append(nearest_euler_zyz_deg(rotation, written))
    return np.array(out).reshape(-1, 3)


def program_edits(program, comp, res, job, write, solved, emit, vplus, warnings):
    """The text edits writing the compensated targets ``write`` (id(target) -> job row,
    in text order)."""
    if not write:
        return []
    robot = comp.robot
    rows = list(write.values())
    targets = [res.entry_targets[job[i]] for i in rows]
    edits = []
    if emit == "joints":
        uses: dict[int, list] = {}
        for t, u in zip(res.entry_targets, res.entry_uses):
            uses.setdefault(id(t), []).extend(u)
        convertible = _joint_convertible(program, uses, targets)
        as_joints = [(t, i) for t, i in zip(targets, rows) if id(t) in convertible]
        try:
            edits = joint_emit_edits(program, {t: robot.to_degrees_or_mm(solved.q_ctrl[i])
                                               for t, i in as_joints})
        except DataError as exc:
            warnings.append(f"{exc}; every target is written as a pose instead")
            edits, as_joints = [], []
        for t in targets:
            if id(t) not in convertible:
                warnings.append(f"{t.location}: {t.display_name} stays a Cartesian target "
                                f"(compensated): {_joint_blocker(program, uses, t)}")
        done = {id(t) for t, _ in as_joints}
        rest = [(t, i) for t, i in zip(targets, rows) if id(t) not in done]
        if not rest:
            return sorted(edits, key=_START)
        targets, rows = [t for t, _ in rest], [i for _, i in rest]
    new_targets = solved.new_targets[rows]
    orientation = orientations(targets, new_targets[:, :3, :3], vplus)
    edits += edits_for_targets(program, new_targets[:, :3, 3] / MM, orientation, None, targets,
                               res.written[[job[i] for i in rows]])
    if not vplus:
        conf = solved.conf[rows]
        changed = np.flatnonzero(np.any(conf != solved.written[rows], axis=1)
                                 & solved.has_conf[rows])
        for j in changed.tolist():
            edits += target_edits(targets[j], config=conf[j])
    edits.sort(key=_START)
    return edits


_START = operator.itemgetter(0)
_JOINT_INSTRUCTIONS = {"movel", "movej", "move", "moves", "appro", "appros", "depart", "departs"}


def _joint_blocker(program: Program, uses: dict, t) -> str | None:
    """Why target ``t`` cannot become a joint target, or None (``uses``: id(target) ->
    its motion uses)."""
    for u in uses.get(id(t), ()):
        if u.instruction.lower() not in _JOINT_INSTRUCTIONS:
            return f"{u.instruction} at line {u.location.line} needs a Cartesian target"
        if u.wobj is not None and program.dialect == "vplus":
            return f"used relative to frame {u.wobj} at line {u.location.line}"
    if t.storage == "assigned":
        return f"assigned in {t.routine} at line {t.location.line}: stays a robtarget"
    if t.name is None:
        return None
    key = t.name.lower()
    for r in program.runtime:
        if r.base_name and r.base_name.lower() == key:
            return f"{r.expression!r} at line {r.location.line} needs a Cartesian target"
    for r in program.references:
        if r.name.lower() == key:
            return f"passed to {r.context} at line {r.location.line}"
    return None


def _joint_convertible(program: Program, uses: dict, targets) -> set[int]:
    """ids of the targets that can become joint targets: every use a plain move, no
    run-time use, and (RAPID arrays) every element of the declaration convertible."""
    chosen = {id(t) for t in targets}
    ok = {id(t) for t in targets if _joint_blocker(program, uses, t) is None}
    if program.dialect == "rapid":
        by_decl: dict = {}
        for t in program.targets:
            if t.storage not in ("inline", "assigned"):
                by_decl.setdefault(t.type_span, []).append(t)
        for members in by_decl.values():
            if any(id(m) not in ok or id(m) not in chosen for m in members):
                ok -= {id(m) for m in members}
    return ok
