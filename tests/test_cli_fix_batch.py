"""olp-fix over several programs: folders and backups mirrored into -o, dialects detected per
file, KRL .src/.dat pairs written together, -j N processes giving the same bytes as one,
a failing file reported while the others go on."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.cli.fix import main
from olp_compensate.io.calibration_file import write_calibration
from olp_compensate.kinematics.robot import load_robot

SAMPLES = Path(__file__).resolve().parents[1] / "samples"


@pytest.fixture(scope="module")
def backup(tmp_path_factory):
    """A controller-backup-like tree of several dialects, and the IRB 2400 nominal model."""
    root = tmp_path_factory.mktemp("backup")
    tree = root / "BACKUP"
    (tree / "RAPID" / "TASK1" / "PROGMOD").mkdir(parents=True)
    (tree / "KRL" / "R1" / "Program").mkdir(parents=True)
    shutil.copy(SAMPLES / "cell_a.mod", tree / "RAPID" / "TASK1" / "PROGMOD" / "cell_a.mod")
    (tree / "cell_b.pg").write_bytes(irb2400_vplus())
    from test_programs_krl import _program_joints, _targets_at, krl_module

    src, dat = krl_module(_targets_at(_program_joints(3, 4)))
    (tree / "KRL" / "R1" / "Program" / "Cell.src").write_bytes(src.encode("latin-1"))
    (tree / "KRL" / "R1" / "Program" / "Cell.dat").write_bytes(dat.encode("latin-1"))
    (tree / "notes.txt").write_text("not a program")
    model = root / "nominal.json"
    write_calibration(model, nominal_calibration(load_robot("abb_irb2400")))
    return tree, model


def irb2400_vplus() -> bytes:
    """The V+ sample with its precision points moved inside the IRB 2400's axis ranges (as
    taught on it: the PUMA's own are not, and olp-fix refuses them on an IRB 2400)."""
    text = (SAMPLES / "cell_b.pg").read_bytes()
    for old, new in ((b"#PPOINT(0.0, 60.0, -120.0, 0.0, 30.0, 0.0)",
                      b"#PPOINT(0.0, 30.0, -20.0, 0.0, 30.0, 0.0)"),
                     (b"#ready         0.000    90.000   -90.000",
                      b"#ready         0.000    40.000   -30.000"),
                     (b"#park         90.000   135.000  -160.000",
                      b"#park         90.000    35.000   -50.000")):
        assert old in text
        text = text.replace(old, new)
    return text


def test_a_program_of_another_robot_in_a_backup_is_refused(backup, tmp_path, capsys):
    """A PUMA .pg (its taught precision points outside the IRB 2400's axis ranges) in a
    backup compensated with an IRB 2400 calibration: refused with the reason, the others
    written; a 5-axis precision point against the 6-axis arm the same."""
    tree, model = backup
    copy = tmp_path / "in"
    shutil.copytree(tree, copy)
    shutil.copy(SAMPLES / "cell_b.pg", copy / "puma.pg")
    (copy / "five.pg").write_bytes(b".PROGRAM five()\n    MOVE #a\n.END\n.LOCATIONS\n"
                                   b"#a  0.0 10.0 -10.0 0.0 30.0\n.END\n")
    out = tmp_path / "out"
    assert main([str(copy), "--model", str(model), "-o", str(out), "-j", "1", "-q"]) == 1
    err = capsys.readouterr().err
    assert "puma.pg:" in err and "outside abb_irb2400's range" in err
    assert "taught on another robot" in err
    assert "five.pg:" in err and "5 joint values" in err and "6 axes" in err
    assert not (out / "puma.pg").exists() and not (out / "five.pg").exists()
    assert (out / "cell_b.pg").read_bytes() == (copy / "cell_b.pg").read_bytes()


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_a_folder_is_mirrored_into_the_output_folder(backup, tmp_path, capsys):
    tree, model = backup
    out = tmp_path / "out"
    code = main([str(tree), "--model", str(model), "-o", str(out), "--report",
                 str(tmp_path / "r.csv"), "-j", "1"])
    assert code == 2                      # cell_a has joint_limit targets
    written = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert written == ["KRL/R1/Program/Cell.dat", "KRL/R1/Program/Cell.src",
                       "RAPID/TASK1/PROGMOD/cell_a.mod", "cell_b.pg"]
    # nominal calibration: every program comes back byte for byte
    for rel in written:
        assert (out / rel).read_bytes() == (tree / rel).read_bytes(), rel
    files = {r["file"] for r in _rows(tmp_path / "r.csv")}
    assert {"RAPID/TASK1/PROGMOD/cell_a.mod", "cell_b.pg", "KRL/R1/Program/Cell.dat"} <= files
    text = capsys.readouterr().out
    assert "3 programs" in text and "statuses:" in text


def test_two_processes_write_what_one_writes(backup, tmp_path):
    tree, model = backup
    for jobs in ("1", "2"):
        assert main([str(tree), "--model", str(model), "-o", str(tmp_path / jobs), "--report",
                     str(tmp_path / f"{jobs}.csv"), "-j", jobs, "-q"]) == 2
    one = sorted(p.relative_to(tmp_path / "1") for p in (tmp_path / "1").rglob("*.*"))
    for rel in one:
        assert (tmp_path / "1" / rel).read_bytes() == (tmp_path / "2" / rel).read_bytes()
    assert (tmp_path / "1.csv").read_bytes() == (tmp_path / "2.csv").read_bytes()


def test_a_krl_pair_named_by_its_src_is_written_as_a_pair(backup, tmp_path):
    tree, _ = backup
    model = tmp_path / "kr16.json"
    write_calibration(model, nominal_calibration(load_robot("kuka_kr16_2")))
    config = tmp_path / "$config.dat"
    from test_programs_krl import CONFIG_DAT

    config.write_text(CONFIG_DAT)
    src = tree / "KRL" / "R1" / "Program" / "Cell.src"
    out = tmp_path / "Fixed.src"
    assert main([str(src), "--model", str(model), "-o", str(out), "--config", str(config),
                 "-q"]) == 0
    # KSS loads a module only when DEF/DEFDAT name its files: renamed, every other byte kept
    assert out.read_bytes() == src.read_bytes().replace(b"DEF CELL(", b"DEF Fixed(", 1)
    assert (tmp_path / "Fixed.dat").read_bytes() == src.with_suffix(".dat").read_bytes(
        ).replace(b"DEFDAT  CELL", b"DEFDAT  Fixed", 1)
    text = out.read_text(encoding="latin-1")
    assert text.count("Fixed") == 1 and "DEF CELL" not in text


def test_a_failing_program_is_reported_and_the_others_go_on(backup, tmp_path, capsys):
    tree, model = backup
    broken = tmp_path / "in"
    shutil.copytree(tree, broken)
    (broken / "bad.mod").write_text("MODULE bad\n  PROC main()\n    MoveL [[1,2,3],;\nENDMODULE\n")
    out = tmp_path / "out"
    assert main([str(broken), "--model", str(model), "-o", str(out), "-j", "1", "-q"]) == 1
    assert not (out / "bad.mod").exists()
    assert (out / "cell_b.pg").read_bytes() == (broken / "cell_b.pg").read_bytes()
    assert "bad.mod" in capsys.readouterr().err


def test_an_output_folder_on_the_inputs_is_refused(backup, tmp_path, capsys):
    tree, model = backup
    copy = tmp_path / "in"
    shutil.copytree(tree, copy)
    before = {p: p.read_bytes() for p in copy.rglob("*") if p.is_file()}
    assert main([str(copy), "--model", str(model), "-o", str(copy), "-q"]) == 1
    assert "-o is the input folder" in capsys.readouterr().err   # refused before any read
    assert {p: p.read_bytes() for p in before} == before
    assert sorted(p for p in copy.rglob("*") if p.is_file()) == sorted(before)


def test_a_calibration_with_regions_and_region_forcing(tmp_path, capsys):
    """olp-fix with a calibration holding a local model: --region forces it (a nominal
    local model gives the input back), an unknown region is one line naming the known."""
    import dataclasses

    from olp_compensate.calibration.calibration import RegionBox, RegionCalibration

    robot = load_robot("abb_irb2400")
    nominal = nominal_calibration(robot)
    region = RegionCalibration(name="fixture", box=RegionBox(min_m=np.array([0.5, -0.5, 0.0]),
                                                             max_m=np.array([1.5, 0.5, 1.2])),
                               calibration=nominal)
    model = tmp_path / "regions.json"
    write_calibration(model, dataclasses.replace(nominal, regions=(region,)))
    program = SAMPLES / "cell_a.mod"
    out = tmp_path / "a.mod"
    for forced in ("fixture", "global"):
        assert main([str(program), "--model", str(model), "--region", forced, "-o", str(out),
                     "-q"]) == 2
        assert out.read_bytes() == program.read_bytes()
    assert main([str(program), "--model", str(model), "--region", "nowhere", "-o",
                 str(tmp_path / "b.mod"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "nowhere" in err and "fixture" in err
    assert not (tmp_path / "b.mod").exists()


def test_a_krl_pair_named_by_its_dat_writes_the_dat_to_o(backup, tmp_path):
    tree, _ = backup
    model = tmp_path / "kr16.json"
    write_calibration(model, nominal_calibration(load_robot("kuka_kr16_2")))
    dat = tree / "KRL" / "R1" / "Program" / "Cell.dat"
    out = tmp_path / "Fixed.dat"
    main([str(dat), "--model", str(model), "-o", str(out), "-q"])
    # the names inside follow the files' (KSS), every other byte as read
    assert out.read_bytes() == dat.read_bytes().replace(b"DEFDAT  CELL", b"DEFDAT  Fixed")
    assert (tmp_path / "Fixed.src").read_bytes() == dat.with_suffix(".src").read_bytes(
        ).replace(b"DEF CELL(", b"DEF Fixed(")


def test_a_task_folder_resolves_across_its_modules(tmp_path):
    """The golden task's modules, given as a folder: the tools of CalibData.mod and the work
    objects of WObjData.mod reach the motions of the others (no 'unresolved' but the one
    whose tool is declared nowhere), and every module comes back byte for byte."""
    task = Path(__file__).resolve().parent / "tasks" / "cell_task"
    model = tmp_path / "n.json"
    write_calibration(model, nominal_calibration(load_robot("abb_irb2400")))
    out = tmp_path / "out"
    main([str(task), "--model", str(model), "-o", str(out), "--report",
          str(tmp_path / "r.csv"), "-q"])
    for module in task.iterdir():
        if module.suffix.lower() in (".mod", ".sys"):
            assert (out / module.name).read_bytes() == module.read_bytes()
    unresolved = [r for r in _rows(tmp_path / "r.csv") if r["status"] == "unresolved"]
    assert unresolved and all("tMissing" in r["note"] for r in unresolved)


def test_targets_inside_a_region_are_solved_on_its_model(tmp_path):
    """A local model (the nominal arm with a 1 mm longer lower arm) whose box holds every
    target of cell_a.mod gives what that model gives alone, and the notes say which model;
    a box holding none gives the global (nominal) result."""
    import dataclasses

    from olp_compensate.calibration.calibration import RegionBox, RegionCalibration
    from olp_compensate.programs.object_model.task import compensate_program

    robot = load_robot("abb_irb2400")
    nominal = nominal_calibration(robot)
    values = nominal.values.copy()
    values[nominal.model.index("j2.a")] += 1e-3
    local = dataclasses.replace(nominal, values=values)
    text = (SAMPLES / "cell_a.mod").read_bytes()
    alone, alone_report = compensate_program(text, "rapid", local)
    for box, expected, model_note in (
            (RegionBox(min_m=np.full(3, -5.0), max_m=np.full(3, 5.0)), alone, "region cell"),
            (RegionBox(min_m=np.full(3, 9.0), max_m=np.full(3, 10.0)),
             text.decode("latin-1"), "global model")):
        regional = dataclasses.replace(nominal, regions=(RegionCalibration(
            name="cell", box=box, calibration=local),))
        from olp_compensate.cli.fix_unit import make_compensator

        out, report = compensate_program(text, "rapid", make_compensator(regional, None))
        assert out == expected
        solved = [r for r in report.rows if r.status in ("ok", "singular", "joint_limit")]
        assert solved and all(model_note in r.note for r in solved), [r.note for r in solved]
    assert alone != text.decode("latin-1")


def test_a_dump_without_location_data_is_written_as_it_is_and_system_lists_are_skipped(
        backup, tmp_path, capsys):
    """A complete AS dump of auxiliary data only (no targets) is valid input: written back
    byte for byte, exit 0. A cut-off one (no '.END') stays a one-line refusal. KRL system
    data lists ($machine.dat) in a backup are not programs."""
    tree, model = backup
    dump = tmp_path / "aux.as"
    dump.write_bytes(b".AUXDATA\r\nN_INT1    \"x\"\r\n.END\r\n.REALS\r\nspeed = 100\r\n.END\r\n")
    assert main([str(dump), "--model", str(model), "-o", str(tmp_path / "aux_out.as")]) == 0
    assert (tmp_path / "aux_out.as").read_bytes() == dump.read_bytes()
    assert "no location data" in capsys.readouterr().out
    cut = tmp_path / "cut.as"
    cut.write_bytes(b".REALS\r\nspeed = 1")
    assert main([str(cut), "--model", str(model), "-o", str(tmp_path / "cut_out.as")]) == 1
    assert not (tmp_path / "cut_out.as").exists()
    copy = tmp_path / "in"
    shutil.copytree(tree, copy)
    (copy / "KRL" / "R1" / "$machine.dat").write_text("DEFDAT $MACHINE\nENDDAT\n")
    assert main([str(copy), "--model", str(model), "-o", str(tmp_path / "out"), "-q"]) == 2
    assert not (tmp_path / "out" / "KRL" / "R1" / "$machine.dat").exists()


def test_a_folder_report_is_each_programs_report_in_input_order(backup, tmp_path):
    """The folder run spools each program's rows as it finishes; the report it writes is
    the programs' own reports, run one by one, joined in the order of the input tree."""
    tree, model = backup
    assert main([str(tree), "--model", str(model), "-o", str(tmp_path / "out"), "--report",
                 str(tmp_path / "all.csv"), "-j", "2", "-q"]) == 2
    from olp_compensate.cli.fix_inputs import plan_units
    from olp_compensate.programs.languages import extensions

    alone = []
    for k, unit in enumerate(plan_units([str(tree)], None, None, extensions())):
        program = unit.paths[0]     # a KRL .src brings its .dat
        main([str(program), "--model", str(model), "-o", str(tmp_path / f"{k}{program.suffix}"),
              "--report", str(tmp_path / f"{k}.csv"), "-q"])
        alone += _rows(tmp_path / f"{k}.csv")
    together = _rows(tmp_path / "all.csv")

    def without_file(rows):
        return [{k: v for k, v in r.items() if k != "file"} for r in rows]

    assert len(together) == len(alone) > 10
    assert without_file(together) == without_file(alone)
