"""Every robtarget literal of every RAPID golden program is accounted for in the report of
olp-fix: compensated, or listed with its place and a reason.

The literals are found here by a scanner of our own (a regular expression for the
``[[x,y,z],[q1,q2,q3,q4],[c1,c4,c6,cx],[e1..e6]]`` shape, comments and strings removed
first), not by the parser. A literal that is the whole value of a scalar declaration is
reported at the declared name; any other (array elements, inline, assigned, inside
records or expressions) at its ``[``.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.errors import ParseError
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import load
from olp_compensate.programs.object_model.task import compensate_program

FOLDER = Path(__file__).parent / "programs"
CASES = sorted(FOLDER.glob("rapid_*/input.*")) + [FOLDER.parent.parent / "samples" / "cell_a.mod"]
_NUM = r"\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*"
_GROUP = lambda n: r"\[" + ",".join([_NUM] * n) + r"\]"  # noqa: E731
LITERAL = re.compile(r"\[\s*" + r"\s*,\s*".join(_GROUP(n) for n in (3, 4, 4, 6)) + r"\s*\]")
DECLARED = re.compile(r"(?:CONST|PERS|VAR)\s+[A-Za-z_]\w*\s+([A-Za-z_]\w*)\s*:=\s*$", re.I)


def blank_comments_and_strings(text: str) -> str:
    """``text`` with every comment and string replaced by spaces (offsets kept)."""
    out = []
    for line in text.split("\n"):
        chars, quoted = list(line), False
        for k, c in enumerate(line):
            if c == '"':
                quoted = not quoted
                chars[k] = " "
            elif quoted:
                chars[k] = " "
            elif c == "!":
                chars[k:] = " " * (len(line) - k)
                break
        out.append("".join(chars))
    return "\n".join(out)


def literal_places(text: str) -> list[tuple[int, int]]:
    """(line, column) where each robtarget literal is to be reported."""
    clean = blank_comments_and_strings(text)
    places = []
    for m in LITERAL.finditer(clean):
        at = m.start()
        declared = DECLARED.search(clean, max(at - 200, 0), at)
        if declared is not None:
            at = declared.start(1)
        line = clean.count("\n", 0, at) + 1
        places.append((line, at - clean.rfind("\n", 0, at)))
    return places


def test_the_scanner_finds_literals_and_skips_comments():
    text = ('  CONST robtarget p1 := [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n'
            '  ! MoveL [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]\n'
            '  MoveL [[1,2,3],[1,0,0,0],[0,0,0,0],[9,9,9,9,9,9]], v1, fine, tool0;\n')
    assert literal_places(text) == [(1, 19), (3, 9)]


@pytest.mark.parametrize("path", CASES, ids=[p.parent.name if p.stem == "input" else p.name for p in CASES])
def test_every_robtarget_literal_is_accounted_for(path):
    text = path.read_bytes().decode("latin-1")
    try:
        program = load(path)
    except ParseError:
        assert path.parent.name.startswith("rapid_error_")
        return
    _, report = compensate_program(program, None,
                                   nominal_calibration(load_robot("abb_irb2400")))
    reported = {(r.line, r.column) for r in report.rows}
    missing = [p for p in literal_places(text) if p not in reported]
    assert not missing, f"literals not in the report: {missing}"
