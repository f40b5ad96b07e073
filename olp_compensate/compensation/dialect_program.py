"""Compensation of a program of a pose dialect (KRL, FANUC TP, VAL3, URScript).

For each target a motion uses, as for RAPID
(:mod:`olp_compensate.programs.object_model.program`): the pose the program means (base
frame x target x tool), the joints the dialect's controller takes for it (its written
configuration picks the branch: :mod:`.dialect_rules`), the joints at which the calibrated
arm puts its real tool there on that branch, and the target the nominal controller turns
into exactly those joints, written back in place of the original numbers (configuration
numbers updated where the solution's differ). Every target is compensated or reported with
its file, line, column and reason.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ..calibration.calibration import Calibration
from ..kinematics.conventions import MM, invert_pose, rotation_angle_between
from ..programs.emit import format_like, splice
from ..programs.pose_dialects import JOINTS, PoseProgram, PoseTarget
from ..programs.targets import Edit
from .dialect_config import (choose_all, config_namer, dialect_asked, geometry_of, on_rows,
                             rule_alone)
from .dialect_rules import ArmGeometry, DialectRules
from .failures import explain_failures
from .frame_lookup import FrameLookup
from .pose import COMPENSATED, Compensator
from .regions import RegionalCompensator
from .report import CompensationReport, TargetReport

@dataclass
class _Job:
    """One target to solve: where it is, what the program asks, in metres."""

    index: int
    target: PoseTarget
    tool_key: str | None
    base_key: str | None
    base: np.ndarray
    tool: np.ndarray
    real_tool: np.ndarray
    wobj_T_target: np.ndarray
    note: str
    left: np.ndarray | None = None       # KRL ``left : target``: the left operand's pose, m


def compensate_pose_program(program: PoseProgram, rules: DialectRules,
                            calibration: Calibration | Compensator,
                            taught_on: Calibration | Compensator | None = None
                            ) -> tuple[dict[str, str], CompensationReport]:
    """Compensate every target of ``program``; returns the new text of each file and the
    report. ``taught_on``: the calibration of the robot the targets were taught on (robot
    to robot transfer): the pose to reach is where that robot's real tool went."""
    comp = calibration if isinstance(calibration, Compensator) else Compensator(calibration)
    teacher = (None if taught_on is None else taught_on if isinstance(taught_on, Compensator)
               else Compensator(taught_on, comp.controller))
    geometry = geometry_of(comp)
    frames = FrameLookup(program, rules, comp.calibration)
    rows: list[TargetReport] = []
    jobs = _jobs(program, rules, frames, rows)
    edits: dict[str, list[Edit]] = defaultdict(list)
    if jobs:
        _solve(comp, teacher, geometry, rules, jobs, rows, edits)
        _external_rows(program, rules, rows, edits)
    texts = {file: (splice(text, edits[file]) if edits.get(file) else text)
             for file, text in program.texts.items()}
    rows.sort(key=lambda r: (r.file, r.line, r.column))
    report = CompensationReport(file=next(iter(program.texts), "<string>"), rows=tuple(rows),
                                warnings=tuple(program.notes), n_joints=comp.robot.n_joints,
                                edits=sum(len(e) for e in edits.values()))
    return texts, report


def _row(target: PoseTarget, status: str, note: str, tool: str = "", base: str = "",
         config_before: str = "") -> TargetReport:
    file, line, column = target.source
    return TargetReport(target=target.name or "<inline>", file=file, line=line, column=column,
                        status=status, tool=tool or "", wobj=base or "",
                        config_before=config_before, note=note)


@dataclass
class _Uses:
    """What the motions do with each target (index into ``program.targets``): its
    (tool, base) pairs, the order of its first use, and the left operand it is composed
    with (KRL ``left : {target}``)."""

    uses: dict[int, set]
    first_use: dict[int, int]
    composed: dict[int, int]


def _motion_uses(program: PoseProgram, by_name, rows: list[TargetReport]) -> _Uses:
    """The uses of every target by the motions; rows for run-time motions (at the literal
    a motion writes, else at the motion), motions to names declared nowhere, targets kept
    with a reason and unknown instructions."""
    out = _Uses(defaultdict(set), {}, {})
    for order, motion in enumerate(program.motions):
        if motion.runtime is not None:
            where = (motion.source if motion.inline is None       # a literal: at its place
                     else program.targets[motion.inline].source)
            rows.append(TargetReport(target=motion.target or "<inline>", file=where[0],
                                     line=where[1], column=where[2],
                                     status="runtime", tool=motion.tool or "",
                                     wobj=motion.base or "", note=motion.runtime))
            if motion.inline is not None:
                out.uses[motion.inline].add(("runtime", None))
            for name in motion.candidates:          # an array indexed at run time
                for k in by_name.get(name.upper(), []):
                    out.uses[k].add((motion.tool, motion.base))
                    out.first_use.setdefault(k, order)
            continue
        if motion.left is not None and motion.inline is not None:
            left = _left_operand(program, by_name, motion, rows)
            if left is None:
                out.uses[motion.inline].add(("runtime", None))
                continue
            out.composed[motion.inline] = left
            out.uses[left].add(OPERAND)
        found = ([motion.inline] if motion.inline is not None
                 else by_name.get((motion.target or "").upper(), []))
        if not found:
            rows.append(TargetReport(target=motion.target or "<target>", file=motion.source[0],
                                     line=motion.source[1], column=motion.source[2],
                                     status="unresolved", tool=motion.tool or "",
                                     wobj=motion.base or "",
                                     note=f"{motion.target} is declared in no file given"))
        for k in found:
            out.uses[k].add((motion.tool, motion.base))
            out.first_use.setdefault(k, order)
    for where, name, status, note in program.kept:
        rows.append(TargetReport(target=name, file=where[0], line=where[1], column=where[2],
                                 status=status, note=note))
    for where, instruction in program.unknown:
        rows.append(TargetReport(target=instruction, file=where[0], line=where[1],
                                 column=where[2], status="unknown_instruction",
                                 note=f"{instruction}: a motion whose target could not be read"))
    return out


def _not_solved(program: PoseProgram, target: PoseTarget, pairs: set,
                config: str) -> TargetReport | None:
    """The row of a target decided without solving (joints, unused, ambiguous...), or
    None for a target to solve with its one pair."""
    if target.kind == JOINTS:
        return _row(target, "joint_target", "axis values kept as written")
    if not target.numbers:
        return _row(target, "runtime", "the aggregate leaves some of the pose to the "
                                       "position at run time")
    if not pairs and target.name in program.runtime_uses:
        return _row(target, "runtime", program.runtime_uses[target.name], config_before=config)
    if not pairs:
        return _row(target, "unused", "not moved to in the files given: tool and base "
                                      "unknown, left as written", config_before=config)
    if len(pairs) > 1:
        return _row(target, "ambiguous", "used with several tools/bases needing different "
                                         "corrections; left as written", config_before=config)
    return None


def _jobs(program: PoseProgram, rules: DialectRules, frames: FrameLookup,
          rows: list[TargetReport]) -> list[_Job]:
    """The targets to solve; rows for the others (unused, joints, run-time, unknown
    instructions, unresolved frames, several tools)."""
    by_name: dict[str, list[int]] = defaultdict(list)
    for k, t in enumerate(program.targets):
        if t.name is not None:
            by_name[t.name.upper()].append(k)
    found = _motion_uses(program, by_name, rows)
    jobs = []
    for k, target in enumerate(program.targets):
        pairs = found.uses.get(k, set())
        config = rules.config_words(rules.written(target))
        if ("runtime", None) in pairs:
            continue
        if OPERAND in pairs:
            pairs = pairs - {OPERAND}
            if not pairs:
                rows.append(_row(target, "unused", "moved to only as the left operand of ':' "
                                 "(geometric operator): kept as written, the correction is "
                                 "written into the right operand", config_before=config))
                continue
        row = _not_solved(program, target, pairs, config)
        if row is not None:
            rows.append(row)
            continue
        (tool_key, base_key), = pairs
        tool, why_tool = frames.program_frame(tool_key, "tool")
        base, why_base = frames.program_frame(base_key, "base")
        if tool is None or base is None:
            rows.append(_row(target, "unresolved", why_tool if tool is None else why_base,
                             tool_key or "", base_key or "", config))
            continue
        real, real_note = frames.real_tool(tool_key, tool)
        note = "; ".join(x for x in (why_tool, why_base, real_note) if x)
        wobj_T_target = rules.convention.pose(np.array([n.value for n in target.numbers]))
        left = None
        if k in found.composed:
            left_target = program.targets[found.composed[k]]
            left = rules.convention.pose(np.array([n.value for n in left_target.numbers]))
            wobj_T_target = left @ wobj_T_target
            note = "; ".join(x for x in (
                f"{left_target.name} : this target (geometric operator), the correction "
                f"written here; branch: by this literal's own configuration, else the one "
                f"nearest the previous target ({left_target.name}'s S and T are not used)",
                note) if x)
        jobs.append(_Job(index=k, target=target, tool_key=tool_key, base_key=base_key,
                         base=base, tool=tool, real_tool=real,
                         wobj_T_target=wobj_T_target, note=note, left=left))
    # in program order (the order the controller meets them): the previous joints of a
    # target are those of the target moved to before it
    jobs.sort(key=lambda job: found.first_use.get(job.index, len(program.motions)))
    return jobs


OPERAND = ("operand", None)
"""The use of a target as the left operand of a KRL geometric operator ``left : {...}``."""


def _left_operand(program: PoseProgram, by_name, motion, rows: list[TargetReport]):
    """Index of the target a ``left : {...}`` motion composes with, or None (a row says
    why the motion is not solved)."""
    found = by_name.get(motion.left.upper(), [])
    why = None
    if not found:
        why = f"{motion.left} is declared in no file given"
    elif len(found) > 1:
        why = f"{motion.left} is declared more than once"
    elif program.targets[found[0]].kind == JOINTS or not program.targets[found[0]].numbers:
        why = f"{motion.left} is not a complete frame (X, Y, Z, A, B, C)"
    if why is None:
        return found[0]
    rows.append(TargetReport(target=f"{motion.left} : {{...}}", file=motion.source[0],
                             line=motion.source[1], column=motion.source[2],
                             status="unresolved", tool=motion.tool or "",
                             wobj=motion.base or "", note=f"geometric operator: {why}"))
    return None


def _solve(comp: Compensator, teacher: Compensator | None, geometry: ArmGeometry,
           rules: DialectRules, jobs: list[_Job], rows: list[TargetReport],
           edits: dict[str, list[Edit]]) -> None:
    """Solve the jobs; a row (and the edits) for each. The status is the configuration
    rule's (:mod:`.config_rule`), the configuration asked for being the dialect's written
    one (:func:`_dialect_asked`), also where the nominal arm has no branch with it."""
    robot = comp.robot
    requested = np.array([j.base @ j.wobj_T_target @ invert_pose(j.tool) for j in jobs])
    desired = (requested @ np.array([j.tool for j in jobs])
               @ invert_pose(np.array([j.real_tool for j in jobs])))
    chosen, previous_of = choose_all(comp, geometry, rules, jobs, requested)
    asked = dialect_asked(rules, geometry, jobs, previous_of)
    words = config_namer(rules, geometry, jobs)
    q_nominal = chosen.copy()
    unchosen = np.flatnonzero(~np.all(np.isfinite(chosen), axis=1))
    if len(unchosen):
        # no branch of the nominal arm has the written configuration: the calibrated arm's
        # may (then its joints stand in for the controller's), else the rule says why not
        found = rule_alone(comp, desired[unchosen], on_rows(asked, unchosen))
        explained = explain_failures(comp, found, desired[unchosen], None,
                                     on_rows(words, unchosen))
        for r, i in enumerate(unchosen.tolist()):
            if found.success[r]:
                chosen[i] = robot.controller_from_joints(found.q[r][None])[0]
            else:
                rows.append(_failure_row(jobs[i], rules, explained[r], robot))
    keep = np.flatnonzero(np.all(np.isfinite(chosen), axis=1))
    if not len(keep):
        return
    jobs = [jobs[i] for i in keep.tolist()]
    requested, desired = requested[keep], desired[keep]
    q_chosen, q_nominal = chosen[keep], q_nominal[keep]
    confdata = comp.confdata(robot.joints_from_controller(q_chosen))
    if teacher is not None:                     # where the teaching robot's real tool went
        desired = _taught(comp, teacher, rules, jobs, q_nominal, requested, desired)
    options = {} if isinstance(comp, RegionalCompensator) else {"asked": on_rows(asked, keep)}
    q, flange, solution, _ = comp.compensate_flanges(desired, None, confdata, **options)
    failures = explain_failures(comp, solution, desired, confdata, on_rows(words, keep))
    notes = [""] * len(jobs)         # the residual map and the effects' fitted ranges
    parts = comp.fitted_parts(desired, q, flange, solution.success, notes)
    q, flange = parts.q, parts.flange
    for i, job in enumerate(jobs):
        if not solution.success[i]:
            rows.append(_failure_row(job, rules, failures[i], robot))
            continue
        q_ctrl = robot.controller_from_joints(q[i][None])[0]
        rows.append(_solved_row(job, rules, geometry, q_ctrl, flange[i], q_nominal[i],
                                str(solution.reason[i]), robot, edits, notes[i]))


def _failure_row(job: _Job, rules: DialectRules, failure, robot) -> TargetReport:
    """The row of a job the rule did not let through: its status, note and joints."""
    before = rules.config_words(rules.written(job.target))
    row = _row(job.target, failure.status,
               "; ".join(x for x in (failure.note, job.note) if x),
               job.tool_key or "", job.base_key or "", before)
    if np.all(np.isfinite(failure.joints)):
        row.joints = tuple(robot.to_degrees_or_mm(failure.joints[None])[0].tolist())
    return row


def _taught(comp: Compensator, teacher: Compensator, rules: DialectRules, jobs: list[_Job],
            q_nominal: np.ndarray, requested: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Robot-to-robot transfer: the flange poses putting this robot's real tool where the
    teaching robot's real tool went at the joints its controller takes for the
    ``requested`` flange poses (the nominal ones, refined on ``comp``'s controller model
    where it has one; ``fallback`` where the nominal arm had none)."""
    out = fallback.copy()
    known = np.flatnonzero(np.all(np.isfinite(q_nominal), axis=1))
    if not len(known):
        return out
    taught_tool = np.array([FrameLookup(None, rules, teacher.calibration)  # type: ignore[arg-type]
                            .real_tool(jobs[i].tool_key, jobs[i].tool)[0] for i in known])
    q_urdf = comp.controller_joints(teacher.robot.joints_from_controller(q_nominal[known]),
                                    requested[known])
    real_flange, _ = teacher.real_flange_and_jacobian(q_urdf)
    meant = real_flange @ taught_tool
    out[known] = meant @ invert_pose(np.array([jobs[i].real_tool for i in known]))
    return out


def _solved_row(job: _Job, rules: DialectRules, geometry: ArmGeometry, q_ctrl: np.ndarray,
                flange: np.ndarray, q_nominal: np.ndarray, status: str, robot,
                edits: dict[str, list[Edit]], extra_note: str = "") -> TargetReport:
    """The row of a compensated job; its edits (numbers, and the configuration of the
    joints written) added to ``edits``; ``extra_note`` joins the job's note."""
    before = rules.config_words(rules.written(job.target))
    new_target = invert_pose(job.base) @ flange @ job.tool
    original = np.array([nb.value for nb in job.target.numbers])
    written = new_target if job.left is None else invert_pose(job.left) @ new_target
    numbers = rules.convention.numbers(written, original)
    config = rules.config(geometry, q_ctrl, job.target)
    file = job.target.source[0]
    edits[file].extend(_number_edits(job.target, numbers, rules))
    edits[file].extend(rules.config_edits(job.target, config))
    shift = (new_target[:3, 3] - job.wobj_T_target[:3, 3]) / MM
    turn = float(np.degrees(rotation_angle_between(new_target[:3, :3],
                                                   job.wobj_T_target[:3, :3])))
    change = robot.to_degrees_or_mm((q_ctrl - q_nominal)[None])[0]
    return TargetReport(
        target=job.target.name or "<inline>", file=file, line=job.target.source[1],
        column=job.target.source[2], status=status,
        tool=job.tool_key or "", wobj=job.base_key or "",
        correction_mm=tuple(float(v) for v in shift), correction_deg=turn,
        joint_change=float(np.max(np.abs(change))) if np.all(np.isfinite(change)) else np.nan,
        config_before=before, config_after=rules.config_words(config),
        joints=tuple(robot.to_degrees_or_mm(q_ctrl[None])[0].tolist()),
        note="; ".join(x for x in (job.note, extra_note) if x))


def _external_rows(program: PoseProgram, rules: DialectRules, rows: list[TargetReport],
                   edits: dict[str, list[Edit]]) -> None:
    """Rows of targets in a file that is not written (``program.external``, a FANUC
    ``POSREG.VA``): a compensated one takes that file's status (``register``...), its note
    the values to set."""
    if not program.external:
        return
    by_place = {(t.source, t.name): t for t in program.targets
                if t.source[0] in program.external}
    for k, row in enumerate(rows):
        target = by_place.get(((row.file, row.line, row.column), row.target))
        if target is None or row.status not in COMPENSATED:
            continue
        new = {e.start: e.replacement for e in edits.get(row.file, ())}
        values = ", ".join(new.get(n.start, n.text).strip() for n in target.numbers)
        config = ", ".join(new.get(n.start, n.text) for n in target.config)
        solved = row.status
        row.status, what = program.external[row.file]
        row.note = "; ".join(x for x in (
            f"{row.target} is {what}: set it to ({values})"
            + (f" with configuration '{config}'" if config else "")
            + f" (solved: {solved}; {row.file} is not written)", row.note) if x)


def _decimals(text: str) -> int:
    mantissa = text.lower().split("e")[0]
    return len(mantissa) - mantissa.find(".") - 1 if "." in mantissa else 0


def _number_edits(target: PoseTarget, numbers: np.ndarray, rules: DialectRules) -> list[Edit]:
    """Edits for the pose numbers whose value changes at the resolution written (at least
    the convention's)."""
    out = []
    for k, (number, value) in enumerate(zip(target.numbers, numbers)):
        floor = rules.convention.position_decimals if k < 3 else rules.convention.angle_decimals
        decimals = max(_decimals(number.text), floor)
        if abs(value - number.value) >= 0.5 * 10.0 ** -decimals:
            text = (format_like(number.text, value, decimals) if rules.format_number is None
                    else rules.format_number(number, value, decimals, k))
            out.append(Edit(number.start, number.end, text))
    return out
