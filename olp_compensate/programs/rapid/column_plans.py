"""Which targets of a RAPID task's column tables are plain (their meaning a table row can
hold: declared once, moved to by name, one tool and work object pair per target), and how
they resolve (:class:`Plan`). A target that is not plain goes to the object model."""

from __future__ import annotations

from dataclasses import dataclass
from itertools import count, repeat

import numpy as np

from ..frame_pairs import frame_pair
from ..semantics import Resolver
from ..targets import MotionUse, Program
from .columns import ModuleColumns

DEFAULT_KEY = (("tool0",), ("wobj0",))
"""The pair of a target no motion moves to."""


def task_plans(programs: list[Program], columns: list[ModuleColumns]) -> list:
    """Each module's :class:`Plan`, or None where its table targets are not plain within
    the task: a name declared in another module's table too, named by any module's objects
    or moved to by another module's table motions."""
    shared = modules_sharing_names(programs, columns)
    resolver = Resolver(programs) if any(len(c.targets) for c in columns) else None
    return [None if m in shared or not len(c.targets) else plan(program, c, resolver, m)
            for m, (program, c) in enumerate(zip(programs, columns))]


def modules_sharing_names(programs: list[Program], columns: list[ModuleColumns]) -> set:
    """The modules with a table target declared in another module too, named by any
    module's objects (displaced by Offs()/RelTool(): by another module's), or moved to by
    another module's table motions (one dict of the table names, no lower-case copies of
    names already in lower case)."""
    owner: dict[str, int] = {}    # lower-case table name -> the first module declaring it
    shared = set()
    for m, c in enumerate(columns):
        for name in c.targets.names:
            first = owner.setdefault(name if name.islower() else name.lower(), m)
            if first != m:
                shared.update((first, m))
    if not owner:
        return shared
    for m, program in enumerate(programs):
        for name in named_elsewhere(program, displaced=False):
            if name in owner:
                shared.add(owner[name])
        for name in displaced_names(program):   # Offs()/RelTool() of another module's
            if owner.get(name, m) != m:         # target: the task's resolution
                shared.add(owner[name])
    if len(columns) > 1:
        for m, c in enumerate(columns):
            for name in c.moves.target_names:
                first = owner.get(name if name.islower() else name.lower(), m)
                if first != m:
                    shared.add(first)
    return shared


@dataclass(frozen=True, eq=False)
class Plan:
    """How the table targets resolve: ``pair`` (n,) each one's index into ``pairs``
    (tool0/wobj0 for a target no motion moves to) and ``uses`` (n,) its motions."""

    pair: np.ndarray
    uses: np.ndarray
    pairs: tuple


def plan(program: Program, columns: ModuleColumns, resolver: Resolver | None = None,
          m: int = 0) -> Plan | None:
    """The resolution of the table targets of module ``m`` (``resolver``: of the task's
    modules, default of this one alone), or None where their meaning is not plain."""
    table, moves = columns.targets, columns.moves
    row_of = _first_rows(_lower(table.names))
    if len(row_of) < len(table) or any(k >= 0 for k in moves.indices):
        return None
    if not named_elsewhere(program, displaced=False).isdisjoint(row_of):
        return None
    rows = _rows_of(row_of, moves.target_names)
    if np.any(rows < 0):
        return None
    if outside_their_routine(table.routines, moves.routines, rows):
        return None   # a routine's target moved to from another routine
    moved = np.zeros(len(table), bool)
    moved[rows] = True
    if any(not moved[row_of[name]] for name in displaced_names(program) & row_of.keys()):
        return None   # moved to only through Offs()/RelTool(): the object model's pairs
    resolver = Resolver([program]) if resolver is None else resolver
    keys: dict = {}    # pair key -> index into pairs
    infos: list = []
    triples, codes = _triple_codes(moves)   # (tool, wobj, routine) in order of first use
    pair_of_code = np.zeros(len(moves) + 1, np.intp)
    for (tool, wobj, routine), code in triples.items():
        key, info = resolver.frames_of(MotionUse(instruction="MoveL", source=(
            program.file, 0, 0), tool=tool, wobj=wobj, routine=routine), m)
        p = pair_of_code[code] = keys.setdefault(key, len(keys))
        if p == len(infos):
            infos.append(info)
    move_pair = pair_of_code[codes]
    uses = np.bincount(rows, minlength=len(table))
    pair = np.full(len(table), -1, np.intp)
    pair[rows[::-1]] = move_pair[::-1]     # each target's first motion's pair
    if np.any(pair[rows] != move_pair):    # moved to with several pairs
        return None
    if np.any(uses == 0):
        default = keys.setdefault(DEFAULT_KEY, len(keys))
        if default == len(infos):
            infos.append((("tool0", None), ("wobj0", None)))
        pair[uses == 0] = default
    return Plan(pair=pair, uses=uses, pairs=tuple(frame_pair(info) for info in infos))


def named_elsewhere(program: Program, displaced: bool = True) -> set[str]:
    """Lower-case names that the program's objects declare or use as targets;
    ``displaced=False``: without the names used only as the target a motion displaces at
    run time (``MoveL Offs(p, ...)``, ``RelTool``: :func:`displaced_names`), which leave
    the meaning of a target moved to by name as well unchanged."""
    names = {t.name for t in program.targets + program.joint_targets if t.name}
    names.update(u.target_name for u in program.motions if u.target_name)
    if displaced:
        names.update(r.base_name for r in program.runtime if r.base_name)
    else:
        of_motions = {id(u.runtime) for u in program.motions if u.runtime is not None}
        names.update(r.base_name for r in program.runtime
                     if r.base_name and id(r) not in of_motions)
    names.update(u.runtime.base_name for u in program.motions
                 if displaced and u.runtime is not None and u.runtime.base_name)
    names.update(r.name for r in program.references)
    for c in program.copies:
        names.update(n for n in (c.name, c.source_name) if n)
    names.update(p for r in program.routines for p in r.parameters)
    return {n.lower() for n in names}


def displaced_names(program: Program) -> set[str]:
    """Lower-case names of the targets that motions displace at run time (the first
    argument of ``Offs()`` or ``RelTool()`` as a motion's target). Such a use is reported
    as its own ``runtime`` row and changes nothing of a target that motions also move to
    by name (:meth:`~..semantics.Resolver.entries_of`): that target stays a table row.
    A target moved to only through them takes their pairs: it goes to the object model."""
    return {u.runtime.base_name.lower() for u in program.motions
            if u.runtime is not None and u.runtime.base_name}


def outside_their_routine(routines: list, move_routines: list, rows: np.ndarray) -> list:
    """The motions (indices) to a routine's table target (``routines`` of the rows, None
    at module level; ``rows``: each motion's table row or -1) made outside that routine,
    where the name means something else (another target, or none)."""
    if not any(routines):
        return []
    return [k for k, row in enumerate(rows.tolist()) if row >= 0 and routines[row]
            and (move_routines[k] or "").lower() != routines[row].lower()]


def plain_rows(program: Program, columns: ModuleColumns, displaced: list[str] = ()
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(targets (n,) bool, motions (k,) bool, displaced (d,) bool): the table rows whose
    meaning is plain within the module. A target is not plain when its name is declared
    twice, named by any of the module's objects (a run-time expression, routine argument,
    copy, assignment, another declaration), moved to with an index, or moved to with
    several tool/work-object pairs, or (a routine's target) moved to from another
    routine, or moved to only through Offs()/RelTool(); a motion is not plain when its
    target is not a plain table target (a name the table does not declare). The rows that
    are not plain go to the object path together with every table motion to them.
    ``displaced``: the lower-case names Offs()/RelTool() motions held as rows displace;
    such a motion stays a row where its target is a plain table target."""
    table, moves = columns.targets, columns.moves
    lower = _lower(table.names)
    row_of = _first_rows(lower)
    twice = set()
    if len(row_of) < len(lower):
        twice = {name for k, name in enumerate(lower) if row_of[name] != k}
    named = (twice | named_elsewhere(program, displaced=False)) & row_of.keys()
    keep_targets = np.ones(len(lower), bool)
    if named:
        keep_targets &= ~np.fromiter(map(named.__contains__, lower), bool, len(lower))
    rows = _rows_of(row_of, moves.target_names)
    indexed = np.frombuffer(moves.indices, np.int64) >= 0 if len(moves) else \
        np.zeros(0, bool)
    keep_targets[rows[indexed & (rows >= 0)]] = False
    for k in outside_their_routine(table.routines, moves.routines, rows):
        keep_targets[rows[k]] = False   # a routine's target named in another routine
    moved = np.zeros(len(lower), bool)
    moved[rows[rows >= 0]] = True
    bases = np.fromiter(map(row_of.get, displaced, repeat(-1)), np.intp, len(displaced))
    displacing = np.concatenate([bases[bases >= 0], _rows_of(row_of, [
        name for name in displaced_names(program) if name in row_of])])
    keep_targets[displacing[~moved[displacing]]] = False   # moved to only through Offs()...
    codes = _triple_codes(moves)[1][rows >= 0]
    moving = rows[rows >= 0]
    first = np.full(len(lower), -1, np.int64)
    first[moving[::-1]] = codes[::-1]         # each target's first motion's (tool, wobj, routine)
    keep_targets[moving[codes != first[moving]]] = False   # another in a later motion
    keep_moves = (rows >= 0) & ~indexed
    keep_moves[keep_moves] = keep_targets[rows[keep_moves]]
    keep_displaced = bases >= 0
    keep_displaced[keep_displaced] = keep_targets[bases[keep_displaced]]
    return keep_targets, keep_moves, keep_displaced


def _lower(names: list[str]) -> list[str]:
    """``names`` in lower case (a name already so is the same string)."""
    return [name if name.islower() else name.lower() for name in names]


def _first_rows(lower: list[str]) -> dict[str, int]:
    """Each name of ``lower`` -> the row where it is first."""
    n = len(lower)
    return dict(zip(reversed(lower), range(n - 1, -1, -1)))


def _rows_of(row_of: dict[str, int], names: list[str]) -> np.ndarray:
    """(k,) the row of each of ``names`` (any case) in ``row_of`` (lower-case names),
    -1 where none."""
    rows = np.fromiter(map(row_of.get, names, repeat(-1)), np.intp, len(names))
    missing = np.flatnonzero(rows < 0).tolist()   # a name not in lower case, or none
    if missing:
        rows[missing] = [row_of.get(names[k].lower(), -1) for k in missing]
    return rows


def _triple_codes(moves) -> tuple[dict, np.ndarray]:
    """({(tool, wobj, routine): code} in order of first use, (k,) each motion's code):
    the same code for the same three words."""
    triples: dict = {}
    codes = np.fromiter(map(triples.setdefault, zip(moves.tools, moves.wobjs, moves.routines),
                            count()), np.int64, len(moves))
    return triples, codes
