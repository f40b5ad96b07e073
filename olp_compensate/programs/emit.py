"""The one splice emitter: edits on the original text, numbers written "like" the original.

Only the characters of changed numbers are replaced; every other byte (comments, spacing,
case, line endings, untouched numbers) stays. How a new number is written is
:mod:`.number_format`; many targets at once is :mod:`.emit_batch`; turning Cartesian
targets into joint targets (``--emit joints``) is :mod:`.emit_joints`. This module holds
the splice and the edits of one target, tool or joint target.
"""

from __future__ import annotations

import heapq
import itertools
import math
import operator
from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from ..errors import DataError
from .number_format import (DEG_DECIMALS, MM_DECIMALS, QUAT_DECIMALS, aligned_quaternion,
                            check_values, format_int_like, format_like, nearest_euler_zyz_deg)
from .targets import QUAT_WXYZ, CartesianTarget, Edit, JointTarget, ToolData

__all__ = ["splice", "splice_in_order", "SplicedText", "EditColumns", "EditsInTurn",
           "target_edits", "tool_edits", "joint_target_edits", "format_like", "format_int_like",
           "aligned_quaternion", "nearest_euler_zyz_deg", "MM_DECIMALS", "QUAT_DECIMALS",
           "DEG_DECIMALS"]


def splice(text: str, edits: Iterable[Edit]) -> str:
    """``text`` with every edit applied. Edits may come in any order but must not overlap
    (two insertions at one offset keep their given order); raises DataError otherwise."""
    edits = list(edits)
    if not edits:
        return text
    if any(a[0] > b[0] for a, b in zip(edits, edits[1:])):
        edits.sort(key=_edit_start)  # stable: insertions at one offset keep their order
    return splice_in_order(text, edits)


def splice_in_order(text: str, edits: Iterable[Edit]) -> str:
    """:func:`splice` of edits given in offset order (any iterable of (start, end,
    replacement), read once: a generator over columns of edits holds none of them)."""
    parts = list(_spliced_pieces(text, edits))
    return text if len(parts) == 1 else "".join(parts)


class EditColumns:
    """Edits held as columns, in offset order: ``starts`` and ``ends`` (character offsets)
    and ``replacements``; iterating gives (start, end, replacement) each time anew."""

    __slots__ = ("starts", "ends", "replacements")

    def __init__(self, starts: Sequence[int], ends: Sequence[int],
                 replacements: Sequence[str]):
        self.starts, self.ends, self.replacements = starts, ends, replacements

    def __len__(self) -> int:
        return len(self.starts)

    def __iter__(self) -> Iterator[tuple[int, int, str]]:
        return zip(self.starts, self.ends, self.replacements)


class EditsInTurn:
    """Runs of edits that follow one another in the text (each run ending before the next
    starts), read as one run without copying them; iterable again."""

    __slots__ = ("runs",)

    def __init__(self, runs: Sequence[Iterable[Edit]]):
        self.runs = tuple(runs)

    def __len__(self) -> int:
        return sum(map(len, self.runs))

    def __iter__(self) -> Iterator[Edit]:
        return itertools.chain.from_iterable(self.runs)


class SplicedText:
    """``text`` with edits, spliced when read: :meth:`blocks` gives the new text's bytes a
    block at a time (a big module is written without its new text ever held whole),
    :meth:`encode` all of them. ``runs``: sequences of edits, each in offset order and
    iterable again, merged by offset (at one offset, the earlier run's edit first)."""

    __slots__ = ("text", "runs")

    def __init__(self, text: str, runs: Sequence[Iterable[Edit]] = ()):
        self.text, self.runs = text, tuple(runs)

    def edits(self) -> Iterator[Edit]:
        """All edits in offset order."""
        if len(self.runs) == 1:
            return iter(self.runs[0])
        return heapq.merge(*self.runs, key=_edit_start)

    def __len__(self) -> int:
        """The number of edits."""
        return sum(len(run) for run in self.runs)

    def spliced(self) -> str:
        """The new text."""
        return splice_in_order(self.text, self.edits())

    def blocks(self, encoding: str, block: int = 1 << 20) -> Iterator[bytes]:
        """The new text's bytes in ``encoding``, about ``block`` characters at a time (at
        least ``block`` in each but the last). Edits held in columns are merged, checked
        and spliced as columns, a group of :data:`GROUP` edits per join."""
        columns = _columns_of(self.runs)
        if columns is not None and _in_bounds(*columns[:2], len(self.text)):
            yield from _joined_blocks(self.text, *columns, encoding, block)
            return
        parts, size = [], 0
        for piece in _spliced_pieces(self.text, self.edits()):
            parts.append(piece)
            size += len(piece)
            if size >= block:
                yield "".join(parts).encode(encoding)
                parts, size = [], 0
        if parts:
            yield "".join(parts).encode(encoding)

    def encode(self, encoding: str) -> bytes:
        """The new text's bytes in ``encoding``."""
        return b"".join(self.blocks(encoding))


GROUP = 4096
"""Edits spliced per join by :meth:`SplicedText.blocks` (the new text is never held whole)."""


def _columns_of(runs: Sequence) -> tuple[np.ndarray, np.ndarray, list[str]] | None:
    """(starts, ends, replacements) of all edits of ``runs`` in the order
    :meth:`SplicedText.edits` gives (by offset, the earlier run first at one offset), or
    None where a run is neither a list or tuple of edits, :class:`EditColumns` nor
    :class:`EditsInTurn` of those, or is not in offset order (left to the merge)."""
    starts, ends, replacements = [], [], []
    for run in runs:
        pieces = run.runs if type(run) is EditsInTurn else (run,)
        for piece in pieces:
            if type(piece) is EditColumns:
                starts.append(np.asarray(piece.starts, np.int64))
                ends.append(np.asarray(piece.ends, np.int64))
                replacements += piece.replacements
            elif type(piece) in (list, tuple):
                a, b, texts = zip(*piece) if piece else ((), (), ())
                starts.append(np.array(a, np.int64))
                ends.append(np.array(b, np.int64))
                replacements += texts
            else:
                return None
        if len(pieces) > 1 or len(runs) > 1:
            joined = np.concatenate(starts[-len(pieces):])
            if np.any(joined[1:] < joined[:-1]):
                return None
    if not starts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), []
    start, end = np.concatenate(starts), np.concatenate(ends)
    if len(runs) > 1 and len(start) > 1:
        order = np.argsort(start, kind="stable")
        start, end = start[order], end[order]
        replacements = list(operator.itemgetter(*order.tolist())(replacements))
    return start, end, replacements


def _in_bounds(start: np.ndarray, end: np.ndarray, n: int) -> bool:
    """Whether edits (in offset order) neither overlap nor leave a text of length ``n``."""
    if not len(start):
        return True
    return bool(np.all(start[1:] >= end[:-1]) and np.all(end >= start) and end.max() <= n)


def _joined_blocks(text: str, start: np.ndarray, end: np.ndarray, replacements: list[str],
                   encoding: str, block: int) -> Iterator[bytes]:
    """:meth:`SplicedText.blocks` of edits in order that neither overlap nor leave the
    text: the kept text before each edit and its replacement, :data:`GROUP` edits a
    join."""
    kept_from = np.concatenate([[0], end])
    parts, size, given = [], 0, False
    for a in range(0, len(start), GROUP):
        b = a + GROUP
        kept = map(text.__getitem__, map(slice, kept_from[a:b].tolist(), start[a:b].tolist()))
        piece = "".join(itertools.chain.from_iterable(zip(kept, replacements[a:b])))
        parts.append(piece)
        size += len(piece)
        if size >= block:
            yield "".join(parts).encode(encoding)
            parts, size, given = [], 0, True
    parts.append(text[int(kept_from[-1]):])
    if not given or any(parts):
        yield "".join(parts).encode(encoding)


def _spliced_pieces(text: str, edits: Iterable[Edit]) -> Iterator[str]:
    """The pieces of the spliced text in order: kept text, replacement, kept text, ...
    (``text`` alone without edits); raises DataError on overlapping or outside edits."""
    pos = 0
    n = len(text)
    for start, end, rep in edits:
        if start < pos:
            raise DataError(f"overlapping edits at offsets {start}..{end} (previous edit "
                            f"ends at {pos})")
        if end < start or end > n:
            raise DataError(f"edit {start}..{end} outside the text (length {n})")
        yield text[pos:start]
        yield rep
        pos = end
    yield text[pos:] if pos else text


def _edit_start(e: Edit) -> int:
    return e[0]


def _number_edits(numbers, new_values, decimals, out: list, integer=False) -> None:
    """Edits for the numbers whose value changes by half a unit of the last written
    decimal or more; the others keep their text."""
    tol = 0.5 * 10.0 ** -decimals
    for n, v in zip(numbers, new_values):
        if integer:
            if int(v) != float(n.text):
                out.append(Edit(n.start, n.end, format_int_like(n.text, v)))
        elif abs(v - float(n.text)) >= tol:
            out.append(Edit(n.start, n.end, format_like(n.text, v, decimals)))


def _span_edits(texts, starts, lo: int, new_values, decimals: int, out: list) -> None:
    """As _number_edits, straight from a target's compact storage (the hot path)."""
    tol = 0.5 * 10.0 ** -decimals
    k = lo
    for v in new_values:
        t = texts[k]
        if abs(v - float(t)) >= tol:
            s = starts[k]
            out.append(Edit(s, s + len(t), format_like(t, v, decimals)))
        k += 1




def _quaternion_edits(texts, starts, lo: int, quat_wxyz, out: list) -> None:
    """Edits for the four quaternion numbers ``texts[lo:lo + 4]``: none when ``quat_wxyz``
    is the written rotation (compared with the written quaternion normalized, so an
    unnormalized one survives), else the unit quaternion, sign-aligned; a written
    quaternion that is not unit length is then rewritten whole, never mixed with its old
    scale."""
    written = [float(t) for t in texts[lo:lo + 4]]
    norm = math.sqrt(sum(c * c for c in written)) or 1.0
    q = aligned_quaternion(quat_wxyz, written)
    tol = 0.5 * 10.0 ** -QUAT_DECIMALS
    changed = [abs(v - w / norm) >= tol for v, w in zip(q, written)]
    if not any(changed):
        return
    whole = abs(norm - 1.0) > 1e-6
    for k, (v, hit) in enumerate(zip(q, changed)):
        if hit or whole:
            t, start = texts[lo + k], starts[lo + k]
            out.append(Edit(start, start + len(t), format_like(t, v, QUAT_DECIMALS)))


# ---- edits for targets, tools ---------------------------------------------------------

def target_edits(target: CartesianTarget, position_mm=None, orientation=None, config=None,
                 external=None) -> list[Edit]:
    """Edits giving ``target`` new values; parts left None stay as written.

    position_mm : (3,) mm. orientation : quaternion (w, x, y, z) for RAPID (normalized and
    sign-aligned with the original here), or (yaw, pitch, roll) in degrees for V+.
    config : RAPID (cf1, cf4, cf6, cfx) integers. external : RAPID (6,) mm or degrees.
    Returns edits in text order, only for numbers whose value changes at the written
    resolution.
    """
    out: list[Edit] = []
    texts, starts = target.texts, target.starts
    if position_mm is not None:
        _span_edits(texts, starts, 0, check_values("position_mm", position_mm, 3), MM_DECIMALS, out)
    if orientation is not None:
        if target.orientation_kind == QUAT_WXYZ:
            _quaternion_edits(texts, starts, 3, orientation, out)
        else:
            _span_edits(texts, starts, 3, check_values("orientation", orientation, 3),
                        DEG_DECIMALS, out)
    if config is not None:
        if not target.config:
            raise DataError(f"{target.display_name}: this dialect has no confdata")
        c = check_values("config", config, 4)
        if any(v != round(v) for v in c):
            raise DataError(f"config: expected integers, got {c}")
        _number_edits(target.config, [int(v) for v in c], 0, out, integer=True)
    if external is not None:
        if not target.external:
            raise DataError(f"{target.display_name}: this dialect has no external axes")
        _number_edits(target.external, check_values("external", external, 6), DEG_DECIMALS, out)
    return out


def joint_target_edits(target: JointTarget, joints_deg, external=None) -> list[Edit]:
    """Edits giving a jointtarget / precision point new joint values (degrees)."""
    out: list[Edit] = []
    _number_edits(target.joints, check_values("joints_deg", joints_deg, len(target.joints)),
                  DEG_DECIMALS, out)
    if external is not None:
        _number_edits(target.external, check_values("external", external, len(target.external)),
                      DEG_DECIMALS, out)
    return out


def tool_edits(tool: ToolData, position_mm=None, quat_wxyz=None) -> list[Edit]:
    """Edits giving a tooldata a new TCP (tframe): position mm, quaternion (w, x, y, z)."""
    if not tool.defined:
        raise DataError(f"tool {tool.name}: no literal value in this file to rewrite")
    out: list[Edit] = []
    if position_mm is not None:
        _number_edits(tool.position, check_values("position_mm", position_mm, 3), MM_DECIMALS, out)
    if quat_wxyz is not None:
        numbers = tool.orientation
        _quaternion_edits([n.text for n in numbers], [n.start for n in numbers], 0,
                          quat_wxyz, out)
    return out
