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

import numpy as np

from ..kinematics.conventions import invert_pose
from .frame_pairs import FramePair, frame_pair
from .rapid.task_scope import TaskScope, local_data_names
from .target_values import (WRITTEN_COLUMNS, bad_values, target_poses,  # noqa: F401
                            value_problem, written_values)
from .targets import CartesianTarget, JointTarget, MotionUse, Program
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
    bad_value : (m,) the target's written values are no target a controller accepts (a
        zero quaternion, a confdata that is not a plausible integer); its notes say why.
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
    bad_value: np.ndarray | None = None

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


def resolve(program: Program) -> Resolution:
    """Resolve every target of ``program`` with its tool and work object (see module doc)."""
    return resolve_task([program])[0]


def resolve_task(programs) -> tuple[Resolution, ...]:
    """Resolve the targets of the modules of one task (RAPID scope rules across modules,
    see :mod:`.rapid.task_scope`): one :class:`Resolution` per program, in order, each holding that
    module's targets, the motions of that module whose target is unknown, and the
    warnings about that module."""
    programs = list(programs)
    resolver = Resolver(programs)
    for m, program in enumerate(programs):
        for use in program.motions:
            resolver.assign_use(use, m)
    per_module = []
    for m, program in enumerate(programs):
        resolver.entry_count, resolver.shared = 0, []
        entries = [e for t in sorted(program.targets + program.joint_targets, key=_SPAN)
                   for e in resolver.entries_of(t, m)]
        per_module.append((entries, tuple(resolver.shared)))
    frames = tuple(sorted(resolver.frame_names))
    return tuple(
        _columns(entries, resolver.pair_info, shared,
                 tuple((u, why) for k, u, why in resolver.unresolved if k == m), frames,
                 tuple(w for k, w in resolver.warnings if k == m))
        for m, (entries, shared) in enumerate(per_module))


class Resolver:
    """The state of one resolution, built in steps: each motion use is assigned to the
    literal target it moves to with its (tool, work object) pair (:meth:`assign_use`),
    then each target becomes one entry per pair (:meth:`entries_of`).

    Lookups go through :class:`~.task.TaskScope` tables built from the declarations of
    every module of the task; ``m`` arguments are module indices into the programs given.
    """

    def __init__(self, programs: list[Program]):
        self.vplus = bool(programs) and programs[0].dialect == "vplus"
        local_names = [local_data_names(p) for p in programs]
        self.targets = TaskScope([[t for t in p.targets if t.storage != "assigned"]
                               + list(p.joint_targets) for p in programs], local_names)
        self.assigned: dict = {}   # (lower name, module, routine) -> [(offset, literal/copy)]
        for m, program in enumerate(programs):
            for t in program.targets:
                if t.storage == "assigned":
                    self.assigned.setdefault((t.name.lower(), m, t.routine), []).append(
                        (t.span[0], t))
            for c in program.copies:
                self.assigned.setdefault((c.name.lower(), m, c.routine), []).append(
                    (c.offset, c))
        self.tools = TaskScope([p.tools for p in programs], local_names)
        self.wobjs = TaskScope([p.wobjs for p in programs], local_names)
        self.params = {(m, r.name): {p.lower() for p in r.parameters}
                       for m, program in enumerate(programs) for r in program.routines}
        self.runtime_names = {r.base_name.lower() for p in programs for r in p.runtime
                              if r.base_name}
        self.warnings: list[tuple[int, str]] = []             # (module, line)
        self.unresolved: list[tuple[int, MotionUse, str]] = []  # (module, use, why)
        self.frame_names: set[str] = set()
        self.groups: dict = {}     # id(target) -> [(pair key, use), ...] in text order
        self.pair_info: dict = {}  # pair key -> ((tool name, tool), (wobj name, wobj))
        self.indirect: dict = {}   # id(target) -> [(use, key, info)] through Offs()...
        self.shared: list = []     # entry index groups of one target with several pairs
        self.entry_count = 0
        self._frames_memo: dict = {}
        self.references = self._references(programs)
        self.changed = self._changed(programs)

    # -- tools and work objects (memoized: a program has few of them)
    def frames_of(self, use: MotionUse, m: int):
        """((tool key, wobj key), (tool info, wobj info)) of a use in module ``m``."""
        k = (use.tool, use.wobj, m, use.routine, id(use.tool_inline), id(use.wobj_inline))
        got = self._frames_memo.get(k)
        if got is None:
            (tk, tinfo), (wk, winfo) = self.tool_of(use, m), self.wobj_of(use, m)
            got = self._frames_memo[k] = ((tk, wk), (tinfo, winfo))
        return got

    def tool_of(self, use: MotionUse, m: int):
        """(pair key part, (name, ToolData / V+ target / 'unknown' / None)) of a use."""
        if use.tool_inline is not None:
            return ("inline", m, use.tool_inline.span), ("<inline>", use.tool_inline)
        return self._frame(use.tool, m, use.routine, self.tools, "tool0", "NULL", "t")

    def wobj_of(self, use: MotionUse, m: int):
        """As :meth:`tool_of`, for the work object (V+: the compound frame)."""
        if use.wobj_inline is not None:
            return ("inline", m, use.wobj_inline.span), ("<inline>", use.wobj_inline)
        return self._frame(use.wobj, m, use.routine, self.wobjs, "wobj0", "base", "w")

    def _frame(self, name, m: int, routine, scope, default: str, vplus_default: str,
               tag: str):
        if name is None or (not self.vplus and name.lower() == default
                            and not scope.get(name, m, routine)):
            return (default,), (vplus_default if self.vplus else default, None)
        low = name.lower()
        if self.vplus:   # V+: tools and frames are transformations of the file
            found = self.targets.get(name, m, routine)
            self.frame_names.add(low)
            return (("v", low, self.targets.owner(low, m, routine)),
                    (name, found[0] if found else "unknown"))
        found = scope.get(name, m, routine)
        return (tag, low, scope.owner(low, m, routine)), (name, found[0] if found else "unknown")

    # -- motion uses
    def assign_use(self, use: MotionUse, m: int = 0) -> None:
        """Record which literal target ``use`` (of module ``m``) moves to, with its pair;
        or why none."""
        key, info = self.frames_of(use, m)
        if use.inline is not None:
            self._add(use.inline, use, key, info)
            return
        if use.runtime is not None:
            base = use.runtime.base_name
            for t in (self.targets.get(base, m, use.routine) if base else None) or ():
                self.indirect.setdefault(id(t), []).append((use, key, info))
            self.unresolved.append((m, use, use.runtime.reason))
            return
        name, index, routine = use.target_name, use.target_index, use.routine
        if self.assigned and name is not None and not isinstance(index, str):
            name, index, literal = self._follow(name, index, m, routine, use.target_span[0])
            if literal is not None:
                self._add(literal, use, key, info)
                return
        if name is not None and not isinstance(index, str):
            low = name.lower()   # one element: routine data, LOCAL data, global data
            one = self.targets.elements.get((low, self.targets.owner(low, m, routine), index))
            if one is not None:
                self._add(one, use, key, info)
                return
        found = self.targets.get(name, m, routine) if name else None
        if not found:
            self.unresolved.append((m, use, self._why_unknown(name, m, routine)))
            return
        if isinstance(index, str):
            chosen = [t for t in found if t.array_index is not None]
            shown = f"{name}[{index}]" if self.vplus else f"{name}{{{index}}}"
            self.warnings.append((m,
                f"{use.location}: {shown} has a run-time index: every element of {name} is "
                f"taken as used with this tool and work object"))
        else:
            chosen = [t for t in found if t.array_index == index]
        if not chosen:
            self.unresolved.append((m, use, f"no element {index} in {name}"))
        for t in chosen:
            self._add(t, use, key, info)

    def _follow(self, name: str, index, m: int, routine, offset: int):
        """(name, index, literal): what a motion at ``offset`` moves to after the
        assignments before it in its routine, in text order: the robtarget literal last
        assigned (``p := [...]``), or the variable last copied (``p := q``), followed."""
        for _ in range(8):   # copies of copies, not for ever
            last = None
            for at, what in self.assigned.get((name.lower(), m, routine), ()):
                held = what.array_index if type(what) is CartesianTarget else what.index
                if at < offset and held == index and (last is None or at > last[0]):
                    last = (at, what)
            if last is None:
                return name, index, None
            what = last[1]
            if type(what) is CartesianTarget:
                return name, index, what
            name, index, offset = what.source_name, what.source_index, what.offset
        return name, index, None

    def _add(self, target, use, key, info) -> None:
        found = self.groups.get(id(target))
        if found is None:
            self.groups[id(target)] = [(key, use)]
        else:
            found.append((key, use))
        self.pair_info[key] = info

    def _why_unknown(self, name: str, m: int, routine) -> str:
        params = self.params.get((m, routine))
        if params is not None and name.lower() in params:
            return f"{name} is a parameter of {routine}: its value comes from the caller"
        if name.lower() in self.runtime_names:
            return f"{name} has no literal value (set at run time or in another module)"
        return f"unknown target {name}"

    def _references(self, programs: list[Program]) -> dict:
        """id(target) -> (module, reference) of the references passing it to a routine
        (not a motion)."""
        refs: dict = {}
        for m, program in enumerate(programs):
            for r in program.references:
                for t in self.targets.get(r.name, m, r.routine) or ():
                    refs.setdefault(id(t), []).append((m, r))
        return refs

    def _changed(self, programs: list[Program]) -> dict:
        """id(target) -> its run-time changes (assignments, SearchL results)."""
        changed: dict = {}
        for m, program in enumerate(programs):
            for r in program.runtime:
                if r.base_name and ("assigned" in r.reason or "written" in r.reason):
                    for t in self.targets.get(r.base_name, m, r.routine) or ():
                        changed.setdefault(id(t), []).append(r)
        return changed

    # -- entries
    def entries_of(self, t, m: int = 0) -> list:
        """The entries (target, uses, pair key, notes) of target ``t`` of module ``m``:
        one per pair."""
        tid = id(t)
        notes = []
        same = self.targets.aliases.get(tid)
        if same is not None:   # a global declared again in another module: one variable
            tid = id(same)
            notes.append(f"the same variable as {same.display_name} at {same.location} "
                         f"(declared in several modules)")
            if same.texts != t.texts:
                self.warnings.append((m,
                    f"{t.location}: {t.display_name} is declared again with another value "
                    f"than at {same.location}: the controller keeps the first value"))
        used = self.groups.get(tid)
        if self.vplus and t.name and t.name.lower() in self.frame_names:
            if used is None:
                return []  # a tool or frame, not a target
            self.warnings.append((m, f"{t.location}: {t.display_name} is used both as a "
                                     f"target and as a tool or frame"))
        if used is not None and len(used) == 1 and tid not in self.changed and not notes:
            key, use = used[0]   # the common case
            return self._counted([(t, (use,), key, ())])
        notes += [f"changed at run time by {r.expression!r} (line {r.location.line}): the "
                  f"literal is only its first value" for r in self.changed.get(tid, ())]
        pairs: dict = {}   # pair key -> uses, in order of first use
        for key, use in used or ():
            pairs.setdefault(key, []).append(use)
        if not pairs:
            pairs = self._pairs_if_not_moved_to(t, tid, notes)
        if len(pairs) == 1:
            ((key, uses),) = pairs.items()
            return self._counted([(t, tuple(uses), key, tuple(notes))])
        if isinstance(t, JointTarget):
            # joint values do not depend on the tool or work object: one entry
            return self._counted([(t, tuple(u for us in pairs.values() for u in us),
                                   next(iter(pairs)), tuple(notes))])
        listed = "; ".join(f"{self.pair_info[k][0][0]}/{self.pair_info[k][1][0]} (line "
                           f"{us[0].location.line})" for k, us in pairs.items())
        self.warnings.append((m, f"{t.location}: {t.display_name} is used with {len(pairs)} "
                                 f"tool/work-object pairs: {listed}"))
        self.shared.append(tuple(range(self.entry_count, self.entry_count + len(pairs))))
        return self._counted([(t, tuple(uses), key, tuple(notes))
                              for key, uses in pairs.items()])

    def _counted(self, entries: list) -> list:
        self.entry_count += len(entries)
        return entries

    def _pairs_if_not_moved_to(self, t, tid: int, notes: list) -> dict:
        """The pairs of a target no motion moves to: those of the Offs()/RelTool() motions
        built on it, else tool0/wobj0 with the note 'unused' (``notes`` is extended)."""
        via = self.indirect.get(tid)
        if via:
            pairs: dict = {}
            for use, key, info in via:
                pairs.setdefault(key, []).append(use)
                self.pair_info[key] = info
            notes.append("moved to only through " + ", ".join(sorted(
                {u.runtime.expression.split("(")[0] + "()" for u, _, _ in via})))
            return pairs
        default_key = (("tool0",), ("wobj0",))
        self.pair_info.setdefault(default_key, (
            ("NULL" if self.vplus else "tool0", None), ("base" if self.vplus else "wobj0", None)))
        notes.append("unused")
        for m, r in self.references.get(tid, ()):
            self.warnings.append((m,
                f"{r.location}: {r.name} is passed to {r.context}: its tool and work object "
                f"are unknown, {'tool0/wobj0' if not self.vplus else 'identity'} assumed"))
        return {default_key: []}


def _columns(entries, pair_info, shared, unresolved, frames, warnings) -> Resolution:
    """The Resolution of ``entries`` (target, uses, pair key, notes): poses in batches."""
    m = len(entries)
    keys: dict = {}   # pair key -> index into pairs
    pair_index = np.fromiter((keys.setdefault(e[2], len(keys)) for e in entries), np.intp, m)
    pairs = tuple(frame_pair(pair_info[key]) for key in keys)
    targets = tuple([e[0] for e in entries])
    cart = np.fromiter((type(t) is CartesianTarget for t in targets), bool, m)
    wobj_T_target = np.full((m, 4, 4), np.nan)
    written = np.full((m, WRITTEN_COLUMNS), np.nan)
    rows = np.flatnonzero(cart)
    cartesian = [targets[k] for k in rows.tolist()]
    written[rows] = written_values(cartesian)
    bad_value = bad_values(written)
    rows = rows[~bad_value[rows]]
    wobj_T_target[rows] = target_poses([targets[k] for k in rows.tolist()], written[rows])
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
    notes = [e[3] + pairs[p].notes if pairs[p].notes else e[3]
             for e, p in zip(entries, pair_index.tolist())]
    for k in np.flatnonzero(bad_value).tolist():
        notes[k] = (value_problem(targets[k]),) + notes[k]
    return Resolution(targets, tuple([e[1] for e in entries]), tuple(notes), pair_index,
                      pairs, written, wobj_T_target, base_T_flange, shared, unresolved,
                      frames, warnings, bad_value)


__all__ = ["resolve", "resolve_task", "Resolver", "frame_pair", "target_poses",
           "written_values", "Resolution",
           "ResolvedTarget", "FramePair"]
