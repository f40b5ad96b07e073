"""Parse then dump with no edit gives the same bytes; an edit changes only its number."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from olp_compensate.programs import dialect_for, dump, dumps, load, loads, target_edits

ROOT = Path(__file__).resolve().parents[1]
# the programs the text-model API reads (RAPID, V+); the other dialects' golden cases
# check their round trip in test_programs_golden.py
INPUTS = sorted(ROOT.glob("samples/*.mod")) + sorted(ROOT.glob("samples/*.pg")) + sorted(
    p for p in ROOT.glob("tests/programs/*/input.*")
    if "error" not in p.parent.name and p.parent.name.startswith(("rapid_", "vplus_", "as_")))


@pytest.mark.parametrize("path", INPUTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_no_edit_round_trip_is_byte_identical(path: Path):
    data = path.read_bytes()
    program = load(path)
    assert dumps(program).encode("latin-1") == data


@pytest.mark.parametrize("path", INPUTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_round_trip_with_crlf_and_latin1(path: Path, tmp_path: Path):
    # whatever line ends the checkout has, check both styles and every Latin-1 byte
    data = path.read_bytes().replace(b"\r\n", b"\n")
    first_nl = data.index(b"\n")
    latin = bytes(range(0x80, 0x100))
    comment = b"!" if dialect_for(path) == "rapid" else b";"
    body = data[:first_nl] + b"\n" + comment + b" " + latin + data[first_nl:]
    for nl in (b"\n", b"\r\n"):
        variant = body.replace(b"\n", nl)
        out = tmp_path / f"x{path.suffix}"
        out.write_bytes(variant)
        program = load(out)
        assert program.newline == nl.decode()
        assert dumps(program).encode("latin-1") == variant
        dump(program, [], tmp_path / f"copy{path.suffix}")
        assert (tmp_path / f"copy{path.suffix}").read_bytes() == variant


def test_edit_changes_only_that_number():
    path = ROOT / "samples" / "cell_a.mod"
    data = path.read_bytes()
    program = load(path)
    t = program.target("p20")
    new_x = t.position_mm()[0] + 0.1234
    edits = target_edits(t, position_mm=[new_x, *t.position_mm()[1:]])
    assert len(edits) == 1
    out = dumps(program, edits).encode("latin-1")
    x = t.position[0]
    assert out[:x.start] == data[:x.start]
    assert out[x.start:x.start + len("1100.123")] == b"1100.123"
    assert out[x.start + len("1100.123"):] == data[x.end:]
    again = loads(out, "rapid")
    assert again.target("p20").position_mm()[0] == pytest.approx(new_x, abs=5e-4)
    assert again.target("p20").texts[1:] == t.texts[1:]


def test_every_target_edited_round_trips_through_the_parser():
    program = load(ROOT / "samples" / "cell_a.mod")
    rng = np.random.default_rng(0)
    edits, wanted = [], {}
    for t in program.targets:
        p = t.position_mm() + rng.normal(0, 1.0, 3)
        q = t.orientation_values() + rng.normal(0, 1e-3, 4)
        q /= np.linalg.norm(q)
        edits += target_edits(t, position_mm=p, orientation=q)
        wanted[t.span[0]] = (p, q)
    again = loads(dumps(program, edits), "rapid")
    assert len(again.targets) == len(program.targets)
    for old, new in zip(program.targets, again.targets):
        p, q = wanted[old.span[0]]
        assert new.name == old.name and new.location.line == old.location.line
        np.testing.assert_allclose(new.position_mm(), p, atol=5e-4)
        np.testing.assert_allclose(new.orientation_values(), q, atol=5e-7)
        assert new.texts[7:] == old.texts[7:]  # config and external axes untouched


def test_dump_refuses_to_overwrite_its_input(tmp_path: Path):
    src = tmp_path / "a.mod"
    src.write_bytes((ROOT / "samples" / "cell_a.mod").read_bytes())
    program = load(src)
    with pytest.raises(ValueError, match="overwrite"):
        dump(program, [], src)


@pytest.mark.parametrize("name, dialect", [
    ("a.mod", "rapid"), ("B.MODX", "rapid"), ("c.Prg", "rapid"), ("user.sys", "rapid"),
    ("d.pg", "vplus"), ("e.V2", "vplus"), ("f.lc", "vplus"), ("g.loc", "vplus"),
    ("h.as", "vplus")])
def test_dialect_from_extension(name, dialect):
    assert dialect_for(name) == dialect


def test_unknown_extension_is_a_parse_error():
    from olp_compensate.errors import ParseError
    with pytest.raises(ParseError, match="unknown program extension"):
        dialect_for("robot.txt")
