"""What ``olp-cal identify`` loads (issue 32): the modules only other paths need stay
unloaded, and what replaced them gives the same answers (fingerprint, data folders)."""

from __future__ import annotations

import argparse
import hashlib
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.cli import cal
from olp_compensate.cli.cal import build_parser
from olp_compensate.cli.common import terminal_columns
from olp_compensate.data import data_folder
from olp_compensate.io.measurements import write_measurements
from olp_compensate.kinematics.robot import load_robot

NOT_NEEDED = ("xml.etree", "hashlib", "importlib.resources", "tempfile", "scipy",
              "olp_compensate.calibration.effects", "olp_compensate.camera")

PROBE = """
import sys
from olp_compensate.cli.cal import main
code = main(sys.argv[1:])
print(code)
print(" ".join(sorted(sys.modules)))
"""


def test_identify_loads_no_module_only_other_paths_need(tmp_path):
    robot = load_robot("abb_irb2400")
    rng = np.random.default_rng(3)
    meas = make_virtual_robot(robot, 1).measure(random_joints(robot, 40, rng), 5e-5, rng)
    csv = tmp_path / "m.csv"
    write_measurements(str(csv), meas, [j.unit for j in robot.joints])
    out = subprocess.run([sys.executable, "-c", PROBE, "identify", str(csv), "--robot",
                          robot.name, "-o", str(tmp_path / "calib.json")], check=True,
                         capture_output=True, text=True).stdout.splitlines()
    assert out[-2] == "0" and (tmp_path / "calib.json").is_file()
    loaded = out[-1].split()
    assert "olp_compensate.calibration.identify" in loaded  # the probe sees the run's modules
    assert [m for m in loaded if m.startswith(NOT_NEEDED)] == []


def test_fingerprint_is_hashlibs_sha256_of_the_chain():
    """The recipe of :attr:`Robot.fingerprint`, computed here with hashlib."""
    robot = load_robot("abb_irb2400")
    h = hashlib.sha256()
    for j in robot.joints:
        h.update(j.kind.encode())
        h.update(np.round(j.parent_T_joint, 9).tobytes())
        h.update(np.round(j.axis, 9).tobytes())
    h.update(np.round(robot.last_T_flange, 9).tobytes())
    h.update(np.round(robot.urdf_from_controller, 9).tobytes())
    assert robot.fingerprint == "sha256:" + h.hexdigest()


def test_data_folders_of_a_wheel_are_what_importlib_resources_gives(tmp_path):
    """In a wheel, robots/ and grammars/ are folders inside the package: the same files as
    importlib.resources lists, read alike."""
    root = Path(__file__).resolve().parents[1]
    probe = ("import sys; from importlib import resources; "
             "from olp_compensate.data import data_folder\n"
             "for name in ('robots', 'grammars'):\n"
             "    a, b = data_folder(name), resources.files('olp_compensate.' + name)\n"
             "    print(type(a).__name__, sorted(p.name for p in a.iterdir()) == "
             "sorted(p.name for p in b.iterdir()), "
             "(a / 'README.md').read_text('utf-8') == (b / 'README.md').read_text('utf-8'))")
    package = tmp_path / "olp_compensate"
    subprocess.run(["cp", "-r", str(root / "olp_compensate"), str(package)], check=True)
    for name in ("robots", "grammars"):
        subprocess.run(["cp", "-r", str(root / name), str(package / name)], check=True)
    out = subprocess.run([sys.executable, "-I", "-c", f"import sys; sys.path.insert(0, "
                          f"{str(tmp_path)!r})\n" + probe], check=True, capture_output=True,
                         text=True, cwd=tmp_path).stdout
    assert out.split() == ["PosixPath", "True", "True"] * 2


def test_data_folder_of_this_install_holds_the_robots():
    folder = data_folder("robots")
    assert (folder / "abb_irb2400.robot.json").is_file()


@pytest.mark.parametrize("columns", [None, "57", "200", "abc", "0", "-3"])
def test_terminal_columns_are_shutils(monkeypatch, columns):
    if columns is None:
        monkeypatch.delenv("COLUMNS", raising=False)
    else:
        monkeypatch.setenv("COLUMNS", columns)
    assert terminal_columns() == shutil.get_terminal_size().columns


@pytest.mark.parametrize("command", [None, "identify", "simulate", "camera"])
def test_help_is_argparses_own(monkeypatch, command):
    """The commands' help, usage and errors read as argparse's default formatter writes
    them (narrow terminal, so that the width matters)."""
    monkeypatch.setenv("COLUMNS", "61")
    argv = [] if command is None else [command]
    ours = build_parser(argv)
    monkeypatch.setattr(cal, "help_formatter", argparse.HelpFormatter)
    theirs = build_parser(argv)
    assert ours.format_help() == theirs.format_help()
    if command is not None:
        pick = [a for a in ours._actions if isinstance(a, argparse._SubParsersAction)]
        mine = pick[0].choices[command]
        pick = [a for a in theirs._actions if isinstance(a, argparse._SubParsersAction)]
        other = pick[0].choices[command]
        narrow = mine.format_help()
        assert narrow == other.format_help()
        assert mine.format_usage() == other.format_usage()
        monkeypatch.setenv("COLUMNS", "200")  # the width is read: the test can fail
        assert mine.format_help() != narrow
