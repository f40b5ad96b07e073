"""Damaged files of the pose dialects and of V+/AS (issue 25 item 5): binary, UTF-16, cut
short, malformed or non-finite numbers, fragments. Each is refused by olp-fix with exit 1,
one line with file:line:column, and no output written."""

from __future__ import annotations

from pathlib import Path

import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.cli.fix import main
from olp_compensate.io.calibration_file import write_calibration
from olp_compensate.kinematics.robot import load_robot

PROGRAMS = Path(__file__).parent / "programs"
SAMPLES = {
    "val3": ("staubli_tx2_60", PROGRAMS / "val3_value_attributes" / "input.dtx"),
    "fanuc": ("fanuc_r2000ic_165f", PROGRAMS / "fanuc_frames_and_motions" / "input.ls"),
    "urscript": ("ur10e", PROGRAMS / "urscript_polyscope_export" / "input.script"),
    "as": ("unimation_puma560", PROGRAMS / "vplus_kawasaki" / "input.as"),
    "krl": ("kuka_kr16_2", PROGRAMS / "krl_inline_forms" / "input.dat"),
}


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    folder = tmp_path_factory.mktemp("models")
    out = {}
    for dialect, (robot, _) in SAMPLES.items():
        out[dialect] = folder / f"{robot}.json"
        write_calibration(out[dialect], nominal_calibration(load_robot(robot)))
    return out


def _position(data: bytes, offset: int) -> tuple[int, int]:
    """1-based (line, column) of byte ``offset`` (lines end at LF): this test's own count."""
    line = data.count(b"\n", 0, offset) + 1
    return line, offset - (data.rfind(b"\n", 0, offset) + 1) + 1


def _refused(tmp_path, capsys, models, dialect, data: bytes) -> str:
    _, sample = SAMPLES[dialect]
    program = tmp_path / sample.name
    program.write_bytes(data)
    out = tmp_path / f"out{sample.suffix}"
    capsys.readouterr()
    assert main([str(program), "--model", str(models[dialect]), "-o", str(out), "-q"]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert not out.exists() and "Traceback" not in err
    return err


@pytest.mark.parametrize("dialect", sorted(SAMPLES))
def test_binary_bytes_are_refused_at_the_first(dialect, tmp_path, capsys, models):
    data = SAMPLES[dialect][1].read_bytes()
    at = data.index(b"\n", 40) + 3
    bad = data[:at] + bytes(range(32)) * 4 + data[at:]
    err = _refused(tmp_path, capsys, models, dialect, bad)
    line, column = _position(bad, at)
    assert f":{line}:{column}: binary or encrypted file" in err, err


@pytest.mark.parametrize("dialect", sorted(SAMPLES))
def test_utf16_is_refused(dialect, tmp_path, capsys, models):
    text = SAMPLES[dialect][1].read_bytes().decode("latin-1")
    err = _refused(tmp_path, capsys, models, dialect, text.encode("utf-16"))
    assert ":1:1: the file is UTF-16 text" in err, err


@pytest.mark.parametrize("dialect, cut_after, words", [
    ("val3", b'rz="-51.7524" sho', "cut short"),
    ("fanuc", b"W =   180.000 deg", "cut short"),
    ("urscript", b"movej(get_inverse_kin(Waypoint_1_p", "cut short"),
    ("krl", b"DECL E6AXIS XHOME={A1 0.0", "cut short"),
    ("krl", b"DECL FDAT FHOME=", "DEFDAT without ENDDAT: the file is cut short"),
])
def test_a_file_cut_short_is_refused(dialect, cut_after, words, tmp_path, capsys, models):
    data = SAMPLES[dialect][1].read_bytes()
    assert cut_after in data
    cut = data[:data.index(cut_after) + len(cut_after)]
    err = _refused(tmp_path, capsys, models, dialect, cut)
    assert words in err, err


def test_a_val3_fragment_of_bare_points_is_refused(tmp_path, capsys, models):
    fragment = (b'<valuePoint index="0"><tpValue x="1" y="2" z="3" rx="0" ry="0" rz="0" />'
                b'</valuePoint>\n<valuePoint index="1"><tpValue x="4" y="5" z="6" rx="0" '
                b'ry="0" rz="0" /></valuePoint>\n')
    err = _refused(tmp_path, capsys, models, "val3", fragment)
    assert ":2:1: not well-formed VAL3 data (.dtx): junk after document element" in err, err


@pytest.mark.parametrize("dialect, old, new", [
    ("fanuc", b"X =  1800.000  mm", b"X =  1.8E+  mm"),
    ("fanuc", b"X =  1800.000  mm", b"X =  nan  mm"),
    ("val3", b'x="297.928"', b'x="2.9E+"'),
    ("val3", b'x="297.928"', b'x="nan"'),
])
def test_malformed_numbers_are_refused_at_their_place(dialect, old, new, tmp_path, capsys,
                                                      models):
    data = SAMPLES[dialect][1].read_bytes()
    if old not in data:
        pytest.skip("sample without that value")
    bad = data.replace(old, new, 1)
    err = _refused(tmp_path, capsys, models, dialect, bad)
    at = bad.index(new) + len(new) - len(new.lstrip(b"X =x\""))
    line, column = _position(bad, at)
    assert f":{line}:{column}:" in err, err
