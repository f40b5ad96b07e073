"""Compensate a whole robot program: parse, resolve, solve the real arm, splice the numbers.

Only the numbers of compensated targets change (see :mod:`olp_compensate.programs.emit`);
with the nominal calibration nothing changes at all. What is done with each target:

- a Cartesian target (robtarget, V+ transformation) with known tool and work object is
  compensated (:mod:`olp_compensate.compensation.pose`); a calibrated tool of the same name as
  the program's tooldata is the real tool; its confdata is the quadrants of the joints
  written (:func:`~.confdata.written_confdata`: the configuration rule);
- a target used with several tool/work-object pairs is compensated only when every pair
  gives the same numbers (within the written resolution); otherwise it is left as written
  and reported 'ambiguous';
- joint targets (jointtarget, V+ precision points) are joints already: kept, 'joint_target';
- targets never moved to in the file are left as written ('unused'), unless the caller
  assumes tool0/wobj0 for them;
- motions whose target is computed at run time (Offs(), RelTool(), CRobT(), parameters)
  are listed 'runtime' / 'unresolved' with their reason;
- with ``taught_on`` (robot-to-robot transfer) the pose to reach is where the teaching
  robot's real tool went at its nominal joints for the target (:func:`_taught_flanges`).

:func:`compensate_module` does this for one module resolved alone or within its task;
:func:`compensate_program` is :func:`~.task.compensate_task` of one module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...calibration.calibration import GLOBAL_MODEL, Calibration
from ...compensation.failures import explain_failures
from ...compensation.ik import OPWParameters
from ...compensation.pose import COMPENSATED, Compensator
from ...compensation.program_tools import program_tool, program_tool_note
from ...compensation.report import (KEPT, LINE_COLUMN, NOT_MOVED, CompensationReport, TargetReport,
                                    config_texts)
from ...errors import DataError
from ...kinematics.conventions import (MM, invert_pose, matrix_from_quat_wxyz,
                                       pose_from_rotation_translation, rotation_angle_between)
from ..emit import splice
from ..targets import JointTarget, Program
from .confdata import vplus_configuration, written_confdata
from .frame_rows import frame_rows
from .program_edits import program_edits
from .rows import failure_row, joint_target_row, motion_row, row_name, solved_note, written_row

__all__ = ["TargetReport", "CompensationReport", "compensate_module",
           "ModuleResult", "check_options", "KEPT", "EMIT_MODES"]

EMIT_MODES = ("pose", "joints")
TOOL_FRAME_SLACK_RAD = math.radians(5.0)
"""A calibrated tool orientation this close to the tooldata's is taken as the real one."""
_SAME_MM, _SAME_RAD = 5e-4, 1e-6   # two compensations of one target agree within this


def _real_tool(calibration: Calibration, name: str, tooldata: np.ndarray):
    """flange_T_tool of the real robot for the program tool ``name`` (``tooldata``), and a
    note: a tool calibrated for programs of that name (:mod:`.program_tools`), else none.

    A calibrated orientation more than :data:`TOOL_FRAME_SLACK_RAD` from the tooldata's is
    the frame of the measuring device's probe, not the tool's axes: the tooldata's
    orientation is kept then (and the note says so)."""
    found = program_tool(calibration, [name])
    if found is None:
        return tooldata, ""
    note, tool, rotation = program_tool_note(name, found[0]), found[1], tooldata[:3, :3]
    if tool.quat_wxyz is not None:
        measured = matrix_from_quat_wxyz(tool.quat_wxyz)
        apart = float(rotation_angle_between(measured, rotation))
        if apart <= TOOL_FRAME_SLACK_RAD:
            rotation = measured
        else:
            note += (f" (its measured frame is {math.degrees(apart):.1f} deg from the "
                     f"tooldata's: the tooldata's orientation kept)")
    return pose_from_rotation_translation(rotation, tool.xyz_m), note


def check_options(emit: str, unused: str) -> None:
    """Raise DataError for an ``emit`` or ``unused`` value that is not known."""
    if emit not in EMIT_MODES:
        raise DataError(f"emit: expected one of {', '.join(EMIT_MODES)}, got {emit!r}")
    if unused not in ("skip", "tool0"):
        raise DataError(f"unused: expected 'skip' or 'tool0', got {unused!r}")


@dataclass(frozen=True, eq=False)
class ModuleResult:
    """What compensating one module of a task gave: its new text, its report rows (text
    order), its warnings (one line each) and the number of edits made."""

    text: str
    rows: list
    warnings: list
    edits: int


def compensate_module(program: Program, res, comp: Compensator, *, emit: str, unused: str,
                      teacher: Compensator | None = None,
                      not_moved: str = NOT_MOVED) -> ModuleResult:
    """Compensate the targets of one module, resolved (``res``, a
    :class:`~olp_compensate.programs.semantics.Resolution`, alone or within its task).

    teacher : the compensator of the robot the targets were taught on, or None.
    not_moved : the note of a target never moved to (left as written with unused='skip').
    """
    rows, warnings, edits = module_rows_and_edits(program, res, comp, emit=emit, unused=unused,
                                                  teacher=teacher, not_moved=not_moved)
    text = splice(program.text, edits) if edits else program.text
    return ModuleResult(text=text, rows=rows, warnings=warnings, edits=len(edits))


def module_rows_and_edits(program: Program, res, comp: Compensator, *, emit: str,
                          unused: str, teacher: Compensator | None = None,
                          not_moved: str = NOT_MOVED) -> tuple[list, list, list]:
    """:func:`compensate_module` before the splice: (rows in text order, warnings, the
    edits of the text sorted by offset)."""
    vplus = program.dialect == "vplus"
    rows, job = _rows_not_solved(res, unused, not_moved)
    solved = solve_entries(comp, res, job, vplus, teacher) if job else None
    write = _rows_solved(res, job, solved, comp.robot, vplus, rows) if job else {}
    rows.extend(motion_row(use, "runtime" if use.runtime is not None else "unresolved", why)
                for use, why in res.unresolved)
    rows.extend(_problem_rows(program) + frame_rows(program, res))
    rows.sort(key=LINE_COLUMN)
    warnings = list(res.warnings)
    edits = program_edits(program, comp, res, job, write, solved, emit, vplus, warnings)
    return rows, warnings, edits


def _rows_not_solved(res, unused: str, not_moved: str) -> tuple[list, list[int]]:
    """(rows, job): a row for each entry decided without solving (joint targets, unused,
    unresolved), None for the others, whose entry indices are the ``job`` to solve."""
    targets, pairs = res.entry_targets, res.pairs
    pair_of = res.entry_pairs.tolist()
    rows: list = [None] * len(targets)
    job: list[int] = []
    known = np.isfinite(res.base_T_flange[:, 0, 0]).tolist()
    skip_unused = unused == "skip"
    bad = res.bad_value.tolist()
    for k, t in enumerate(targets):
        if type(t) is JointTarget:
            rows[k] = joint_target_row(t, pairs[pair_of[k]])
        elif bad[k]:
            rows[k] = written_row(t, pairs[pair_of[k]], "bad_target", res.entry_notes[k][0])
        elif skip_unused and not res.entry_uses[k] and "unused" in res.entry_notes[k]:
            rows[k] = written_row(t, pairs[pair_of[k]], "unused", not_moved)
        elif known[k]:
            job.append(k)
        else:
            rows[k] = written_row(t, pairs[pair_of[k]], "unresolved",
                                  "; ".join(res.entry_notes[k]))
    return rows, job


def _rows_solved(res, job: list[int], solved, robot, vplus: bool, rows: list
                 ) -> dict[int, int]:
    """Fill ``rows`` for the solved ``job`` entries; returns the targets to write:
    id(target) -> job row, in text order."""
    targets, pairs = res.entry_targets, res.pairs
    pair_of = res.entry_pairs.tolist()
    write: dict[int, int] = {}
    ambiguous = _ambiguous(res, job, solved)
    config_after = ([solved.vplus_text.get(i, "") for i in range(len(job))] if vplus else
                    config_texts(solved.conf))
    ok, reason = solved.ok.tolist(), solved.reason
    shift = list(map(tuple, solved.shift_mm.tolist()))
    turn, change = solved.turn_deg.tolist(), solved.change_deg.tolist()
    joints = list(map(tuple, solved.joints_deg.tolist()))
    entry_notes, tool_note = res.entry_notes, solved.tool_note
    for i, (k, before) in enumerate(zip(job, solved.config_before)):
        t = targets[k]
        pair = pairs[pair_of[k]]
        notes = entry_notes[k]
        note = solved_note(notes, tool_note[i]) if notes else tool_note[i]
        file, line, column = t.source
        name = row_name(t)
        if not ok[i]:
            rows[k] = failure_row(TargetReport(
                target=name, file=file, line=line, column=column, status=reason[i],
                tool=pair.tool_name, wobj=pair.wobj_name, config_before=before, note=note),
                solved.failures[i], robot, vplus)
        elif k in ambiguous:
            rows[k] = TargetReport(
                target=name, file=file, line=line, column=column, status="ambiguous",
                tool=pair.tool_name, wobj=pair.wobj_name, config_before=before,
                joints=joints[i], note="used with several tools/work objects needing "
                                       "different corrections; left as written")
        else:
            write[id(t)] = i
            rows[k] = TargetReport(
                target=name, file=file, line=line, column=column, status=reason[i],
                tool=pair.tool_name, wobj=pair.wobj_name, correction_mm=shift[i],
                correction_deg=turn[i], joint_change=change[i], config_before=before,
                config_after=config_after[i], joints=joints[i], note=note)
    return write


def _problem_rows(program: Program) -> list[TargetReport]:
    """Rows for what the parser found but could not take as a target (``program.problems``:
    a literal with a zero quaternion, a motion instruction it does not know...)."""
    return [TargetReport(target=p.target, file=p.location.file, line=p.location.line,
                         column=p.location.column, status=p.status, note=p.reason)
            for p in program.problems]


@dataclass(eq=False)
class _Solved:
    """The solved job (one row per job entry); lengths mm, angles deg, joints controller.

    written : (n, 4) confdata as written, has_conf : (n,) whether there is one (not V+);
    config_before : its text; conf : (n, 4) the confdata to write.
    new_targets : (n, 4, 4) the compensated targets in their work objects, m (NaN rows
    where not compensated).
    """

    ok: np.ndarray
    reason: list
    written: np.ndarray
    has_conf: np.ndarray
    config_before: list
    conf: np.ndarray
    new_targets: np.ndarray
    q_ctrl: np.ndarray
    shift_mm: np.ndarray
    turn_deg: np.ndarray
    change_deg: np.ndarray
    joints_deg: np.ndarray
    tool_note: list
    vplus_text: dict
    failures: list
    state: object = None    # the solver's SolverState of the rows (retries left out), or None


def solve_entries(comp: Compensator, res, job: list[int], vplus: bool,
                  teacher: Compensator | None = None, *, retries: bool = True,
                  resume=None) -> _Solved:
    """Solve the real arm for the job entries and derive what the report and the emitter
    need (``teacher``: the robot the targets were taught on, see :func:`_taught_flanges`).
    ``res``: a Resolution, or anything with its arrays ``written``, ``base_T_flange``,
    ``wobj_T_target``, ``entry_pairs`` and its ``pairs``. ``retries`` False (a plain
    Compensator only): the solver's retries of failed entries are left out, and so is the
    account of why they failed (their ``failures`` are None): the caller solves them
    again, from the solver's state where the result keeps one (``state``: every entry
    with a written configuration, the program's tool the real one) by passing that
    state of the entries it solves as ``resume``."""
    robot = comp.robot
    n = len(job)
    written = res.written[job, 7:11]
    has_conf = np.isfinite(written).all(axis=1)
    written = np.where(has_conf[:, None], np.rint(written), -99).astype(int)
    requested = res.base_T_flange[job]
    desired, tool_note, tool_change = _aim(comp, res, job, requested, teacher)
    q = np.full((n, robot.n_joints), np.nan)
    flange = np.full((n, 4, 4), np.nan)
    nominal = np.full((n, robot.n_joints), np.nan)
    reason = np.empty(n, dtype=object)
    failures: list = [None] * n
    regional = _regions(comp, res, job, requested)
    groups = _configuration_groups(comp, written, has_conf, requested)
    single = len(groups) == 1 and groups[0][1] is not None and regional is None
    keep = [] if single and not retries else None
    resume = resume if single and resume is not None and len(resume.start) == n else None
    for idx, conf in groups:
        if teacher is not None:
            desired[idx] = _taught_flanges(teacher, requested[idx], conf, desired[idx],
                                           tool_change[idx])
        if regional is None:
            qi, fi, sol, nomi = comp.compensate_flanges(desired[idx], requested[idx], conf,
                                                        retries=retries, keep=keep,
                                                        resume=resume)
            explained = explain_failures(comp, sol, desired[idx], conf) \
                if retries and not sol.success.all() else ()
        else:
            regions, tool_keys = regional
            qi, fi, sol, nomi, where = comp.solve_regions(
                desired[idx], requested[idx], conf, regions=regions[idx], tools=tool_keys[idx])
            explained = comp.explain_failures(sol, where, conf) if not sol.success.all() else ()
            for i, name in zip(idx, where.regions.tolist()):
                used = "global model" if name == GLOBAL_MODEL else f"model of region {name}"
                tool_note[i] = f"{tool_note[i]}; {used}" if tool_note[i] else used
        q[idx], flange[idx], nominal[idx] = qi, fi, nomi
        reason[idx] = sol.reason
        for i, failure in zip(idx, explained):
            failures[i] = failure
    reason = reason.tolist()
    ok = np.fromiter((r in COMPENSATED for r in reason), bool, n)
    if regional is None:       # the effects' fitted ranges and the residual map
        parts = comp.fitted_parts(desired, q, flange, ok, tool_note)
        q, flange = parts.q, parts.flange
    new_targets = _written_targets(res, job, flange, ok)
    original = res.wobj_T_target[job]
    q_ctrl = robot.controller_from_joints(q)
    nominal_ctrl = robot.controller_from_joints(nominal)
    conf = np.full((n, 4), -99, int)
    if np.any(ok):
        conf[ok] = comp.confdata(q[ok])
    if not vplus:
        rows_c = np.flatnonzero(ok & has_conf)
        if len(rows_c):
            conf[rows_c] = written_confdata(written[rows_c], q_ctrl[rows_c],
                                            nominal_ctrl[rows_c])
    change = np.abs(robot.to_degrees_or_mm(q_ctrl - nominal_ctrl))
    change = np.where(np.all(np.isnan(change), axis=1), np.nan,
                      np.nanmax(np.where(np.isnan(change), -np.inf, change), axis=1))
    return _Solved(
        ok=ok, reason=reason, written=written, has_conf=has_conf,
        config_before=config_texts(written, has_conf), conf=conf, new_targets=new_targets,
        q_ctrl=q_ctrl, shift_mm=(new_targets[:, :3, 3] - original[:, :3, 3]) / MM,
        turn_deg=np.degrees(rotation_angle_between(new_targets[:, :3, :3],
                                                   original[:, :3, :3])),
        change_deg=change, joints_deg=robot.to_degrees_or_mm(q_ctrl), tool_note=tool_note,
        vplus_text=_vplus_texts(comp, q, ok) if vplus else {}, failures=failures,
        state=keep[0] if keep else None)


def _regions(comp: Compensator, res, job: list[int], requested: np.ndarray):
    """With a :class:`~.regions.RegionalCompensator`: each row's region (by the program
    tool's TCP in the base frame; a stationary tool's by the flange) and the name of the
    calibrated tool that is its real TCP (None where none is); else None."""
    from ...compensation.regions import RegionalCompensator

    if not isinstance(comp, RegionalCompensator):
        return None
    pair_index = res.entry_pairs[job]
    tcp = requested.copy()
    tool_keys = np.full(len(job), None, dtype=object)
    for p in sorted(set(pair_index.tolist())):   # (np.unique imports numpy.ma: 7 ms)
        pair = res.pairs[p]
        members = np.flatnonzero(pair_index == p)
        if not pair.stationary_tool:
            tcp[members] = requested[members] @ pair.flange_T_tool
            tool_keys[members] = _calibrated_tool_key(comp.calibration, pair.tool_name)
    return comp.regions_for(tcp), tool_keys


def _calibrated_tool_key(calibration: Calibration, name: str) -> str | None:
    """The calibration's name of the program tool the program calls ``name``, or None."""
    return (program_tool(calibration, [name]) or (None,))[0]


def _aim(comp: Compensator, res, job: list[int], requested: np.ndarray,
         teacher: Compensator | None):
    """The flange poses (n, 4, 4) the real arm must reach: ``requested`` re-aimed where a
    calibrated tool of the tooldata's name is the real TCP; each row's tool note; and, for
    a transfer, the change from the teacher's real tool to this robot's (else None)."""
    n = len(job)
    pair_index = res.entry_pairs[job]
    desired = requested.copy()
    tool_note = [""] * n
    tool_change = None if teacher is None else np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    for p in sorted(set(pair_index.tolist())):   # (np.unique imports numpy.ma: 7 ms)
        pair = res.pairs[p]
        members = np.flatnonzero(pair_index == p)
        if pair.stationary_tool:
            note = "stationary tool"
        else:
            tool, note = _real_tool(comp.calibration, pair.tool_name, pair.flange_T_tool)
            if note:  # a calibrated tool differs from the program's: re-aim the flange
                desired[members] = requested[members] @ pair.flange_T_tool @ invert_pose(tool)
            if tool_change is not None:
                taught_tool, _ = _real_tool(teacher.calibration, pair.tool_name,
                                            pair.flange_T_tool)
                tool_change[members] = taught_tool @ invert_pose(tool)
        for i in members.tolist():
            tool_note[i] = note
    return desired, tool_note, tool_change


def _configuration_groups(comp: Compensator, written: np.ndarray, has_conf: np.ndarray,
                          requested: np.ndarray):
    """(rows, confdata or None) groups to solve: the rows with a written configuration and
    those of no configuration (V+) whose nominal solution implies one; then the rows the
    nominal arm cannot reach at all (solved on any configuration)."""
    with_conf = np.flatnonzero(has_conf).tolist()
    without = np.flatnonzero(~has_conf).tolist()
    conf_all = written[has_conf]
    if without:
        # no written configuration (V+): the arm stays in the one the nominal
        # controller takes for the original target (the branch nearest zero)
        q_nominal = comp.solve_nominal(requested[without], None)
        reachable = np.all(np.isfinite(q_nominal), axis=1)
        implied = [i for i, r in zip(without, reachable) if r]
        if implied:
            conf_all = np.concatenate([conf_all, comp.confdata(q_nominal[reachable])])
        without = [i for i, r in zip(without, reachable) if not r]
        with_conf = with_conf + implied
    return [(idx, conf) for idx, conf in ((with_conf, conf_all), (without, None)) if idx]


def _written_targets(res, job: list[int], flange: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """The targets (n, 4, 4) to write in their work objects, m: robot-held tool
    inv(wobj) F tool; stationary tool inv(flange_T_wobj) inv(F) world_T_tool; NaN where not
    compensated."""
    pair_index = res.entry_pairs[job]
    pair_wobj = np.array([_pose_or_nan(p.base_T_wobj) for p in res.pairs])
    pair_tool = np.array([_pose_or_nan(p.flange_T_tool) for p in res.pairs])
    stationary = np.array([p.stationary_tool for p in res.pairs], bool)[pair_index]
    moved = flange.copy()
    if np.any(stationary):
        moved[stationary] = invert_pose(flange[stationary])
    new_targets = invert_pose(pair_wobj)[pair_index] @ moved @ pair_tool[pair_index]
    new_targets[~ok] = np.nan
    return new_targets


def _vplus_texts(comp: Compensator, q: np.ndarray, ok: np.ndarray) -> dict[int, str]:
    """Row -> the V+ configuration words of the solved joints (report only)."""
    texts = {}
    if isinstance(comp.family, OPWParameters) and np.any(ok):
        flags = vplus_configuration(comp.family, q[ok])
        for i, (righty, above, flip) in zip(np.flatnonzero(ok).tolist(), flags):
            texts[i] = " ".join(("RIGHTY" if righty else "LEFTY", "ABOVE" if above else "BELOW",
                                 "FLIP" if flip else "NOFLIP"))
    return texts


def _taught_flanges(teacher: Compensator, requested: np.ndarray, confdata, fallback,
                    tool_change: np.ndarray) -> np.ndarray:
    """Robot-to-robot transfer: the flange poses (k, 4, 4), base frame, m, that put this
    robot's real tool where the teaching robot's real tool went for the written targets.

    The teaching robot's nominal controller took the joints q_A of the nominal closed form
    for ``requested`` (its flange poses, on ``confdata``; None: the branch nearest zero);
    its real tool went to teacher.real_flange(q_A) @ real_tool_A; this robot's flange
    must go there @ inv(real_tool_B). ``tool_change`` (k, 4, 4) is real_tool_A @
    inv(real_tool_B) (identity for a stationary tool: the flange carries the work
    object). Rows the teacher's controller cannot reach keep ``fallback``."""
    q_taught = teacher.solve_nominal(requested, confdata)
    reached = np.all(np.isfinite(q_taught), axis=1)
    out = np.array(fallback, dtype=float, copy=True)
    if np.any(reached):
        flange, _ = teacher.real_flange_and_jacobian(q_taught[reached])
        out[reached] = flange @ tool_change[reached]
    return out


def _pose_or_nan(pose) -> np.ndarray:
    return np.full((4, 4), np.nan) if pose is None else pose


def _ambiguous(res, job: list[int], solved: _Solved) -> set[int]:
    """Entries of targets used with several tool/work-object pairs whose compensations
    differ (or fail for one pair): those are left as written."""
    if not res.shared:
        return set()
    row = {k: i for i, k in enumerate(job)}
    ambiguous: set[int] = set()
    for group in res.shared:
        members = [k for k in group if k in row]   # the entries that were solved
        if len(members) < 2:
            continue
        if not all(solved.ok[row[k]] for k in members):
            ambiguous.update(members)
            continue
        poses = solved.new_targets[[row[k] for k in members]]
        apart = np.linalg.norm(poses[1:, :3, 3] - poses[0, :3, 3], axis=1)
        turned = rotation_angle_between(poses[1:, :3, :3], poses[0, :3, :3])
        if np.any(apart > _SAME_MM * MM) or np.any(turned > _SAME_RAD):
            ambiguous.update(members)
    return ambiguous
