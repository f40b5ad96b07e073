"""The one splice emitter: edits on the original text, numbers written "like" the original.

Only the characters of changed numbers are replaced; every other byte (comments, spacing,
case, line endings, untouched numbers) stays. A new number keeps the original's style
(plain decimal or exponent, exponent letter case and sign, a leading ``+``, a missing
leading zero) with at least ``MM_DECIMALS`` decimals for millimetres, ``QUAT_DECIMALS`` for
quaternion components and ``DEG_DECIMALS`` for degrees (about 1 micrometre and 1
microradian), or more when the original had more.
"""

from __future__ import annotations

import math
from itertools import chain, compress, repeat
import operator
import re
from collections import Counter
from collections.abc import Iterable, Mapping

import numpy as np

from ..kinematics.conventions import euler_zyz_from_matrix, matrix_from_euler_zyz
from ..errors import DataError
from .grammar import no_gc
from .targets import (QUAT_WXYZ, CartesianTarget, Edit, JointTarget, MotionUse, Program,
                      ToolData)

MM_DECIMALS = 3
QUAT_DECIMALS = 6
DEG_DECIMALS = 4


def splice(text: str, edits: Iterable[Edit]) -> str:
    """``text`` with every edit applied. Edits may come in any order but must not overlap
    (two insertions at one offset keep their given order); raises DataError otherwise."""
    edits = list(edits)
    if not edits:
        return text
    if any(a[0] > b[0] for a, b in zip(edits, edits[1:])):
        edits.sort(key=_edit_start)  # stable: insertions at one offset keep their order
    parts = []
    pos = 0
    n = len(text)
    for e in edits:
        start, end, rep = e
        if start < pos:
            raise DataError(f"overlapping edits at offsets {start}..{end} (previous edit "
                            f"ends at {pos})")
        if end < start or end > n:
            raise DataError(f"edit {start}..{end} outside the text (length {n})")
        parts.append(text[pos:start])
        parts.append(rep)
        pos = end
    parts.append(text[pos:])
    return "".join(parts)


def _edit_start(e: Edit) -> int:
    return e[0]


# ---- numbers --------------------------------------------------------------------------

def format_like(original: str, value: float, decimals: int) -> str:
    """``value`` written in the style of ``original`` with at least ``decimals`` decimals
    (plain style) or resolution 10**-decimals (exponent style)."""
    value = float(value)
    if not math.isfinite(value):
        raise DataError(f"cannot write {value} into a program (replacing {original!r})")
    return _format(original, value, decimals)


def _format(original: str, value: float, decimals: int) -> str:
    """format_like for a finite float (the hot path)."""
    if "e" in original or "E" in original:
        return _format_exp(original, value, decimals)
    dot = original.find(".")
    d = len(original) - dot - 1 if dot >= 0 else 0
    s = "%.*f" % (d if d > decimals else decimals, value)
    if s[0] == "-" and not s.strip("-0."):
        s = s[1:]  # no "-0.000"
    c = original[0]
    if c == "+":
        if s[0] != "-":
            s = "+" + s
        c = original[1:2]
    elif c == "-":
        c = original[1:2]
    if c == "." and "0." in s[:3]:
        s = s.replace("0.", ".", 1)  # the original wrote ".5", not "0.5"
    return s


def _format_exp(original: str, value: float, decimals: int) -> str:
    mant_o, _, exp_o = original.replace("E", "e").partition("e")
    letter = "E" if "E" in original else "e"
    dot = mant_o.find(".")
    d0 = len(mant_o) - dot - 1 if dot >= 0 else 0
    k = math.floor(math.log10(abs(value))) if value != 0 else 0
    d = max(d0, decimals + k, 0)
    mant, _, ex = ("%.*e" % (d, value)).partition("e")
    exn = int(ex)
    if mant[0] == "-" and not mant.strip("-0."):
        mant = mant[1:]
    digits = exp_o.lstrip("+-")
    sign = "-" if exn < 0 else ("+" if exp_o[:1] == "+" else "")
    if original[:1] == "+" and mant[0] != "-":
        mant = "+" + mant
    return f"{mant}{letter}{sign}{str(abs(exn)).zfill(len(digits))}"


def format_int_like(original: str, value: int) -> str:
    """An integer (confdata) in the style of ``original`` (keeps a leading ``+``)."""
    s = str(int(value))
    return "+" + s if original[:1] == "+" and value >= 0 else s


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
            out.append(_edit((s, s + len(t), format_like(t, v, decimals))))
        k += 1


_edit = Edit._make


def _floats(name: str, values) -> list[float]:
    """``values`` as a list of finite floats, or DataError naming ``name``."""
    try:
        vals = [float(v) for v in (values.tolist() if hasattr(values, "tolist")
                                   else values)]
    except (TypeError, ValueError):
        raise DataError(f"{name}: expected numbers, got {values!r}") from None
    if not all(map(math.isfinite, vals)):
        raise DataError(f"{name}: values must be finite, got {vals}")
    return vals


def _check(name: str, values, count: int) -> list[float]:
    """``values`` as a list of ``count`` finite floats, or DataError naming ``name``."""
    vals = _floats(name, values)
    if len(vals) != count:
        raise DataError(f"{name}: expected {count} values, got {len(vals)}")
    return vals


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
            out.append(_edit((start, start + len(t), format_like(t, v, QUAT_DECIMALS))))


def aligned_quaternion(quat_wxyz, reference_wxyz) -> list[float]:
    """Unit quaternion ``quat_wxyz`` with the sign (q or -q) nearest ``reference_wxyz``."""
    q = _check("orientation", quat_wxyz, 4)
    norm = math.sqrt(sum(c * c for c in q))
    if norm < 1e-12:
        raise DataError("orientation: a zero quaternion is no rotation")
    dot = sum(a * float(b) for a, b in zip(q, reference_wxyz))
    scale = (-1.0 if dot < 0 else 1.0) / norm
    return [c * scale for c in q]


def nearest_euler_zyz_deg(rotation, reference_deg) -> np.ndarray:
    """V+ (yaw, pitch, roll) in degrees for ``rotation`` (3, 3), choosing among the
    equivalent triples (the two Z-Y-Z branches, multiples of 360) the one nearest
    ``reference_deg``, so an unchanged orientation keeps its numbers."""
    ref = np.asarray(reference_deg, dtype=float)
    yaw, pitch, roll = np.rad2deg(euler_zyz_from_matrix(np.asarray(rotation, dtype=float)))
    best = None
    for cand in (np.array([yaw, pitch, roll]), np.array([yaw + 180.0, -pitch, roll + 180.0])):
        cand = ref + (cand - ref + 180.0) % 360.0 - 180.0
        if abs(cand[1]) < 1e-9 or abs(abs(cand[1]) - 180.0) < 1e-9:
            # gimbal lock: only yaw + roll (pitch 0) or yaw - roll (pitch 180) is defined
            total = cand[0] + cand[2] if abs(cand[1]) < 90 else cand[0] - cand[2]
            sgn = 1.0 if abs(cand[1]) < 90 else -1.0
            r0 = ref[2] + ((total - ref[0] - sgn * ref[2]) / 2.0)
            cand = np.array([total - sgn * r0, cand[1], r0])
        err = np.abs(cand - ref).sum()
        if best is None or err < best[0]:
            best = (err, cand)
    out = best[1]
    check = matrix_from_euler_zyz(*np.deg2rad(out))
    if not np.allclose(check, rotation, atol=1e-9):
        raise DataError("orientation: could not express the rotation as Z-Y-Z angles")
    return out


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
        _span_edits(texts, starts, 0, _check("position_mm", position_mm, 3), MM_DECIMALS, out)
    if orientation is not None:
        if target.orientation_kind == QUAT_WXYZ:
            _quaternion_edits(texts, starts, 3, orientation, out)
        else:
            _span_edits(texts, starts, 3, _check("orientation", orientation, 3),
                        DEG_DECIMALS, out)
    if config is not None:
        if not target.config:
            raise DataError(f"{target.display_name}: this dialect has no confdata")
        c = _check("config", config, 4)
        if any(v != round(v) for v in c):
            raise DataError(f"config: expected integers, got {c}")
        _number_edits(target.config, [int(v) for v in c], 0, out, integer=True)
    if external is not None:
        if not target.external:
            raise DataError(f"{target.display_name}: this dialect has no external axes")
        _number_edits(target.external, _check("external", external, 6), DEG_DECIMALS, out)
    return out


class _FastRun:
    """The common case of :func:`edits_for_targets` in one ``%`` format per target: every
    column changes, the columns are consecutive numbers, and each is written plainly
    (``-12.5``: no exponent, sign ``+`` or bare ``.5``) with no more decimals than the new
    value gets. Then the new text is the old span with each number replaced by
    ``%.{decimals}f``; the separators between the numbers (commas, brackets, spaces) come
    from the text and the template is cached per separator tuple.

    A separator may hold no digit, point or sign: then the numbers the pattern finds in a
    target's span are exactly the parser's (each is a maximal run of those characters),
    and anything else (a comment with a number in it) takes the general path.

    The regex engine takes about a microsecond per span, so the spans that share one set of
    separators are checked all at once by :class:`_PlainSpans` instead."""

    SAMPLE = 16    # plain spans matched one by one to choose the separators checked at once

    def __init__(self, cols: list[int], decimals: list[int], text: str):
        self.ok = cols == list(range(cols[0], cols[0] + len(cols)))
        self.cols, self.decimals, self.text = cols, decimals, text
        self.first, self.last = cols[0], cols[-1]
        # possessive: a number takes its whole digit run, as the parser's does (the
        # backtracking form spent 170 us failing each exponent-style span, 1.5E0)
        plain = [r"-?\d++(?:\.\d{0,%d})?+" % d for d in decimals]
        self.pattern = re.compile("(" + ")([^-+.0-9]*+)(".join(plain) + ")")
        self.templates: dict[tuple[str, ...], str] = {}

    def zero_small(self, new: np.ndarray) -> list[list[float]]:
        """``new`` (k, columns) as rows of floats, values that round to zero written as 0 so
        no ``-0.000`` appears (the general path strips the sign the same way)."""
        tol = 0.5 * 10.0 ** -np.array(self.decimals, float)
        return np.where(np.abs(new) < tol, 0.0, new).tolist()

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
        """The template of each span ``text[begin:end]``, None where it is not of the plain
        form. The first spans are matched one by one up to ``SAMPLE`` plain ones; the
        spans after them are checked for the separators most of those have (most of a
        module's spans share them) all at once by :class:`_PlainSpans`, and only those it
        rejects are matched one by one."""
        text, fullmatch = self.text, self.pattern.fullmatch
        templates: list[str | None] = [None] * len(begins)
        sampled: Counter[tuple[str, ...]] = Counter()
        for j, match in enumerate(map(fullmatch, repeat(text), begins, ends)):
            if match is not None:
                separators = match.groups()[1::2]
                templates[j] = self.template(separators)
                sampled[separators] += 1
                if sampled.total() == self.SAMPLE:
                    break
        else:
            return templates
        separators = sampled.most_common(1)[0][0]
        after = j + 1
        left_to_regex = range(after, len(begins))
        if left_to_regex and _PlainSpans.applies(separators):
            accepted = _PlainSpans(separators, self.decimals).accepts(
                _char_codes(text), begins[after:], ends[after:])
            template = self.template(separators)
            templates[after:] = [template if ok else None for ok in accepted.tolist()]
            left_to_regex = (after + np.flatnonzero(~accepted)).tolist()
        for j in left_to_regex:
            match = fullmatch(text, begins[j], ends[j])
            if match is not None:
                templates[j] = self.template(match.groups()[1::2])
        return templates

    def edits(self, targets, new: np.ndarray, whole: np.ndarray
              ) -> tuple[list[int], list[Edit]]:
        """The edits writing ``new[i]`` (n, columns) into ``targets[i]`` where ``whole[i]``
        (every column changes) and the target's span is of the plain form, and those
        indices ``i``."""
        first, last = self.first, self.last
        rows, begins, ends = [], [], []
        for i in np.flatnonzero(whole).tolist():
            texts = targets[i].texts
            if len(texts) > last:
                starts = targets[i].starts
                rows.append(i)
                begins.append(starts[first])
                ends.append(starts[last] + len(texts[last]))
        templates = self.span_templates(begins, ends)
        plain = [template is not None for template in templates]
        replacements = map(operator.mod, compress(templates, plain),
                           map(tuple, compress(self.zero_small(new[rows]), plain)))
        edits = list(map(tuple.__new__, repeat(Edit),
                         zip(compress(begins, plain), compress(ends, plain), replacements)))
        return list(compress(rows, plain)), edits


class _PlainSpans:
    r"""An automaton accepting exactly the spans ``n0 s0 n1 s1 ... nk`` with the given
    separators ``s`` and each number ``n`` plain (``-?\d+(?:\.\d{0,d})?``, d its column's
    decimals), run over many spans at once: one numpy table look-up per character
    position for all spans, where the regex engine takes about a microsecond per span.

    The separators must be non-empty ASCII without digit, point or sign: a number then
    ends exactly where a separator begins, so a span is accepted exactly when the
    pattern of :class:`_FastRun` fullmatches it with these separators."""

    LONGEST_SPAN = 1000        # longer spans (a comment inside) are left to the regex

    @staticmethod
    def applies(separators: tuple[str, ...]) -> bool:
        """Whether the automaton can be built for these separators."""
        return all(separators) and all(map(str.isascii, separators))

    def __init__(self, separators: tuple[str, ...], decimals: list[int]):
        # a row per state, a column per character code (every non-ASCII one rejects);
        # state 0 is rejected for good
        table = [[0] * 256]

        def new_state() -> int:
            table.append([0] * 256)
            return len(table) - 1

        last = len(decimals) - 1
        next_start = final = None
        for k in range(last, -1, -1):       # each number leads to the next one's start
            start, minus, integer = new_state(), new_state(), new_state()
            fraction = [new_state() for _ in range(decimals[k] + 1)]  # i decimals read
            table[start][ord("-")] = minus
            table[integer][ord(".")] = fraction[0]
            for digit in b"0123456789":
                table[start][digit] = table[minus][digit] = table[integer][digit] = integer
                for i in range(decimals[k]):
                    table[fraction[i]][digit] = fraction[i + 1]
            number_ends = [integer] + fraction
            if k == last:
                final = number_ends
            else:
                entry = next_start
                for char in reversed(separators[k][1:]):
                    state = new_state()
                    table[state][ord(char)] = entry
                    entry = state
                for state in number_ends:
                    table[state][ord(separators[k][0])] = entry
            next_start = start
        # a state is held as its row's offset in the flat table: one add and one take a step
        self.start = next_start * 256
        self.next = (np.array(table, np.intp) * 256).ravel()
        self.final = np.zeros(len(table), bool)
        self.final[final] = True

    def accepts(self, codes: np.ndarray, begins: list[int], ends: list[int]) -> np.ndarray:
        """Whether each span ``codes[begin:end]`` (codes from :func:`_char_codes`) is
        accepted."""
        begins = np.asarray(begins, np.intp)
        lengths = np.asarray(ends, np.intp) - begins
        lengths[lengths > self.LONGEST_SPAN] = 0      # an empty span is never accepted
        # shortest first, so the spans still running at a position form a suffix ("stable"
        # is a radix sort for 16-bit keys)
        order = np.argsort(lengths.astype(np.uint16), kind="stable")
        begins, lengths = begins[order], lengths[order]
        state = np.full(len(order), self.start, np.intp)
        running_from = np.searchsorted(lengths, np.arange(lengths[-1]), side="right")
        for position, lo in enumerate(running_from.tolist()):
            running = state[lo:]
            running += codes.take(begins[lo:] + position)
            self.next.take(running, out=running)
        accepted = np.empty(len(order), bool)
        accepted[order] = self.final[state // 256]
        return accepted


def _char_codes(text: str) -> np.ndarray:
    """One byte per character of ``text``: its code, 255 for a code above that (the
    automaton rejects every code from 128 alike)."""
    try:
        return np.frombuffer(text.encode("latin-1"), np.uint8)
    except UnicodeEncodeError:
        wide = np.frombuffer(text.encode("utf-32-le", "surrogatepass"), np.uint32)
        return np.minimum(wide, 255).astype(np.uint8)


def edits_for_targets(program: Program, position_mm=None, orientation=None, config=None,
                      targets=None, written=None) -> list[Edit]:
    """:func:`target_edits` for many targets at once (vectorized): one edit per changed
    target, spanning its first to its last changed number with the original text between
    them kept, in target order (text order for ``program.targets``).

    targets : default ``program.targets``, all of one dialect.
    position_mm : (n, 3) mm; orientation : (n, 4) quaternions (RAPID) or (n, 3) degrees
    (V+); config : (n, 4) integers; each None to leave that part as written.
    written : (n, >= 7 or 6) the targets' leading numbers as written, when the caller has
    converted them already (:func:`~olp_compensate.programs.semantics.written_values`).
    """
    targets = program.targets if targets is None else targets
    text = program.text
    n = len(targets)
    if n == 0:
        return []
    kinds = {t.orientation_kind for t in targets}
    if len(kinds) != 1:
        raise DataError("targets: expected targets of one dialect")
    quat = kinds.pop() == QUAT_WXYZ
    width = 3 + (4 if quat else 3)
    parts = []  # (first number index, new values (n, k), decimals)
    with no_gc():
        if written is None:
            old = np.fromiter(map(float, chain.from_iterable(t.texts[:width]
                                                             for t in targets)),
                              float, n * width).reshape(n, width)
        else:
            old = np.asarray(written, dtype=float)[:, :width]
            if old.shape != (n, width):
                raise DataError(f"written: expected shape ({n}, >= {width}), got "
                                f"{np.shape(written)}")
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
        if parts:
            new = np.concatenate([p[1] for p in parts], axis=1)
            cols = [lo + j for lo, v, _ in parts for j in range(v.shape[1])]
            tol = np.concatenate([np.full(v.shape[1], 0.5 * 10.0 ** -d) for _, v, d in parts])
            decimals = [d for _, v, d in parts for _ in range(v.shape[1])]
            reference = old[:, cols]
            if quat and orientation is not None:
                # compare with the written quaternion normalized (an unnormalized one that
                # describes the same rotation is left alone); a changed unnormalized
                # quaternion is rewritten whole, never mixed with its old scale
                q_cols = [c for c, col in enumerate(cols) if 3 <= col < 7]
                old_quat = old[:, 3:7]
                w_norm = np.linalg.norm(old_quat, axis=1, keepdims=True)
                reference[:, q_cols] = old_quat / np.where(w_norm > 0, w_norm, 1.0)
                mask = np.abs(new - reference) >= tol
                scaled = np.abs(w_norm[:, 0] - 1.0) > 1e-6
                rewrite = scaled & np.any(mask[:, q_cols], axis=1)
                mask[np.ix_(rewrite, q_cols)] = True
            else:
                mask = np.abs(new - reference) >= tol
        slots: list[Edit | None] = [None] * n   # each target's edit of its numbers
        if parts:
            fast = _FastRun(cols, decimals, text)
            if fast.ok:
                rows, edits = fast.edits(targets, new, mask.all(axis=1))
                for i, edit in zip(rows, edits):
                    slots[i] = edit
            fmt = _format
            # the changed targets the fast path left: number by number
            for i in np.flatnonzero(mask.any(axis=1)).tolist():
                if slots[i] is not None:
                    continue
                texts, starts = targets[i].texts, targets[i].starts
                pieces = []
                first = last = -1
                for j, hit in enumerate(mask[i].tolist()):
                    if hit:
                        k = cols[j]
                        t0 = texts[k]
                        s0 = starts[k]
                        if first < 0:
                            first = s0
                        else:
                            pieces.append(text[last:s0])
                        pieces.append(fmt(t0, float(new[i, j]), decimals[j]))
                        last = s0 + len(t0)
                slots[i] = _edit((first, last, "".join(pieces)))
        if config is None:
            out = [edit for edit in slots if edit is not None]
        else:
            out = []
            for i, (t, edit) in enumerate(zip(targets, slots)):
                if edit is not None:
                    out.append(edit)
                out += target_edits(t, config=config[i])
    return out


def _batch(name: str, values, n: int, k: int) -> np.ndarray:
    a = np.asarray(values, dtype=float)
    if a.shape != (n, k):
        raise DataError(f"{name}: expected shape ({n}, {k}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise DataError(f"{name}: values must be finite")
    return a


def joint_target_edits(target: JointTarget, joints_deg, external=None) -> list[Edit]:
    """Edits giving a jointtarget / precision point new joint values (degrees)."""
    out: list[Edit] = []
    _number_edits(target.joints, _check("joints_deg", joints_deg, len(target.joints)),
                  DEG_DECIMALS, out)
    if external is not None:
        _number_edits(target.external, _check("external", external, len(target.external)),
                      DEG_DECIMALS, out)
    return out


def tool_edits(tool: ToolData, position_mm=None, quat_wxyz=None) -> list[Edit]:
    """Edits giving a tooldata a new TCP (tframe): position mm, quaternion (w, x, y, z)."""
    if not tool.defined:
        raise DataError(f"tool {tool.name}: no literal value in this file to rewrite")
    out: list[Edit] = []
    if position_mm is not None:
        _number_edits(tool.position, _check("position_mm", position_mm, 3), MM_DECIMALS, out)
    if quat_wxyz is not None:
        numbers = tool.orientation
        _quaternion_edits([n.text for n in numbers], [n.start for n in numbers], 0,
                          quat_wxyz, out)
    return out


# ---- --emit joints --------------------------------------------------------------------

_JOINT_MOVES = {"movel": "MoveAbsJ", "movej": "MoveAbsJ"}


def _like_case(word: str, original: str) -> str:
    if original.isupper():
        return word.upper()
    if original.islower():
        return word.lower()
    return word


def joint_emit_edits(program: Program,
                     joints: Mapping[CartesianTarget, Iterable[float]]) -> list[Edit]:
    """Edits turning Cartesian targets into joint targets (``--emit joints``).

    RAPID: ``CONST robtarget p10 := [...]`` becomes ``CONST jointtarget p10 :=
    [[j1,...,j6],[eax_a,...]]`` (external axes copied as written), and every MoveL/MoveJ
    using it (or using a converted inline target) becomes MoveAbsJ. An array declaration
    is converted only whole. V+: a transformation ``name x y z y p r`` becomes the
    precision point ``#name j1 ... jn`` and its motion references become ``#name``;
    ``SET name = TRANS(...)`` becomes ``SET #name = #PPOINT(...)``.
    Raises DataError, naming the target and the place, when a use cannot take a joint
    target (MoveC, Offs(), a field assignment, a procedure argument...).

    joints : target -> robot joint values in degrees.
    """
    if program.dialect == "vplus":
        return _vplus_joint_edits(program, joints)
    text = program.text
    wanted = {id(t): (t, np.asarray(_check(f"joints of {t.display_name}", q, 6)))
              for t, q in joints.items()}
    out: list[Edit] = []
    by_decl: dict = {}
    for t in program.targets:
        if t.storage != "inline":
            by_decl.setdefault(t.type_span, []).append(t)
    names = set()
    for type_span, members in by_decl.items():
        chosen = [m for m in members if id(m) in wanted]
        if not chosen:
            continue
        if len(chosen) != len(members):
            missing = [m.display_name for m in members if id(m) not in wanted]
            raise DataError(f"{members[0].location}: array {members[0].name} must be "
                            f"converted whole (missing {', '.join(missing[:5])})")
        word = text[type_span[0]:type_span[1]]
        out.append(Edit(type_span[0], type_span[1], _like_case("jointtarget", word)))
        for m in members:
            out.append(_rapid_joint_literal(text, m, wanted[id(m)][1]))
        names.add((members[0].name.lower(), members[0].routine))
    _check_other_uses(program, names)
    converted_inline = {id(t) for t, _ in wanted.values() if t.storage == "inline"}
    done_instr = set()
    for use in program.motions:
        hit = (use.inline is not None and id(use.inline) in converted_inline) or (
            use.target_name is not None and _resolves(program, use, names))
        if not hit:
            continue
        new = _JOINT_MOVES.get(use.instruction.lower())
        if new is None:
            raise DataError(f"{use.location}: {use.instruction} needs a robtarget; cannot "
                            f"emit joints for {use.target_name or 'its inline target'}")
        stmt = text[use.statement_span[0]:use.statement_span[1]]
        if "\\corr" in stmt.lower():
            raise DataError(f"{use.location}: MoveAbsJ has no \\Corr argument")
        if use.inline is not None:
            out.append(_rapid_joint_literal(text, use.inline, wanted[id(use.inline)][1]))
        if use.instruction_span not in done_instr:
            done_instr.add(use.instruction_span)
            out.append(Edit(*use.instruction_span, _like_case(new, use.instruction)))
    return out


def _resolves(program: Program, use: MotionUse, names: set) -> bool:
    key = use.target_name.lower()
    if (key, use.routine) in names:
        return True
    if (key, None) in names:
        # a routine-local declaration of the same name would shadow the module one
        return not any(t.name and t.name.lower() == key and t.routine == use.routine
                       for t in program.targets if use.routine is not None)
    return False


def _check_other_uses(program: Program, names: set) -> None:
    plain = {n for n, _ in names}
    for r in program.runtime:
        if r.base_name and r.base_name.lower() in plain:
            raise DataError(f"{r.location}: {r.base_name} is used in {r.expression!r}, "
                            f"which needs a robtarget; cannot emit joints for it")
    for r in program.references:
        if r.name.lower() in plain:
            raise DataError(f"{r.location}: {r.name} is passed to {r.context}, which may "
                            f"need a robtarget; cannot emit joints for it")


def _rapid_joint_literal(text: str, t: CartesianTarget, q: np.ndarray) -> Edit:
    if q.shape != (6,):
        raise DataError(f"{t.display_name}: expected 6 joint values, got {q.size}")
    ext = t.external
    a = text.rfind("[", 0, ext[0].start)
    b = text.find("]", ext[-1].end) + 1
    js = ",".join(format_like("0", v, DEG_DECIMALS) for v in q)
    return Edit(t.span[0], t.span[1], f"[[{js}],{text[a:b]}]")


def _vplus_joint_edits(program: Program, joints) -> list[Edit]:
    text = program.text
    out: list[Edit] = []
    existing = {j.name.lower() for j in program.joint_targets if j.name}
    chosen = {id(t) for t in joints}
    for t in joints:
        rest = [o.display_name for o in program.targets if o.name and t.name
                and o.name.lower() == t.name.lower() and id(o) not in chosen]
        if rest:
            raise DataError(f"{t.location}: {t.name} must be converted whole (missing "
                            f"{', '.join(rest[:5])})")
    converted = set()
    for t, q in joints.items():
        q = _floats(f"joints of {t.display_name}", q)
        if t.name is None or t.type_span is None:
            raise DataError(f"{t.location}: only named V+ transformations can become "
                            f"precision points")
        pp = "#" + t.name
        if pp.lower() in existing:
            raise DataError(f"{t.location}: precision point {pp} already exists")
        out.append(Edit(t.type_span[0], t.type_span[1], pp))
        js = [format_like("0", v, DEG_DECIMALS) for v in q]
        if text[t.span[0]:t.span[0] + 5].upper() == "TRANS":
            func = _like_case("#PPOINT", text[t.span[0]:t.span[0] + 5])
            out.append(Edit(t.span[0], t.span[1], f"{func}({','.join(js)})"))
        else:
            out.append(Edit(t.span[0], t.span[1], " ".join(js)))
        converted.add(t.name.lower())
    for use in program.motions:
        if use.target_name and use.target_name.lower() in converted:
            if use.wobj is not None:
                raise DataError(f"{use.location}: {use.wobj}:{use.target_name} is relative "
                                f"to a frame; a precision point cannot be")
            off = use.target_span[0]
            out.append(Edit(off, off, "#"))
    for r in program.runtime:
        if r.base_name and r.base_name.lower() in converted:
            raise DataError(f"{r.location}: {r.base_name} is used in {r.expression!r}; "
                            f"cannot make it a precision point")
    return out
