"""Every robtarget literal of a RAPID module accounted for.

After the builder has taken what it understands (declared, inline and assigned targets,
literals handed to unknown instructions), the module text is searched for robtarget
literals of the common shape ``[[x,y,z],[q1..q4],[cf1,cf4,cf6,cfx],[eax_a..eax_f]]``
(outside comments and strings) that none of those is: inside the value of a user RECORD,
inside ``Offs(...)`` or another expression, handed to a routine of the module. Each
becomes a :class:`~.targets.TargetProblem` with its place and the reason it is left as
written, so no literal is silently skipped.

The search runs only when the module holds more ``[[`` openings than the literals already
read account for (counted without a scan), so a large generated module costs nothing.
"""

from __future__ import annotations

import bisect
import re

from ..literals import ROBTARGET_RE
from ..targets import RuntimeTarget, TargetProblem

_OPENING = re.compile(r"\[(?=[ \t\r\n\f]*\[)")
_EXCERPT = 50
_NESTED = 8   # run-time expressions that may hold one literal


def expected_openings(targets, joints, tools, wobjs) -> int:
    """How many ``[[`` the literals already read hold (a wobjdata holds two)."""
    return (len(targets) + len(joints) + sum(1 for t in tools if t.span is not None)
            + 2 * sum(1 for w in wobjs if w.span is not None))


def unaccounted_literals(text: str, file: str, builder) -> list[TargetProblem]:
    """Problems for the robtarget literals of ``text`` that ``builder`` (a
    :class:`~.rapid_build.Builder` after its records are read) did not account for."""
    columns = builder.sink.columns   # a column parse: the plain declarations' table
    table = columns.targets if columns is not None else ()
    expected = expected_openings(builder.targets, builder.joints, builder.tools,
                                 builder.wobjs) + len(table)
    if text.count("[[") <= expected:
        return []
    known = {t.span[0] for t in builder.targets}
    if table:
        known.update(table.spans[0::2])
    known.update(p_offset for p_offset in _problem_offsets(builder))
    runtime = sorted((r for r in builder.runtime if r.span is not None),
                     key=lambda r: r.span[0])
    out = []
    for m in _OPENING.finditer(text):
        pos = m.start()
        if pos in known or ROBTARGET_RE.match(text, pos) is None or _in_comment(text, pos):
            continue
        status, reason = _why(text, pos, builder.record_values, runtime)
        out.append(TargetProblem(target="<inline>", location=builder.loc(pos), status=status,
                                 reason=reason))
    return out


def _problem_offsets(builder) -> list[int]:
    """Offsets of the literals the builder already reported as problems."""
    index = builder.index
    starts = index.starts
    return [starts[p.location.line - 1] + p.location.column - 1 for p in builder.problems]


def _why(text: str, pos: int, record_values, runtime: list[RuntimeTarget]
         ) -> tuple[str, str]:
    """(status, reason) of a literal the builder did not take as a target."""
    for start, end, what in record_values:
        if start <= pos < end:
            return "unresolved", (f"{what}: record fields are not followed to the motions "
                                  f"that use them; left as written")
    k = bisect.bisect_right([r.span[0] for r in runtime], pos)
    for r in reversed(runtime[max(k - _NESTED, 0):k]):   # the expressions around it
        if r.span[0] <= pos < r.span[1]:
            return "runtime", f"inside {_short(r.expression)}: {r.reason}; left as written"
    line_start = text.rfind("\n", 0, pos) + 1
    statement = text[line_start:pos + 1].strip()
    return "unresolved", (f"not moved to by a motion this version follows "
                          f"({_short(statement)}...); left as written")


def _short(text: str) -> str:
    text = " ".join(text.split())
    return text if len(text) <= _EXCERPT else text[:_EXCERPT] + "..."


def _in_comment(text: str, pos: int) -> bool:
    """Whether ``pos`` is inside a ``!`` comment or a string of its line."""
    line_start = text.rfind("\n", 0, pos) + 1
    quoted = False
    for c in text[line_start:pos]:
        if c == '"':
            quoted = not quoted
        elif c == "!" and not quoted:
            return True
    return quoted
