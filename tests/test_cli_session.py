"""``olp-cal record | merge`` and ``identify`` on sessions, end to end on a virtual robot."""

from __future__ import annotations

import importlib.util
import io
import json
import sys
import time

import numpy as np
import pytest
from mcap.reader import make_reader

from olp_compensate.cli.cal import main
from olp_compensate.io.calibration_file import read_calibration
from olp_compensate.io.measurements import read_measurements
from olp_compensate.io.session import read_measurements_any
from olp_compensate.io.session import read_session
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints

ROBOT = "abb_irb2400"
NOISE_M = 0.05e-3
needs_ur_rtde = pytest.mark.skipif(importlib.util.find_spec("rtde_receive") is None,
                                   reason="ur-rtde is not installed")


def _stdin(monkeypatch, lines):
    monkeypatch.setattr(sys, "stdin", io.StringIO("".join(f"{line}\n" for line in lines)))


def one_line_error(capsys, *words):
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """30 poses of a virtual robot typed into ``record`` (stdin ends the session), and the
    device's points for them (0.05 mm noise), in pose order."""
    folder = tmp_path_factory.mktemp("session")
    robot = load_robot(ROBOT)
    virtual = make_virtual_robot(robot, seed=12)
    rng = np.random.default_rng(13)
    joints = random_joints(robot, 30, rng)
    typed = [" ".join(f"{v:.6f}" for v in np.degrees(q)) for q in joints]
    session = folder / "cell3.mcap"
    mp = pytest.MonkeyPatch()
    try:
        _stdin(mp, typed)  # no 'q': the end of input ends the session
        assert main(["record", "--robot", ROBOT, "-o", str(session),
                     "--note", "cell 3, tracker T1"]) == 0
    finally:
        mp.undo()
    points = virtual.true_points(joints, ["tcp"] * 30) + rng.normal(0, NOISE_M, (30, 3))
    device = folder / "tracker.csv"
    device.write_text("# tracker export\nx_mm,y_mm,z_mm\n"
                      + "".join(",".join(f"{v:.4f}" for v in p) + "\n" for p in points * 1e3))
    return folder, session, device, joints


def test_recorded_session_opens_with_the_mcap_library(campaign):
    _, session, _, joints = campaign
    with open(session, "rb") as stream:
        reader = make_reader(stream)
        topics = {c.topic for c in reader.get_summary().channels.values()}
        messages = [(c.topic, json.loads(m.data)) for _, c, m in reader.iter_messages()]
    assert topics == {"/robot/joints", "/session/info"}
    info = [m for t, m in messages if t == "/session/info"][0]
    assert info["robot"] == ROBOT and info["n_joints"] == 6 and info["note"] == "cell 3, tracker T1"
    poses = [m for t, m in messages if t == "/robot/joints"]
    assert [m["pose"] for m in poses] == list(range(1, 31))
    assert np.allclose([m["q_rad"] for m in poses], joints, atol=1e-7)


def test_merge_then_identify_and_identify_straight_from_the_session(campaign, tmp_path, capsys):
    _, session, device, joints = campaign
    meas = tmp_path / "meas.csv"
    assert main(["merge", str(session), str(device), "-o", str(meas)]) == 0
    assert "wrote 30 measured points" in capsys.readouterr().out
    merged = read_measurements(meas, ["deg"] * 6)
    assert np.allclose(merged.joints, joints, atol=1e-7) and merged.n_poses == 30

    calib_csv, calib_mcap = tmp_path / "from_csv.json", tmp_path / "from_mcap.json"
    assert main(["identify", str(meas), "--robot", ROBOT, "-o", str(calib_csv)]) == 0
    report = capsys.readouterr().out
    assert "30 poses" in report and "held-out" in report
    rms = float(report.split("residual: RMS ")[1].split(" mm")[0])
    assert rms < 3 * NOISE_M * 1e3 * np.sqrt(3)
    assert main(["identify", str(session), "--points", str(device), "--robot", ROBOT,
                 "-o", str(calib_mcap)]) == 0
    assert "30 poses" in capsys.readouterr().out
    a, b = read_calibration(calib_csv), read_calibration(calib_mcap)
    assert np.allclose(a.values, b.values, atol=1e-9)


class _PacedStdin:
    """stdin typing one line every ``pause_s`` (a technician's pace, scaled down)."""

    def __init__(self, lines, pause_s):
        self.lines, self.pause_s = list(lines), pause_s

    def readline(self):
        time.sleep(self.pause_s)
        return self.lines.pop(0) + "\n" if self.lines else ""

    def isatty(self):
        return False


def test_merge_by_time(campaign, tmp_path, capsys, monkeypatch):
    _, _, device, joints = campaign
    session = tmp_path / "paced.mcap"
    typed = [" ".join(f"{v:.6f}" for v in np.degrees(q)) for q in joints[:5]]
    monkeypatch.setattr(sys, "stdin", _PacedStdin(typed, 0.06))
    assert main(["record", "--robot", ROBOT, "-o", str(session)]) == 0
    _, times, _ = read_session(session)
    assert np.min(np.diff(times)) > 0.05
    # the device's clock: seconds since its own start, 1e9 s before Unix time; 2 ms late
    lines = device.read_text().splitlines()[2:7]
    rows = [f"{t + 0.002 - 1e9:.4f},{row}" for t, row in zip(times, lines)]
    timed = tmp_path / "timed.csv"
    timed.write_text("time_s,x_mm,y_mm,z_mm\n" + "\n".join(reversed(rows)) + "\n")
    out = tmp_path / "by_time.csv"
    args = ["merge", str(session), str(timed), "-o", str(out), "--by", "time",
            "--time-offset-s", "1e9"]
    assert main(args + ["--tolerance-s", "0.02"]) == 0
    meas = read_measurements(out, ["deg"] * 6)
    assert list(meas.pose_ids) == ["5", "4", "3", "2", "1"]
    assert np.allclose(meas.joints, joints[:5][::-1], atol=1e-7)
    capsys.readouterr()
    assert main(args + ["--tolerance-s", "0.5"]) == 1
    one_line_error(capsys, "is within 0.5 s of poses")


def test_session_errors_are_one_line(campaign, tmp_path, capsys, monkeypatch):
    _, session, device, _ = campaign
    short = tmp_path / "short.csv"
    short.write_text("x_mm,y_mm,z_mm\n1,2,3\n")
    cases = [
        (["identify", str(session), "--robot", ROBOT], "holds the joints only; give the"),
        (["identify", str(device), "--points", str(device), "--robot", ROBOT],
         "not one; a measurement CSV already holds its points"),
        (["merge", str(session), str(short), "-o", str(tmp_path / "m.csv")],
         "short.csv has 1 points but"),
        (["merge", str(session), str(device), "-o", str(device)], "refusing to overwrite"),
        (["merge", str(tmp_path / "none.mcap"), str(device), "-o", str(tmp_path / "m.csv")],
         "none.mcap: cannot read"),
        (["identify", str(session), "--points", str(device), "--robot", "ur5e_x"],
         "unknown robot 'ur5e_x'"),
    ]
    for args, message in cases:
        assert main(args) == 1, args
        one_line_error(capsys, message)
    before = session.read_bytes()
    _stdin(monkeypatch, ["0 0 0 0 0 0"])
    assert main(["record", "-o", str(session)]) == 1
    one_line_error(capsys, "already exists")
    assert session.read_bytes() == before


def test_typed_record_with_joint_count_and_q(tmp_path, capsys, monkeypatch):
    _stdin(monkeypatch, ["1 2 3", "1, 2, x", "10 20 30", "[4; 5; 6]", "q", "7 8 9"])
    out = tmp_path / "s.mcap"
    assert main(["record", "--typed", "--joints", "3", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "joint 3: 'x' is not a number" in text and "3 poses saved" in text
    joints_deg, _, info = read_session(out)
    assert np.allclose(joints_deg, [[1, 2, 3], [10, 20, 30], [4, 5, 6]]) and info["robot"] == "unspecified"
    _stdin(monkeypatch, ["q"])
    assert main(["record", "-o", str(tmp_path / "empty.mcap")]) == 0
    assert "nothing written" in capsys.readouterr().out
    assert not (tmp_path / "empty.mcap").exists()


def test_record_ur_connection_refused_is_clear_and_fast(tmp_path, capsys, monkeypatch):
    _stdin(monkeypatch, [])
    start = time.monotonic()
    out = tmp_path / "s.mcap"
    assert main(["record", "--ur", "127.0.0.77", "-o", str(out),
                 "--connect-timeout-s", "1"]) == 1
    assert time.monotonic() - start < 3.0
    one_line_error(capsys, "connection refused by 127.0.0.77:30004")
    assert not list(tmp_path.iterdir())


class _JogStdin:
    """stdin for ``record --ur``: each Enter first 'jogs' the peer to the next joints."""

    def __init__(self, peer, joints):
        self.peer, self.pending = peer, list(joints)

    def readline(self):
        if not self.pending:
            return "q\n"
        self.peer.set_joints(self.pending.pop(0))
        time.sleep(0.1)  # let the new joints reach the reader
        return "\n"

    def isatty(self):
        return False


@needs_ur_rtde
def test_record_live_from_a_loopback_ur(tmp_path, capsys, monkeypatch):
    from rtde_peer import RtdePeer

    joints = np.radians([[0, -90, 90, 0, 90, 0], [10, -80, 85, 5, 95, -20],
                         [-15.5, -100, 70, 30, 60, 45]])
    out = tmp_path / "live.mcap"
    with RtdePeer(lifetime_s=30) as peer:
        peer.set_joints(np.zeros(6))
        monkeypatch.setattr(sys, "stdin", _JogStdin(peer, joints))
        assert main(["record", "--ur", peer.host, "--robot", "ur5e", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "UR controller at" in text and "3 poses saved" in text
    joints_deg, _, info = read_session(out)
    assert np.allclose(np.radians(joints_deg), joints, atol=1e-9)
    assert info["robot"] == "ur5e" and not np.any(np.isnan(info["controller_time_s"]))


def test_read_measurements_any_dispatches_on_content(campaign, tmp_path):
    _, session, device, joints = campaign
    renamed = tmp_path / "session.bin"
    renamed.write_bytes(session.read_bytes())
    meas = read_measurements_any(renamed, ["deg"] * 6, points=device)
    assert meas.n_rows == 30 and np.allclose(meas.joints, joints, atol=1e-7)
    assert meas.source == str(device) and meas.rows[0] == 3  # messages name the device file
