"""The whole-statement fast paths (FAST_DECLS, FAST_CALLS) and the ordinary grammar rules
must build the same records: the same module is parsed once as written (one-line
statements: fast) and once with a comment and a line break inside every statement (which
the fast paths refuse), and the results are compared."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from olp_compensate.programs import loads, rapid_fast

ROOT = Path(__file__).resolve().parents[1]


def _defeat_fast_paths(text: str) -> str:
    out = []
    for line in text.split("\n"):
        if re.match(r"\s*(LOCAL\s+|TASK\s+)?(CONST|PERS|VAR)\s.*:=", line):
            line = line.replace(":=", ":= ! slow\n     ", 1)
        elif re.match(r"\s*\w+[ \\].*,.*;", line) and not re.match(
                r"\s*(IF|FOR|WHILE|TEST|CASE|ELSEIF)\b", line):
            line = line.replace(",", ", ! slow\n     ", 1)
        out.append(line)
    return "\n".join(out)


def _norm(expression: str | None) -> str | None:
    return None if expression is None else re.sub(r"!\s*slow|\s+", "", expression)


def _view(program):
    return dict(
        targets=[(t.name, t.array_index, t.texts, t.storage, t.routine) for t in
                 program.targets],
        joints=[(t.name, t.array_index, t.texts) for t in program.joint_targets],
        tools=[(t.name, tuple(n.text for n in t.position)) for t in program.tools],
        wobjs=[(w.name, w.ufprog) for w in program.wobjs],
        motions=[(m.instruction, m.role, m.target_name, m.target_index, m.tool, m.wobj,
                  m.joint, m.routine, m.inline.texts if m.inline else None,
                  _norm(m.runtime.expression) if m.runtime else None)
                 for m in program.motions],
        runtime=[(_norm(r.expression), r.base_name) for r in program.runtime],
        references=[(r.name, r.context) for r in program.references])


SOURCES = [ROOT / "samples" / "cell_a.mod"] + sorted(
    (ROOT / "tests" / "programs").glob("rapid_[!e]*/input.mod"))


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: p.parent.name + "/" + p.name)
def test_fast_and_grammar_paths_agree(path: Path, monkeypatch):
    text = path.read_bytes().decode("latin-1").replace("\r\n", "\n")
    used = {"decls": 0, "calls": 0}
    real_d, real_c = rapid_fast._split_fast_decls, rapid_fast._split_fast_calls

    def spy_d(*args):
        used["decls"] += 1
        real_d(*args)

    def spy_c(*args):
        used["calls"] += 1
        real_c(*args)

    monkeypatch.setattr(rapid_fast, "_split_fast_decls", spy_d)
    monkeypatch.setattr(rapid_fast, "_split_fast_calls", spy_c)
    fast = loads(text, "rapid")
    fast_used = dict(used)
    slow_text = _defeat_fast_paths(text)
    used.update(decls=0, calls=0)
    slow = loads(slow_text, "rapid")
    assert fast_used["decls"] + fast_used["calls"] > 0
    assert used["decls"] < fast_used["decls"] or fast_used["decls"] == 0
    assert _view(fast) == _view(slow)


def test_motion_call_the_fast_regexes_cannot_read_is_reparsed_by_the_grammar():
    # an inline tooldata (depth 3) inside a one-line MoveL: split regex fails, grammar reads
    text = ("MODULE M\n  PROC main()\n    MoveL [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,"
            "9E9,9E9]], v100, fine, [TRUE,[[0,0,1],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]]"
            "\\WObj:=w1;\n  ENDPROC\nENDMODULE\n")
    (m,) = loads(text, "rapid").motions
    assert m.inline.texts[:3] == ("1", "2", "3")
    assert m.tool_inline.position[2].text == "1" and m.wobj == "w1"
