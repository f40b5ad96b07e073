"""olp-fix on special files and awkward -o: what is not a regular file is skipped in a folder
(with a warning) and refused as a program, never read; -o cases get one clear line; a folder
compensated without -o goes to a sibling folder; pool workers die with their parent."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.cli.fix import main
from olp_compensate.io.calibration_file import write_calibration
from olp_compensate.kinematics.robot import load_robot

SAMPLES = Path(__file__).resolve().parents[1] / "samples"


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    path = tmp_path_factory.mktemp("special") / "nominal.json"
    write_calibration(path, nominal_calibration(load_robot("abb_irb2400")))
    return path


@pytest.fixture
def task(tmp_path):
    folder = tmp_path / "TASK1"
    folder.mkdir()
    shutil.copy(SAMPLES / "cell_a.mod", folder / "cell_a.mod")
    return folder


def _tree(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink()}


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_special_files_in_a_folder_are_skipped_with_a_warning(task, model, capsys):
    os.mkfifo(task / "pipe.mod")
    (task / "zero.mod").symlink_to("/dev/zero")
    (task / "gone.mod").symlink_to(task / "nothing.mod")
    out = task.parent / "out"
    code = main([str(task), "--model", str(model), "-o", str(out), "-q", "-j", "2"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err        # cell_a holds reported targets
    for name in ("pipe.mod", "zero.mod", "gone.mod"):
        assert f"{name}: skipped" in err
    assert "pipe (FIFO)" in err and "character device" in err
    assert _tree(out) == {"cell_a.mod": (SAMPLES / "cell_a.mod").read_bytes()}


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
@pytest.mark.parametrize("kind", ["fifo", "devnull", "zero_link"])
def test_a_program_that_is_no_regular_file_is_refused(tmp_path, model, capsys, kind):
    program = tmp_path / "p.mod"
    if kind == "fifo":
        os.mkfifo(program)
    elif kind == "zero_link":
        program.symlink_to("/dev/zero")
    else:
        program = Path(os.devnull)
    code = main([str(program), "--model", str(model), "--dialect", "rapid", "-q"])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and "not a regular file" in err
    assert str(program) in err


def test_a_pipe_given_by_the_shell_is_refused(tmp_path, model):
    """``olp-fix <(cat x.mod)``: /dev/fd/N is a pipe; one line, exit 1, nothing written."""
    script = (f"import sys; from olp_compensate.cli.fix import main; "
              f"sys.exit(main([sys.argv[1], '--model', {str(model)!r}, '--dialect', 'rapid']))")
    reader, writer = os.pipe()
    env = {**os.environ, "PYTHONPATH": str(SAMPLES.parent)}   # this tree, from any cwd
    proc = subprocess.Popen([sys.executable, "-c", script, f"/dev/fd/{reader}"],
                            pass_fds=(reader,), stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                            env=env)
    os.close(reader)
    os.write(writer, (SAMPLES / "cell_a.mod").read_bytes()[:1000])
    os.close(writer)
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == 1 and "pipe (FIFO), not a regular file" in err
    assert "Traceback" not in err and list(tmp_path.iterdir()) == []


def test_o_cases_get_one_clear_line(task, model, capsys):
    before = _tree(task.parent)
    existing = task.parent / "afile"
    existing.write_text("x")
    before = _tree(task.parent)
    cases = [([str(task), "-o", str(existing)], "-o names an existing file"),
             ([str(task), "-o", str(task / "out")], "-o is inside the input folder"),
             ([str(task), "-o", str(task)], "-o is the input folder"),
             ([str(task / "cell_a.mod"), "-o", str(task.parent)], "-o names a folder"),
             (["", "-o", str(task.parent / "o")], "an empty program path")]
    for argv, message in cases:
        assert main([*argv, "--model", str(model), "-q"]) == 1, argv
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1 and "Traceback" not in err, err
        assert _tree(task.parent) == before


def test_an_empty_path_does_not_scan_the_current_folder(task, model, capsys, monkeypatch):
    monkeypatch.chdir(task)
    assert main(["", "--model", str(model), "-q"]) == 1
    assert "an empty program path" in capsys.readouterr().err
    assert sorted(p.name for p in task.parent.iterdir()) == ["TASK1"]


def test_a_folder_without_o_goes_to_a_sibling_mirror(task, model):
    """A task folder compensated in place would hold Weld.mod and Weld_compensated.mod,
    both MODULE Weld: the task would not load. The outputs go to TASK1_compensated/."""
    (task / "sub").mkdir()
    shutil.copy(SAMPLES / "cell_a.mod", task / "sub" / "second.mod")
    before = _tree(task)
    assert main([str(task), "--model", str(model), "-q"]) == 2
    assert _tree(task) == before                       # nothing written into the task
    mirror = task.parent / "TASK1_compensated"
    assert _tree(mirror) == before                     # nominal model: the same bytes
    # a second run over the parent folder does not take the mirror as input
    assert main([str(task.parent), "--model", str(model), "-q"]) == 2
    assert _tree(task.parent.parent / (task.parent.name + "_compensated")) == {
        f"TASK1/{k}": v for k, v in before.items()}


def test_a_file_given_is_still_written_beside_it(task, model):
    assert main([str(task / "cell_a.mod"), "--model", str(model), "-q"]) == 2
    assert (task / "cell_a_compensated.mod").read_bytes() == (task / "cell_a.mod").read_bytes()


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0]
    except (FileNotFoundError, IndexError):
        return False
    return state not in "ZX"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl is Linux's")
def test_a_pool_worker_dies_with_its_parent():
    """The start of olp-fix's pool workers: killed by the kernel when olp-fix is (SIGKILL
    included), instead of reading on (a worker grew to 11.7 GB on /dev/zero)."""
    script = ("import os, sys, time\n"
              "from olp_compensate.cli.fix_batch import _end_with\n"
              "parent = os.getpid()\n"
              "pid = os.fork()\n"
              "if pid == 0:\n"
              "    _end_with(parent)\n"
              "    time.sleep(120)\n"
              "    os._exit(0)\n"
              "print(pid, flush=True)\n"
              "time.sleep(120)\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    worker = int(proc.stdout.readline())
    assert _alive(worker)
    proc.kill()
    proc.wait()
    for _ in range(300):          # the kernel's signal: at once; waits only for the reaping
        if not _alive(worker):
            break
        time.sleep(0.05)
    else:
        os.kill(worker, 9)
        pytest.fail("the worker outlived its killed parent")


def test_krl_names_follow_the_output_files():
    """DEF/DEFDAT renamed after the output file when it differs, every other byte kept; a
    local DEF and the same word elsewhere untouched; a name KSS refuses is said."""
    from olp_compensate.programs.krl.names import match_krl_names

    src = (b"&ACCESS RVP\r\nGLOBAL DEF Cell( )\r\n  Cell_2()\r\nEND\r\n"
           b"DEF Cell_2( )\r\nEND\r\n")
    dat = b"&ACCESS RVP\r\nDEFDAT  CELL PUBLIC\r\n;Cell data\r\nENDDAT\r\n"
    data, notes = match_krl_names([Path("in/Cell.src"), Path("in/Cell.dat")],
                                  [Path("o/Fixed.src"), Path("o/Fixed.dat")], [src, dat])
    assert data[0] == src.replace(b"DEF Cell(", b"DEF Fixed(")
    assert data[1] == dat.replace(b"DEFDAT  CELL", b"DEFDAT  Fixed")
    assert len(notes) == 2 and "DEF Cell renamed Fixed" in notes[0]
    same, none = match_krl_names([Path("a/Cell.src")], [Path("b/Cell.src")], [src])
    assert same == [src] and none == []
    long = "Cell_" + "x" * 30
    _, notes = match_krl_names([Path("Cell.src")], [Path(long + ".src")], [src])
    assert len(notes) == 2 and "no KRL name KSS accepts" in notes[1]
    kept, notes = match_krl_names([Path("Cell.src")], [Path("Zelle\u20ac.src")], [src])
    assert kept == [src] and len(notes) == 1 and "DEF kept" in notes[0]   # no traceback


def test_a_seven_value_as_step_reports_the_robot_axes_under_its_header(tmp_path, capsys):
    """A Kawasaki block step #[j1..j7] of a 6-axis arm: the seventh value is an external
    axis; the report row has the header's 6 joint columns and names it in its note."""
    import csv

    model = tmp_path / "n.json"
    write_calibration(model, nominal_calibration(load_robot("abb_irb2400")))
    program = tmp_path / "step.as"
    program.write_bytes(b".PROGRAM step()\r\n  JOINT SPEED9 ACCU1 TIMER0 TOOL1 WORK0 CLAMP1 "
                        b"(OFF,0,0,O) 2 (0,0,O) 1 #[0,10,-10,0,30,0,250.5]\r\n.END\r\n")
    report = tmp_path / "r.csv"
    assert main([str(program), "--model", str(model), "-o", str(tmp_path / "o.as"),
                 "--report", str(report), "-q"]) == 0
    rows = list(csv.reader(report.open()))
    assert len(rows) == 2 and len(rows[1]) == len(rows[0]) == 21
    assert rows[1][rows[0].index("q6_deg")] == "0.000000"
    assert "250.5" in rows[1][-1] and "external axes" in rows[1][-1]
    assert (tmp_path / "o.as").read_bytes() == program.read_bytes()


def test_a_closed_stdout_loses_no_output_file(tmp_path):
    """``olp-cal identify ... | head -2``: the reader leaves before the report is printed;
    the calibration is written all the same, the exit code is the command's, and no
    traceback."""
    out = tmp_path / "calib.json"
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys; from olp_compensate.cli.cal import main; "
         "sys.exit(main(sys.argv[1:]))", "identify", str(SAMPLES / "irb2400_measurements.csv"),
         "--robot", "abb_irb2400", "-o", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()                  # the reader is gone before anything is printed
    err = proc.stderr.read()
    assert proc.wait(timeout=300) == 0, err
    assert "Traceback" not in err and "Exception ignored" not in err
    from olp_compensate.io.calibration_file import read_calibration

    assert read_calibration(out).robot.name == "abb_irb2400"


def test_output_checks_look_at_each_path_once(tmp_path, monkeypatch):
    """refuse_clashes over n inputs and n outputs: at most one stat (and one resolve) per
    path, not one per pair (a 1,000-program backup spent 98 s there); a clash is still
    found, by inode through a hard link too."""
    from olp_compensate.cli import common

    n = 400
    inputs = []
    for k in range(n):
        p = tmp_path / f"p{k}.mod"
        p.write_text("x")
        inputs.append(("program", p))
    outputs = [("-o", tmp_path / "out" / f"p{k}.mod") for k in range(n)]
    calls = {"stat": 0, "realpath": 0}
    real_stat, real_realpath = os.stat, os.path.realpath

    def stat(path, *a, **k):
        calls["stat"] += 1
        return real_stat(path, *a, **k)

    def realpath(path, *a, **k):
        calls["realpath"] += 1
        return real_realpath(path, *a, **k)

    monkeypatch.setattr(common.os, "stat", stat)
    monkeypatch.setattr(common.os.path, "realpath", realpath)
    common.refuse_clashes(inputs, outputs)
    assert calls["stat"] <= 3 * 2 * n and calls["realpath"] <= 2 * n, calls
    monkeypatch.undo()
    link = tmp_path / "link.mod"
    os.link(tmp_path / "p7.mod", link)
    from olp_compensate.errors import DataError

    with pytest.raises(DataError, match="is an input"):
        common.refuse_clashes(inputs, [*outputs, ("-o", link)])
    with pytest.raises(DataError, match="named for both"):
        common.refuse_clashes(inputs, [*outputs, ("--report", outputs[3][1])])


def test_a_folder_run_keeps_no_finished_programs_report(tmp_path, model, monkeypatch):
    """A folder of programs: each one's outputs and report rows are written as it is done
    and then dropped (only a summary stays), so memory is bounded by the programs in
    flight, not their sum; the report keeps the input tree's order."""
    import csv
    import gc
    import weakref

    from olp_compensate.cli import fix_batch

    folder = tmp_path / "backup"
    for k in range(6):
        (folder / f"T{k}").mkdir(parents=True)
        shutil.copy(SAMPLES / "cell_a.mod", folder / f"T{k}" / "cell_a.mod")
    alive: list = []
    held_back: list[int] = []
    summary = fix_batch._summary_of

    def watched(outcome):
        gc.collect()
        held_back.append(sum(ref() is not None for ref in alive))
        alive.append(weakref.ref(outcome.report))
        return summary(outcome)

    monkeypatch.setattr(fix_batch, "_summary_of", watched)
    report = tmp_path / "r.csv"
    assert main([str(folder), "--model", str(model), "-o", str(tmp_path / "out"),
                 "--report", str(report), "-j", "1", "-q"]) == 2
    assert max(held_back) <= 1, held_back      # at most the one just written out
    files = [r["file"] for r in csv.DictReader(report.open())]
    assert files == sorted(files, key=lambda f: f.split("/")[0])
    assert {f.split("/")[0] for f in files} == {f"T{k}" for k in range(6)}
