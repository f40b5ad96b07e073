"""The programs' regular expressions give the same answers on every Python that
``requires-python`` admits: 3.11.2 (a fresh Debian's /usr/bin/python3) keeps the partial
match of a failed group under a possessive quantifier, ``1(?:e\\d+)?+,`` matching ``1e,``,
so a bare exponent (``[900,0,1e]``) was read as a number there."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from olp_compensate.cli.cal import main as cal
from olp_compensate.cli.fix import main as fix
from olp_compensate.programs import literals, rapid_fast

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


def _pattern_sources() -> list[tuple[str, str]]:
    """(where, pattern) of every regular expression in programs/ and grammars/."""
    found = []
    for path in sorted((ROOT / "olp_compensate" / "programs").glob("*.py")):
        for number, line in enumerate(path.read_text().splitlines(), 1):
            found.append((f"{path.name}:{number}", line))
    for path in sorted((ROOT / "grammars").glob("*.lark")):
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if not line.lstrip().startswith("//"):
                found.append((f"{path.name}:{number}", line))
    return found


def test_no_possessive_quantifier_on_a_group():
    """Groups that must not backtrack are atomic, ``(?>(?:...)*)``, which 3.11.2 gets right."""
    offending = [where for where, line in _pattern_sources()
                 if not line.lstrip().startswith("#") and GROUP_POSSESSIVE.search(line)]
    assert offending == []
