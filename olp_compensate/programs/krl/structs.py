"""KRL forms around the targets that :mod:`.reader` reads: user ``STRUC`` types whose fields
are frames (``STRUC CNCPOS FRAME fCnC, REAL grFeedrate``; a value ``{fCnC {X ..}, grFeedrate
2000}``, moved to as ``gsCNC1[1].fCnC``), and frame assignments with the geometric operator
(``TOOL_DATA[2] = TOOL_DATA[11] : {X 0, Y 0, Z 100, A 0, B 0, C 0}``).

The geometric operator (KSS 8 programming manual, "Geometric operator"): ``A1 : A2`` is the
frame ``A1`` composed with ``A2`` expressed in ``A1`` (``A1 * A2`` as 4x4 transforms), with
X, Y, Z in mm and A, B, C in degrees (``Rz(A) Ry(B) Rx(C)``).
"""

from __future__ import annotations

import re

import numpy as np

from ...kinematics.conventions import euler_zyx_from_matrix, matrix_from_euler_zyx
from ..brackets import closing

_STRUC = re.compile(r"^[ \t]*(?:GLOBAL[ \t]+)?(?:DECL[ \t]+)?(?:GLOBAL[ \t]+)?STRUC[ \t]+"
                    r"([A-Za-z_]\w*)[ \t]+([^\r\n]*)", re.I | re.M)
_FRAME_SET = re.compile(r"^[ \t]*(TOOL_DATA|BASE_DATA)[ \t]*\[[ \t]*(\d+)[ \t]*\][ \t]*=[ \t]*"
                        r"(TOOL_DATA|BASE_DATA)[ \t]*\[[ \t]*(\d+)[ \t]*\][ \t]*:[ \t]*\{",
                        re.I | re.M)
_FIELD_START = re.compile(r"([A-Za-z_]\w*)[ \t]*\{")


def struc_fields(clean: str) -> dict[str, dict[str, str]]:
    """``STRUC`` types of a comment-blanked text: type name -> {field: field type}, upper
    case (a field without a type takes the one before it: ``FRAME a, b``)."""
    out: dict[str, dict[str, str]] = {}
    for m in _STRUC.finditer(clean):
        fields: dict[str, str] = {}
        typ = ""
        for part in m.group(2).split(","):
            words = part.split()
            if len(words) >= 2:
                typ, name = words[0].upper(), words[1]
            elif len(words) == 1:
                name = words[0]
            else:
                continue
            fields[re.sub(r"\[.*", "", name).upper()] = typ
        out[m.group(1).upper()] = fields
    return out


def frame_fields(clean: str, lo: int, hi: int, fields: dict[str, str],
                 frame_types: set[str]) -> list[tuple[str, int, int]]:
    """(field name as written, '{' offset, '}' end) of the fields of a STRUC value
    ``clean[lo:hi]`` (its outer braces included) whose type is in ``frame_types``."""
    out = []
    depth = 0
    k = lo
    while k < hi:
        c = clean[k]
        if c == "{":
            depth += 1
        elif c == "}":
            depth -= 1
        elif depth == 1:
            m = _FIELD_START.match(clean, k)
            if m is not None and fields.get(m.group(1).upper()) in frame_types:
                start = m.end() - 1
                end = _close(clean, start, hi)
                out.append((m.group(1), start, end))
                k = end
                continue
        k += 1
    return out


def closing_brace(text: str, start: int, hi: int) -> int | None:
    """Offset just past the ``}`` closing the aggregate whose ``{`` is at ``start``,
    searched before ``hi``; None when it is not closed there."""
    return closing(text, start, hi, "{}")


def _close(text: str, start: int, hi: int) -> int:
    end = closing_brace(text, start, hi)
    return hi if end is None else end


def frame_pose(values) -> np.ndarray:
    """(4, 4) pose, mm, of a KRL frame (X, Y, Z mm, A, B, C deg)."""
    T = np.eye(4)
    T[:3, :3] = matrix_from_euler_zyx(*np.radians(np.asarray(values[3:6], dtype=float)))
    T[:3, 3] = np.asarray(values[:3], dtype=float)
    return T


def frame_values(T: np.ndarray) -> tuple[float, ...]:
    """(X, Y, Z mm, A, B, C deg) of a (4, 4) pose in mm."""
    return tuple(T[:3, 3].tolist()) + tuple(np.degrees(euler_zyx_from_matrix(T[:3, :3])).tolist())


def frame_assignments(clean: str, read_fields, frames: dict, notes: list[str],
                      where) -> None:
    """``TOOL_DATA[i] = TOOL_DATA[j] : {...}`` (or BASE_DATA) in ``clean``: ``frames[i]``
    becomes ``frames[j] : {...}`` where both are known; else it is dropped (set at run time
    from what the files do not hold), with a note. ``read_fields(lo, hi)``: the six values
    of the aggregate at ``clean[lo:hi]`` or None; ``where(offset)``: "file:line"."""
    for m in _FRAME_SET.finditer(clean):
        key = f"{m.group(1).upper()}[{int(m.group(2))}]"
        source = f"{m.group(3).upper()}[{int(m.group(4))}]"
        lo = m.end() - 1
        hi = _close(clean, lo, len(clean))
        values = read_fields(lo, hi)
        if source in frames and values is not None:
            frames[key] = frame_values(frame_pose(frames[source]) @ frame_pose(values))
            notes.append(f"{where(m.start(1))}: {key} = {source} : {{...}} composed (geometric "
                         f"operator) from the files' {source}")
        else:
            frames.pop(key, None)
            notes.append(f"{where(m.start(1))}: {key} = {source} : {{...}}: {source} is not in "
                         f"the files given, so {key} is known only at run time")


def is_frame_literal(clean: str, lo: int) -> bool:
    """Whether the aggregate at ``lo`` holds X or A1 directly (a pose or axis literal)."""
    return re.match(r"\{[ \t]*(?:[A-Za-z_]\w*[ \t]*:[ \t]*)?(?:X|A1)[ \t]+[-+.\d]",
                    clean[lo:lo + 40], re.I) is not None
