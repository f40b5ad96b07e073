"""The tool wizard driven by scripts, with typed joints and against a loopback RTDE peer."""

from __future__ import annotations

import importlib.util
import json
import sys
import time
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_tool import FIXED_TILTS_DEG, TOOL_M, irb2400_flange_pose, touches  # noqa: E402

from olp_compensate.kinematics.conventions import MM  # noqa: E402
from olp_compensate.errors import OlpError  # noqa: E402
from olp_compensate.io.rtde_source import RtdeJointSource, parse_joints_deg  # noqa: E402
from olp_compensate.cli.tool_wizard import run_wizard  # noqa: E402
from olp_compensate.io.tool_marks import read_marks_csv  # noqa: E402

HAS_UR_RTDE = importlib.util.find_spec("rtde_receive") is not None
needs_ur_rtde = pytest.mark.skipif(not HAS_UR_RTDE, reason="ur-rtde is not installed")

MARKS_M = np.array([[1.10, -0.25, 0.40], [1.25, 0.10, 0.40], [1.05, 0.30, 0.42],
                    [1.30, -0.05, 0.38], [0.95, 0.05, 0.45], [1.15, 0.20, 0.40]])


class Script:
    """ask() answering from a list (or a callable per prompt); records the conversation."""

    def __init__(self, answers):
        self.answers = list(answers)
        self.prompts: list[str] = []
        self.said: list[str] = []

    def ask(self, prompt: str) -> str:
        self.prompts.append(prompt)
        assert self.answers, f"script exhausted at prompt: {prompt!r}"
        answer = self.answers.pop(0)
        return answer(prompt) if callable(answer) else answer

    def say(self, text: str) -> None:
        self.said.append(text)

    @property
    def text(self) -> str:
        return "\n".join(self.prompts + self.said)


def deg_text(q_rad) -> str:
    return " ".join(f"{v:.6f}" for v in np.degrees(q_rad))


@pytest.fixture(scope="module")
def mark_joints():
    return touches(MARKS_M)


def test_known_marks_with_typed_joints_end_to_end(tmp_path, mark_joints):
    rng = np.random.default_rng(5)
    known_mm = (MARKS_M + rng.normal(0, 0.05 * MM, MARKS_M.shape)) / MM
    answers = ["tGun1", "1", "b"]
    for k in range(6):
        answers += [", ".join(f"{v:.4f}" for v in known_mm[k]), deg_text(mark_joints[k])]
    answers += ["done", "y"]
    script = Script(answers)
    out = tmp_path / "tGun1.json"
    result = run_wizard(irb2400_flange_pose, script.ask, script.say, out_path=out, mass_kg=2.0)
    assert result is not None and not script.answers
    assert np.linalg.norm(result.xyz_m - TOOL_M) / MM < 0.1
    typed_m3 = [float(v) for v in answers[3 + 2 * 2].split(",")]
    assert ("Jog the tool tip onto mark M3 at (" + ", ".join(f"{v:.3f}" for v in typed_m3)
            + ") mm") in script.text
    assert "Fit with 3 touches" in script.text and "PERS tooldata tGun1 := [TRUE,[[" in script.text
    entry = json.loads(out.read_text())["tools"]["tGun1"]
    assert np.allclose(entry["xyz_mm"], result.xyz_m / MM, atol=1e-5)
    request = read_marks_csv(tmp_path / "tGun1_marks.csv", 6)
    assert request.method == "known_marks" and len(request.joints) == 6


def test_bad_touch_is_flagged_at_once_and_can_be_redone(mark_joints):
    slipped = mark_joints[3] + np.radians([0.0, 0.2, 0.0, 0.0, 0.0, 0.0])  # ~3 mm off
    answers = ["tGun1", "known", ""]
    for k in range(4):
        answers += [" ".join(f"{v:.3f}" for v in MARKS_M[k] / MM)]
        answers += [deg_text(slipped if k == 3 else mark_joints[k])]
    answers += ["r", deg_text(mark_joints[3])]  # redo M4 with a good touch
    answers += ["done"]
    script = Script(answers)
    result = run_wizard(irb2400_flange_pose, script.ask, script.say, out_path=None)
    assert "Warning: M4 misses the fit by" in script.text
    assert len(result.residuals_m) == 4 and result.rms_m < 0.01 * MM
    assert np.linalg.norm(result.xyz_m - TOOL_M) / MM < 0.01


def test_fixed_point_typed_with_a_poor_set_asks_for_more():
    point = np.array([1.1, 0.1, 0.4])
    tilts = [(0, 0, 0), (0, 0, 40), (0, 0, -40), (0, 0, 80), (35, 0, 0), (0, -35, 0)]
    joints = touches(np.tile(point, (6, 1)), tilts)
    answers = ["tPin", "2"] + [deg_text(q) for q in joints[:4]]
    answers += ["done", "y"] + [deg_text(q) for q in joints[4:]] + ["done"]
    script = Script(answers)
    result = run_wizard(irb2400_flange_pose, script.ask, script.say)
    assert "about a horizontal axis" in script.text  # the hint after 4 vertical-axis turns
    assert result.method == "fixed_point" and len(result.residuals_m) == 6
    assert np.linalg.norm(result.xyz_m - TOOL_M) / MM < 0.01
    assert np.allclose(result.point_m, point, atol=0.01 * MM)


def test_cancel_returns_none_and_writes_nothing(tmp_path):
    script = Script(["tGun1", "1", "b", "1000 0 500", "q"])
    assert run_wizard(irb2400_flange_pose, script.ask, script.say,
                      out_path=tmp_path / "t.json") is None
    assert "Cancelled" in script.text and not list(tmp_path.iterdir())


def test_typed_joint_errors_are_explained_and_reasked():
    assert np.allclose(parse_joints_deg("[1, 2; 3 4,5 6]", 6), [1, 2, 3, 4, 5, 6])
    script = Script(["tGun1", "2", "1 2 3", "1 2 x 4 5 6", "q"])
    assert run_wizard(irb2400_flange_pose, script.ask, script.say) is None
    assert "expected 6 joint values in degrees" in script.text
    assert "joint 3: 'x' is not a number" in script.text


def test_connection_refused_is_clear_and_fast():
    start = time.monotonic()
    with pytest.raises(OlpError, match=r"connection refused by 127\.0\.0\.\d+:30004"):
        RtdeJointSource("127.0.0.77", connect_timeout_s=2.0)
    assert time.monotonic() - start < 3.0


@needs_ur_rtde
def test_wizard_against_loopback_rtde_peer(tmp_path):
    from rtde_peer import RtdePeer

    point = np.array([1.1, 0.1, 0.4])
    rng = np.random.default_rng(7)
    joints = touches(point + rng.normal(0, 0.05 * MM, (6, 3)), FIXED_TILTS_DEG)

    def jog_to(q):
        def answer(prompt):
            assert "press Enter" in prompt
            peer.set_joints(q)
            time.sleep(0.1)  # let the new joints reach the client
            return ""
        return answer

    with RtdePeer(lifetime_s=60) as peer:
        peer.set_joints(np.zeros(6))
        with RtdeJointSource(peer.host, stall_timeout_s=1.0) as source:
            # the peer runs in its own process: wait (bounded) until it has seen the start
            deadline = time.monotonic() + 5.0
            while "S" not in peer.commands and time.monotonic() < deadline:
                time.sleep(0.02)
            assert peer.requested_outputs == ["timestamp", "actual_q"]
            assert peer.commands[:4] == ["V", "v", "O", "S"]
            script = Script(["tLive", "2"] + [jog_to(q) for q in joints] + ["done"])
            result = run_wizard(irb2400_flange_pose, script.ask, script.say,
                                joint_source=source)
            assert "UR controller at" in script.text
            assert np.linalg.norm(result.xyz_m - TOOL_M) / MM < 0.1

            peer.stop_streaming()
            start = time.monotonic()
            with pytest.raises(OlpError, match="stopped streaming: no new RTDE data for 1 s"):
                source.read()
            assert time.monotonic() - start < 2.5


@needs_ur_rtde
def test_default_ur_rtde_recipe_is_served():
    """The receive interface's default 58-variable recipe gets real types from the peer."""
    import subprocess
    from rtde_peer import RtdePeer

    with RtdePeer(lifetime_s=30) as peer:
        peer.set_joints([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
        code = ("import rtde_receive, time\n"
                f"r = rtde_receive.RTDEReceiveInterface({peer.host!r})\n"
                "time.sleep(0.2)\nprint(r.getActualQ())\n")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=20)
        assert "[0.1, 0.2, 0.3, 0.4, 0.5, 0.6]" in out.stdout, out.stdout + out.stderr
        assert "actual_TCP_pose" in peer.requested_outputs
        assert len(peer.requested_outputs) > 40
