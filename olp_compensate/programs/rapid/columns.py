"""Columns of a big RAPID module's plainest statements, without an object per statement.

A generated module holds tens of thousands of module-level ``CONST robtarget p := [...];``
and ``MoveL p, v, z, tool\\WObj:=w;``. Parsed by
:func:`~.reader.parse_rapid_columns`, the fast paths (fast.py) append those to the
two tables here instead of making a :class:`~.targets.CartesianTarget` or
:class:`~.targets.MotionUse` each: names and flat arrays of offsets (about 150 bytes a
row, against 3 KB as objects; the numbers' values are read in batches,
:meth:`TargetTable.values`). Everything else of the module is parsed into objects as
always.

:meth:`TargetTable.target` and :meth:`MoveTable.use` make the object of one row, equal
to what the object parse makes; :func:`with_objects` turns a column parse into the
ordinary :class:`~.targets.Program`. Offsets are into the decoded program text; numbers
are as written (mm, quaternion w first, confdata, external axes)."""

from __future__ import annotations

import dataclasses
import heapq
import re
from array import array
from itertools import chain, compress, count, islice, repeat

import numpy as np

from ..literals import ROBTARGET_RE
from ..targets import QUAT_WXYZ, CartesianTarget, MotionUse, Program

NUMBERS = 17
"""Numbers of a robtarget literal: x y z, q1..q4, cf1 cf4 cf6 cfx, eax_a..eax_f."""
SPANS = 6
SIMPLE_GROUPS = (1, 3, 4, 5, 6, 2, 7)
"""fast.py ``_SIMPLE_MOVE``'s groups: instruction, name, index, tool, wobj, target, where
the arguments end."""
MIXED_GROUPS = (1, 6, 7, 8, 9, 5, 10)
"""The same of fast.py ``_MIXED_MOVE`` (its displaced moves: :data:`~.displaced.GROUPS`)."""
INSTRUCTION = 5
"""Letters of the instruction word (MoveL, MoveJ) that starts every match of fast.py's
move regexes (their group 1): its span is (start, start + 5) of the match's start."""
MIXED_BATCH = 8192
"""Matches :meth:`MoveTable.run_mixed` holds before adding them as rows."""
_BRACKETS = {ord("["): " ", ord("]"): " "}


class TargetTable:
    """Plain robtarget declarations, in text order: module-level, and ``VAR``/``CONST``
    ones of a routine (``routines``: the routine's name as written, None at module level).

    Per row: ``names`` and ``storage`` ('CONST', 'PERS', 'VAR') as written; ``spans``:
    the literal's (start, end), the type word's (start, end), where its first number (x)
    starts and where its fourth (quaternion) number ends; ``line``, ``column`` of the name
    (1-based; set by :meth:`place`, after the parse). The 17 numbers' values come from
    :meth:`values` (one batch), their texts and offsets from :meth:`target`.
    """

    __slots__ = ("names", "storage", "routines", "spans", "offsets", "line", "column",
                 "_words")

    def __init__(self):
        self.names: list[str] = []
        self.storage: list[str] = []
        self.routines: list[str | None] = []
        self.spans = array("q")      # SPANS per row
        self.offsets = array("q")    # where each name starts
        self.line = self.column = np.zeros(0, np.int64)
        self._words: dict[str, str] = {}   # written storage word -> upper case, one string

    def __len__(self) -> int:
        return len(self.names)

    def append(self, name: str, storage: str, regs, routine: str | None = None) -> None:
        """Add a row from the ``regs`` of a declaration match (see rapid_fast.py
        ``_row_pattern``: group 3 the name, 2 the type word, 4 the literal, 5 its first
        number, 6 its seventh)."""
        self.names.append(name)
        word = self._words.get(storage)
        if word is None:
            word = self._words[storage] = storage.upper()
        self.storage.append(word)
        self.routines.append(routine)
        literal, kind = regs[4], regs[2]
        self.offsets.append(regs[3][0])
        self.spans.extend((literal[0], literal[1], kind[0], kind[1], regs[5][0], regs[6][1]))

    def run(self, regex: re.Pattern, text: str, pos: int, end: int,
            routine: str | None = None, own: bool = False) -> int:
        """Add a row for each match of ``regex`` (a :meth:`append` form) that follows the
        previous one from ``pos`` on, without a gap, in batches (:func:`matches_in_turn`):
        the rows :meth:`append` gives of the same matches. ``own`` (in a routine): only
        its own data, the run stops before a ``PERS`` declaration or one with a ``LOCAL``
        or ``TASK`` word (the builder's to judge). Returns where they end."""
        for ms in matches_in_turn(regex, text, pos, end):
            if own:
                kept = _routine_data(ms)
                if kept < len(ms):
                    self._add(ms[:kept], routine)
                    return ms[kept].start()
            pos = ms[-1].end()
            self._add(ms, routine)
        return pos

    def _add(self, ms: list, routine: str | None) -> None:
        """Add a row per match of ``ms`` (:meth:`run`)."""
        if len(ms) < 16:   # a short run: row by row (arrays cost more than they save)
            for m in ms:
                self.append(m.group(3), m.group(1), m.regs, routine)
            return
        words = self._words
        self.names.extend(map(_GROUP, ms, repeat(3)))
        written = list(map(_GROUP, ms, repeat(1)))
        for word in set(written).difference(words):
            words[word] = word.upper()
        self.storage.extend(map(words.__getitem__, written))
        self.routines.extend(repeat(routine, len(ms)))
        self.offsets.extend(map(_START, ms, repeat(3)))
        _add_rows(self.spans, ms, ((_START, 4), (_END, 4), (_START, 2), (_END, 2),
                                   (_START, 5), (_END, 6)))

    def place(self, line_starts: np.ndarray) -> None:
        """Set ``line`` and ``column`` from the offsets where the text's lines start."""
        self.line, self.column = lines_and_columns(self.offsets, line_starts)

    def span_columns(self) -> np.ndarray:
        """(n, 6) int: literal start, end, type word start, end, first number start,
        fourth number end."""
        return np.frombuffer(self.spans, np.int64).reshape(-1, SPANS) if len(self) else \
            np.zeros((0, SPANS), np.int64)

    def values(self, text: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """(k, 17) the numbers as written of rows ``start:stop``, converted in one batch
        (the same floats as ``float()`` of each number's text)."""
        stop = len(self) if stop is None else stop
        n = stop - start
        if n <= 0:
            return np.zeros((0, NUMBERS))
        spans, rows = self.spans, range(SPANS * start, SPANS * stop, SPANS)
        values = np.empty((n, NUMBERS))
        # the position and quaternion (7 numbers) of each literal, in one batch
        values[:, :7] = _numbers(",".join([text[spans[k + 4]:spans[k + 5]] for k in rows]),
                                 7 * n).reshape(n, 7)
        # the rest (confdata, external axes: 10 numbers) once per distinct text: a
        # module repeats a few ("],[0,-1,0,1],[9E9,9E9,9E9,9E9,9E9,9E9]]")
        codes: dict[str, int] = {}
        code = np.fromiter(map(codes.setdefault, [text[spans[k + 5]:spans[k + 1]] for k in rows],
                               count()), np.intp, n)
        rests = np.empty((n, NUMBERS - 7))
        for rest, k in codes.items():
            rests[k] = _numbers(rest.translate(_BRACKETS).strip().lstrip(","), NUMBERS - 7)
        values[:, 7:] = rests[code]
        return values

    def subset(self, keep: np.ndarray) -> TargetTable:
        """A table of the rows where ``keep`` (n,) bool is true, in order."""
        out = TargetTable()
        rows = np.flatnonzero(keep).tolist()
        out.names = [self.names[k] for k in rows]
        out.storage = [self.storage[k] for k in rows]
        out.routines = [self.routines[k] for k in rows]
        out.spans = array("q", self.span_columns()[keep].ravel().tolist())
        out.offsets = array("q", [self.offsets[k] for k in rows])
        out.line, out.column = self.line[keep], self.column[keep]
        out._words = self._words
        return out

    def target(self, i: int, text: str, file: str) -> CartesianTarget:
        """Row ``i`` as the :class:`CartesianTarget` the object parse makes."""
        s = self.spans[SPANS * i:SPANS * (i + 1)]
        m = ROBTARGET_RE.match(text, s[0], s[1])
        return CartesianTarget(
            name=self.names[i], source=(file, int(self.line[i]), int(self.column[i])),
            texts=m.groups(), starts=tuple(map(m.start, range(1, NUMBERS + 1))),
            orientation_kind=QUAT_WXYZ, span=(s[0], s[1]), storage=self.storage[i],
            array_index=None, routine=self.routines[i], type_span=(s[2], s[3]))

    def targets(self, text: str, file: str) -> list[CartesianTarget]:
        """Every row as :meth:`target` makes it (in one pass)."""
        s = self.spans.tolist()
        matches = map(ROBTARGET_RE.match, repeat(text), s[0::SPANS], s[1::SPANS])
        make, numbers = CartesianTarget._make, range(1, NUMBERS + 1)
        return [make((name, (file, line, column), m.groups(), tuple(map(m.start, numbers)),
                      QUAT_WXYZ, (a, b), storage, None, routine, (ta, tb)))
                for m, name, line, column, storage, routine, a, b, ta, tb in zip(
                    matches, self.names, self.line.tolist(), self.column.tolist(),
                    self.storage, self.routines, s[0::SPANS], s[1::SPANS], s[2::SPANS], s[3::SPANS])]


class MoveTable:
    """Plain ``MoveL``/``MoveJ`` to a named target (``p`` or ``p{k}``), in text order.

    Per row: ``instructions``, ``target_names``, ``tools``, ``wobjs`` (None: wobj0) and
    ``routines`` as written (repeated words stored once); ``indices`` (the literal array
    index, -1 for none); ``spans``: the instruction word, the statement (without ';') and
    the target argument, (start, end) each; ``line``, ``column`` of the target argument
    (set by :meth:`place`, after the parse).
    """

    __slots__ = ("instructions", "target_names", "tools", "wobjs", "routines", "indices",
                 "spans", "line", "column", "_words")

    def __init__(self):
        self.instructions: list[str] = []
        self.target_names: list[str] = []
        self.tools: list[str] = []
        self.wobjs: list[str | None] = []
        self.routines: list[str | None] = []
        self.indices = array("q")
        self.spans = array("q")      # 6 per row
        self.line = self.column = np.zeros(0, np.int64)
        self._words: dict[str, str] = {}

    def __len__(self) -> int:
        return len(self.target_names)

    def append(self, instruction: str, name: str, index: str | None, tool: str,
               wobj: str | None, routine: str | None, spans) -> None:
        """Add a row; ``spans``: the instruction's, the statement's and the target's."""
        words = self._words
        self.instructions.append(words.setdefault(instruction, instruction))
        self.target_names.append(name)
        self.tools.append(words.setdefault(tool, tool))
        self.wobjs.append(None if wobj is None else words.setdefault(wobj, wobj))
        self.routines.append(routine)
        self.indices.append(-1 if index is None else int(index))
        self.spans.extend(spans)

    def run(self, regex: re.Pattern, text: str, pos: int, end: int,
            routine: str | None) -> int:
        """Add a row for each match of ``regex`` (fast.py ``_SIMPLE_MOVE``) that follows
        the previous one from ``pos`` on, without a gap, in batches
        (:func:`matches_in_turn`): the rows :meth:`append` gives of the same matches.
        Returns where they end."""
        for ms in matches_in_turn(regex, text, pos, end):
            pos = ms[-1].end()
            self.extend(ms, routine, SIMPLE_GROUPS)
        return pos

    def run_mixed(self, regex: re.Pattern, text: str, pos: int, end: int,
                  routine: str | None, displaced) -> int:
        """:meth:`run` of ``regex`` (fast.py ``_MIXED_MOVE``, groups :data:`MIXED_GROUPS`),
        a plain move or an Offs()/RelTool() one each: the plain ones rows here, the others
        rows of ``displaced`` (a :class:`~.displaced.DisplacedMoves`, its ``extend``), each
        batch split by kind, the matches of each kind added together at the end of the run
        (or every :data:`MIXED_BATCH` of them): a routine's run of a few hundred moves
        meets several short batches. Returns where they end."""
        first = regex.match(text, pos, end)   # anchored: no search where none starts
        if first is None:
            return pos
        plain: list = []     # matches of plain moves not yet added, and their names
        names: list = []
        moved: list = []     # of displaced moves
        for ms in chain(([first],), matches_in_turn(regex, text, first.end(), end)):
            pos = ms[-1].end()
            found = list(map(_GROUP, ms, repeat(MIXED_GROUPS[1])))   # None: displaced
            if None not in found:
                plain += ms
                names += found
            else:
                kinds = [name is not None for name in found]
                plain += compress(ms, kinds)
                names += compress(found, kinds)
                moved += [m for m, kind in zip(ms, kinds) if not kind]
            if len(plain) + len(moved) >= MIXED_BATCH:
                self.extend(plain, routine, MIXED_GROUPS, names)
                displaced.extend(moved, routine)
                plain, names, moved = [], [], []
        self.extend(plain, routine, MIXED_GROUPS, names)
        displaced.extend(moved, routine)
        return pos

    def extend(self, ms: list, routine: str | None, groups: tuple,
               names: list | None = None) -> None:
        """Add a row per match of ``ms``: the rows :meth:`append` gives of them;
        ``groups``: their instruction, name, index, tool, wobj, target and arguments' end
        groups (:data:`SIMPLE_GROUPS`, :data:`MIXED_GROUPS`), ``names`` the name group's
        texts if known. Short lists row by row (arrays cost more than they save)."""
        instruction, name, index, tool, wobj, target, stop = groups
        if len(ms) < 16:
            for m in ms:
                regs = m.regs
                self.append(*m.group(instruction, name, index, tool, wobj), routine,
                            (*regs[instruction], regs[0][0], regs[stop][0], *regs[target]))
            return
        words = self._words
        if names is None:
            names = list(map(_GROUP, ms, repeat(name)))
        instructions, indices, tools, wobjs = (
            list(map(_GROUP, ms, repeat(k))) for k in (instruction, index, tool, wobj))
        self.instructions.extend(map(words.setdefault, instructions, instructions))
        self.target_names.extend(names)
        self.tools.extend(map(words.setdefault, tools, tools))
        self.wobjs.extend(None if w is None else words.setdefault(w, w) for w in wobjs)
        self.routines.extend(repeat(routine, len(ms)))
        self.indices.extend(-1 if k is None else int(k) for k in indices)
        start = np.fromiter(map(_START, ms), np.int64, len(ms))   # the instruction word's
        _add_rows(self.spans, ms, ((_START, stop), (_START, target), (_END, target)),
                  [start, start + INSTRUCTION, start])

    def place(self, line_starts: np.ndarray) -> None:
        """Set ``line`` and ``column`` from the offsets where the text's lines start."""
        self.line, self.column = lines_and_columns(self.spans[4::6], line_starts)

    def subset(self, keep: np.ndarray) -> MoveTable:
        """A table of the rows where ``keep`` (n,) bool is true, in order."""
        out = MoveTable()
        rows = np.flatnonzero(keep).tolist()
        for name in ("instructions", "target_names", "tools", "wobjs", "routines"):
            column = getattr(self, name)
            setattr(out, name, [column[k] for k in rows])
        out.indices = array("q", [self.indices[k] for k in rows])
        spans = np.frombuffer(self.spans, np.int64).reshape(-1, 6) if len(self) else \
            np.zeros((0, 6), np.int64)
        out.spans = array("q", spans[keep].ravel().tolist())
        out.line, out.column = self.line[keep], self.column[keep]
        out._words = self._words
        return out

    def use(self, i: int, file: str) -> MotionUse:
        """Row ``i`` as the :class:`MotionUse` the object parse makes."""
        s = self.spans[6 * i:6 * i + 6]
        index = self.indices[i]
        return MotionUse(
            instruction=self.instructions[i],
            source=(file, int(self.line[i]), int(self.column[i])),
            role="to", target_name=self.target_names[i],
            target_index=None if index < 0 else (index,), inline=None, runtime=None,
            tool=self.tools[i], tool_inline=None, wobj=self.wobjs[i], wobj_inline=None,
            joint=False, routine=self.routines[i], instruction_span=(s[0], s[1]),
            statement_span=(s[2], s[3]), target_span=(s[4], s[5]))

    def uses(self, file: str) -> list[MotionUse]:
        """Every row as :meth:`use` makes it (in one pass)."""
        s = self.spans.tolist()
        make = MotionUse._make
        return [make((instruction, (file, line, column), "to", name,
                      None if index < 0 else (index,), None, None, tool, None, wobj, None,
                      False, routine, (a, b), (c, d), (e, f)))
                for instruction, line, column, name, index, tool, wobj, routine, a, b, c, d,
                e, f in zip(self.instructions, self.line.tolist(), self.column.tolist(),
                            self.target_names, self.indices, self.tools, self.wobjs,
                            self.routines, s[0::6], s[1::6], s[2::6], s[3::6], s[4::6],
                            s[5::6])]


@dataclasses.dataclass(frozen=True, eq=False)
class ModuleColumns:
    """The tables of one column parse (see the module docstring)."""

    targets: TargetTable
    moves: MoveTable

    def place(self, line_starts, displaced=None) -> None:
        """Give every row its line and column (``line_starts``: where the lines start),
        those of ``displaced`` (a :class:`~.displaced.DisplacedMoves`, or None) too."""
        starts = np.asarray(line_starts, np.int64)
        self.targets.place(starts)
        self.moves.place(starts)
        if displaced is not None:
            displaced.place(starts)


_GROUP, _START, _END = re.Match.group, re.Match.start, re.Match.end


def _routine_data(ms: list) -> int:
    """How many of the declaration matches ``ms`` (TargetTable forms), from the first, are
    a routine's own data: no LOCAL or TASK word, not PERS."""
    for k, m in enumerate(ms):
        if m.start(1) != m.start() or m.group(1).upper() == "PERS":
            return k
    return len(ms)


def _numbers(joined: str, n: int) -> np.ndarray:
    """(n,) the numbers of ``joined`` (numbers of robtarget literals between commas, their
    brackets left), converted in one batch (the same floats as ``float()`` of each)."""
    values = np.fromstring(joined.translate(_BRACKETS), sep=",")
    if values.shape != (n,):   # cannot be: each literal holds 17 numbers
        raise AssertionError("robtarget literals do not hold 17 numbers each")
    return values


def matches_in_turn(regex: re.Pattern, text: str, pos: int, end: int):
    """The matches of ``regex`` in ``text[pos:end]`` each starting where the previous one
    ends, the first at ``pos`` (what ``regex.match`` from ``pos`` on, one after the other,
    finds), as lists: the first 16 read one by one (a gap stops them at once: statements
    of other kinds in between cost one search each), then batches of 32, each twice the
    last (to 8,192), as long as no gap is found. A search finds at each start what an
    anchored match finds there; the matches searched past a gap (at most about the
    number before it) are left."""
    found = regex.finditer(text, pos, end)
    head = []
    for m in found:
        if m.start() != pos:
            break
        head.append(m)
        pos = m.end()
        if len(head) == 16:
            break
    if head:
        yield head
    size = 32
    while len(head) == 16:
        batch = list(islice(found, size))
        n = len(batch)
        if not n:
            return
        starts = np.fromiter(map(_START, batch), np.int64, n)
        ends = np.fromiter(map(_END, batch), np.int64, n)
        gaps = np.flatnonzero(starts[1:] != ends[:-1])
        if starts[0] != pos:
            return
        k = int(gaps[0]) + 1 if len(gaps) else n
        yield batch if k == n else batch[:k]
        if k < n or n < size:
            return
        pos = int(ends[-1])
        size = min(2 * size, 8192)


def _add_rows(spans: array, matches: list, fields, first: list = ()) -> None:
    """Append to ``spans`` one row per match: the columns ``first`` ((n,) int64 each),
    then for each ``(method, group)`` of ``fields``, ``method(match, group)`` (start or
    end)."""
    columns = [*first, *(np.fromiter(map(method, matches, repeat(group)), np.int64,
                                     len(matches)) for method, group in fields)]
    spans.frombytes(np.column_stack(columns).astype(np.int64, copy=False).tobytes())


def lines_and_columns(offsets, line_starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """1-based (line, column) arrays of character ``offsets``."""
    at = np.asarray(offsets, np.int64)
    line = np.searchsorted(line_starts, at, side="right")
    return line, at - line_starts[line - 1] + 1


def with_objects(program: Program, columns: ModuleColumns) -> Program:
    """The ordinary :class:`Program` of a column parse: the table rows made into objects
    and merged in text order with the others (what the object parse gives)."""
    targets = columns.targets.targets(program.text, program.file)
    motions = columns.moves.uses(program.file)
    return dataclasses.replace(
        program,
        targets=_merged(program.targets, targets, lambda t: t.span[0]),
        motions=_merged(program.motions, motions, lambda u: u.target_span or u.statement_span))


def split(program: Program, columns: ModuleColumns, keep_targets: np.ndarray,
          keep_moves: np.ndarray) -> tuple[Program, ModuleColumns]:
    """``(program, columns)`` with the table rows not kept (``keep_targets`` (n,) and
    ``keep_moves`` (k,) bool) made into objects of the program, merged in text order, and
    the kept rows left in the tables: :func:`with_objects` of the result is that of the
    input."""
    if keep_targets.all() and keep_moves.all():
        return program, columns
    text, file = program.text, program.file
    targets = [columns.targets.target(i, text, file) for i in np.flatnonzero(~keep_targets)]
    motions = [columns.moves.use(i, file) for i in np.flatnonzero(~keep_moves)]
    program = dataclasses.replace(
        program,
        targets=_merged(program.targets, targets, lambda t: t.span[0]),
        motions=_merged(program.motions, motions, lambda u: u.target_span or u.statement_span))
    return program, ModuleColumns(columns.targets.subset(keep_targets),
                                  columns.moves.subset(keep_moves))


def _merged(objects: tuple, rows: list, key) -> tuple:
    """``objects`` and ``rows`` (each in order of ``key``) as one tuple in that order."""
    if not rows:
        return objects
    if not objects:
        return tuple(rows)
    return tuple(heapq.merge(objects, rows, key=key))
