"""MoveL/MoveJ of ``Offs(p, x, y, z)`` or ``RelTool(p, x, y, z)`` read by one regex match
(rapid/fast.py ``_DISPLACED_MOVE``): the motion and run-time target it makes must be the
ones the builder makes of the same call when the fast path is off, in every form the
regex reads and beside the forms it leaves to the item reader and the grammar."""

from __future__ import annotations

import random
import re

from olp_compensate.programs import loads
from olp_compensate.programs.rapid import fast as rapid_fast
from olp_compensate.programs.rapid.columns import with_objects
from olp_compensate.programs.rapid.reader import parse_rapid_columns

LITERAL = "[[1.5,-2,3E2],[1,0,0,0],[0,-1,2,1],[9E9,9E9,9E9,9E9,9E9,9E9]]"
READ = ["MoveJ Offs(p{k},0,0,50),v500,z10,tGun;",
        "MoveL RelTool(p{k},0,0,-20),v500,z10,tGun\\WObj:=wTable;",
        "movel offs( p{k} , -1.5, .5 ,2E3 ), v100 , fine , tGun \\wobj := wTable ;",
        "MOVEJ RELTOOL(p{k},1e-3,0.,-7),v500,z10,tGun;",
        "MoveL Offs(p{k},0,0,50),v500,z10,tGun;   ! approach"]
LEFT = ["MoveL RelTool(p{k},0,0,-20\\Rz:=45),v500,z10,tGun;",   # an optional argument
        "MoveL Offs(p{k},dx,0,0),v500,z10,tGun;",                # a name as offset
        "MoveL Offs(p{k},0,0),v500,z10,tGun;",                   # two numbers: no Offs
        "MoveL Offs(p{k},0,0,+5),v500,z10,tGun;",                # a signed number
        "MoveC Offs(p{k},0,0,5),p{k},v500,z10,tGun;",            # not MoveL/MoveJ
        "MoveL CRobT(\\Tool:=tGun),v500,z10,tGun;",
        "MoveL p{k},v500,z10,tGun;"]


def _module(seed: int, n: int = 40) -> str:
    rng = random.Random(seed)
    out = ["MODULE M\r\n  PERS tooldata tGun:=[TRUE,[[1,0,2],[1,0,0,0]],"
           "[2.5,[0,0,80],[1,0,0,0],0,0,0]];\r\n  VAR num dx := 5;\r\n"]
    out += [f"  CONST robtarget p{k}:={LITERAL};\r\n" for k in range(n)]
    for r in range(3):
        out.append(f"  PROC r{r}()\r\n")
        if r == 1:
            out.append(f"    VAR robtarget p0:={LITERAL};\r\n")   # a local one shadows
        for k in range(n):
            form = rng.choice(READ if rng.random() < 0.7 else LEFT)
            out.append("    " + form.format(k=k) + rng.choice(["\r\n", "\n", " "]))
        out.append("  ENDPROC\r\n")
    out.append("ENDMODULE\r\n")
    return "".join(out)


def test_offs_and_reltool_moves_read_at_once_are_the_builders(monkeypatch):
    texts = [_module(seed) for seed in range(5)]
    taken = []
    made = rapid_fast._displaced_move
    monkeypatch.setattr(rapid_fast, "_displaced_move",
                        lambda sink, m: (taken.append(m.group(2)), made(sink, m)))
    fast = [loads(text, "rapid", "m.mod") for text in texts]
    columns = [with_objects(*parse_rapid_columns(text, "m.mod")) for text in texts]
    read = len(taken)
    assert read > 200 and all(re.match(r"(?i)(offs|reltool)\(", t) for t in taken)
    monkeypatch.setattr(rapid_fast, "_DISPLACED_MOVE", re.compile(r"(?!)"))
    items = []
    item_reader = rapid_fast._items_regex
    monkeypatch.setattr(rapid_fast, "_items_regex",
                        lambda *a: (items.append(a[1]), item_reader(*a))[1])
    slow = [loads(text, "rapid", "m.mod") for text in texts]
    assert len(taken) == read and len(items) >= read // 2   # the builder made these
    assert fast == slow
    assert columns == slow
    for program in fast:
        assert {m.runtime for m in program.motions if m.runtime} <= set(program.runtime)
        bases = {m.runtime.base_name for m in program.motions if m.runtime} - {None}
        assert bases and bases <= {f"p{k}" for k in range(40)}
