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

import functools
import operator
from dataclasses import dataclass
from itertools import chain

import numpy as np

from ..kinematics.conventions import (MM, invert_pose, matrix_from_euler_zyz, matrix_from_quat_wxyz,
                           pose_from_rotation_translation)
from .grammar import no_gc
from .targets import (QUAT_WXYZ, CartesianTarget, JointTarget, MotionUse, Program, ToolData,
                      WorkObject)

IDENTITY = np.eye(4)
IDENTITY.flags.writeable = False
_SPAN = operator.attrgetter("span")   # text order (spans of two targets never overlap)


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


@dataclass(frozen=True, eq=False, slots=True)
class FramePair:
    """The tool and work object of some target uses, as poses (metres).

    flange_T_tool, base_T_wobj : see :class:`ResolvedTarget`; None when unknown.
    stationary_tool : the tool is fixed and the robot holds the work object.
    notes : remarks and problems of the pair; problem : the flange pose cannot be known.
    """

    tool_name: str
    wobj_name: str
    flange_T_tool: np.ndarray | None
    base_T_wobj: np.ndarray | None
    stationary_tool: bool
    notes: tuple[str, ...]
    problem: bool


@dataclass(frozen=True, eq=False)
class Resolution:
    """Everything :func:`resolve` found.

    One entry per (target, tool, work object), every literal target at least once, in
    text order, held as columns (a 100,000-target program resolves without making an
    object per entry; :attr:`targets` makes them on demand):

    entry_targets : the target of each entry; entry_uses : its motion uses with this pair
        (empty when never moved to); entry_notes : its notes (pair notes included).
    entry_pairs : (m,) index into ``pairs``, the entry's tool and work object.
    written : (m, 11) each target's leading numbers as written (:func:`written_values`;
        NaN for joint targets).
    wobj_T_target : (m, 4, 4) each target in its work object, m (NaN for joint targets).
    base_T_flange : (m, 4, 4) the flange pose asked for, m (NaN where it cannot be known).
    shared : entry index groups of one target used with several pairs.
    unresolved : motion uses that name no literal target of the file, with the reason.
    frames : names of V+ transformations used as tool or frame, not as targets.
    warnings : one line each, starting with file:line.
    """

    entry_targets: tuple[CartesianTarget | JointTarget, ...]
    entry_uses: tuple[tuple[MotionUse, ...], ...]
    entry_notes: tuple[tuple[str, ...], ...]
    entry_pairs: np.ndarray
    pairs: tuple[FramePair, ...]
    written: np.ndarray
    wobj_T_target: np.ndarray
    base_T_flange: np.ndarray
    shared: tuple[tuple[int, ...], ...]
    unresolved: tuple[tuple[MotionUse, str], ...]
    frames: tuple[str, ...]
    warnings: tuple[str, ...]

    @functools.cached_property
    def targets(self) -> tuple[ResolvedTarget, ...]:
        """The entries as :class:`ResolvedTarget` records."""
        out = []
        for k, (t, uses, notes, p) in enumerate(zip(self.entry_targets, self.entry_uses,
                                                     self.entry_notes,
                                                     self.entry_pairs.tolist())):
            pair = self.pairs[p]
            cartesian = isinstance(t, CartesianTarget)
            known = cartesian and not pair.problem
            out.append(ResolvedTarget(t, uses, pair.tool_name, pair.wobj_name,
                                      pair.flange_T_tool, pair.base_T_wobj,
                                      self.wobj_T_target[k] if cartesian else None,
                                      self.base_T_flange[k] if known else None,
                                      pair.stationary_tool, notes))
        return tuple(out)


class _Scope:
    """Name lookup with RAPID rules: routine-local first, then module level; no case.
    ``get`` gives every item of a name (all elements of an array); ``elements`` holds each
    one under (lower name, routine, array index)."""

    def __init__(self, items):
        self.table: dict = {}      # (lower name, routine) -> items
        self.elements: dict = {}   # (lower name, routine, array index) -> item
        table, elements = self.table, self.elements
        for it in items:
            name = it.name
            if name is not None:
                key = (name.lower(), it.routine)
                found = table.get(key)
                if found is None:
                    table[key] = [it]
                else:
                    found.append(it)
                elements[(*key, getattr(it, "array_index", None))] = it

    def get(self, name: str, routine):
        key = name.lower()
        return self.table.get((key, routine)) or self.table.get((key, None))


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
    groups: dict = {}  # id(target) -> [(pair key, use), ...] in text order
    pair_info: dict = {}

    def add(target, use, key, info):
        found = groups.get(id(target))
        if found is None:
            groups[id(target)] = [(key, use)]
        else:
            found.append((key, use))
        pair_info[key] = info

    # -- tools and work objects of every use (memoized: a program has few of them)
    memo: dict = {}

    def frames_of(use: MotionUse):
        """((tool key, wobj key), (tool info, wobj info)) of a use."""
        k = (use.tool, use.wobj, use.routine, id(use.tool_inline), id(use.wobj_inline))
        got = memo.get(k)
        if got is None:
            (tk, tinfo), (wk, winfo) = tool_of(use), wobj_of(use)
            got = memo[k] = ((tk, wk), (tinfo, winfo))
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
    plain_memo: dict = {}   # (tool, wobj, routine) -> frames_of() of uses without literals
    table, elements = targets.table, targets.elements
    for use in program.motions:
        (_, _, _, name, index, inline, runtime, tool, tool_inline, wobj, wobj_inline, _,
         routine, _, _, _) = use
        if tool_inline is None and wobj_inline is None:
            k = (tool, wobj, routine)
            got = plain_memo.get(k)
            if got is None:
                got = plain_memo[k] = frames_of(use)
            key, info = got
        else:
            key, info = frames_of(use)
        if inline is not None:
            add(inline, use, key, info)
            continue
        if runtime is not None:
            base = runtime.base_name
            found = targets.get(base, routine) if base else None
            if found:
                for t in found:
                    indirect.setdefault(id(t), []).append((use, key, info))
            unresolved.append((use, runtime.reason))
            continue
        if name is not None and not isinstance(index, str):
            low = name.lower()   # one element: routine-local first, then module level
            one = elements.get((low, routine if (low, routine) in table else None, index))
            if one is not None:
                add(one, use, key, info)
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
            add(t, use, key, info)

    refs: dict = {}
    for r in program.references:
        for t in targets.get(r.name, r.routine) or ():
            refs.setdefault(id(t), []).append(r)
    changed: dict = {}  # target id -> run-time changes (assignments, SearchL results)
    for r in program.runtime:
        if r.base_name and ("assigned" in r.reason or "written" in r.reason):
            for t in targets.get(r.base_name, r.routine) or ():
                changed.setdefault(id(t), []).append(r)

    entries: list = []  # (target, uses, pair key, notes)
    shared: list = []
    all_targets = sorted(program.targets + program.joint_targets, key=_SPAN)
    default_key = (("tool0",), ("wobj0",))
    default_info = (("NULL" if vplus else "tool0", None), ("base" if vplus else "wobj0", None))
    no_notes = ()
    for t in all_targets:
        tid = id(t)
        used = groups.get(tid)
        if vplus and t.name and t.name.lower() in frame_names:
            if used is None:
                continue  # a tool or frame, not a target
            warnings.append(f"{t.location}: {t.display_name} is used both as a target and as "
                            f"a tool or frame")
        if used is not None and len(used) == 1 and tid not in changed:   # the common case
            key, use = used[0]
            entries.append((t, (use,), key, no_notes))
            continue
        notes: list[str] = [f"changed at run time by {r.expression!r} (line "
                            f"{r.location.line}): the literal is only its first value"
                            for r in changed.get(tid, ())]
        pairs: dict = {}   # pair key -> uses, in order of first use
        for key, use in used or ():
            pairs.setdefault(key, []).append(use)
        if not pairs:
            via = indirect.get(tid)
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
                for r in refs.get(tid, ()):
                    warnings.append(f"{r.location}: {r.name} is passed to {r.context}: its "
                                    f"tool and work object are unknown, "
                                    f"{'tool0/wobj0' if not vplus else 'identity'} assumed")
        if len(pairs) == 1:
            ((key, uses),) = pairs.items()
            entries.append((t, tuple(uses), key, tuple(notes)))
            continue
        if isinstance(t, JointTarget):
            # joint values do not depend on the tool or work object: one entry
            entries.append((t, tuple(u for us in pairs.values() for u in us),
                            next(iter(pairs)), tuple(notes)))
            continue
        listed = "; ".join(f"{pair_info[k][0][0]}/{pair_info[k][1][0]} (line "
                           f"{us[0].location.line})" for k, us in pairs.items())
        warnings.append(f"{t.location}: {t.display_name} is used with "
                        f"{len(pairs)} tool/work-object pairs: {listed}")
        shared.append(tuple(range(len(entries), len(entries) + len(pairs))))
        for key, uses in pairs.items():
            entries.append((t, tuple(uses), key, tuple(notes)))
    return _columns(entries, pair_info, tuple(shared), tuple(unresolved),
                    tuple(sorted(frame_names)), tuple(warnings))


WRITTEN_COLUMNS = 11


def written_values(targets) -> np.ndarray:
    """The leading numbers of Cartesian targets as written, (n, 11), converted in one batch:
    position in mm (columns 0-2), orientation (3-6: quaternion w, x, y, z, or V+ Z-Y-Z
    degrees then NaN) and RAPID confdata cf1, cf4, cf6, cfx (7-10; NaN for V+)."""
    n = len(targets)
    out = np.full((n, WRITTEN_COLUMNS), np.nan)
    full = [i for i, t in enumerate(targets)
            if t.orientation_kind == QUAT_WXYZ and len(t.texts) >= WRITTEN_COLUMNS]
    if full:
        out[full] = np.fromiter(
            map(float, chain.from_iterable(targets[i].texts[:WRITTEN_COLUMNS] for i in full)),
            float, WRITTEN_COLUMNS * len(full)).reshape(-1, WRITTEN_COLUMNS)
    if len(full) < n:
        done = set(full)
        for i, t in enumerate(targets):
            if i not in done:
                width = 7 if t.orientation_kind == QUAT_WXYZ else 6
                out[i, :width] = [float(x) for x in t.texts[:width]]
                if width == 7 and len(t.texts) > 7:
                    config = [float(x) for x in t.texts[7:WRITTEN_COLUMNS]]
                    out[i, 7:7 + len(config)] = config
    return out


def target_poses(targets, values: np.ndarray | None = None) -> np.ndarray:
    """wobj_T_target of Cartesian targets, (n, 4, 4), metres, computed in one batch.

    values : their :func:`written_values`, when the caller has them already."""
    n = len(targets)
    poses = np.zeros((n, 4, 4))
    if n == 0:
        return poses
    v = written_values(targets) if values is None else values
    euler = np.fromiter((t.orientation_kind != QUAT_WXYZ for t in targets), bool, n)
    if not euler.all():
        quat = ~euler
        poses[quat] = pose_from_rotation_translation(matrix_from_quat_wxyz(v[quat, 3:7]),
                                                     v[quat, :3] * MM)
    if euler.any():
        a = np.deg2rad(v[euler, 3:6])
        poses[euler] = pose_from_rotation_translation(
            matrix_from_euler_zyz(a[:, 0], a[:, 1], a[:, 2]), v[euler, :3] * MM)
    return poses


def _columns(entries, pair_info, shared, unresolved, frames, warnings) -> Resolution:
    """The Resolution of ``entries`` (target, uses, pair key, notes): poses in batches."""
    m = len(entries)
    keys: dict = {}   # pair key -> index into pairs
    pair_index = np.fromiter((keys.setdefault(e[2], len(keys)) for e in entries), np.intp, m)
    pairs = tuple(_pair(pair_info[key]) for key in keys)
    targets = tuple([e[0] for e in entries])
    cart = np.fromiter((type(t) is CartesianTarget for t in targets), bool, m)
    wobj_T_target = np.full((m, 4, 4), np.nan)
    written = np.full((m, WRITTEN_COLUMNS), np.nan)
    rows = np.flatnonzero(cart)
    cartesian = [targets[k] for k in rows.tolist()]
    written[rows] = written_values(cartesian)
    wobj_T_target[rows] = target_poses(cartesian, written[rows])
    base_T_flange = np.full((m, 4, 4), np.nan)
    for p, pair in enumerate(pairs):
        if pair.problem:
            continue
        ks = rows[pair_index[rows] == p]
        if not len(ks):
            continue
        poses = wobj_T_target[ks]
        if pair.stationary_tool:
            base_T_flange[ks] = (pair.flange_T_tool @ invert_pose(poses)
                                 @ invert_pose(pair.base_T_wobj))
        else:
            base_T_flange[ks] = pair.base_T_wobj @ poses @ invert_pose(pair.flange_T_tool)
    notes = tuple([e[3] + pairs[p].notes if pairs[p].notes else e[3]
                   for e, p in zip(entries, pair_index.tolist())])
    return Resolution(targets, tuple([e[1] for e in entries]), notes, pair_index, pairs,
                      written, wobj_T_target, base_T_flange, shared, unresolved, frames,
                      warnings)


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


def _pair(info) -> FramePair:
    """The poses of a (tool, work object) pair, with its notes and problems."""
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
    return FramePair(tool_name, wobj_name, tool_pose, wobj_pose, stationary,
                     tuple(notes), problem)


__all__ = ["resolve", "target_poses", "written_values", "Resolution", "ResolvedTarget", "FramePair"]
