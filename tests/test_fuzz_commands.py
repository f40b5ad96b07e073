"""Mutated inputs through every command, in-process: no traceback, exit 0, 2 or 1 with one
line, inputs untouched, no partial or temporary output.

Mutations: deleted, duplicated and swapped lines, flipped bytes, truncation, huge and
non-finite numbers, byte-order marks, ``;`` separators and decimal commas. Examples per
command: 30, or ``OLP_FUZZ_EXAMPLES``.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from olp_compensate.cli.cal import main as cal
from olp_compensate.cli.fix import main as fix

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples"
PROGRAMS = sorted(p for p in (ROOT / "tests" / "programs").glob("*/input.*")
                  if "error" not in p.parent.name)
EXAMPLES = int(os.environ.get("OLP_FUZZ_EXAMPLES", "30"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
NUMBER = re.compile(rb"-?\d+\.\d+|-?\d+")
STRANGE = [b"nan", b"inf", b"-inf", b"1e308", b"-1e308", b"1e6", b"NaN", b"", b"0", b"1,5"]


@st.composite
def mutated(draw, data: bytes) -> bytes:
    """``data`` with one to three mutations."""
    for _ in range(draw(st.integers(1, 3))):
        lines = data.split(b"\n")
        kind = draw(st.sampled_from(["delete", "duplicate", "swap", "flip", "truncate",
                                     "number", "bom", "semicolon"]))
        k = draw(st.integers(0, max(len(lines) - 1, 0)))
        if kind == "delete" and lines:
            del lines[k]
        elif kind == "duplicate" and lines:
            lines.insert(k, lines[k])
        elif kind == "swap" and len(lines) > 1:
            j = draw(st.integers(0, len(lines) - 1))
            lines[k], lines[j] = lines[j], lines[k]
        data = b"\n".join(lines)
        if kind == "flip" and data:
            at = draw(st.integers(0, len(data) - 1))
            data = data[:at] + bytes([data[at] ^ draw(st.integers(1, 255))]) + data[at + 1:]
        elif kind == "truncate":
            data = data[:draw(st.integers(0, len(data)))]
        elif kind == "number":
            found = list(NUMBER.finditer(data))
            if found:
                m = found[draw(st.integers(0, len(found) - 1))]
                data = data[:m.start()] + draw(st.sampled_from(STRANGE)) + data[m.end():]
        elif kind == "bom":
            data = b"\xef\xbb\xbf" + data
        elif kind == "semicolon":
            data = data.replace(b",", b";").replace(b".", b",")
    return data


@pytest.fixture(scope="module")
def nominal_model(tmp_path_factory) -> bytes:
    path = tmp_path_factory.mktemp("model") / "c.json"
    assert cal(["nominal", "--robot", "abb_irb2400", "-o", str(path)]) == 0
    return path.read_bytes()


@pytest.fixture(scope="module")
def puma_model(tmp_path_factory) -> bytes:
    path = tmp_path_factory.mktemp("model") / "c.json"
    assert cal(["nominal", "--robot", "unimation_puma560", "-o", str(path)]) == 0
    return path.read_bytes()


def check_run(command, argv_of, inputs: dict[str, bytes], outputs: list[str]) -> None:
    """Write ``inputs`` into a fresh folder, run ``command(argv_of(folder))`` and check the
    rules of the module docstring."""
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        for file, data in inputs.items():
            (folder / file).write_bytes(data)
        err, out = io.StringIO(), io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            code = command(argv_of(folder))   # an exception here is a traceback: a failure
        message = err.getvalue()
        assert "Traceback" not in message, message
        assert code in (0, 1, 2), (code, message)
        assert "the computation failed on these data" not in message, message
        for file, data in inputs.items():
            assert (folder / file).read_bytes() == data, f"{file} changed"
        left = [p.name for p in folder.iterdir() if ".olp-" in p.name or p.name.endswith(".tmp")]
        assert not left, left
        if code == 1:
            errors = [ln for ln in message.splitlines() if ": error: " in ln]
            assert len(errors) == 1, message
            assert not [o for o in outputs if (folder / o).exists()], message
        else:
            assert all((folder / o).exists() for o in outputs), message


MEAS = (SAMPLES / "irb2400_measurements.csv").read_bytes()
MARKS = (SAMPLES / "marks.csv").read_bytes()
JOINTS = (SAMPLES / "joints.csv").read_bytes()


@FUZZ
@given(data=mutated(MEAS))
def test_identify(data):
    check_run(cal, lambda f: ["identify", str(f / "m.csv"), "--robot", "abb_irb2400",
                              "--folds", "0", "-o", str(f / "c.json")],
              {"m.csv": data}, ["c.json"])


@FUZZ
@given(joints=mutated(JOINTS), which=st.booleans(), data=st.data())
def test_predict(nominal_model, joints, which, data):
    model = data.draw(mutated(nominal_model)) if which else nominal_model
    check_run(cal, lambda f: ["predict", "--model", str(f / "c.json"), str(f / "j.csv"),
                              "-o", str(f / "p.csv")],
              {"c.json": model, "j.csv": joints}, ["p.csv"])


@FUZZ
@given(joints=mutated(JOINTS))
def test_simulate_and_plan(joints):
    check_run(cal, lambda f: ["simulate", "--robot", "abb_irb2400", "--joints",
                              str(f / "j.csv"), "-o", str(f / "m.csv")],
              {"j.csv": joints}, ["m.csv"])
    check_run(cal, lambda f: ["plan", "--robot", "abb_irb2400", "--poses", "2", "--from",
                              str(f / "j.csv"), "-o", str(f / "p.csv")],
              {"j.csv": joints}, ["p.csv"])


@FUZZ
@given(marks=mutated(MARKS))
def test_tool(marks):
    check_run(cal, lambda f: ["tool", "--robot", "abb_irb2400", "--marks", str(f / "k.csv"),
                              "-o", str(f / "t.json")],
              {"k.csv": marks}, ["t.json"])


@FUZZ
@given(data=st.data())
def test_export_urdf(nominal_model, data):
    model = data.draw(mutated(nominal_model))
    check_run(cal, lambda f: ["export-urdf", "--model", str(f / "c.json"), "-o",
                              str(f / "x.urdf")],
              {"c.json": model}, ["x.urdf"])


@FUZZ
@given(index=st.integers(0, max(len(PROGRAMS) - 1, 0)), mutate_model=st.booleans(),
       data=st.data())
def test_olp_fix(nominal_model, puma_model, index, mutate_model, data):
    program = PROGRAMS[index]
    assume(program.exists())   # the golden set may change while the suite runs
    model = puma_model if program.suffix != ".mod" else nominal_model
    if mutate_model:
        model = data.draw(mutated(model))
    text = data.draw(mutated(program.read_bytes()))
    name = "p" + program.suffix
    check_run(fix, lambda f: [str(f / name), "--model", str(f / "c.json"), "-o",
                              str(f / ("out" + program.suffix)), "--report",
                              str(f / "r.csv")],
              {name: text, "c.json": model}, ["out" + program.suffix, "r.csv"])
