"""The programs' regular expressions give the same answers on every Python that
``requires-python`` admits: 3.11.2 (a fresh Debian's /usr/bin/python3) keeps the partial
match of a failed group under a possessive quantifier, ``1(?:e\\d+)?+,`` matching ``1e,``,
so a bare exponent (``[900,0,1e]``) was read as a number there."""

from __future__ import annotations

import random
import re
from pathlib import Path

import pytest

from olp_compensate.cli.cal import main as cal
from olp_compensate.cli.fix import main as fix
from olp_compensate.programs import literals, regex_compat
from olp_compensate.programs.rapid import fast as rapid_fast

ROOT = Path(__file__).resolve().parents[1]
GOOD = ["900", "0", "1000", "1", "0", "0", "0", "0", "0", "0", "0",
        "9E9", "9E9", "9E9", "9E9", "9E9", "9E9"]
# a possessive quantifier right after a group: the construct 3.11.2 gets wrong
GROUP_POSSESSIVE = re.compile(r"(?<!\\)\)[*+?]\+")


def _literal(numbers: list[str]) -> str:
    n = numbers
    return (f"[[{','.join(n[0:3])}],[{','.join(n[3:7])}],[{','.join(n[7:11])}],"
            f"[{','.join(n[11:17])}]]")


@pytest.fixture(scope="module")
def nominal(tmp_path_factory):
    path = tmp_path_factory.mktemp("rx") / "nominal.json"
    assert cal(["nominal", "--robot", "abb_irb2400", "-o", str(path)]) == 0
    return path


@pytest.mark.parametrize("inline", [False, True])
@pytest.mark.parametrize("slot", range(17))
def test_bare_exponent_is_refused_with_its_position(tmp_path, nominal, capsys, slot, inline):
    numbers = list(GOOD)
    numbers[slot] = ["1e", "2E+", "3e-", ".5E"][slot % 4]
    literal = _literal(numbers)
    if inline:
        body = f"  PROC main()\n    MoveL {literal},v100,z1,tool0;\n  ENDPROC\n"
    else:
        body = (f"  CONST robtarget p1:={literal};\n"
                "  PROC main()\n    MoveL p1,v100,z1,tool0;\n  ENDPROC\n")
    program = tmp_path / "bad.mod"
    program.write_text(f"MODULE M\n{body}ENDMODULE\n")
    code = fix([str(program), "--model", str(nominal), "-o", str(tmp_path / "out.mod"), "-q"])
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err
    line = 2 if not inline else 3
    column = 1 + (body.splitlines()[line - 2].index(numbers[slot] + ",")
                  if slot not in (2, 6, 10, 16) else
                  body.splitlines()[line - 2].index(numbers[slot] + "]"))
    assert f"bad.mod:{line}:" in err and "malformed number" in err
    assert f":{line}:{column}:" in err
    assert not (tmp_path / "out.mod").exists()


@pytest.mark.parametrize("text, number", [
    ("1e", None), ("1e+", None), ("1.5E-", None), ("1e5", "1e5"), ("-.5e-3", "-.5e-3"),
    ("12.", "12."), ("+7", "+7")])
def test_number_group_takes_whole_numbers_only(text, number):
    m = re.fullmatch(literals.NUMBER_GROUP + ",", text + ",")
    assert (m and m.group(1)) == number


def test_plain_argument_and_separator_patterns():
    plain = re.compile(rapid_fast._PLAIN + ",")
    assert plain.fullmatch("1e,") is None and plain.fullmatch("a.,") is None
    assert plain.fullmatch("v100,") and plain.fullmatch("a.b.c,") and plain.fullmatch("2E3,")
    assert rapid_fast._FAST_ITEM.match("[a,[b]],").group("val") == "[a,[b]]"
    assert rapid_fast._SEP_RE.match("  ! c\n  x").end() == 8


def _grammar_lines() -> list[tuple[str, str]]:
    """(where, line) of the lark grammars' rules (lark compiles them, no guard there)."""
    found = []
    for path in sorted((ROOT / "grammars").glob("*.lark")):
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if not line.lstrip().startswith("//"):
                found.append((f"{path.name}:{number}", line))
    return found


def test_the_grammars_hold_no_possessive_quantifier_on_a_group():
    """Groups of the grammars that must not backtrack are atomic, ``(?>(?:...)*)``."""
    assert [where for where, line in _grammar_lines() if GROUP_POSSESSIVE.search(line)] == []


def _compiled() -> dict:
    """Every compiled pattern of the modules that read and write RAPID numbers."""
    from olp_compensate.programs.emit_batch import _PlainRun

    found = {f"{m.__name__}.{k}": v for m in (literals, rapid_fast)
             for k, v in vars(m).items() if isinstance(v, re.Pattern)}
    run = _PlainRun([0, 1, 2], [3, 3, 3], "")
    found["emit_batch"], found["emit_batch joined"] = run.pattern, run.joined
    return found


def test_patterns_in_use_have_no_possessive_group_where_re_gets_them_wrong():
    patterns = _compiled()
    assert len(patterns) > 10
    if regex_compat.GROUPS_OK:
        assert any(GROUP_POSSESSIVE.search(p.pattern) for p in patterns.values())
        return
    assert [k for k, p in patterns.items() if GROUP_POSSESSIVE.search(p.pattern)] == []


@pytest.mark.skipif(not regex_compat.GROUPS_OK, reason="possessive groups are wrong here")
def test_the_atomic_rewrite_matches_the_same():
    """On a Python whose possessive groups are right, each pattern and its atomic rewrite
    (what 3.11.2 runs) match the same spans and groups on texts made to end anywhere."""
    rnd = random.Random(7)
    alphabet = list("0123456789.eE+-,[]() \t\n!;:={}*\\") + [
        "MoveL ", "p1", "v100", "z1", "tool0", "\\WObj:=", "CONST robtarget ", "x.y"]
    literal = "[[900,0,1e],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]"
    for name, pattern in _compiled().items():
        twin = re.compile(regex_compat.atomic(pattern.pattern), pattern.flags)
        if twin.pattern == pattern.pattern:
            continue
        for _ in range(1500):
            text = literal[:rnd.randint(0, len(literal))] * (rnd.random() < 0.4) + "".join(
                rnd.choice(alphabet) for _ in range(rnd.randint(0, 25)))
            for a, b in ((pattern.match(text), twin.match(text)),
                         (pattern.search(text), twin.search(text))):
                assert (a and (a.span(), a.groups())) == (b and (b.span(), b.groups())), \
                    (name, text)
