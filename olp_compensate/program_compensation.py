"""Compensate a whole robot program: parse, resolve, solve the real arm, splice the numbers.

Only the numbers of compensated targets change (see :mod:`olp_compensate.programs.emit`);
with the nominal calibration nothing changes at all. What is done with each target:

- a Cartesian target (robtarget, V+ transformation) with known tool and work object is
  compensated (:mod:`olp_compensate.compensate`); a calibrated tool of the same name as
  the program's tooldata is the real tool; its confdata is kept unless the joints left the
  written quadrant by more than a degree;
- a target used with several tool/work-object pairs is compensated only when every pair
  gives the same numbers (within the written resolution); otherwise it is left as written
  and reported 'ambiguous';
- joint targets (jointtarget, V+ precision points) are joints already: kept, 'joint_target';
- targets never moved to in the file are left as written ('unused'), unless the caller
  assumes tool0/wobj0 for them;
- motions whose target is computed at run time (Offs(), RelTool(), CRobT(), parameters)
  are listed 'runtime' / 'unresolved' with their reason.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field

import numpy as np

from .calibration import Calibration
from .compensate import COMPENSATED, Compensator
from .confdata import vplus_configuration
from .conventions import (MM, invert_pose, matrix_from_quat_wxyz, pose_from_rotation_translation,
                          quat_wxyz_from_matrix, rotation_angle_between)
from .errors import DataError
from .ik import OPWParameters
from .programs import Program, loads, resolve
from .programs.grammar import no_gc
from .programs.emit import (edits_for_targets, joint_emit_edits, nearest_euler_zyz_deg, splice,
                            target_edits)
from .programs.targets import JointTarget

__all__ = ["TargetReport", "CompensationReport", "compensate_program", "KEPT", "EMIT_MODES"]

KEPT = ("joint_target",)
"""Statuses of targets that need no compensation (the program is still fully compensated)."""
EMIT_MODES = ("pose", "joints")
CONFIG_SLACK_RAD = math.radians(1.0)
"""A written quadrant is kept while its axis is less than this outside it."""
TOOL_FRAME_SLACK_RAD = math.radians(5.0)
"""A calibrated tool orientation this close to the tooldata's is taken as the real one."""
_SAME_MM, _SAME_RAD = 5e-4, 1e-6   # two compensations of one target agree within this


@dataclass(slots=True)   # not frozen: a frozen __init__ costs 2 us a row
class TargetReport:
    """One row of the report: one target with one tool/work-object pair (or one run-time
    motion). Lengths in mm, angles in degrees; NaN where not compensated.

    correction_mm : (dx, dy, dz) change of the written target, in its work object.
    joints : (n,) controller axes the real robot takes, deg (mm for prismatic axes).
    joint_change : largest |real - nominal| joint value for the original target, deg.
    """

    target: str
    file: str
    line: int
    column: int
    status: str
    tool: str = ""
    wobj: str = ""
    correction_mm: tuple[float, float, float] = (math.nan,) * 3
    correction_deg: float = math.nan
    joint_change: float = math.nan
    config_before: str = ""
    config_after: str = ""
    joints: tuple[float, ...] = ()
    note: str = ""

    @property
    def compensated(self) -> bool:
        return self.status in COMPENSATED

    @property
    def fine(self) -> bool:
        """Compensated, or needing no compensation."""
        return self.status in COMPENSATED or self.status in KEPT


@dataclass(frozen=True)
class CompensationReport:
    """Everything :func:`compensate_program` did: one row per target use, and warnings
    (one line each, file:line first)."""

    file: str
    rows: tuple[TargetReport, ...]
    warnings: tuple[str, ...] = ()
    n_joints: int = 6
    emit: str = "pose"
    edits: int = 0

    @property
    def all_compensated(self) -> bool:
        return all(r.fine for r in self.rows)

    @property
    def exit_code(self) -> int:
        """0 when every target was compensated (or needs no compensation), else 2."""
        return 0 if self.all_compensated else 2

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for r in self.rows:
            out[r.status] = out.get(r.status, 0) + 1
        return out

    def to_csv(self) -> str:
        """The report as CSV text (one row per target use; units in the column names)."""
        buf = io.StringIO()
        joints = [f"q{k + 1}_deg" for k in range(self.n_joints)]
        csv.writer(buf, lineterminator="\n").writerow(
            ["target", "file", "line", "column", "status", "tool", "wobj", "dx_mm", "dy_mm",
             "dz_mm", "drot_deg", "dq_max_deg", "config_before", "config_after", *joints, "note"])
        # one %-format per row for the numbers (100k-target programs); rows with a
        # missing number take the per-field path
        numbers = ",".join(["%.4f"] * 3 + ["%.5f"] * 2)
        joint_numbers = ",".join(["%.6f"] * self.n_joints)
        empty_joints = "," * (self.n_joints - 1)
        lines = []
        field_text = _csv_field
        for r in self.rows:
            values = (*r.correction_mm, r.correction_deg, r.joint_change)
            try:
                middle = numbers % values if math.isfinite(sum(values)) else None
            except TypeError:   # a None
                middle = None
            if middle is None:
                middle = ",".join([*(_num(v, 4) for v in r.correction_mm),
                                   _num(r.correction_deg, 5), _num(r.joint_change, 5)])
            q = r.joints
            if not q:
                joint_text = empty_joints
            elif len(q) == self.n_joints and math.isfinite(sum(q)):
                joint_text = joint_numbers % q
            else:
                joint_text = ",".join(_num(v, 6) for v in q)
            lines.append(",".join((field_text(r.target), field_text(r.file), str(r.line),
                                   str(r.column), field_text(r.status), field_text(r.tool),
                                   field_text(r.wobj), middle, field_text(r.config_before),
                                   field_text(r.config_after), joint_text,
                                   field_text(r.note))))
        lines.append("")
        return buf.getvalue() + "\n".join(lines)


def _csv_field(text: str) -> str:
    """One CSV field as csv.writer writes it (quoted only when it must be)."""
    if "," in text or '"' in text or "\n" in text or "\r" in text:
        return '"' + text.replace('"', '""') + '"'
    return text


def _num(value: float, decimals: int) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:.{decimals}f}"


# ----------------------------------------------------------------------------------------

@dataclass
class _Job:
    """Targets to solve: desired real flange, the flange the program asks the nominal
    controller for, and how to turn a flange back into the written target."""

    entries: list = field(default_factory=list)       # ResolvedTarget
    confdata: list = field(default_factory=list)      # (4,) or None
    real_tool_note: list = field(default_factory=list)
    base: list = field(default_factory=list)          # report fields (_base_fields)


def _real_tool(calibration: Calibration, name: str, program_tool: np.ndarray):
    """flange_T_tool of the real robot for the program tool ``name``, and a note.

    A calibrated orientation more than :data:`TOOL_FRAME_SLACK_RAD` from the tooldata's is
    the frame of the measuring device's probe, not the tool's axes: the tooldata's
    orientation is kept then (and the note says so)."""
    for cal_name, tool in calibration.tools.items():
        if cal_name.lower() == name.lower():
            note = f"real TCP of {name} from the calibration"
            rotation = program_tool[:3, :3]
            if tool.quat_wxyz is not None:
                measured = matrix_from_quat_wxyz(tool.quat_wxyz)
                apart = float(rotation_angle_between(measured, rotation))
                if apart <= TOOL_FRAME_SLACK_RAD:
                    rotation = measured
                else:
                    note += (f" (its measured frame is {math.degrees(apart):.1f} deg from the "
                             f"tooldata's: the tooldata's orientation kept)")
            return pose_from_rotation_translation(rotation, tool.xyz_m), note
    return program_tool, ""


_CONFIG_TEXT: dict = {}


def _config_text(values) -> str:
    """'[cf1,cf4,cf6,cfx]' of a confdata (memoized: programs repeat a few of them)."""
    key = tuple(values)
    text = _CONFIG_TEXT.get(key)
    if text is None:
        text = _CONFIG_TEXT[key] = "[" + ",".join(str(int(v)) for v in key) + "]" if key else ""
    return text


def _base_fields(rt, config) -> dict:
    """The report fields every row of resolved target ``rt`` shares."""
    t = rt.target
    where = t.location
    return dict(target=t.display_name, file=where.file, line=where.line, column=where.column,
                tool=rt.tool_name, wobj=rt.wobj_name, config_before=_config_text(config))


def _keep_config(original: np.ndarray, computed: np.ndarray, q_ctrl: np.ndarray,
                 nominal_ctrl: np.ndarray) -> np.ndarray:
    """The confdata (k, 4) to write: the original, except a quadrant of axis 1, 4 or 6 that
    compensation moved out of the one the nominal controller was in for the original
    target and more than :data:`CONFIG_SLACK_RAD` out of the written one (cfx: the solver
    kept the requested branch). So a written confdata is never rewritten just for being
    slightly off."""
    quarter = math.pi / 2
    lower = original[:, :3] * quarter
    axes = q_ctrl[:, [0, 3, 5]]
    outside = (axes < lower - CONFIG_SLACK_RAD) | (axes > lower + quarter + CONFIG_SLACK_RAD)
    with np.errstate(invalid="ignore"):
        before = np.floor(nominal_ctrl[:, [0, 3, 5]] / quarter + 1e-12)
    moved = outside & ~(before == computed[:, :3])
    kept = original.copy()
    kept[:, :3] = np.where(moved, computed[:, :3], original[:, :3])
    return kept


def compensate_program(program: Program | str | bytes, dialect: str | None,
                       calibration: Calibration | Compensator, *, emit: str = "pose",
                       file: str = "<string>", unused: str = "skip"):
    """Compensate every target of a program on a calibration.

    program : a parsed :class:`Program`, or its text (str or latin-1 bytes) of ``dialect``
        ('rapid' or 'vplus'), named ``file`` in messages.
    emit : 'pose' rewrites Cartesian targets; 'joints' turns them into joint targets
        (RAPID jointtarget + MoveAbsJ, V+ precision points) where every use allows it.
    unused : 'skip' leaves targets never moved to as written; 'tool0' compensates them with
        tool0 and wobj0 (for data modules whose motions live elsewhere).
    Returns ``(text, report)``: the compensated program text and a
    :class:`CompensationReport`. Raises :class:`~olp_compensate.errors.ParseError` for a
    malformed program and DataError for bad arguments.
    """
    with no_gc():   # hundreds of thousands of small records: no collector passes
        return _compensate_program(program, dialect, calibration, emit, file, unused)


def _compensate_program(program, dialect, calibration, emit, file, unused):
    if emit not in EMIT_MODES:
        raise DataError(f"emit: expected one of {', '.join(EMIT_MODES)}, got {emit!r}")
    if unused not in ("skip", "tool0"):
        raise DataError(f"unused: expected 'skip' or 'tool0', got {unused!r}")
    if not isinstance(program, Program):
        if dialect is None:
            raise DataError("dialect: needed when the program is given as text")
        program = loads(program, dialect, file)
    comp = calibration if isinstance(calibration, Compensator) else Compensator(calibration)
    cal, robot = comp.calibration, comp.robot
    resolution = resolve(program)
    vplus = program.dialect == "vplus"
    rows: dict[int, TargetReport] = {}          # index in resolution.targets -> row
    job = _Job()
    index_of = {}
    for k, rt in enumerate(resolution.targets):
        t = rt.target
        if isinstance(t, JointTarget):
            rows[k] = TargetReport(**_base_fields(rt, ()), status="joint_target",
                                   joints=tuple(t.joints_deg()), note="joints kept as written")
            continue
        config = t.config_values() if not vplus else ()
        base = _base_fields(rt, config)
        if "unused" in rt.notes and not rt.uses and unused == "skip":
            rows[k] = TargetReport(**base, status="unused",
                                   note="not moved to in this file: tool and work object "
                                        "unknown, left as written")
            continue
        if rt.base_T_flange is None:
            rows[k] = TargetReport(**base, status="unresolved", note="; ".join(rt.notes))
            continue
        index_of[k] = len(job.entries)
        job.entries.append(rt)
        job.confdata.append(config if config else None)
        job.base.append(base)

    n = len(job.entries)
    if n:
        with_conf = [i for i, c in enumerate(job.confdata) if c is not None]
        without = [i for i, c in enumerate(job.confdata) if c is None]
        requested = np.array([rt.base_T_flange for rt in job.entries])
        desired = requested.copy()
        # the real TCP: a calibrated tool of the tooldata's name (one pose per tool name)
        real_tools: dict = {}
        for i, rt in enumerate(job.entries):
            if rt.stationary_tool:
                job.real_tool_note.append("stationary tool")
                continue
            key = (rt.tool_name, id(rt.flange_T_tool))
            if key not in real_tools:
                real_tools[key] = (_real_tool(cal, rt.tool_name, rt.flange_T_tool), [])
            (tool, note), members = real_tools[key]
            members.append(i)
            job.real_tool_note.append(note)
        for ((tool, note), members) in real_tools.values():
            if note:  # a calibrated tool differs from the program's: re-aim the flange
                tcp = requested[members] @ job.entries[members[0]].flange_T_tool
                desired[members] = tcp @ invert_pose(tool)
        q = np.full((n, robot.n_joints), np.nan)
        flange = np.full((n, 4, 4), np.nan)
        nominal = np.full((n, robot.n_joints), np.nan)
        status = np.empty(n, dtype=object)
        if without:
            # no written configuration (V+): the arm stays in the one the nominal
            # controller takes for the original target (the branch nearest zero)
            q_nominal = comp.solve_nominal(requested[without], None)
            reachable = np.all(np.isfinite(q_nominal), axis=1)
            implied = [i for i, r in zip(without, reachable) if r]
            implied_conf = comp.confdata(q_nominal[reachable]) if implied else None
            without = [i for i, r in zip(without, reachable) if not r]
            with_conf_arr = np.array([job.confdata[i] for i in with_conf], int).reshape(-1, 4)
            with_conf = with_conf + implied
            conf_all = np.concatenate([with_conf_arr, implied_conf.reshape(-1, 4)]) \
                if implied else with_conf_arr
        else:
            conf_all = np.array([job.confdata[i] for i in with_conf], int).reshape(-1, 4)
        for idx, conf in ((with_conf, conf_all), (without, None)):
            if not idx:
                continue
            qi, fi, sol, nomi = comp.compensate_flanges(desired[idx], requested[idx], conf)
            q[idx], flange[idx], nominal[idx] = qi, fi, nomi
            status[idx] = sol.reason
        ok = np.isin(status.astype(str), COMPENSATED)
        wobj = np.array([rt.base_T_wobj for rt in job.entries])
        tool = np.array([rt.flange_T_tool for rt in job.entries])
        original = np.array([rt.wobj_T_target for rt in job.entries])
        stationary = np.array([rt.stationary_tool for rt in job.entries], bool)
        # robot-held tool: inv(wobj) F tool; stationary tool: inv(flange_T_wobj) inv(F) world_T_tool
        moved = flange.copy()
        if np.any(stationary):
            moved[stationary] = invert_pose(flange[stationary])
        new_targets = invert_pose(wobj) @ moved @ tool
        new_targets[~ok] = np.nan
        q_ctrl = robot.controller_from_joints(q)
        nominal_ctrl = robot.controller_from_joints(nominal)
        computed_conf = np.full((n, 4), -99, int)
        if np.any(ok):
            computed_conf[ok] = comp.confdata(q[ok])
        if with_conf and not vplus:
            rows_c = np.array([i for i in range(n) if job.confdata[i] is not None and ok[i]], int)
            if len(rows_c):
                written = np.array([job.confdata[i] for i in rows_c], int)
                computed_conf[rows_c] = _keep_config(written, computed_conf[rows_c],
                                                     q_ctrl[rows_c], nominal_ctrl[rows_c])
        conf_list = computed_conf.tolist()
        shift_mm = ((new_targets[:, :3, 3] - original[:, :3, 3]) / MM).tolist()
        turn_deg = np.degrees(rotation_angle_between(new_targets[:, :3, :3],
                                                     original[:, :3, :3])).tolist()
        joints_deg = robot.to_degrees_or_mm(q_ctrl).tolist()
        change = np.abs(robot.to_degrees_or_mm(q_ctrl - nominal_ctrl))
        change = np.where(np.all(np.isnan(change), axis=1), np.nan,
                          np.nanmax(np.where(np.isnan(change), -np.inf, change), axis=1)).tolist()
        vplus_text = {}
        if vplus and isinstance(comp.family, OPWParameters) and np.any(ok):
            flags = vplus_configuration(comp.family, q[ok])
            for i, (righty, above, flip) in zip(np.flatnonzero(ok), flags):
                vplus_text[i] = " ".join(("RIGHTY" if righty else "LEFTY",
                                          "ABOVE" if above else "BELOW",
                                          "FLIP" if flip else "NOFLIP"))
    else:
        ok = np.zeros(0, bool)

    # one target, several tool/work-object pairs: write only when they agree
    by_target: dict[int, list[int]] = {}
    for k, i in index_of.items():
        by_target.setdefault(id(job.entries[i].target), []).append(i)
    ambiguous = set()
    for members in by_target.values():
        if len(members) < 2:
            continue
        good = [i for i in members if ok[i]]
        if len(good) < len(members):
            ambiguous.update(members)
            continue
        first = new_targets[good[0]]
        for i in good[1:]:
            if (np.linalg.norm(new_targets[i][:3, 3] - first[:3, 3]) > _SAME_MM * MM
                    or rotation_angle_between(new_targets[i][:3, :3], first[:3, :3]) > _SAME_RAD):
                ambiguous.update(members)
                break

    write: dict[int, int] = {}                   # id(target) -> job index to write
    for k, i in index_of.items():
        rt = job.entries[i]
        t = rt.target
        base = job.base[i]
        if rt.notes:
            notes = [x for x in rt.notes if x != "unused"] + [job.real_tool_note[i]]
            if "unused" in rt.notes:
                notes.append("not moved to in this file: tool0/wobj0 assumed")
            note = "; ".join(x for x in notes if x)
        else:
            note = job.real_tool_note[i]
        if not ok[i]:
            rows[k] = TargetReport(**base, status=str(status[i]), note=note)
            continue
        if i in ambiguous:
            rows[k] = TargetReport(**base, status="ambiguous",
                                   joints=tuple(joints_deg[i]),
                                   note="used with several tools/work objects needing "
                                        "different corrections; left as written")
            continue
        write[id(t)] = i
        if vplus:
            config_after = vplus_text.get(i, "")
        else:
            config_after = _config_text(conf_list[i])
        rows[k] = TargetReport(
            **base, config_after=config_after, status=str(status[i]),
            correction_mm=tuple(shift_mm[i]), correction_deg=turn_deg[i],
            joint_change=change[i], joints=tuple(joints_deg[i]), note=note)

    order = [rows[k] for k in sorted(rows)]
    for use, why in resolution.unresolved:
        where = use.location
        name = (use.runtime.expression if use.runtime is not None
                else use.target_name or "<target>")
        order.append(TargetReport(target=name, file=where.file, line=where.line,
                                  column=where.column,
                                  status="runtime" if use.runtime is not None else "unresolved",
                                  tool=use.tool or "", wobj=use.wobj or "", note=why))
    order.sort(key=lambda r: (r.line, r.column))

    warnings = list(resolution.warnings)
    edits = _edits(program, comp, job, write, new_targets if n else None,
                   computed_conf if n else None, q_ctrl if n else None, emit, vplus, warnings)
    text = splice(program.text, edits) if edits else program.text
    report = CompensationReport(file=program.file, rows=tuple(order), warnings=tuple(warnings),
                                n_joints=robot.n_joints, emit=emit, edits=len(edits))
    return text, report


def _orientations(targets, rotations: np.ndarray, vplus: bool) -> np.ndarray:
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


def _edits(program, comp, job, write, new_targets, conf, q_ctrl, emit, vplus, warnings):
    if not write:
        return []
    robot = comp.robot
    chosen = sorted(write.items(), key=lambda kv: job.entries[kv[1]].target.span[0])
    targets = [job.entries[i].target for _, i in chosen]
    rows = [i for _, i in chosen]
    edits = []
    if emit == "joints":
        convertible = _joint_convertible(program, job, targets)
        as_joints = [(t, i) for t, i in zip(targets, rows) if id(t) in convertible]
        try:
            edits = joint_emit_edits(program, {t: robot.to_degrees_or_mm(q_ctrl[i])
                                               for t, i in as_joints})
        except DataError as exc:
            warnings.append(f"{exc}; every target is written as a pose instead")
            edits, as_joints = [], []
        for t, i in zip(targets, rows):
            if id(t) not in convertible:
                warnings.append(f"{t.location}: {t.display_name} stays a Cartesian target "
                                f"(compensated): {_joint_blocker(program, job, t)}")
        done = {id(t) for t, _ in as_joints}
        rest = [(t, i) for t, i in zip(targets, rows) if id(t) not in done]
        if not rest:
            return sorted(edits, key=lambda e: e.start)
        targets, rows = [t for t, _ in rest], [i for _, i in rest]
    positions = new_targets[rows, :3, 3] / MM
    orientation = _orientations(targets, new_targets[rows, :3, :3], vplus)
    edits += edits_for_targets(program, positions, orientation, None, targets)
    if not vplus:
        for t, i in zip(targets, rows):
            if tuple(conf[i]) != tuple(job.confdata[i]):
                edits += target_edits(t, config=conf[i])
    edits.sort(key=lambda e: e.start)
    return edits


_JOINT_INSTRUCTIONS = {"movel", "movej", "move", "moves", "appro", "appros", "depart", "departs"}


def _joint_blocker(program: Program, job, t) -> str | None:
    """Why target ``t`` cannot become a joint target, or None."""
    uses = [u for rt in job.entries if rt.target is t for u in rt.uses]
    for u in uses:
        if u.instruction.lower() not in _JOINT_INSTRUCTIONS:
            return f"{u.instruction} at line {u.location.line} needs a Cartesian target"
        if u.wobj is not None and program.dialect == "vplus":
            return f"used relative to frame {u.wobj} at line {u.location.line}"
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


def _joint_convertible(program: Program, job, targets) -> set[int]:
    """ids of the targets that can become joint targets: every use a plain move, no
    run-time use, and (RAPID arrays) every element of the declaration convertible."""
    chosen = {id(t) for t in targets}
    ok = {id(t) for t in targets if _joint_blocker(program, job, t) is None}
    if program.dialect == "rapid":
        by_decl: dict = {}
        for t in program.targets:
            if t.storage != "inline":
                by_decl.setdefault(t.type_span, []).append(t)
        for members in by_decl.values():
            if any(id(m) not in ok or id(m) not in chosen for m in members):
                ok -= {id(m) for m in members}
    return ok
