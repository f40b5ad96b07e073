"""What each target means: its tool and work object, and the flange pose it asks for.

For every motion use the target, the tool (named or inline tooldata; default ``tool0`` =
identity) and the work object (named or inline; default ``wobj0`` = identity; pose =
uframe * oframe) are resolved into 4x4 poses in METRES, robot base frame = world frame
(RAPID's base frame offset lives in the controller configuration, not in the module):

- robot-held tool:   base_T_flange = base_T_wobj @ wobj_T_target @ inv(flange_T_tool)
- stationary tool (tooldata robhold FALSE, wobjdata robhold TRUE, the work object on the
  flange):            base_T_flange = base_T_tool @ inv(wobj_T_target) @ inv(flange_T_wobj)

A target used with several (tool, work object) pairs gives one :class:`ResolvedTarget` per
pair, and a warning; a target never moved to is still listed (tool0/wobj0, note
'unused'). V+ files have no tool or work-object data: a ``TOOL name`` step and a
``frame:name`` compound name transformations of the same file; else identity. A pose that
cannot be known from the file (unknown or valueless tool, moving user frame, inconsistent
robhold) is None with the reason in ``notes``.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import chain

import numpy as np

from ..conventions import (MM, invert_pose, matrix_from_euler_zyz, matrix_from_quat_wxyz,
                           pose_from_rotation_translation)
from .grammar import no_gc
from .targets import (QUAT_WXYZ, CartesianTarget, JointTarget, MotionUse, Program, ToolData,
                      WorkObject)

IDENTITY = np.eye(4)
IDENTITY.flags.writeable = False


@dataclass(eq=False, slots=True)   # not frozen: frozen __init__ costs 4 us a target
class ResolvedTarget:
    """One target with one (tool, work object) pair.

    uses : the motion uses with this pair (empty when the target is never moved to).
    tool_name, wobj_name : as written ('tool0'/'wobj0' by default, '<inline>' for literals;
        V+: the TOOL and frame names, or 'NULL' / 'base').
    flange_T_tool : TCP in the flange frame (or world_T_tool for a stationary tool), m.
    base_T_wobj : work-object frame (uframe * oframe) in the base frame (or in the flange
        frame when the robot holds the work object), m.
    wobj_T_target : the target in its work object, m (None for joint targets).
    base_T_flange : the flange pose the program asks for, m; None when it cannot be known.
    notes : short reasons and remarks ('unused', 'stationary tool', 'unknown tool t9'...).
    """

    target: CartesianTarget | JointTarget
    uses: tuple[MotionUse, ...]
    tool_name: str
    wobj_name: str
    flange_T_tool: np.ndarray | None
    base_T_wobj: np.ndarray | None
    wobj_T_target: np.ndarray | None
    base_T_flange: np.ndarray | None
    stationary_tool: bool = False
    notes: tuple[str, ...] = ()

    @property
    def resolved(self) -> bool:
        """Whether the flange pose is known (always False for joint targets)."""
        return self.base_T_flange is not None

    @property
    def base_T_tcp(self) -> np.ndarray | None:
        """The TCP pose asked for, in the base frame, m."""
        if self.base_T_flange is None:
            return None
        return self.base_T_flange @ self.flange_T_tool


@dataclass(frozen=True, eq=False)
class Resolution:
    """Everything :func:`resolve` found.

    targets : one entry per (target, tool, work object); every literal target at least once.
    unresolved : motion uses that name no literal target of the file, with the reason.
    frames : names of V+ transformations used as tool or frame, not as targets.
    warnings : one line each, starting with file:line.
    """

    targets: tuple[ResolvedTarget, ...]
    unresolved: tuple[tuple[MotionUse, str], ...]
    frames: tuple[str, ...]
    warnings: tuple[str, ...]


class _Scope:
    """Name lookup with RAPID rules: routine-local first, then module level; no case.
    ``get`` gives every item of a name (all elements of an array), ``element`` one."""

    def __init__(self, items):
        self.table: dict = {}
        self.elements: dict = {}
        for it in items:
            name = it.name
            if name is not None:
                key = (name.lower(), it.routine)
                self.table.setdefault(key, []).append(it)
                self.elements[key + (getattr(it, "array_index", None),)] = it

    def get(self, name: str, routine):
        key = name.lower()
        return self.table.get((key, routine)) or self.table.get((key, None))

    def element(self, name: str, routine, index):
        key = name.lower()
        if (key, routine) in self.table:
            return self.elements.get((key, routine, index))
        return self.elements.get((key, None, index))


def resolve(program: Program) -> Resolution:
    """Resolve every target of ``program`` with its tool and work object (see module doc)."""
    with no_gc():
        return _resolve(program)


def _resolve(program: Program) -> Resolution:
    vplus = program.dialect == "vplus"
    targets = _Scope(program.targets + program.joint_targets)
    tools = _Scope(program.tools)
    wobjs = _Scope(program.wobjs)
    params = {r.name: {p.lower() for p in r.parameters} for r in program.routines}
    runtime_names = {r.base_name.lower() for r in program.runtime if r.base_name}
    warnings: list[str] = []
    unresolved: list[tuple[MotionUse, str]] = []
    frame_names: set[str] = set()
    groups: dict = {}  # id(target) -> {pair key: [uses]}
    order: dict = {}
    pair_info: dict = {}

    def add(target, use, key, info):
        groups.setdefault(id(target), {}).setdefault(key, []).append(use)
        order.setdefault(id(target), target)
        pair_info[key] = info

    # -- tools and work objects of every use (memoized: a program has few of them)
    memo: dict = {}

    def frames_of(use: MotionUse):
        k = (use.tool, use.wobj, use.routine, id(use.tool_inline), id(use.wobj_inline))
        got = memo.get(k)
        if got is None:
            got = memo[k] = (tool_of(use), wobj_of(use))
        return got

    def tool_of(use: MotionUse):
        if use.tool_inline is not None:
            return ("inline", use.tool_inline.span), ("<inline>", use.tool_inline)
        name = use.tool
        if name is None or (not vplus and name.lower() == "tool0" and not tools.get(name,
                                                                                   use.routine)):
            return ("tool0",), ("NULL" if vplus else "tool0", None)
        if vplus:
            found = targets.get(name, use.routine)
            frame_names.add(name.lower())
            return ("v", name.lower()), (name, found[0] if found else "unknown")
        found = tools.get(name, use.routine)
        return ("t", name.lower()), (name, found[0] if found else "unknown")

    def wobj_of(use: MotionUse):
        if use.wobj_inline is not None:
            return ("inline", use.wobj_inline.span), ("<inline>", use.wobj_inline)
        name = use.wobj
        if name is None or (not vplus and name.lower() == "wobj0" and not wobjs.get(name,
                                                                                   use.routine)):
            return ("wobj0",), ("base" if vplus else "wobj0", None)
        if vplus:
            found = targets.get(name, use.routine)
            frame_names.add(name.lower())
            return ("v", name.lower()), (name, found[0] if found else "unknown")
        found = wobjs.get(name, use.routine)
        return ("w", name.lower()), (name, found[0] if found else "unknown")

    indirect: dict = {}  # target id -> uses through Offs()/RelTool() (runtime base name)
    for use in program.motions:
        (tk, tinfo), (wk, winfo) = frames_of(use)
        key = (tk, wk)
        if use.inline is not None:
            add(use.inline, use, key, (tinfo, winfo))
            continue
        if use.runtime is not None:
            base = use.runtime.base_name
            found = targets.get(base, use.routine) if base else None
            if found:
                for t in found:
                    indirect.setdefault(id(t), []).append((use, key, (tinfo, winfo)))
            unresolved.append((use, use.runtime.reason))
            continue
        name = use.target_name
        index = use.target_index
        if not isinstance(index, str):
            one = targets.element(name, use.routine, index)
            if one is not None:
                add(one, use, key, (tinfo, winfo))
                continue
        found = targets.get(name, use.routine) if name else None
        if not found:
            if use.routine in params and name.lower() in params[use.routine]:
                why = f"{name} is a parameter of {use.routine}: its value comes from the caller"
            elif name.lower() in runtime_names:
                why = f"{name} has no literal value (set at run time or in another module)"
            else:
                why = f"unknown target {name}"
            unresolved.append((use, why))
            continue
        if isinstance(index, str):
            chosen = [t for t in found if t.array_index is not None]
            shown = f"{name}[{index}]" if vplus else f"{name}{{{index}}}"
            warnings.append(f"{use.location}: {shown} has a run-time index: every element "
                            f"of {name} is taken as used with this tool and work object")
        else:
            chosen = [t for t in found if t.array_index == index]
        if not chosen:
            unresolved.append((use, f"no element {index} in {name}"))
            continue
        for t in chosen:
            add(t, use, key, (tinfo, winfo))

    refs: dict = {}
    for r in program.references:
        for t in targets.get(r.name, r.routine) or ():
            refs.setdefault(id(t), []).append(r)
    changed: dict = {}  # target id -> run-time changes (assignments, SearchL results)
    for r in program.runtime:
        if r.base_name and ("assigned" in r.reason or "written" in r.reason):
            for t in targets.get(r.base_name, r.routine) or ():
                changed.setdefault(id(t), []).append(r)

    entries: list = []  # (target, uses, info, notes)
    all_targets = sorted(program.targets + program.joint_targets, key=lambda t: t.span[0])
    default_key = (("tool0",), ("wobj0",))
    default_info = (("NULL" if vplus else "tool0", None), ("base" if vplus else "wobj0", None))
    for t in all_targets:
        if vplus and t.name and t.name.lower() in frame_names and id(t) not in groups:
            continue  # a tool or frame, not a target
        pairs = groups.get(id(t))
        notes: list[str] = [f"changed at run time by {r.expression!r} (line "
                            f"{r.location.line}): the literal is only its first value"
                            for r in changed.get(id(t), ())]
        if vplus and t.name and t.name.lower() in frame_names:
            warnings.append(f"{t.location}: {t.display_name} is used both as a target and as "
                            f"a tool or frame")
        if not pairs:
            via = indirect.get(id(t))
            if via:
                pairs = {}
                for use, key, info in via:
                    pairs.setdefault(key, []).append(use)
                    pair_info[key] = info
                notes.append("moved to only through " + ", ".join(sorted(
                    {u.runtime.expression.split("(")[0] + "()" for u, _, _ in via})))
            else:
                pairs = {default_key: []}
                pair_info.setdefault(default_key, default_info)
                notes.append("unused")
                for r in refs.get(id(t), ()):
                    warnings.append(f"{r.location}: {r.name} is passed to {r.context}: its "
                                    f"tool and work object are unknown, "
                                    f"{'tool0/wobj0' if not vplus else 'identity'} assumed")
        if len(pairs) > 1 and isinstance(t, JointTarget):
            # joint values do not depend on the tool or work object: one entry
            merged = [u for us in pairs.values() for u in us]
            pairs = {next(iter(pairs)): merged}
        if len(pairs) > 1:
            listed = "; ".join(f"{pair_info[k][0][0]}/{pair_info[k][1][0]} (line "
                               f"{us[0].location.line})" for k, us in pairs.items())
            warnings.append(f"{t.location}: {t.display_name} is used with "
                            f"{len(pairs)} tool/work-object pairs: {listed}")
        for key, uses in pairs.items():
            entries.append((t, tuple(uses), key, notes))
    return Resolution(_resolve_all(entries, pair_info), tuple(unresolved),
                      tuple(sorted(frame_names)), tuple(warnings))


def target_poses(targets) -> np.ndarray:
    """wobj_T_target of Cartesian targets, (n, 4, 4), metres, computed in one batch."""
    n = len(targets)
    poses = np.zeros((n, 4, 4))
    if n == 0:
        return poses
    quat = [i for i, t in enumerate(targets) if t.orientation_kind == QUAT_WXYZ]
    euler = [i for i, t in enumerate(targets) if t.orientation_kind != QUAT_WXYZ]
    if quat:
        v = np.fromiter(map(float, chain.from_iterable(targets[i].texts[:7] for i in quat)),
                        float, 7 * len(quat)).reshape(-1, 7)
        poses[quat] = pose_from_rotation_translation(matrix_from_quat_wxyz(v[:, 3:7]),
                                                     v[:, :3] * MM)
    if euler:
        v = np.fromiter(map(float, chain.from_iterable(targets[i].texts[:6] for i in euler)),
                        float, 6 * len(euler)).reshape(-1, 6)
        a = np.deg2rad(v[:, 3:6])
        poses[euler] = pose_from_rotation_translation(
            matrix_from_euler_zyz(a[:, 0], a[:, 1], a[:, 2]), v[:, :3] * MM)
    return poses


def _resolve_all(entries, pair_info) -> tuple[ResolvedTarget, ...]:
    cart = [k for k, e in enumerate(entries) if isinstance(e[0], CartesianTarget)]
    poses = target_poses([entries[k][0] for k in cart])
    row = {k: i for i, k in enumerate(cart)}
    frames: dict = {}  # pair key -> (tool pose, wobj pose, stationary, notes, problem)
    flange: dict = {}
    by_key: dict = {}
    for k in cart:
        by_key.setdefault(entries[k][2], []).append(k)
    for key in {e[2] for e in entries}:
        frames[key] = _pair(pair_info[key])
    for key, ks in by_key.items():
        tool, wobj, stationary, _, problem = frames[key]
        if problem:
            continue
        p = poses[[row[k] for k in ks]]
        if stationary:
            f = tool @ invert_pose(p) @ invert_pose(wobj)
        else:
            f = wobj @ p @ invert_pose(tool)
        flange.update(zip(ks, f))
    out = []
    for k, (t, uses, key, notes) in enumerate(entries):
        tool, wobj, stationary, pnotes, _ = frames[key]
        (tool_name, _), (wobj_name, _) = pair_info[key]
        pose = poses[row[k]] if k in row else None
        out.append(ResolvedTarget(t, uses, tool_name, wobj_name, tool, wobj, pose,
                                  flange.get(k), stationary, tuple(notes) + pnotes))
    return tuple(out)


def _frame_pose(item) -> tuple[np.ndarray | None, str | None, bool | None]:
    """(pose, problem, robhold) of a tool/wobj/V+ frame found by lookup."""
    if item is None:
        return IDENTITY, None, None
    if isinstance(item, str):
        return None, "unknown", None
    if isinstance(item, CartesianTarget):  # V+ transformation used as tool or frame
        return item.pose(), None, None
    if isinstance(item, ToolData):
        if not item.defined:
            return None, "has no value in this file", item.robhold
        return item.pose(), None, item.robhold
    if isinstance(item, WorkObject):
        if not item.defined:
            return None, "has no value in this file", item.robhold
        if item.ufprog is False:
            mec = f" by {item.ufmec}" if item.ufmec else ""
            return None, f"has a user frame moved{mec} (ufprog FALSE)", item.robhold
        return item.pose(), None, item.robhold
    return None, "is not a frame", None


def _pair(info):
    """(flange_T_tool, base_T_wobj, stationary, notes, problem) of a tool/wobj pair."""
    (tool_name, tool), (wobj_name, wobj) = info
    notes = []
    tool_pose, tproblem, tool_robhold = _frame_pose(tool)
    wobj_pose, wproblem, wobj_robhold = _frame_pose(wobj)
    if tproblem:
        notes.append(f"tool {tool_name} {tproblem}")
    if wproblem:
        notes.append(f"work object {wobj_name} {wproblem}")
    stationary = tool_robhold is False
    problem = bool(tproblem or wproblem)
    if stationary:
        notes.append("stationary tool (robhold FALSE)")
        if wobj_robhold is not True:
            notes.append(f"stationary tool {tool_name} needs a robot-held work object")
            problem = True
    elif wobj_robhold is True:
        notes.append(f"work object {wobj_name} is robot-held but tool {tool_name} is not "
                     f"stationary")
        problem = True
    return tool_pose, wobj_pose, stationary, tuple(notes), problem


__all__ = ["resolve", "target_poses", "Resolution", "ResolvedTarget"]
