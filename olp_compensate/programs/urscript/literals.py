"""URScript pose literals that are not motion targets, each reported with what it is, and
the checks that refuse a damaged script (see :mod:`.reader`).

Every ``p[...]`` of a script gets a report row: the targets :mod:`.reader` reads, and
here the others, by the call they are an argument of (UR Script Manual, e-Series):
``set_tcp`` (a tool), ``force_mode`` (its task frame), ``calculate_point_to_move_towards``
(a Polyscope Direction node's feature pose: the point moved to is computed at run time),
``pose_trans``/``pose_add``/``pose_sub``/``interpolate_pose`` operands (a pose computed at
run time), a function's default argument; a literal built from variables is computed at run
time. Named relative waypoints (``Waypoint_1_from_p``/``_to_p``) that a motion moves by
through ``pose_sub`` are run-time uses of those names.
"""

from __future__ import annotations

import re

from ...errors import ParseError
from ..pose_dialects import PoseProgram, line_column

_P_OPEN = re.compile(r"(?<![\w.])p[ \t]*\[")
_P_SIMPLE = re.compile(r"(?<![\w.])p[ \t]*\[([^\[\]()\r\n]*)\]")
"""A pose literal on one line without brackets inside (nearly every one)."""
_CALL_NAME = re.compile(r"(?<![\w.])([A-Za-z_]\w*)[ \t]*\($")
_DEF = re.compile(r"^[ \t]*def[ \t]+([A-Za-z_]\w*)[ \t]*\(", re.M)
"""A function definition: its parameters' default values are run-time targets."""
_OPENER = re.compile(r"^[ \t]*(def|thread|if|while|for)\b[^\r\n]*:[ \t]*\r?$", re.M)
_CLOSER = re.compile(r"^[ \t]*end\b", re.M)
_POSE_SUB = re.compile(r"\bpose_sub[ \t]*\([ \t]*([A-Za-z_]\w*)[ \t]*,[ \t]*([A-Za-z_]\w*)"
                       r"[ \t]*\)")
_ELEMENT_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_LOOKS_NUMERIC = re.compile(r"[-+]?[\d.]")
_NON_FINITE = re.compile(r"[-+]?(?:nan|inf|infinity)", re.I)

RUNTIME_CALLS = ("calculate_point_to_move_towards", "pose_trans", "pose_add", "pose_sub",
                 "interpolate_pose", "pose_inv", "pose_dist")


def _close(clean: str, open_at: int) -> int:
    depth = 0
    for k in range(open_at, len(clean)):
        if clean[k] in "([":
            depth += 1
        elif clean[k] in ")]":
            depth -= 1
            if depth == 0:
                return k + 1
    return -1


def _enclosing_call(clean: str, at: int) -> tuple[str | None, int]:
    """(name of the call whose argument list holds offset ``at``, its offset) or (None, -1)."""
    depth = 0
    k = at - 1
    stop = max(0, at - 4000)         # a call's arguments are near: no walk to the file start
    while k >= stop:
        c = clean[k]
        if c in ")]":
            depth += 1
        elif c in "([":
            if depth == 0:
                if c == "(":
                    m = _CALL_NAME.search(clean, max(0, k - 200), k + 1)
                    return (m.group(1), m.start(1)) if m else (None, -1)
            else:
                depth -= 1
        k -= 1
    return None, -1


def check_elements(text: str, clean: str, file: str, starts: list[int]) -> None:
    """Refuse a pose literal element that starts like a number but is not one (``2E+``,
    ``1.2.3``) or is ``nan``/``inf``, at its place."""
    for m in _P_SIMPLE.finditer(clean):
        k = m.start(1)
        for part in m.group(1).split(","):
            token = part.strip()
            at = k + len(part) - len(part.lstrip())
            k += len(part) + 1
            if _ELEMENT_NUMBER.fullmatch(token):
                continue
            bad = (_NON_FINITE.fullmatch(token) or
                   (_LOOKS_NUMERIC.match(token) and re.fullmatch(r"[-+\w.]+", token)))
            if bad:
                raise ParseError(f"malformed number {token!r} in a pose literal", file,
                                 *line_column(text, at, starts))


def check_blocks(text: str, clean: str, file: str, starts: list[int]) -> None:
    """Refuse a script whose blocks (``def``, ``thread``, ``if``, ``while``, ``for``) are
    not all closed by ``end``: a file cut short."""
    events = sorted([(m.start(1), m) for m in _OPENER.finditer(clean)] +
                    [(m.start(), None) for m in _CLOSER.finditer(clean)], key=lambda e: e[0])
    open_blocks: list[re.Match] = []
    for _, opener in events:
        if opener is not None:
            open_blocks.append(opener)
        elif open_blocks:
            open_blocks.pop()
    if open_blocks:
        first = open_blocks[0]
        line = line_column(text, first.start(1), starts)[0]
        end = len(text.rstrip())
        raise ParseError(f"{len(open_blocks)} block(s) never closed by 'end' (the outermost, "
                         f"'{first.group(1)}' at line {line}): the script is cut short",
                         file, *line_column(text, end, starts))


_ASSIGNED = re.compile(r"(?:^|[\r\n])[ \t]*(?:global[ \t]+|local[ \t]+)?([A-Za-z_]\w*)[ \t]*="
                       r"[ \t]*$")


def other_literals(text: str, clean: str, file: str, starts: list[int],
                   program: PoseProgram, tcp_names=frozenset(), runtime_names=None) -> None:
    """A row (``program.kept``) for each ``p[...]`` that is not one of the targets read.
    ``tcp_names``: names given to ``set_tcp``; ``runtime_names``: name -> why its value is
    known only at run time (assigned several times...)."""
    runtime_names = runtime_names or {}
    covered = {n.start for t in program.targets for n in t.numbers}
    defaults = {m.start(1): m.group(1) for m in _DEF.finditer(clean)}
    for m in _P_OPEN.finditer(clean):
        simple = _P_SIMPLE.match(clean, m.start())
        end = simple.end() if simple is not None else _close(clean, m.end() - 1)
        if end < 0:
            continue
        first = m.end() + len(clean[m.end():end]) - len(clean[m.end():end].lstrip())
        if first in covered or (simple is None and any(k in covered
                                                       for k in range(m.end(), end))):
            continue
        call, call_at = _enclosing_call(clean, m.start())
        status, what = _what(clean, m.start(), end, call, call_at, defaults)
        assigned = _ASSIGNED.search(clean, max(0, m.start() - 200), m.start())
        if call is None and assigned is not None and status == "frame":
            name = assigned.group(1)
            if name in runtime_names:
                status, what = "runtime", f"a value of {name}: {runtime_names[name]}"
            elif name not in tcp_names:
                status, what = "unused", f"assigned to {name}, which no motion moves to; " \
                                         f"kept as written"
        at = m.start()
        if assigned is not None and call is None:      # the value of a name: at its number
            at = next((k for k in range(m.end(), end) if not clean[k].isspace()), at)
        where = (file, *line_column(text, at, starts))
        program.kept.append((where, clean[m.start():end] if end - m.start() <= 60 else
                             clean[m.start():m.start() + 57] + "...", status, what))


def _what(clean, start, end, call, call_at, defaults) -> tuple[str, str]:
    values = [v.strip() for v in clean[clean.index("[", start) + 1:end - 1].split(",")]
    if len(values) != 6 or not all(_ELEMENT_NUMBER.fullmatch(v) for v in values):
        return "runtime", "a pose built from values known only at run time; kept as written"
    if call == "set_tcp":
        return "frame", "a TCP (set_tcp): the tool of the motions after it, not a target; " \
                        "kept as written"
    if call == "force_mode":
        return "frame", "the task frame of force_mode, not a target; kept as written"
    if call in ("movej", "movel", "movep", "movec"):
        return "unknown_instruction", f"in a {call}() whose arguments could not be read; " \
                                      f"kept as written"
    if call == "calculate_point_to_move_towards":
        return "runtime", ("the feature pose of a Polyscope Direction node: the point moved "
                           "to is computed from it at run time; kept as written")
    if call in RUNTIME_CALLS:
        return "runtime", f"an operand of {call}(): the pose moved to is computed at run time; " \
                          f"kept as written"
    if call is not None and call_at in defaults:
        return "runtime", f"a default argument of {defaults[call_at]}(): the pose moved to " \
                          f"is the argument given at run time; kept as written"
    if call is not None:
        return "unused", f"an argument of {call}(), not a motion target; kept as written"
    return "frame", "a TCP (assigned, then given to set_tcp): not a target; kept as written"


def relative_waypoints(clean: str, text: str, starts: list[int], program: PoseProgram) -> None:
    """Names moved by through ``pose_sub(to, from)`` (Polyscope relative waypoints): a
    run-time use each (the motion moves by their difference from where the robot is)."""
    for m in _POSE_SUB.finditer(clean):
        line = line_column(text, m.start(), starts)[0]
        for name in (m.group(1), m.group(2)):
            program.runtime_uses.setdefault(
                name, f"pose_sub({m.group(1)}, {m.group(2)}) at line {line}: the motion moves "
                      f"by the difference of two poses from where the robot is, at run time "
                      f"(a relative waypoint); kept as written")
