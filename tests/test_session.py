"""MCAP measurement sessions: record, open with the mcap library, merge with device points."""

from __future__ import annotations

import importlib.util
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

sys.path.insert(0, str(Path(__file__).parent))

from olp_compensate.errors import DataError, OlpError  # noqa: E402
from olp_compensate.io.measurements import read_measurements  # noqa: E402
from olp_compensate.io.rtde_source import TypedJointSource  # noqa: E402
from olp_compensate.io.session import merge_session, read_session, record_session  # noqa: E402

JOINTS_DEG = np.array([[0, 10, 20, 0, 30, 0], [15.5, -5, 25, 10, 40, -90],
                       [-30, 20, 5, -45, 60, 180], [45, 0, 0, 0, 90, 12.25]])


class Script:
    def __init__(self, answers):
        self.answers = list(answers)
        self.said: list[str] = []

    def ask(self, prompt: str) -> str:
        assert self.answers, f"script exhausted at prompt: {prompt!r}"
        answer = self.answers.pop(0)
        return answer(prompt) if callable(answer) else answer

    def say(self, text: str) -> None:
        self.said.append(text)


class PacedSource(TypedJointSource):
    """Typed joints, stamped 20 s apart (a technician's pace) from 1.7e9 s Unix time."""

    def __init__(self, n_joints):
        super().__init__(n_joints)
        self.count = 0

    def capture(self, ask, say, instruction, commands=()):
        reading = super().capture(ask, say, instruction, commands)
        if isinstance(reading, str):
            return reading
        self.count += 1
        return replace(reading, time_s=1.7e9 + 20.0 * self.count)


@pytest.fixture
def session(tmp_path):
    script = Script([" ".join(str(v) for v in q) for q in JOINTS_DEG] + ["q"])
    path = tmp_path / "cell3.mcap"
    count = record_session(path, PacedSource(6), script.ask, script.say,
                           robot_name="irb2400")
    assert count == 4 and "4 poses saved" in script.said[-1]
    return path


def test_session_opens_with_the_mcap_library(session):
    with open(session, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == {"/robot/joints", "/session/info"}
        assert all(c.message_encoding == "json" for c in topics.values())
        assert all(s.encoding == "jsonschema" for s in summary.schemas.values())
        messages = [(c.topic, json.loads(m.data)) for _, c, m in reader.iter_messages()]
    info = [m for t, m in messages if t == "/session/info"]
    assert len(info) == 1 and info[0]["robot"] == "irb2400" and info[0]["n_joints"] == 6
    joints = [m for t, m in messages if t == "/robot/joints"]
    assert [m["pose"] for m in joints] == [1, 2, 3, 4]
    assert np.allclose([m["q_deg"] for m in joints], JOINTS_DEG)
    assert np.allclose([m["q_rad"] for m in joints], np.radians(JOINTS_DEG))


def test_read_session_returns_degrees_times_and_info(session):
    joints_deg, times, info = read_session(session)
    assert np.allclose(joints_deg, JOINTS_DEG) and times.shape == (4,)
    assert np.allclose(times, 1.7e9 + 20.0 * np.arange(1, 5))
    assert info["n_joints"] == 6 and info["pose"] == [1, 2, 3, 4]


def test_merge_by_order_writes_the_measurement_csv(session, tmp_path):
    device = tmp_path / "tracker.csv"
    device.write_text("# exported by the tracker\nx_mm,y_mm,z_mm\n"
                      "1000.1,2.2,3.3\n1001,2,3\n1002,2,3\n1003.25,-2,3.5\n")
    out = tmp_path / "measurements.csv"
    assert merge_session(session, device, out) == 4
    lines = out.read_text().splitlines()
    assert lines[0] == "# olp-compensate measurements v1" and "# robot: irb2400" in lines
    header = next(line for line in lines if not line.startswith("#"))
    assert header == "pose,point,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm,time_s"
    meas = read_measurements(out, ["deg"] * 6)
    assert np.allclose(np.degrees(meas.joints), JOINTS_DEG)
    assert np.allclose(meas.points[3] * 1e3, [1003.25, -2, 3.5])
    assert list(meas.pose_ids) == ["1", "2", "3", "4"] and set(meas.point_names) == {"tcp"}


def test_merge_by_time_and_by_pose_column(session, tmp_path):
    _, times, _ = read_session(session)
    device = tmp_path / "arm.csv"
    rows = [f"{t + 0.05:.3f},{k}.0,0,0,p{k % 2}" for k, t in enumerate(times)]
    rows.insert(2, f"{times[1] - 0.02:.3f},9,9,9,p9")  # a second point on pose 2
    device.write_text("time_s,x_mm,y_mm,z_mm,point\n" + "\n".join(rows) + "\n")
    out = tmp_path / "by_time.csv"
    assert merge_session(session, device, out, by="time", tolerance_s=0.5) == 5
    with pytest.raises(DataError, match="within 30 s of poses 1 and 2"):
        merge_session(session, device, tmp_path / "x.csv", by="time", tolerance_s=30)
    meas = read_measurements(out, ["deg"] * 6)
    assert list(meas.pose_ids) == ["1", "2", "2", "3", "4"]
    assert list(meas.point_names) == ["p0", "p1", "p9", "p0", "p1"]

    by_pose = tmp_path / "by_pose.csv"
    by_pose.write_text("pose,x_mm,y_mm,z_mm\n3,1,2,3\n1,4,5,6\n")
    merge_session(session, by_pose, tmp_path / "by_pose_out.csv")
    meas = read_measurements(tmp_path / "by_pose_out.csv", ["deg"] * 6)
    assert np.allclose(np.degrees(meas.joints), JOINTS_DEG[[2, 0]])


def test_merge_errors_name_file_and_line(session, tmp_path):
    device = tmp_path / "d.csv"
    device.write_text("x_mm,y_mm,z_mm\n1,2,3\n1,abc,3\n")
    with pytest.raises(DataError, match=r"d.csv:3: column 'y_mm': 'abc' is not a number"):
        merge_session(session, device, tmp_path / "o.csv")
    device.write_text("x_mm,y_mm,z_mm\n1,2,3\n")
    with pytest.raises(DataError, match="has 1 points but .* has 4 poses"):
        merge_session(session, device, tmp_path / "o.csv")
    with pytest.raises(DataError, match="is an input"):
        merge_session(session, device, device)
    device.write_text("time_s,x_mm,y_mm,z_mm\n12.0,1,2,3\n")
    with pytest.raises(DataError, match=r"d.csv:2: no pose within 0.5 s"):
        merge_session(session, device, tmp_path / "o.csv", by="time")
    assert not (tmp_path / "o.csv").exists()


def test_sessions_are_never_overwritten_and_bad_files_are_refused(session, tmp_path):
    with pytest.raises(DataError, match="already exists"):
        record_session(session, TypedJointSource(6), Script([]).ask, print, robot_name="r")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    with pytest.raises(DataError, match="junk.mcap"):
        read_session(junk)


def test_a_failing_source_keeps_the_poses_recorded_so_far(tmp_path):
    class Flaky(TypedJointSource):
        def capture(self, ask, say, instruction, commands=()):
            if ask("next?") == "boom":
                raise OlpError("lost the RTDE connection")
            return super().capture(lambda p: "1 2 3 4 5 6", say, instruction, commands)

    path = tmp_path / "s.mcap"
    with pytest.raises(OlpError, match=r"the 2 poses recorded so far are saved in .*s.mcap"):
        record_session(path, Flaky(6), Script(["", "", "boom"]).ask, print, robot_name="r")
    joints_deg, _, _ = read_session(path)
    assert joints_deg.shape == (2, 6)
    assert [p.name for p in tmp_path.iterdir()] == ["s.mcap"]  # no temporary file left


@pytest.mark.skipif(importlib.util.find_spec("rtde_receive") is None,
                    reason="ur-rtde is not installed")
def test_record_session_from_the_rtde_peer(tmp_path):
    from rtde_peer import RtdePeer

    from olp_compensate.io.rtde_source import RtdeJointSource

    q_rad = np.radians(JOINTS_DEG)

    def enter_at(k):
        def answer(prompt):
            peer.set_joints(q_rad[k])
            time.sleep(0.1)
            return ""
        return answer

    with RtdePeer(lifetime_s=60) as peer, RtdeJointSource(peer.host) as source:
        script = Script([enter_at(k) for k in range(4)] + ["q"])
        assert record_session(tmp_path / "live.mcap", source, script.ask, script.say,
                              robot_name="ur5e") == 4
    joints_deg, _, info = read_session(tmp_path / "live.mcap")
    assert np.allclose(joints_deg, JOINTS_DEG, atol=1e-9)
    assert np.all(np.isfinite(info["controller_time_s"]))
