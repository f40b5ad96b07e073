"""The whole-statement fast paths (FAST_DECLS, FAST_CALLS) and the ordinary grammar rules
must build the same records: the same module is parsed once as written (one-line
statements: fast) and once with a comment and a line break inside every statement (which
the fast paths refuse), and the results are compared; and the very same text is parsed
once more by the grammar alone (without the two run tokens), which must give the same
Program to the line, column and span, or the same error."""

from __future__ import annotations

import re
from pathlib import Path

import lark
import numpy as np
import pytest

from olp_compensate.errors import ParseError
from olp_compensate.programs import loads
from olp_compensate.programs.rapid import fast as rapid_fast
from olp_compensate.programs.rapid import reader as rapid
from olp_compensate.programs.grammar import grammar_text

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


# ---- the same text through the grammar alone --------------------------------------------
# Without its two run tokens (they can never match: check_text rejects NUL), the grammar
# reads every statement itself; the result must be the same Program, to the line, column
# and character span of every target, motion and record, and the same errors.

def _grammar_only_parser() -> lark.Lark:
    text = grammar_text("rapid.lark")
    slow, n = re.subn(r"^(FAST_DECLS|FAST_CALLS)\.2:.*$", r'\1: "\\x00\1"', text, flags=re.M)
    assert n == 2
    callbacks = rapid.Callbacks()
    return lark.Lark(slow, parser="lalr", lexer="contextual", transformer=callbacks,
                     maybe_placeholders=False, propagate_positions=False,
                     start=["start", "call"], lexer_callbacks=dict(callbacks.lexer_callbacks))


@pytest.fixture(scope="module")
def grammar_only():
    """parse(text, fast): a Program or the ParseError's (file, line, column, caret line),
    with the fast paths or through the grammar alone."""
    slow = _grammar_only_parser()

    def parse(text: str, fast: bool):
        real = rapid.parser
        if not fast:
            rapid.parser = lambda *args: slow
        try:
            return loads(text, "rapid", "prog.mod")
        except ParseError as err:
            return ("error", err.file, err.line, err.column, err.context)
        finally:
            rapid.parser = real

    return parse


def _varied_module(n: int, seed: int, newline: str) -> str:
    """A module mixing every fast-path form with statements they leave to the grammar."""
    rng = np.random.default_rng(seed)

    def num(k):
        forms = ["{:.2f}", "{:.6f}", "{:g}", "{:.1E}", "{:.0f}."]
        v = float(rng.normal(0, 500))
        return forms[k % len(forms)].format(v).replace("+0", "+") if k % 7 else str(int(v))

    def literal(k, spaced=False):
        sep = " , " if spaced else ","
        groups = [[num(k + i) for i in range(3)], ["0.5", "-0.5", ".5", "0.5"],
                  [str(int(rng.integers(-2, 3))) for _ in range(3)] + ["0"],
                  ["9E9", "9E+09", "9E9", "9E9", "9E9", "9E9"]]
        inner = sep.join("[" + sep.join(g) + "]" for g in groups)
        return f"[ {inner} ]" if spaced else f"[{inner}]"

    lines = ["%%%", "  VERSION:1", "%%%", "MODULE Varied(SYSMODULE)",
             "  PERS tooldata tGun:=[TRUE,[[120.5,0,210],[0.92388,0,0.382683,0]],"
             "[2.5,[0,0,80],[1,0,0,0],0,0,0]];",
             "  PERS wobjdata wTable:=[FALSE,TRUE,\"\",[[700,-300,300],[1,0,0,0]],"
             "[[0,0,0],[1,0,0,0]]];"]
    storages = ["CONST", "PERS", "VAR", "LOCAL CONST", "TASK PERS", "const", "Local Var"]
    for k in range(n):
        form = k % 9
        st = storages[k % len(storages)]
        if form == 0:
            lines.append(f"  {st} robtarget p{k} := {literal(k, spaced=True)};")
        elif form == 1:
            lines.append(f"\t{st} RobTarget p{k}:=\t{literal(k)} ; ! trailing comment")
        elif form == 2:
            lines.append(f"  {st} robtarget arr{k}{{2}}:=[{literal(k)},{literal(k + 1)}];")
        elif form == 3:
            lines.append(f"  {st} jointtarget j{k}:=[[0,-10.5,20,0,90,{k}],"
                         f"[9E9,9E9,9E9,9E9,9E9,9E9]];")
        elif form == 4:  # a line break inside the literal
            lines.append(f"  {st} robtarget p{k}:=[[1,2,{k}],[1,0,0,0],")
            lines.append("      [0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];")
        elif form == 5:
            lines.append(f"  {st} num n{k} := {k} + 1;")
        elif form == 6:
            lines.append("")
            lines.append(f"  ! comment {k} with [brackets] and \"quotes\"")
            lines.append(f"  {st} robtarget p{k}:={literal(k)};")
        elif form == 7:
            lines.append(f"  VAR robtarget pv{k};")
            lines.append(f"  {st} robtarget p{k}:={literal(k)};")
        else:
            lines.append(f"  {st} robtarget p{k}:={literal(k)};")
    moves = [
        "MoveL p{k},v500,z10,tGun\\WObj:=wTable;",
        "MoveJ p{k}, v100, fine, tool0;",
        "movel arr{a}{{2}},v500,z10,tGun;",
        "MoveL arr{a}{{ 1 }} , v500 , z10 , tGun \\WObj := wTable ;",
        "MoveL " + literal(1) + ",v50,fine,tGun\\WObj:=wTable;",
        "MoveJ " + literal(2, spaced=True) + ", v50, z1, tGun;",
        "MoveL Offs(p{k},0,0,50), v100, fine, tGun\\WObj:=wTable;",
        "MoveC p{k}, p{k}, v100, z10, tGun;",
        "MoveAbsJ j{j}, v100, fine, tool0;",
        "MoveL p{k}\\ID:=10, v100, fine, tGun\\WObj?wTable;",
        "MoveL \\Conc, p{k}, v100, z10, tGun;",
        "SearchL \\Stop, di1, pv{v}, p{k}, v50, tGun\\WObj:=wTable;",
        "MyProc p{k}, arr{a}{{1}};",
        "Set do1; WaitTime 0.5;",
        "pv{v} := p{k};",
        "IF n5 > 2 MoveL p{k}, v100, fine, tGun;",
        "MoveL p{k}, v100, fine, tGun; ! after a move",
        "TriggL p{k}, v500, trigg1, z10, tGun\\WObj:=wTable;",
        # function calls the fast path reads whole, and ones it leaves to the grammar
        "MoveL RelTool(p{k}, 0, 0, -20\\Rz:=45), v100, z10, tGun;",
        "MoveJ Offs(arr{a}{{2}}, 10*2, -n5, 0.5E1), v100, z10, tGun\\WObj:=wTable;",
        "MoveL Offs( p{k} ,n5+1, 0 , 0 ), v100, fine, tGun;",
        "MoveL RelTool(Offs(p{k},0,0,10),0,0,0), v100, fine, tGun;",
        "MoveL Offs(pv{v}.trans.x, 0, 0, 0), v100, fine, tGun;",
        "MoveL Offs(p{k}, 0, 0, 10\\Ignored), v100, fine, tGun;",
    ]
    decl_of = {}
    for k in range(n):
        decl_of.setdefault(k % 9, []).append(k)
    lines.append("  PROC main()")
    lines.append(f"    VAR robtarget pLocal:={literal(0)};")
    for i in range(3 * n):
        k = int(rng.choice(decl_of[0] + decl_of[1] + decl_of[6]))
        a = int(rng.choice(decl_of[2]))
        j = int(rng.choice(decl_of[3]))
        v = int(rng.choice(decl_of[7]))
        lines.append("    " + moves[i % len(moves)].format(k=k, a=a, j=j, v=v))
        if i % 11 == 0:
            lines.append("")
    lines += ["  ENDPROC", "  PROC second()", "    MoveL pLocal, v10, fine, tool0;",
              "    FOR i FROM 1 TO 3 DO", "      MoveJ p0, v100, z10, tGun;", "    ENDFOR",
              "  ENDPROC", "ENDMODULE", ""]
    return newline.join(lines)


GRAMMAR_ONLY_SOURCES = [ROOT / "samples" / "cell_a.mod"] + sorted(
    (ROOT / "tests" / "programs").glob("rapid_[!e]*/input.mod"))


@pytest.mark.parametrize("path", GRAMMAR_ONLY_SOURCES, ids=lambda p: p.parent.name)
def test_fast_paths_give_the_grammars_program(path: Path, grammar_only):
    text = path.read_bytes().decode("latin-1")
    fast = grammar_only(text, fast=True)
    assert fast == grammar_only(text, fast=False)
    assert not isinstance(fast, tuple), fast


@pytest.mark.parametrize("newline", ["\n", "\r\n"], ids=["lf", "crlf"])
def test_fast_paths_give_the_grammars_program_varied(newline, grammar_only):
    text = _varied_module(120, seed=1, newline=newline)
    fast = grammar_only(text, fast=True)
    slow = grammar_only(text, fast=False)
    assert not isinstance(fast, tuple), fast
    assert len(fast.targets) > 100 and len(fast.motions) > 300 and fast.runtime
    assert fast == slow  # every field: sources (line, column), spans, texts, starts
    # and the places are right: a declared target's source is its name (an array
    # element's: its value), an inline target's and a motion's: the target argument
    line_starts = [0] + [k + 1 for k, c in enumerate(text) if c == "\n"]

    def offset(source):
        file, line, col = source
        assert file == "prog.mod"
        return line_starts[line - 1] + col - 1

    for t in fast.targets:
        if t.name is None or t.array_index is not None:
            assert offset(t.source) == t.span[0]
        else:
            assert re.match(r"\w+", text[offset(t.source):]).group() == t.name
    for m in fast.motions:
        assert offset(m.source) == m.target_span[0]


MALFORMED = [  # (all but one are errors; '1.2.3' makes a runtime target)
    # a one-line motion the fast regexes refuse, then the grammar (re-parse) refuses
    "MODULE A\n  PROC main()\n    MoveJ p1, v1000, z5\xa1, tGun;\n    MoveL p1, v10, z5, t;\n"
    "  ENDPROC\nENDMODULE\n",
    "MODULE A\n  PROC main()\n    MoveL p1 v100, fine, tool0;\n  ENDPROC\nENDMODULE\n",
    "MODULE A\n  PROC main()\n    MoveL p1, v100, fine, tool0 \\WObj:=;\n  ENDPROC\n"
    "ENDMODULE\n",
    "MODULE A\n  PROC main()\n    MoveL Offs(p1,1,2, v100, fine, tool0;\n  ENDPROC\nENDMODULE\n",
    "MODULE A\n  PROC main()\n    MoveL Offs(p1,0,0 50), v100, fine, tool0;\n  ENDPROC\n"
    "ENDMODULE\n",
    "MODULE A\n  PROC main()\n    MoveL Offs(p1,,0,0), v100, fine, tool0;\n  ENDPROC\nENDMODULE\n",
    "MODULE A\n  PROC main()\n    MoveL RelTool(p1,0,0,0\\Rz:=), v100, fine, tool0;\n  ENDPROC\n"
    "ENDMODULE\n",
    # literals of the wrong shape, in one-line declarations and motions
    "MODULE A\n  CONST robtarget p:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9]];\nENDMODULE\n",
    "MODULE A\n  CONST robtarget p:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,1.2.3]];\n"
    "ENDMODULE\n",
    "MODULE A\n  CONST robtarget p{2}:=[[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];"
    "\nENDMODULE\n",
    "MODULE A\n  PROC main()\n    MoveL [[1,2,3],[1,0,0,0],[0,0,0,0]], v100, fine, tool0;\n"
    "  ENDPROC\nENDMODULE\n",
    "MODULE A\r\n  VAR num x := 3 +;\r\n  CONST robtarget p:=[[1,2,3],[1,0,0,0],[0,0,0,0],"
    "[9E9,9E9,9E9,9E9,9E9,9E9]];\r\nENDMODULE\r\n",
    "MODULE A\n  PROC main()\n    MoveL p1, v100, fine, tool0;\n    MoveL p2, v100\n"
    "  ENDPROC\nENDMODULE\n",
]


@pytest.mark.parametrize("text", MALFORMED, ids=range(len(MALFORMED)))
def test_fast_paths_give_the_grammars_errors(text, grammar_only):
    # the same ParseError (file, line, column, caret line) or the same Program
    assert grammar_only(text, fast=True) == grammar_only(text, fast=False)


# FAST_DECLS takes any [...] without '"', '!' or ';' (brackets not counted), and the
# literal reader then says what is wrong with it; the grammar's AGGREGATE token counts
# brackets, so the grammar alone stops at another spot. Both reject these.
REJECTED_AT_ANOTHER_SPOT = [
    "MODULE A\n  CONST robtarget p:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,"
    "9E9]]];\nENDMODULE\n",
    "MODULE A\n  CONST robtarget p:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]\n"
    "  CONST robtarget q:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
    "ENDMODULE\n",
]


@pytest.mark.parametrize("text", REJECTED_AT_ANOTHER_SPOT,
                         ids=range(len(REJECTED_AT_ANOTHER_SPOT)))
def test_a_declaration_the_fast_path_misreads_is_an_error_either_way(text, grammar_only):
    fast, slow = grammar_only(text, fast=True), grammar_only(text, fast=False)
    assert fast[0] == slow[0] == "error"
    assert fast[2] == 2  # the declaration's line
