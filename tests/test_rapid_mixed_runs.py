"""A column parse reads runs of plain MoveL/MoveJ and, from the first Offs()/RelTool() one
on, of both kinds in batches (rapid/fast.py ``_MIXED_MOVE``, columns.py
``MoveTable.run_mixed``, displaced.py ``DisplacedMoves.extend``): the MotionUse,
RuntimeTarget and CartesianTarget objects made of its rows must be the object parse's of
the same module, whatever the mix, the run lengths (row by row, the first batches, long
batches), the comments, blank lines and other statements between, and the routine-local
targets."""

from __future__ import annotations

import random

import pytest

from olp_compensate.programs.rapid.columns import with_objects
from olp_compensate.programs.rapid.displaced import DisplacedMoves, with_displaced
from olp_compensate.programs.rapid.reader import parse_rapid, parse_rapid_columns

LITERAL = "[[1.5,-2,3E2],[1,0,0,0],[0,-1,2,1],[9E9,9E9,9E9,9E9,9E9,9E9]]"
PLAIN = ["MoveL p{k},v500,z10,tGun;",
         "MoveJ p{k},v500,z10,tGun\\WObj:=wTable;",
         "movel p{k} , v100 , fine , tGun \\wobj := wTable ;",
         "MOVEJ q{{2}},vmax,z50,tGun;",
         "MoveL p{k},v500,z10,tGun;   ! to the part"]
DISPLACED = ["MoveJ Offs(p{k},0,0,50),v500,z10,tGun;",
             "MoveL RelTool(p{k},0,0,-20),v500,z10,tGun\\WObj:=wTable;",
             "movel offs( p{k} , -1.5, .5 ,2E3 ), v100 , fine , tGun \\wobj := wTable ;",
             "MOVEJ RELTOOL(p{k},1e-3,0.,-7),v500,z10,tGun;",
             "MoveJ Offs(p{k},0,0,50),v500,z10,tGun\\WObj:=wFix;  ! above"]
# statements that break a run: other calls, forms of Offs()/RelTool() the regex leaves
# to the item reader or the grammar, an inline target, an assignment
OTHER = ["SetDO do1, 1;", "WaitTime 0.5;",
         "MoveL RelTool(p{k},0,0,-20\\Rz:=45),v500,z10,tGun;",
         "MoveL Offs(p{k},dx,0,0),v500,z10,tGun;",
         "MoveC Offs(p{k},0,0,5),p{k},v500,z10,tGun;",
         "MoveL " + LITERAL + ",v500,z10,tGun;",
         "dx := dx + 1;"]
BETWEEN = ["\r\n    ", "\n    ", " ", "\r\n\r\n    ", "\r\n    ! a comment\r\n    ",
           "\n  \t\n    "]


def _body(rng: random.Random, n: int, kinds: str) -> list[str]:
    """n statements: ``kinds`` 'p' plain, 'd' displaced, 'o' other, drawn in turn."""
    out = []
    for _ in range(n):
        kind = rng.choice(kinds)
        forms = PLAIN if kind == "p" else DISPLACED if kind == "d" else OTHER
        out.append(rng.choice(forms).format(k=rng.randrange(30)) + rng.choice(BETWEEN))
    return out


def _module(seed: int) -> str:
    rng = random.Random(seed)
    out = ["MODULE M\r\n  PERS tooldata tGun:=[TRUE,[[1,0,2],[1,0,0,0]],"
           "[2.5,[0,0,80],[1,0,0,0],0,0,0]];\r\n  VAR num dx := 5;\r\n"
           "  PERS wobjdata wTable:=[FALSE,TRUE,\"\",[[700,-300,300],[1,0,0,0]],"
           "[[0,0,0],[1,0,0,0]]];\r\n"
           f"  CONST robtarget q{{3}}:=[{LITERAL},{LITERAL},{LITERAL}];\r\n"]
    out += [f"  CONST robtarget p{k}:={LITERAL};\r\n" for k in range(0, 30, 2)]
    for r in range(6):
        out.append(f"  PROC r{r}()\r\n    ")
        out += [f"VAR robtarget p{k}:={LITERAL};\r\n    " for k in range(1, 30, 2 + r)]
        # runs of every length the batches meet: short, the first 16, 32, 64, 128...
        n = rng.choice([1, 3, 15, 16, 17, 40, 49, 300, 700])
        kinds = rng.choice(["pd", "ppppd", "pdd", "d", "p", "pdpdo", "ppdppdpppppppo"])
        out += _body(rng, n, kinds)
        out.append("\r\n  ENDPROC\r\n")
    out.append("ENDMODULE\r\n")
    return "".join(out)


def _column_objects(text: str) -> tuple:
    """The Program a column parse with a DisplacedMoves table gives, its rows made objects,
    and the row counts of its displaced and move tables."""
    table = DisplacedMoves()
    program, columns = parse_rapid_columns(text, "m.mod", table)
    return with_displaced(with_objects(program, columns), table), len(table), len(columns.moves)


@pytest.mark.parametrize("seed", range(12))
def test_mixed_runs_give_the_object_parse(seed):
    text = _module(seed)
    want = parse_rapid(text, "m.mod")
    got, displaced_rows, move_rows = _column_objects(text)
    assert got == want
    readable = sum(1 for u in want.motions if u.runtime is not None
                   and u.instruction.lower() in ("movel", "movej")
                   and "Rz" not in u.runtime.expression and "dx" not in u.runtime.expression)
    assert displaced_rows == readable       # every plain Offs()/RelTool() one is a row
    assert move_rows == sum(1 for u in want.motions if u.target_name
                            and u.instruction.lower() in ("movel", "movej"))


def test_a_long_interleaved_run_is_read_in_batches_split_by_kind():
    """One routine of 2,000 moves, every third an Offs(): rows in text order, each kind in
    its table, the objects the object parse makes (lines and columns included)."""
    body = "".join(("    MoveJ Offs(p{0},0,0,{1}),v500,z10,tGun\\WObj:=wTable;\r\n"
                    if k % 3 == 1 else "    MoveL p{0},v500,z10,tGun;\r\n").format(k % 7, k)
                   for k in range(2000))
    text = ("MODULE M\r\n  PROC main()\r\n"
            + "".join(f"    VAR robtarget p{k}:={LITERAL};\r\n" for k in range(7))
            + body + "  ENDPROC\r\nENDMODULE\r\n")
    want = parse_rapid(text, "m.mod")
    got, displaced_rows, move_rows = _column_objects(text)
    assert (displaced_rows, move_rows) == (667, 1333)
    assert got == want
    offsets = [u.runtime.expression for u in got.motions if u.runtime is not None]
    assert offsets == [f"Offs(p{k % 7},0,0,{k})" for k in range(1, 2000, 3)]
    assert [u.source[1] for u in got.motions] == list(range(10, 2010))


@pytest.mark.parametrize("held", [1, 7, 16, 40])
@pytest.mark.parametrize("seed", [0, 5, 9])
def test_matches_held_and_added_every_few_give_the_same_rows(monkeypatch, seed, held):
    """``run_mixed`` holds a run's matches of each kind and adds them every
    ``MIXED_BATCH`` matches (and at the run's end): with a few held at a time (rows added
    row by row, in the first batches, mid-batch) the objects are the object parse's, and
    the tables the same rows as with the default."""
    from olp_compensate.programs.rapid import columns
    text = _module(seed)
    want = parse_rapid(text, "m.mod")
    default = _column_objects(text)
    monkeypatch.setattr(columns, "MIXED_BATCH", held)
    got = _column_objects(text)
    assert got[0] == want
    assert got == default


def test_targets_named_like_offs_or_reltool_are_plain_moves_in_a_mixed_run():
    """_MIXED_MOVE tries the Offs()/RelTool() form first: a plain target whose name
    starts like that (``Offs``, ``RelTool1``, ``offset``) is still read as a plain move,
    in a run of both kinds, as the object parse reads it."""
    names = ["Offs", "RelTool", "offs1", "RELTOOLx", "Offset", "Rel", "O", "p1"]
    decls = "".join(f"    VAR robtarget {n}:={LITERAL};\r\n" for n in names)
    body = "".join(
        f"    MoveL {n},v500,z10,tGun;\r\n    MoveJ Offs({n},0,0,{k}),v500,z10,tGun;\r\n"
        f"    MoveL RelTool({n},0,0,-{k}),v500,z10,tGun\\WObj:=wTable;\r\n"
        for k, n in enumerate(names * 3))
    text = "MODULE M\r\n  PROC main()\r\n" + decls + body + "  ENDPROC\r\nENDMODULE\r\n"
    got, displaced_rows, move_rows = _column_objects(text)
    assert got == parse_rapid(text, "m.mod")
    assert (displaced_rows, move_rows) == (48, 24)
    assert [u.target_name for u in got.motions if u.target_name] == names * 3


def test_displaced_rows_share_their_words():
    """Batches and single rows store each instruction, tool and reason once."""
    text = _module(3)
    table = DisplacedMoves()
    parse_rapid_columns(text, "m.mod", table)
    assert len(table) > 8
    assert len({id(r) for r in table.reasons}) == len(set(table.reasons))
    assert len({id(t) for t in table.tools}) == len(set(table.tools))


@pytest.mark.parametrize("odd", ["PERS robtarget", "LOCAL VAR robtarget", "TASK PERS robtarget",
                                 "VAR num", "CONST robtarget"])
def test_a_routines_own_targets_are_read_in_runs_up_to_any_other_declaration(odd):
    """Routine-local VAR/CONST robtargets are rows, read in runs (TargetTable.run, own);
    a PERS, LOCAL or TASK one (or other data) between them stops the run there and is
    left to the builder: the objects are the object parse's."""
    decls = [f"    VAR robtarget p{k}:={LITERAL};\r\n" for k in range(40)]
    value = "5" if odd == "VAR num" else LITERAL
    for at in (0, 3, 15, 16, 17, 33, 39):
        lines = decls[:at] + [f"    {odd} x{at}:={value};\r\n"] + decls[at:]
        text = ("MODULE M\r\n  PROC main()\r\n" + "".join(lines)
                + "".join(f"    MoveL p{k},v500,z10,tool0;\r\n" for k in range(40))
                + "  ENDPROC\r\nENDMODULE\r\n")
        want = parse_rapid(text, "m.mod")
        table = DisplacedMoves()
        program, columns = parse_rapid_columns(text, "m.mod", table)
        assert with_displaced(with_objects(program, columns), table) == want
        rows = 40 + (odd == "CONST robtarget")
        assert len(columns.targets) == rows
        assert set(columns.targets.routines) == {"main"}


@pytest.mark.parametrize("file", ["m.mod", "cell 2, 100%d.mod", 'a "b".mod'])
@pytest.mark.parametrize("seed", [1, 4, 7])
def test_displaced_rows_csv_lines_are_their_report_rows_lines(seed, file):
    """``DisplacedMoves.csv_lines`` (written without making the rows, the fields after
    the column once per tool, work object and reason) gives each row's line as
    ``CsvRows.line`` writes its report row, for any mix of forms and a file name the CSV
    must quote or that holds a '%'."""
    from olp_compensate.compensation.report_csv import CsvRows

    text = _module(seed)
    table = DisplacedMoves()
    parse_rapid_columns(text, file, table)
    assert len(table) > 8
    rows = list(range(len(table)))
    random.Random(seed).shuffle(rows)
    for n_joints in (6, 7):
        writer = CsvRows(n_joints)
        want = [writer.line(table.report_row(i, text, file)) + "\n" for i in rows]
        assert table.csv_lines(rows, text, file, writer) == want
