"""The hot loops of the RAPID fast paths keep their own line count (LineIndex.position /
moved) and read blank-free robtarget literals with a tighter regex first: the targets and
motions they build must be the ones the plain LineIndex and the general regex give."""

from __future__ import annotations

import random
import re

from olp_compensate.programs import loads, rapid_fast
from olp_compensate.programs.grammar import LineIndex

LITERAL = "[[1.5,-2,3E2],[1,0,0,0],[0,-1,2,1],[9E9,9E9,9E9,9E9,9E9,9E9]]"
SPACED = "[ [1.5, -2,3E2],[1,0,0,0] ,[0,-1,2,1],\r\n  [9E9,9E9,9E9,9E9,9E9,9E9] ]"


def _reference(text: str, offset: int) -> tuple[int, int]:
    return text.count("\n", 0, offset) + 1, offset - text.rfind("\n", 0, offset)


def _module(seed: int, n: int = 60) -> str:
    rng = random.Random(seed)
    seps = ["\r\n", "\n", "\r\n\r\n", "\r\n  ! note; [x]\r\n", "\t", "  ", "\r\n\f\n"]
    decls, moves = [], []
    for k in range(n):
        storage = rng.choice(["CONST", "PERS", "VAR", "LOCAL CONST", "task pers", "const"])
        literal = LITERAL if rng.random() < 0.6 else SPACED
        form = rng.random()
        if form < 0.1:
            decls.append(f"{storage} num n{k}:=[{k}];")
        elif form < 0.15:
            decls.append(f"{storage} robtarget p{k} :=\r\n    {literal};")
        else:
            decls.append(f"{storage} robtarget p{k}:={literal};")
        form = rng.random()
        if form < 0.1:
            moves.append(f"MoveL {LITERAL},v50,fine,tGun\\WObj:=wTable;")
        elif form < 0.15:
            moves.append(f"MoveJ p{k}, v100 ,fine, tGun;")
        elif form < 0.2:
            moves.append("Set do1; WaitTime 0.5;")
        else:
            moves.append(f"movel p{k},v500,z10,tGun\\WObj:=wTable;")
    out = ["MODULE M\r\n  PERS tooldata tGun:=[TRUE,[[1,0,2],[1,0,0,0]],"
           "[2.5,[0,0,80],[1,0,0,0],0,0,0]];\r\n"]
    out += [d + rng.choice(seps) for d in decls]
    out.append("\r\n  PROC main()\r\n")
    out += ["    " + m + rng.choice(seps) for m in moves]
    out.append("\r\n  ENDPROC\r\nENDMODULE\r\n")
    return "".join(out)


def test_line_index_answers_any_order_as_the_reference():
    text = "".join(random.Random(1).choice(["ab", "\n", "\r\n", " ", "!x"])
                   for _ in range(4000))
    rng = random.Random(2)
    index = LineIndex(text)
    index._budget = 5000  # a few direct counts, then the line starts are listed
    offsets = sorted(rng.randrange(len(text) + 1) for _ in range(300))
    for _ in range(200):  # interleave text-order and earlier offsets
        offsets.insert(rng.randrange(len(offsets)), rng.randrange(len(text) + 1))
    for offset in offsets:
        assert index.line_col(offset) == _reference(text, offset), offset
    assert index._starts is not None  # the budget ran out


def test_position_and_moved_hand_over_the_previous_answer():
    text = "a\nbb\n\nccc\n"
    index = LineIndex(text)
    index.line_col(3)
    assert index.position() == (3, 2, 2)
    index.moved(7, 4, 6)
    assert index.line_col(9) == (4, 4) == _reference(text, 9)
    assert index.line_col(1) == (1, 2)  # earlier: the handed-over state is left alone
    assert index.position() == (9, 4, 6)


def test_fast_targets_and_motions_are_where_the_text_says():
    for seed in range(8):
        text = _module(seed)
        program = loads(text, "rapid", "m.mod")
        assert len(program.targets) > 40 and len(program.motions) > 40
        for t in program.targets:
            if t.storage == "inline":
                offset = t.span[0]
            else:
                offset = re.compile(r"[ \t]+(\w+)").match(text, t.type_span[1]).start(1)
            assert t.source == ("m.mod", *_reference(text, offset)), t
        for u in program.motions:
            assert u.source == ("m.mod", *_reference(text, u.target_span[0])), u


def test_the_tight_robtarget_regex_changes_nothing(monkeypatch):
    assert rapid_fast._TIGHT_ROBTARGET.pattern != rapid_fast._FAST_ROBTARGET.pattern
    assert rapid_fast._TIGHT_ROBTARGET.groups == rapid_fast._FAST_ROBTARGET.groups
    texts = [_module(seed) for seed in range(8, 14)]
    tight = [loads(text, "rapid", "m.mod") for text in texts]
    monkeypatch.setattr(rapid_fast, "_TIGHT_ROBTARGET", rapid_fast._FAST_ROBTARGET)
    general = [loads(text, "rapid", "m.mod") for text in texts]
    assert tight == general
