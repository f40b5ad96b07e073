"""Golden files: every folder of tests/programs/ holds one ``input.*`` program and an
``expected.json`` written by hand from reading the input. Only the keys present in the
expected file are compared, so a case can pin just what it is about."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.compensation.program import compensate_program
from olp_compensate.errors import ParseError
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import load

CASES = sorted(p for p in (Path(__file__).parent / "programs").iterdir() if p.is_dir())


def _input(case: Path) -> Path:
    (found,) = [p for p in case.iterdir() if p.name.startswith("input.")]
    return found


def _texts(numbers):
    return [n.text for n in numbers]


def _index(i):
    return list(i) if isinstance(i, tuple) else i


def summary(program) -> dict:
    """The program in the vocabulary of the expected files."""
    return {
        "dialect": program.dialect,
        "newline": program.newline,
        "modules": list(program.modules),
        "targets": [dict(
            name=t.name, line=t.location.line, column=t.location.column, storage=t.storage,
            index=_index(t.array_index), routine=t.routine, numbers=list(t.texts),
            position=_texts(t.position), orientation=_texts(t.orientation),
            config=_texts(t.config), external=_texts(t.external)) for t in program.targets],
        "joint_targets": [dict(
            name=t.name, line=t.location.line, column=t.location.column, storage=t.storage,
            index=_index(t.array_index), joints=_texts(t.joints),
            external=_texts(t.external)) for t in program.joint_targets],
        "tools": [dict(
            name=t.name, line=t.location.line, robhold=t.robhold, position=_texts(t.position),
            orientation=_texts(t.orientation), mass=t.mass.text if t.mass else None)
            for t in program.tools],
        "wobjs": [dict(
            name=w.name, line=w.location.line, robhold=w.robhold, ufprog=w.ufprog,
            ufmec=w.ufmec, uframe_position=_texts(w.uframe_position),
            uframe_orientation=_texts(w.uframe_orientation),
            oframe_position=_texts(w.oframe_position),
            oframe_orientation=_texts(w.oframe_orientation)) for w in program.wobjs],
        "motions": [dict(
            instruction=m.instruction, line=m.location.line, column=m.location.column,
            role=m.role, target=m.target_name, index=_index(m.target_index),
            inline=m.inline is not None, runtime=m.runtime is not None, tool=m.tool,
            tool_inline=m.tool_inline is not None, wobj=m.wobj, joint=m.joint,
            routine=m.routine) for m in program.motions],
        "runtime": [dict(line=r.location.line, base=r.base_name, expression=r.expression)
                    for r in program.runtime],
        "references": [dict(name=r.name, line=r.location.line, context=r.context)
                       for r in program.references],
        "routines": [dict(name=r.name, kind=r.kind, line=r.location.line,
                          parameters=list(r.parameters)) for r in program.routines],
    }


def _match(expected, actual, where: str) -> None:
    if isinstance(expected, dict):
        assert isinstance(actual, dict), f"{where}: expected an object, got {actual!r}"
        for key, value in expected.items():
            assert key in actual, f"{where}: no key {key!r} in the summary"
            _match(value, actual[key], f"{where}.{key}")
    elif isinstance(expected, list) and expected and isinstance(expected[0], dict):
        assert len(actual) == len(expected), \
            f"{where}: expected {len(expected)} items, got {len(actual)}: {actual!r}"
        for k, (e, a) in enumerate(zip(expected, actual)):
            _match(e, a, f"{where}[{k}]")
    else:
        assert actual == expected, f"{where}: expected {expected!r}, got {actual!r}"


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_golden(case: Path):
    expected = json.loads((case / "expected.json").read_text("utf-8"))
    path = _input(case)
    if "error" in expected:
        with pytest.raises(ParseError) as info:
            load(path)
        err, want = info.value, expected["error"]
        assert err.file == str(path)
        assert err.line == want["line"], str(err)
        if "column" in want:
            assert err.column == want["column"], str(err)
        assert want["message_contains"] in err.message, str(err)
        assert err.context and err.context.splitlines()[-1].strip() == "^"
        return
    program = load(path)
    _match({k: v for k, v in expected.items() if k != "report"}, summary(program), case.name)
    if "report" in expected:
        _match_report(expected["report"], program, case.name)
    for t in program.targets + program.joint_targets:  # every span points at its text
        for n in t.numbers:
            assert program.text[n.start:n.end] == n.text


def test_every_feature_group_has_a_case():
    names = {c.name for c in CASES}
    for prefix in ("rapid_declarations", "rapid_arrays", "rapid_motions", "rapid_control_flow",
                   "rapid_runtime", "rapid_crlf_latin1", "vplus_locations", "vplus_program",
                   "rapid_error_", "vplus_error_"):
        assert any(n.startswith(prefix) for n in names), prefix


def _match_report(expected: list, program, where: str) -> None:
    """The report rows of the program compensated on the nominal IRB 2400, in text order:
    target, line, column, status (and tool, wobj, a piece of the note where given); the
    nominal calibration changes no byte."""
    text, report = compensate_program(program, None,
                                      nominal_calibration(load_robot("abb_irb2400")))
    assert text == program.text, f"{where}: the nominal calibration changed the text"
    rows = [dict(target=r.target, line=r.line, column=r.column, status=r.status,
                 tool=r.tool, wobj=r.wobj, note=r.note) for r in report.rows]
    assert len(rows) == len(expected), f"{where}.report: {rows!r}"
    for k, (want, row) in enumerate(zip(expected, rows)):
        for key, value in want.items():
            if key == "note_contains":
                assert value in row["note"], f"{where}.report[{k}]: {row!r}"
            else:
                assert row[key] == value, f"{where}.report[{k}].{key}: {row!r}"
