"""Edits for many Cartesian targets at once (vectorized): the emitter's hot path.

Each changed target gets ONE edit spanning its first to its last changed number, the
original text between them kept. The common case (every number of a target's position and
orientation changes, each written plainly) is one ``%`` format per target
(:class:`_PlainRun`); the rest is written number by number in the original's style.
"""

from __future__ import annotations

import operator
import re
from itertools import chain, compress, repeat
from typing import NamedTuple

import numpy as np

from ..errors import DataError
from .emit import target_edits
from .number_format import (DEG_DECIMALS, MM_DECIMALS, QUAT_DECIMALS, fixed_rows,
                            format_finite)
from .regex_compat import portable
from .targets import QUAT_WXYZ, Edit, Program


class _NewValues(NamedTuple):
    """What changes: ``new`` (n, columns) values of the target numbers ``cols`` (indices
    into a target's numbers), each written with ``decimals``; ``changed`` (n, columns)
    where the value differs from the written one at that resolution."""

    new: np.ndarray
    cols: list[int]
    decimals: list[int]
    changed: np.ndarray


def edits_for_targets(program: Program, position_mm=None, orientation=None, config=None,
                      targets=None, written=None) -> list[Edit]:
    """:func:`~.emit.target_edits` for many targets at once (vectorized): one edit per
    changed target, spanning its first to its last changed number with the original text
    between them kept, in target order (text order for ``program.targets``).

    targets : default ``program.targets``, all of one dialect.
    position_mm : (n, 3) mm; orientation : (n, 4) quaternions (RAPID) or (n, 3) degrees
    (V+); config : (n, 4) integers; each None to leave that part as written.
    written : (n, >= 7 or 6) the targets' leading numbers as written, when the caller has
    converted them already (:func:`~olp_compensate.programs.semantics.written_values`).
    """
    targets = program.targets if targets is None else targets
    n = len(targets)
    if n == 0:
        return []
    kinds = {t.orientation_kind for t in targets}
    if len(kinds) != 1:
        raise DataError("targets: expected targets of one dialect")
    quat = kinds.pop() == QUAT_WXYZ
    old = _written(targets, written, 3 + (4 if quat else 3))
    values = _new_values(old, position_mm, orientation, quat)
    slots: list[Edit | None] = [None] * n   # each target's edit of its numbers
    if values is not None:
        _fill_edits(program.text, targets, values, slots)
    if config is None:
        return [edit for edit in slots if edit is not None]
    out = []
    for i, (t, edit) in enumerate(zip(targets, slots)):
        if edit is not None:
            out.append(edit)
        out += target_edits(t, config=config[i])
    return out


def _written(targets, written, width: int) -> np.ndarray:
    """(n, width) the targets' leading numbers as written."""
    n = len(targets)
    if written is None:
        return np.fromiter(map(float, chain.from_iterable(t.texts[:width] for t in targets)),
                           float, n * width).reshape(n, width)
    old = np.asarray(written, dtype=float)[:, :width]
    if old.shape != (n, width):
        raise DataError(f"written: expected shape ({n}, >= {width}), got "
                        f"{np.shape(written)}")
    return old


def _new_values(old: np.ndarray, position_mm, orientation, quat: bool) -> _NewValues | None:
    """The new position and orientation numbers and where they change; None when neither
    is given. Quaternions are normalized and sign-aligned with the written ones."""
    n = len(old)
    parts = []  # (first number index, new values (n, k), decimals)
    if position_mm is not None:
        parts.append((0, _batch("position_mm", position_mm, n, 3), MM_DECIMALS))
    if orientation is not None:
        o = _batch("orientation", orientation, n, 4 if quat else 3)
        if quat:
            norm = np.linalg.norm(o, axis=1, keepdims=True)
            if np.any(norm < 1e-12):
                raise DataError("orientation: a zero quaternion is no rotation")
            o = o / norm
            o *= np.where(np.sum(o * old[:, 3:7], axis=1, keepdims=True) < 0, -1.0, 1.0)
        parts.append((3, o, QUAT_DECIMALS if quat else DEG_DECIMALS))
    if not parts:
        return None
    new = np.concatenate([p[1] for p in parts], axis=1)
    cols = [lo + j for lo, v, _ in parts for j in range(v.shape[1])]
    tol = np.concatenate([np.full(v.shape[1], 0.5 * 10.0 ** -d) for _, v, d in parts])
    decimals = [d for _, v, d in parts for _ in range(v.shape[1])]
    reference = old[:, cols]
    if not (quat and orientation is not None):
        return _NewValues(new=new, cols=cols, decimals=decimals,
                          changed=np.abs(new - reference) >= tol)
    # compare with the written quaternion normalized (an unnormalized one that describes
    # the same rotation is left alone); a changed unnormalized quaternion is rewritten
    # whole, never mixed with its old scale
    q_cols = [c for c, col in enumerate(cols) if 3 <= col < 7]
    old_quat = old[:, 3:7]
    w_norm = np.linalg.norm(old_quat, axis=1, keepdims=True)
    reference[:, q_cols] = old_quat / np.where(w_norm > 0, w_norm, 1.0)
    changed = np.abs(new - reference) >= tol
    scaled = np.abs(w_norm[:, 0] - 1.0) > 1e-6
    rewrite = scaled & np.any(changed[:, q_cols], axis=1)
    changed[np.ix_(rewrite, q_cols)] = True
    return _NewValues(new=new, cols=cols, decimals=decimals, changed=changed)


def edits_for_spans(text: str, old: np.ndarray, position_mm: np.ndarray,
                    orientation: np.ndarray, begins: np.ndarray, ends: np.ndarray,
                    targets) -> list[Edit]:
    """:func:`edits_for_targets` of RAPID robtargets held as columns: ``old`` (n, >= 7)
    their numbers as written, ``begins``/``ends`` (n,) where each one's x starts and its
    q4 ends; ``targets[i]`` (a sequence that may make each on access) is read only for
    the targets not written by the one-format path. Edits in target order."""
    n = len(old)
    if n == 0:
        return []
    values = _new_values(np.asarray(old, float)[:, :7], position_mm, orientation, True)
    slots: list[Edit | None] = [None] * n
    _fill_edits(text, targets, values, slots, (np.asarray(begins), np.asarray(ends)))
    return [edit for edit in slots if edit is not None]


def _fill_edits(text: str, targets, values: _NewValues, slots: list, bounds=None) -> None:
    """Put each changed target's edit in ``slots``: the plain-run path first, then
    number by number for the targets it left. ``bounds``: (begins, ends) of every
    target's numbers x to q4, when the caller has them (else read from the targets)."""
    cols, decimals, new = values.cols, values.decimals, values.new
    run = _PlainRun(cols, decimals, text)
    if run.ok:
        whole = values.changed.all(axis=1)
        if bounds is not None and cols == list(range(7)):
            rows = np.flatnonzero(whole)
            found = (rows.tolist(), bounds[0][rows].tolist(), bounds[1][rows].tolist())
        else:
            found = run.bounds(targets, whole)
        rows, edits = run.edits(*found, new)
        for i, edit in zip(rows, edits):
            slots[i] = edit
    for i in np.flatnonzero(values.changed.any(axis=1)).tolist():
        if slots[i] is not None:
            continue
        texts, starts = targets[i].texts, targets[i].starts
        pieces = []
        first = last = -1
        for j, hit in enumerate(values.changed[i].tolist()):
            if hit:
                k = cols[j]
                old_text, start = texts[k], starts[k]
                if first < 0:
                    first = start
                else:
                    pieces.append(text[last:start])
                pieces.append(format_finite(old_text, float(new[i, j]), decimals[j]))
                last = start + len(old_text)
        slots[i] = Edit(first, last, "".join(pieces))


class _PlainRun:
    """The common case of :func:`edits_for_targets` in one ``%`` format per target: every
    column changes, the columns are consecutive numbers, and each is written plainly
    (``-12.5``: no exponent, sign ``+`` or bare ``.5``) with no more decimals than the new
    value gets. Then the new text is the old span with each number replaced by
    ``%.{decimals}f``; the separators between the numbers (commas, brackets, spaces) come
    from the text and the template is cached per separator tuple.

    A separator may hold no digit, point or sign: then the numbers the pattern finds in a
    target's span are exactly the parser's (each is a maximal run of those characters),
    and anything else (a comment with a number in it) takes the general path."""

    def __init__(self, cols: list[int], decimals: list[int], text: str):
        self.ok = cols == list(range(cols[0], cols[0] + len(cols)))
        self.cols, self.decimals, self.text = cols, decimals, text
        self.first, self.last = cols[0], cols[-1]
        # possessive: a number takes its whole digit run, as the parser's does (the
        # backtracking form spent 170 us failing each exponent-style span, 1.5E0)
        plain = [portable(r"-?\d++(?:\.\d{0,%d})?+" % d) for d in decimals]   # .regex_compat
        self.pattern = re.compile("(" + ")([^-+.0-9]*+)(".join(plain) + ")")
        # the same form for spans joined by NUL (a separator holds none): one findall over
        # them finds each plain span whole, giving its separators only
        self.joined = re.compile(r"(?<=\0)(?:" + ")([^-+.0-9\0]*+)(?:".join(plain)
                                 + r")(?=\0)")
        self.templates: dict[tuple[str, ...], str] = {}

    def zero_small(self, new: np.ndarray) -> np.ndarray:
        """``new`` (k, columns) with the values that round to zero made 0, so no ``-0.000``
        appears (the general path strips the sign the same way)."""
        tol = 0.5 * 10.0 ** -np.array(self.decimals, float)
        return np.where(np.abs(new) < tol, 0.0, new)

    def template(self, separators: tuple[str, ...]) -> str:
        """The ``%`` template of the columns with these separators between them."""
        template = self.templates.get(separators)
        if template is None:
            pieces = ["%%.%df" % self.decimals[0]]
            for sep, d in zip(separators, self.decimals[1:]):
                pieces += [sep.replace("%", "%%"), "%%.%df" % d]
            template = self.templates[separators] = "".join(pieces)
        return template

    def span_templates(self, begins: list[int], ends: list[int]) -> list[str | None]:
        """The template of each span ``text[begin:end]``, None where it is not of the
        plain form."""
        templates: list[str | None] = []
        for match in map(self.pattern.fullmatch, repeat(self.text), begins, ends):
            templates.append(None if match is None else self.template(match.groups()[1::2]))
        return templates

    def bounds(self, targets, whole: np.ndarray) -> tuple[list[int], list[int], list[int]]:
        """(rows, begins, ends): the targets ``i`` where ``whole[i]`` (every column
        changes) and that have the columns, with where their first column starts and
        their last ends."""
        first, last = self.first, self.last
        rows, begins, ends = [], [], []
        for i in np.flatnonzero(whole).tolist():
            texts = targets[i].texts
            if len(texts) > last:
                starts = targets[i].starts
                rows.append(i)
                begins.append(starts[first])
                ends.append(starts[last] + len(texts[last]))
        return rows, begins, ends

    def edits(self, rows: list[int], begins: list[int], ends: list[int], new: np.ndarray
              ) -> tuple[list[int], list[Edit]]:
        """The edits writing ``new[i]`` (n, columns) over ``text[begin:end]`` for each of
        ``rows`` whose span is of the plain form, and those rows. Where every span is
        (the common case), their separators are read by one regex pass over the spans
        joined, and the new texts written by one ``%`` format per distinct template."""
        if rows:
            found = self.all_plain(begins, ends)
            if found is not None:
                return rows, list(map(Edit, begins, ends, self.written(found, new[rows])))
        templates = self.span_templates(begins, ends)
        plain = [template is not None for template in templates]
        replacements = map(operator.mod, compress(templates, plain),
                           map(tuple, compress(self.zero_small(new[rows]).tolist(), plain)))
        edits = [Edit(start=start, end=end, replacement=replacement)
                 for start, end, replacement in zip(compress(begins, plain),
                                                    compress(ends, plain), replacements)]
        return list(compress(rows, plain)), edits

    def all_plain(self, begins: list[int], ends: list[int]) -> list[tuple] | None:
        """The separators of each span ``text[begin:end]`` when every span is of the plain
        form (one findall over the spans joined by NUL: a match starts after a NUL and
        ends before one, so it is one whole span), else None."""
        spans = list(map(self.text.__getitem__, map(slice, begins, ends)))
        joined = "\0".join(spans)
        if joined.count("\0") != len(spans) - 1:
            return None   # a NUL inside a span
        found = self.joined.findall("\0" + joined + "\0")
        if len(found) != len(spans):
            return None
        if len(self.cols) > 2:   # findall gives a tuple of the groups where there are two
            return found
        return [(sep,) for sep in found] if len(self.cols) == 2 else [()] * len(found)

    def written(self, separators: list[tuple], new: np.ndarray) -> list[str]:
        """The new text of each span: ``new`` (n, columns) written with the template of
        its ``separators``; spans of one template in one ``%`` format."""
        values = self.zero_small(new)
        kinds = set(separators)
        if len(kinds) == 1:   # (a template holds no NUL: the separators hold none)
            return self.written_alike(kinds.pop(), values)
        template_of = self.template
        return list(map(operator.mod, map(template_of, separators),
                        map(tuple, values.tolist())))

    def written_alike(self, separators: tuple[str, ...], values: np.ndarray) -> list[str]:
        """The new texts of spans that all have these ``separators``: each run of columns
        with one number of decimals and ``,`` between them written by :func:`fixed_rows`
        (array operations), the runs put together by one ``%`` format."""
        runs, template, start = [], [], 0
        for k in range(1, len(self.decimals) + 1):
            if (k == len(self.decimals) or separators[k - 1] != ","
                    or self.decimals[k] != self.decimals[start]):
                runs.append(fixed_rows(values[:, start:k], self.decimals[start]))
                template += ["%s", separators[k - 1].replace("%", "%%")] if k < len(
                    self.decimals) else ["%s"]
                start = k
        if len(runs) == 1:
            return runs[0]
        return ("\0".join(["".join(template)] * len(values))
                % tuple(chain.from_iterable(zip(*runs)))).split("\0")


def _batch(name: str, values, n: int, k: int) -> np.ndarray:
    a = np.asarray(values, dtype=float)
    if a.shape != (n, k):
        raise DataError(f"{name}: expected shape ({n}, {k}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise DataError(f"{name}: values must be finite")
    return a
