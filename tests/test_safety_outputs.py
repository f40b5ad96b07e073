"""Every output of every command: never an input (through links too), never another output,
refused before anything is read; temporary files gone on every exit path."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from olp_compensate.cli import common
from olp_compensate.cli.cal import main as cal
from olp_compensate.cli.fix import main as fix
from olp_compensate.io import atomic

ROBOT = "abb_irb2400"


def _inputs(folder: Path) -> dict[str, Path]:
    """Input files of every kind. Their content is no valid input on purpose: a command
    that read one before refusing its output would fail with another message."""
    names = {"meas": "m.csv", "joints": "j.csv", "model": "c.json", "marks": "k.csv",
             "program": "p.mod", "session": "s.mcap", "points": "pts.csv"}
    files = {}
    for key, name in names.items():
        files[key] = folder / name
        files[key].write_bytes(f"not read: {key}\n".encode())
    return files


# (argv builder, output flag, input key); {X} is the output path
CASES = [
    (lambda f, x: ["identify", str(f["meas"]), "--robot", ROBOT, "-o", x], "meas"),
    (lambda f, x: ["diagnose", str(f["meas"]), "--robot", ROBOT, "-o", x], "meas"),
    (lambda f, x: ["diagnose", str(f["meas"]), "--robot", ROBOT, "--json", x], "meas"),
    (lambda f, x: ["diagnose", str(f["meas"]), "--robot", ROBOT, "--html", x], "meas"),
    (lambda f, x: ["predict", "--model", str(f["model"]), str(f["joints"]), "-o", x], "joints"),
    (lambda f, x: ["predict", "--model", str(f["model"]), str(f["joints"]), "-o", x], "model"),
    (lambda f, x: ["simulate", "--robot", ROBOT, "--joints", str(f["joints"]), "-o", x],
     "joints"),
    (lambda f, x: ["simulate", "--robot", ROBOT, "--joints", str(f["joints"]), "-o",
                   str(f["joints"].with_name("out.csv")), "--truth", x], "joints"),
    (lambda f, x: ["plan", "--robot", ROBOT, "--poses", "3", "--from", str(f["joints"]),
                   "-o", x], "joints"),
    (lambda f, x: ["export-urdf", "--model", str(f["model"]), "-o", x], "model"),
    (lambda f, x: ["tool", "--robot", ROBOT, "--marks", str(f["marks"]), "-o", x], "marks"),
    (lambda f, x: ["tool", "--model", str(f["model"]), "--marks", str(f["marks"]), "-o", x],
     "model"),
    (lambda f, x: ["tool", "--robot", ROBOT, "--marks", str(f["marks"]), "--update-program",
                   str(f["program"]), "--program-out", x], "program"),
    (lambda f, x: ["merge", str(f["session"]), str(f["points"]), "-o", x], "session"),
    (lambda f, x: ["merge", str(f["session"]), str(f["points"]), "-o", x], "points"),
    (lambda f, x: ["identify", str(f["session"]), "--points", str(f["points"]), "--robot",
                   ROBOT, "-o", x], "points"),
]
FIX_CASES = [
    (lambda f, x: [str(f["program"]), "--model", str(f["model"]), "-o", x], "program"),
    (lambda f, x: [str(f["program"]), "--model", str(f["model"]), "-o", x], "model"),
    (lambda f, x: [str(f["program"]), "--model", str(f["model"]), "--report", x], "model"),
    (lambda f, x: [str(f["program"]), "--model", str(f["model"]), "--report", x], "program"),
]


def _snapshot(files: dict[str, Path]) -> dict[str, bytes]:
    return {k: p.read_bytes() for k, p in files.items()}


def _check_refused(capsys, code, files, before, folder):
    err = capsys.readouterr().err
    assert code == 1, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "refusing to overwrite" in lines[0], err
    assert _snapshot(files) == before
    assert not [p for p in folder.iterdir() if ".olp-" in p.name or p.name == "out.csv"]


@pytest.mark.parametrize("how", ["same", "link", "dotted"])
@pytest.mark.parametrize("case", range(len(CASES) + len(FIX_CASES)))
def test_an_output_that_is_an_input_is_refused_before_reading(tmp_path, capsys, case, how):
    files = _inputs(tmp_path)
    build, key = (CASES + FIX_CASES)[case]
    target = files[key]
    if how == "link":
        link = tmp_path / "sub" / "link.out"
        link.parent.mkdir()
        link.symlink_to(target)
        out = str(link)
    elif how == "dotted":
        (tmp_path / "sub").mkdir(exist_ok=True)
        out = str(tmp_path / "sub" / ".." / target.name)
    else:
        out = str(target)
    before = _snapshot(files)
    command = fix if case >= len(CASES) else cal
    code = command(build(files, out))
    _check_refused(capsys, code, files, before, tmp_path)


@pytest.mark.parametrize("argv_of", [
    lambda f, x: ["diagnose", str(f["meas"]), "--robot", ROBOT, "--json", x, "--html", x],
    lambda f, x: ["simulate", "--robot", ROBOT, "--poses", "3", "-o", x, "--truth", x],
])
def test_two_outputs_of_one_run_on_one_file_are_refused(tmp_path, capsys, argv_of):
    files = _inputs(tmp_path)
    out = str(tmp_path / "same.out")
    assert cal(argv_of(files, out)) == 1
    err = capsys.readouterr().err
    assert "named for both" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "same.out").exists()


def test_olp_fix_report_and_program_on_one_file_is_refused(tmp_path, capsys):
    files = _inputs(tmp_path)
    out = str(tmp_path / "x.mod")
    assert fix([str(files["program"]), "--model", str(files["model"]), "-o", out,
                "--report", out]) == 1
    assert "named for both -o and --report" in capsys.readouterr().err
    assert not Path(out).exists()


def test_an_interrupted_write_leaves_no_temporary_file_and_says_so(tmp_path, capsys,
                                                                   monkeypatch):
    def interrupted(fd):
        raise KeyboardInterrupt

    def action():
        atomic.write_text_atomic(tmp_path / "first.csv", "done\n")
        monkeypatch.setattr(os, "fsync", interrupted)
        atomic.write_text_atomic(tmp_path / "second.csv", "never\n")
        return 0

    assert common.run_guarded(action, 0, "olp-cal") == common.EXIT_INTERRUPTED
    err = capsys.readouterr().err
    assert err.startswith("olp-cal: interrupted") and "first.csv" in err
    assert "second.csv" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["first.csv"]


def test_files_written_together_appear_together(tmp_path, monkeypatch):
    calls = []
    real = os.replace

    def failing_second(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real(src, dst)

    monkeypatch.setattr(os, "replace", failing_second)
    with pytest.raises(atomic.OlpError, match="No space"):
        atomic.write_files_atomic([(tmp_path / "a.mod", b"a"), (tmp_path / "r.csv", b"r")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.mod"]   # temp of r.csv removed


SIGTERM_SCRIPT = """
import os, signal, sys
from pathlib import Path
from olp_compensate.cli import common
from olp_compensate.io import atomic
folder = Path(sys.argv[1])
real_fsync = os.fsync
def fsync_then_terminate(fd):
    real_fsync(fd)
    os.kill(os.getpid(), signal.SIGTERM)
def action():
    atomic.write_text_atomic(folder / "a.csv", "a\\n")
    os.fsync = fsync_then_terminate
    atomic.write_text_atomic(folder / "b.csv", "b\\n")
    return 0
sys.exit(common.run_guarded(action, 0, "olp-cal"))
"""


def test_sigterm_during_a_write_removes_the_temporary_file(tmp_path):
    done = subprocess.run([sys.executable, "-c", SIGTERM_SCRIPT, str(tmp_path)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == common.EXIT_INTERRUPTED, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.startswith("olp-cal: terminated") and "a.csv" in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv"]


def test_a_killed_runs_temporary_file_is_removed_by_the_next_write(tmp_path):
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    stale = tmp_path / f".out.csv{atomic.TEMP_MARK}{gone}-0badcafe.tmp"
    stale.write_text("half")
    alive = tmp_path / f".out.csv{atomic.TEMP_MARK}{os.getpid()}-0badcafe.tmp"
    alive.write_text("another write of this process")
    other = tmp_path / f".other.csv{atomic.TEMP_MARK}{gone}-0badcafe.tmp"
    other.write_text("not ours to judge")
    atomic.write_text_atomic(tmp_path / "out.csv", "x\n")
    assert not stale.exists() and alive.exists() and other.exists()
    assert (tmp_path / "out.csv").read_text() == "x\n"


def test_sigint_handler_is_restored_after_a_run():
    before = signal.getsignal(signal.SIGTERM)
    common.run_guarded(lambda: 0, 0, "olp-cal")
    assert signal.getsignal(signal.SIGTERM) == before


def test_a_numerical_failure_is_one_line(capsys):
    import numpy as np

    def action():
        raise np.linalg.LinAlgError("SVD did not converge")

    assert common.run_guarded(action, 0, "olp-cal") == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "SVD did not converge" in err


def test_clash_check_sees_hard_links_and_dotted_outputs(tmp_path):
    """One file under two names (a hard link), and two not-yet-existing outputs spelled
    differently, are each caught; distinct files pass."""
    source = tmp_path / "in.mod"
    source.write_text("MODULE m\nENDMODULE\n")
    os.link(source, tmp_path / "hard.mod")
    with pytest.raises(common.DataError, match="is an input"):
        common.refuse_clashes([("program", source)], [("-o", tmp_path / "hard.mod")])
    (tmp_path / "sub").mkdir()
    with pytest.raises(common.DataError, match="named for both -o and --report"):
        common.refuse_clashes([("program", source)],
                              [("-o", tmp_path / "new.mod"),
                               ("--report", tmp_path / "sub" / ".." / "new.mod")])
    common.refuse_clashes([("program", source), ("--robot", "abb_irb2400")],
                          [("-o", tmp_path / "out.mod"), ("--report", tmp_path / "r.csv")])
