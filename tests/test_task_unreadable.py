"""A RAPID task with modules that cannot be read (encrypted, templates, fragments) is
compensated module by module as far as it can be: the readable modules exactly as without
the unreadable ones, each unreadable module copied byte for byte and reported with its
position, the names only it declares 'unresolved' naming it, the report always written."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import pytest

from olp_compensate.cli.fix import main
from olp_compensate.io.calibration_file import write_calibration
from test_compensate import World

FOLDER = Path(__file__).parent / "tasks" / "cell_task"
ENCRYPTED = (b"MODULE Lic (SYSMODULE, NOSTEPIN)\r\n! licence module, encrypted body\r\n"
             b"\x01\x9c\xfe\x02ENC\x00\x7f" * 3 + b"\r\nENDMODULE\r\n")
TEMPLATE = b"MODULE <%= module_name %>\n  PROC main()\n    <%= moves %>\n  ENDPROC\nENDMODULE\n"
FRAGMENT = b"  MoveL p10,v100,z1,tGun;\n  MoveL p20,v100,fine,tGun;\n"


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    path = tmp_path_factory.mktemp("unreadable") / "a.json"
    write_calibration(path, World("abb_irb2400", seed=5).calibration)
    return path


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _run(task: Path, model: Path, out: Path, report: Path) -> int:
    return main([str(task), "--model", str(model), "-o", str(out), "--report", str(report),
                 "-q", "-j", "1"])


def test_readable_modules_are_compensated_as_without_the_unreadable_ones(tmp_path, model):
    plain, mixed = tmp_path / "plain" / "TASK1", tmp_path / "mixed" / "TASK1"
    shutil.copytree(FOLDER, plain)
    shutil.copytree(FOLDER, mixed)
    (mixed / "Lic.sys").write_bytes(ENCRYPTED)
    (mixed / "Template.mod").write_bytes(TEMPLATE)
    (mixed / "Moves.mod").write_bytes(FRAGMENT)
    assert _run(plain, model, tmp_path / "out_plain", tmp_path / "plain.csv") == 2
    code = _run(mixed, model, tmp_path / "out_mixed", tmp_path / "mixed.csv")
    assert code == 2                                   # reported, as other targets are
    for module in FOLDER.iterdir():
        assert ((tmp_path / "out_mixed" / module.name).read_bytes()
                == (tmp_path / "out_plain" / module.name).read_bytes()), module.name
    for name in ("Weld.mod", "Pick.mod"):              # the motions' modules: compensated
        assert (tmp_path / "out_mixed" / name).read_bytes() != (FOLDER / name).read_bytes()
    for name in ("Lic.sys", "Template.mod", "Moves.mod"):    # copied, nothing lost
        assert (tmp_path / "out_mixed" / name).read_bytes() == (mixed / name).read_bytes()
    rows = _rows(tmp_path / "mixed.csv")
    unreadable = {r["file"]: r for r in rows if r["status"] == "unreadable"}
    assert set(unreadable) == {"Lic.sys", "Template.mod", "Moves.mod"}
    # the position given points at a control byte of the encrypted body (line 3)
    lic = unreadable["Lic.sys"]
    assert lic["line"] == "3"
    assert ENCRYPTED.split(b"\r\n")[2][int(lic["column"]) - 1] < 0x20
    assert unreadable["Template.mod"]["line"] == "1"
    assert all("copied unchanged" in r["note"] for r in unreadable.values())
    others = [r for r in rows if r["status"] != "unreadable"]
    assert [(r["target"], r["file"], r["status"]) for r in others] == [
        (r["target"], r["file"], r["status"]) for r in _rows(tmp_path / "plain.csv")]


def test_names_declared_only_in_an_unreadable_module_are_unresolved_naming_it(tmp_path,
                                                                               model):
    """CalibData.mod (the tools) made unreadable: every motion with tGun or tGrip (but
    the run-time Offs one) is unresolved and its note names CalibData.mod; the report is
    written; exit 2."""
    task = tmp_path / "TASK1"
    shutil.copytree(FOLDER, task)
    calib = task / "CalibData.mod"
    calib.write_bytes(calib.read_bytes().replace(b"! the cell", b"\x00\x01 the cell"))
    report = tmp_path / "r.csv"
    assert _run(task, model, tmp_path / "out", report) == 2
    rows = _rows(report)
    tools = [r for r in rows if r["tool"] in ("tGun", "tGrip") and r["status"] != "runtime"]
    assert tools and all(r["status"] == "unresolved" for r in tools)
    assert all("CalibData.mod, which could not be read" in r["note"] for r in tools)
    assert (tmp_path / "out" / "CalibData.mod").read_bytes() == calib.read_bytes()
    assert [r["file"] for r in rows if r["status"] == "unreadable"] == ["CalibData.mod"]


def test_a_task_of_unreadable_modules_only_is_refused(tmp_path, model, capsys):
    task = tmp_path / "TASK1"
    task.mkdir()
    (task / "Lic.sys").write_bytes(ENCRYPTED)
    (task / "Template.mod").write_bytes(TEMPLATE)
    assert _run(task, model, tmp_path / "out", tmp_path / "r.csv") == 1
    err = capsys.readouterr().err
    assert "olp-fix: error: " in err and "Traceback" not in err
    assert "Lic.sys:3:1" in err or "Template.mod:1:" in err
    assert not (tmp_path / "out").exists()
