"""Golden files: every folder of tests/programs/ holds one ``input.*`` program (a KRL case:
``input.src`` and ``input.dat``, read and written as a pair) and an ``expected.json`` written
by hand from reading the input. Only the keys present in the expected file are compared, so
a case can pin just what it is about.

RAPID and V+/AS cases (``rapid_*``, ``vplus_*``, ``as_*``) are summarised from
:func:`olp_compensate.programs.load`; the pose dialects (``krl_*``, ``fanuc_*``, ``val3_*``,
``urscript_*``) from their parsers, and their reports come from
:func:`~olp_compensate.compensation.files.compensate_files` with the nominal calibration of
a robot of that maker, which must give back every byte of every input file."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.compensation.files import ProgramFiles, compensate_files
from olp_compensate.errors import ParseError
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import load
from olp_compensate.programs.object_model.task import compensate_program

CASES = sorted(p for p in (Path(__file__).parent / "programs").iterdir() if p.is_dir())
POSE_PREFIXES = {"krl_": "krl", "fanuc_": "fanuc", "val3_": "val3", "urscript_": "urscript"}
MAKER_ROBOT = {"krl": "kuka_kr16_2", "fanuc": "fanuc_r2000ic_165f", "val3": "staubli_tx2_60",
               "urscript": "ur10e"}


def _input(case: Path) -> Path:
    (found,) = [p for p in case.iterdir() if p.name.startswith("input.")]
    return found


def _pose_dialect(case: Path) -> str | None:
    return next((d for prefix, d in POSE_PREFIXES.items() if case.name.startswith(prefix)),
                None)


def _pose_inputs(case: Path, dialect: str) -> list[Path]:
    """The case's input files (KRL: ``input.src`` then ``input.dat``, either may be
    absent)."""
    found = sorted(p for p in case.iterdir() if p.name.startswith("input."))
    if dialect == "krl":
        found.sort(key=lambda p: p.suffix.lower() != ".src")
    else:
        assert len(found) == 1, f"{case.name}: one input.* expected, found {found}"
    return found


def parse_pose_case(paths: list[Path], dialect: str):
    """The PoseProgram of a case's files, named by their file names (as the CLI reads
    them: latin-1, every byte kept)."""
    texts = {p.name: p.read_bytes().decode("latin-1") for p in paths}
    if dialect == "krl":
        from olp_compensate.programs.krl.reader import parse_krl

        by_ext = {p.suffix.lower(): p.name for p in paths}
        src, dat = by_ext.get(".src"), by_ext.get(".dat")
        return parse_krl(texts[src] if src else None, texts[dat] if dat else None,
                         src or "<src>", dat or "<dat>")
    (name, text), = texts.items()
    if dialect == "fanuc":
        from olp_compensate.programs.fanuc.reader import parse_fanuc_tp

        return parse_fanuc_tp(text, name)
    if dialect == "val3":
        from olp_compensate.programs.val3.reader import parse_val3

        return parse_val3({name: text})
    from olp_compensate.programs.urscript.reader import parse_urscript

    return parse_urscript(text, name)


def pose_summary(program) -> dict:
    """A pose-dialect program in the vocabulary of the expected files."""
    return {
        "dialect": program.dialect,
        "files": list(program.texts),
        "targets": [dict(
            name=t.name, file=t.source[0], line=t.source[1], column=t.source[2], kind=t.kind,
            numbers=_texts(t.numbers), config=_texts(t.config),
            config_text=t.config_text.text if t.config_text is not None else None,
            frame=list(t.frame) if t.frame is not None else None) for t in program.targets],
        "motions": [dict(
            instruction=m.instruction, target=m.target, file=m.source[0], line=m.source[1],
            column=m.source[2], tool=m.tool, base=m.base, inline=m.inline,
            runtime=m.runtime is not None) for m in program.motions],
        "unknown": [dict(instruction=i, file=w[0], line=w[1], column=w[2])
                    for w, i in program.unknown],
        "frames": sorted(program.frames),
        "notes": list(program.notes),
    }


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
    dialect = _pose_dialect(case)
    if dialect is not None:
        _pose_golden(case, dialect, expected)
        return
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


def _pose_golden(case: Path, dialect: str, expected: dict) -> None:
    paths = _pose_inputs(case, dialect)
    if "error" in expected:
        with pytest.raises(ParseError) as info:
            parse_pose_case(paths, dialect)
        err, want = info.value, expected["error"]
        assert err.file == want.get("file", paths[0].name), str(err)
        assert err.line == want["line"], str(err)
        if "column" in want:
            assert err.column == want["column"], str(err)
        assert want["message_contains"] in err.message, str(err)
        with pytest.raises(ParseError):               # the library refuses it too
            _compensate_case(paths, dialect)
        return
    program = parse_pose_case(paths, dialect)
    _match({k: v for k, v in expected.items() if k != "report"}, pose_summary(program),
           case.name)
    for t in program.targets:                    # every span points at its text
        text = program.texts[t.source[0]]
        for n in (*t.numbers, *t.config):
            if n.end > n.start:
                assert text[n.start:n.end] == n.text, (t.name, n)
    data, report = _compensate_case(paths, dialect)
    for path, new in zip(paths, data):            # the nominal calibration changes no byte
        assert new == path.read_bytes(), f"{case.name}: {path.name} changed"
    if "report" in expected:
        rows = [dict(target=r.target, file=r.file, line=r.line, column=r.column,
                     status=r.status, tool=r.tool, wobj=r.wobj, note=r.note)
                for r in report.rows]
        assert len(rows) == len(expected["report"]), f"{case.name}.report: {rows!r}"
        for k, (want, row) in enumerate(zip(expected["report"], rows)):
            for key, value in want.items():
                if key == "note_contains":
                    assert value in row["note"], f"{case.name}.report[{k}]: {row!r}"
                else:
                    assert row[key] == value, f"{case.name}.report[{k}].{key}: {row!r}"


def _compensate_case(paths: list[Path], dialect: str):
    """(new bytes of each file, report) with the nominal calibration of the maker's robot,
    through the library entry the CLI uses."""
    files = ProgramFiles(dialect=dialect, paths=tuple(paths),
                         names=tuple(p.name for p in paths))
    result = compensate_files(files, nominal_calibration(load_robot(MAKER_ROBOT[dialect])))
    return result.data, result.report


def test_every_feature_group_has_a_case():
    names = {c.name for c in CASES}
    for prefix in ("rapid_declarations", "rapid_arrays", "rapid_motions", "rapid_control_flow",
                   "rapid_runtime", "rapid_crlf_latin1", "vplus_locations", "vplus_program",
                   "rapid_error_", "vplus_error_", "krl_", "krl_error_", "fanuc_",
                   "fanuc_error_", "val3_", "val3_error_", "urscript_"):
        assert any(n.startswith(prefix) for n in names), prefix


def test_every_pose_dialect_case_has_its_inputs():
    for case in CASES:
        dialect = _pose_dialect(case)
        if dialect is None:
            continue
        want = {"krl": {".src", ".dat"}, "fanuc": {".ls"}, "val3": {".dtx"},
                "urscript": {".script"}}[dialect]
        suffixes = {p.suffix.lower() for p in _pose_inputs(case, dialect)}
        assert suffixes <= want and suffixes, (case.name, suffixes)


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
