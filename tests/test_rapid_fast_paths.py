"""The hot loops of the RAPID fast paths keep their own line count (LineIndex.position /
moved) and read blank-free robtarget literals with a tighter regex first: the targets and
motions they build must be the ones the plain LineIndex and the general regex give."""

from __future__ import annotations

import random
import re

import pytest

from olp_compensate.errors import ParseError
from olp_compensate.programs import loads
from olp_compensate.programs.rapid import fast as rapid_fast
from olp_compensate.programs.grammar import LineIndex, NewlineIndexedText
from olp_compensate.programs.literals import NUMBER_RE
from olp_compensate.programs.rapid.reader import parse_rapid_columns
from olp_compensate.programs.rapid.columns import with_objects

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


def _general_only(rows: bool):
    """robtarget_regexes with the general regex in place of the tight one."""
    general = _GENERAL(rows)[1]
    return general, general


_GENERAL = rapid_fast.robtarget_regexes
TIGHT, FAST = _GENERAL(rows=False)


def test_the_tight_robtarget_regex_changes_nothing(monkeypatch):
    assert TIGHT.pattern != FAST.pattern
    assert TIGHT.groups == FAST.groups
    texts = [_module(seed) for seed in range(8, 14)]
    tight = [loads(text, "rapid", "m.mod") for text in texts]
    columns = [with_objects(*parse_rapid_columns(text, "m.mod")) for text in texts]
    monkeypatch.setattr(rapid_fast, "robtarget_regexes", _general_only)
    general = [loads(text, "rapid", "m.mod") for text in texts]
    assert tight == general
    assert columns == general
    assert [with_objects(*parse_rapid_columns(text, "m.mod")) for text in texts] == general


# ---- the ASCII tight regex and unusual numbers ------------------------------------------
# _TIGHT_ROBTARGET is compiled with re.ASCII (\d is [0-9], keywords fold ASCII case only):
# it may refuse what the general regex reads (non-ASCII digits, 'ſ' for 's'), which then
# reads it; where it matches, it must give the very same match.

VALID_UNUSUAL = ["9E+09", "9e-9", ".5", "-0.", "+1", "1.e5", "1.10307E-06", "0", "007"]
MALFORMED = ["1.2.3", "1e", "--1", "+-", "e5", ".", "-.", "+", "1e+", "1e5.", "1..2",
             "1e5e5", ".e5", "1-2", "x", "1 2"]
NOT_ONE_ITEM = ["1,2", "", "[1]"]  # the literal's shape is wrong: a ParseError
NON_ASCII = ["\u0663", "1\u06637.5", "9E\u0669"]  # Unicode digits, which \d reads
SLOTS = (0, 3, 6, 11, 16)  # x, q1, q4, cfx, eax_f


def _with_number(token: str, slot: int) -> str:
    """A run of three plain declarations; number ``slot`` of p1 written as ``token``."""
    numbers = ["1.5", "-2", "3E2", "1", "0", "0", "0", "0", "-1", "2", "1"] + ["9E9"] * 6
    numbers[slot] = token
    groups = [numbers[0:3], numbers[3:7], numbers[7:11], numbers[11:17]]
    literal = "[" + ",".join("[" + ",".join(g) + "]" for g in groups) + "]"
    return (f"MODULE M\n  CONST robtarget p0:={LITERAL};\n  CONST robtarget p1:={literal};\n"
            f"  CONST robtarget p2:={LITERAL};\n  PROC main()\n    MoveL p1,v500,z10,tool0;\n"
            "    MoveL p2,v500,z10,tool0;\n  ENDPROC\nENDMODULE\n")


def _outcome(text: str):
    """The Program, or the ParseError's message, file, line, column and context."""
    try:
        return loads(text, "rapid", "m.mod")
    except ParseError as exc:
        return (exc.message, exc.file, exc.line, exc.column, exc.context)


def test_unusual_numbers_in_a_run_are_read_as_the_strict_pattern_says(monkeypatch):
    cases = [(token, slot) for token in VALID_UNUSUAL + MALFORMED + NOT_ONE_ITEM + NON_ASCII
             for slot in SLOTS]
    with monkeypatch.context() as patch:
        patch.setattr(rapid_fast, "robtarget_regexes", _general_only)
        general = {case: _outcome(_with_number(*case)) for case in cases}
    for token, slot in cases:
        text = _with_number(token, slot)
        got = _outcome(text)
        assert got == general[token, slot], (token, slot)
        name = text.index("p1:=")
        literal = name + 4
        where = _reference(text, name)
        if NUMBER_RE.fullmatch(token):  # the strict pattern's verdict: one number
            (p1,) = [t for t in got.targets if t.name == "p1"]
            assert p1.texts[slot] == token and p1.source == ("m.mod", *where)
            assert [text[a:a + len(x)] for a, x in zip(p1.starts, p1.texts)] == list(p1.texts)
            assert p1.span == (literal, text.index(";", literal))
        elif isinstance(got, tuple):  # the literal reader's error, inside the literal
            assert got[2] == where[0] and got[3] > _reference(text, literal)[1], (token, got)
        else:  # not a number: a target computed at run time, located at its name
            assert "p1" not in [t.name for t in got.targets]
            (runtime,) = got.runtime
            assert (runtime.base_name, tuple(runtime.location)[1:]) == ("p1", where), token


def _declarations(seed: int, n: int = 400):
    """Declaration texts: mostly plain robtargets, some with an odd number, non-ASCII
    letters or digits, blanks, another type or a wrong shape."""
    rng = random.Random(seed)
    valid, odd = VALID_UNUSUAL + ["1.5", "-2", "9E9"] * 3, MALFORMED[:-2] + NON_ASCII
    heads = ["CONST", "PERS", "var", "LOCAL CONST", "task pers", "CON\u017fT", "\u212aONST",
             "LOCAL\tVAR"]
    types = ["robtarget", "ROBTARGET"] * 4 + ["robtarge\u0442", "jointtarget"]
    for _ in range(n):
        numbers = [rng.choice(valid) for _ in range(17)]
        if rng.random() < 0.4:
            numbers[rng.randrange(17)] = rng.choice(odd)
        if rng.random() < 0.1:
            del numbers[-1]
        groups = [numbers[0:3], numbers[3:7], numbers[7:11], numbers[11:]]
        literal = "[" + ",".join("[" + ",".join(g) + "]" for g in groups) + "]"
        if rng.random() < 0.2:
            literal = literal.replace(",", rng.choice([", ", " ,", ",\r\n  "]), 1)
        blank = rng.choice(["", " ", "\t", " \r\n  "])
        yield (f"{rng.choice(heads)} {rng.choice(types)} p{rng.randrange(99)}{blank}:={blank}"
               f"{literal}{rng.choice(['', ' '])};"
               + rng.choice(["", "\n", "\r\n  ", " ! [1.2.3]\n  ", "\n\n\f"]))


def test_the_ascii_tight_regex_matches_as_the_general_one():
    tight_hits = 0
    for seed in range(5):
        for text in _declarations(seed):
            tight = TIGHT.match(text)
            general = FAST.match(text)
            if tight is not None:
                tight_hits += 1
                assert general is not None and tight.regs == general.regs, text
            elif general is not None:  # refused only for blanks in the literal or non-ASCII
                literal = general.group(4)
                assert not text.isascii() or any(c in literal for c in " \t\n"), text
    assert tight_hits > 100


@pytest.mark.parametrize("which", [0, 1], ids=["tight", "general"])
def test_the_column_parse_regexes_match_what_the_full_ones_match(which):
    """The column parse's regexes capture only the x and q4 numbers: they match exactly
    the texts the full ones match, with the same name, literal and number spans."""
    row, full = _GENERAL(rows=True)[which], _GENERAL(rows=False)[which]
    assert (row.groups, full.groups) == (6, 21)
    hits = 0
    for seed in range(5):
        for text in _declarations(seed):
            got, expected = row.match(text), full.match(text)
            assert (got is None) == (expected is None), text
            if got is not None:
                hits += 1
                assert got.regs[:5] == expected.regs[:5], text
                assert (got.regs[5], got.regs[6]) == (expected.regs[5], expected.regs[11])
    assert hits > 100


def test_newline_indexed_text_answers_as_str_does():
    """count and rindex of line breaks (what lark asks of a text slice) by bisection give
    str's answers at random bounds, negative and past the end included."""
    rng = random.Random(3)
    text = "".join(rng.choice(["ab", "\n", "\r\n", " ", "\n\n"]) for _ in range(500))
    indexed = NewlineIndexedText(text)
    assert indexed == text and indexed.count("a") == text.count("a")
    for _ in range(2000):
        start = rng.randrange(-len(text) - 5, len(text) + 5)
        end = rng.randrange(-len(text) - 5, len(text) + 5)
        assert indexed.count("\n", start, end) == text.count("\n", start, end)
        try:
            expected = text.rindex("\n", start, end)
        except ValueError:
            with pytest.raises(ValueError):
                indexed.rindex("\n", start, end)
        else:
            assert indexed.rindex("\n", start, end) == expected
    assert indexed.count("\n") == text.count("\n") and indexed.rindex("\n") == text.rindex("\n")


def test_calls_parsed_again_keep_their_lines_in_a_long_module():
    """Calls the fast paths leave to the grammar (Offs, RelTool) deep in a module get the
    line and column of their target as in a module where they come first."""
    head = "MODULE m\n" + "".join(f"  CONST robtarget p{k}:={LITERAL};\n" for k in range(300))
    body = "  PROC main()\n    MoveL Offs(p7,0,0,50),v500,z10,tool0;\n" \
           "    MoveL RelTool(p8,0,0,-5),v500,fine,tool0;\n  ENDPROC\nENDMODULE\n"
    program = loads(head + body, "rapid", "m.mod")
    runtime = [u for u in program.motions if u.runtime is not None]
    assert [u.source[1:] for u in runtime] == [(303, 11), (304, 11)]


def test_matches_in_turn_are_the_anchored_matches_one_after_the_other():
    """columns.matches_in_turn (the column parse's batches) against regex.match from the
    start, one match after the other: the same matches, cut at the first gap, whatever
    the batch sizes (16, 32, ...) and wherever the gap falls."""
    from olp_compensate.programs.rapid.columns import matches_in_turn

    rx = re.compile(r"p(\d+);[ \n]*")
    for n, gap in [(0, None), (1, None), (15, None), (16, None), (17, None), (100, 48),
                   (100, 16), (100, 15), (100, 0), (100, 47), (300, 250), (40, 1)]:
        items = [f"p{k};\n" if k != gap else "q;\n" for k in range(n)]
        text = "x" + "".join(items) + "p9;"
        anchored, pos = [], 1
        while (m := rx.match(text, pos, len(text) - 3)) is not None:
            anchored.append(m.span())
            pos = m.end()
        got = [m.span() for batch in matches_in_turn(rx, text, 1, len(text) - 3)
               for m in batch]
        assert got == anchored, (n, gap)
        assert len(got) == (gap if gap is not None else n)


@pytest.mark.parametrize("seed", [3, 4])
def test_table_values_are_float_of_each_number_as_written(seed):
    """TargetTable.values (the column path's batch conversion, any rows a:b) against
    float() of each number's text of the object the row stands for, on modules mixing
    blank-free and spaced literals, unusual numbers among them."""
    import numpy as np

    text = _module(seed, 80)
    for k, token in enumerate(["0.5e-3", "+7", ".25", "-0.0", "12.", "1E+2"]):
        text = text.replace(LITERAL, LITERAL.replace("1.5", token).replace(
            "[0,-1,2,1]", f"[0,-1,{k},1]"), 1)
    _, columns = parse_rapid_columns(text, "m.mod")
    table = columns.targets
    assert len(table) > 20
    expected = np.array([[float(x) for x in table.target(i, text, "m.mod").texts]
                         for i in range(len(table))])
    assert np.array_equal(table.values(text), expected)
    for a, b in [(0, 1), (3, 11), (len(table) - 1, len(table))]:
        assert np.array_equal(table.values(text, a, b), expected[a:b])
