"""benchmarks/corpus.py --robot auto: the robot each program runs on (header, map, targets),
on RAPID modules written here from the forward kinematics of a known arm."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.compensation.pose import Compensator
from olp_compensate.errors import DataError
from olp_compensate.kinematics.conventions import quat_wxyz_from_matrix
from olp_compensate.kinematics.robot import load_robot

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import corpus_robots  # noqa: E402

SMALL, BIG = "abb_irb120_3_58", "abb_irb2400"


def module_reached_by(robot: str, n: int = 12, seed: int = 3, header: str = "") -> str:
    """A RAPID module of ``n`` robtargets (tool0, wobj0) at the flange poses of ``robot``
    at random joints inside its axis ranges (kept 20 % away from their ends), with the
    confdata of those joints."""
    comp = Compensator(nominal_calibration(load_robot(robot)))
    ranges = comp.robot.controller_ranges
    rng = np.random.default_rng(seed)
    lo, hi = ranges[:, 0], ranges[:, 1]
    q_ctrl = lo + (hi - lo) * rng.uniform(0.2, 0.8, size=(n, 6))
    q = comp.robot.joints_from_controller(q_ctrl)
    flanges = comp.nominal_flange(q)
    conf = comp.confdata(q)
    lines = ["MODULE Cell", header] if header else ["MODULE Cell"]
    for k, (pose, c) in enumerate(zip(flanges, conf)):
        x, y, z = pose[:3, 3] * 1000.0
        qw, qx, qy, qz = quat_wxyz_from_matrix(pose[:3, :3])
        lines.append(f"  CONST robtarget p{k}:=[[{x:.3f},{y:.3f},{z:.3f}],"
                     f"[{qw:.8f},{qx:.8f},{qy:.8f},{qz:.8f}],[{c[0]},{c[1]},{c[2]},{c[3]}],"
                     "[9E9,9E9,9E9,9E9,9E9,9E9]];")
    lines.append("  PROC main()")
    lines += [f"    MoveJ p{k}, v100, fine, tool0;" for k in range(n)]
    lines += ["  ENDPROC", "ENDMODULE", ""]
    return "\n".join(line for line in lines if line is not None)


COMPS = corpus_robots.Compensators()   # one nominal compensator per robot for the module


def choose(path: Path, robot_map=()):
    return corpus_robots.choose("rapid", [path], BIG, list(robot_map), COMPS, None)[0]


def test_targets_of_a_small_arm_choose_it(tmp_path):
    path = tmp_path / "cell.mod"
    path.write_text(module_reached_by(SMALL))
    choice = choose(path)
    assert (choice.robot, choice.how) == (SMALL, "targets")
    assert choice.detail.startswith("12 of 12 reached")
    # the fixed default is scored too, and is worse: an IRB 2400 reaches fewer of them
    reached_on_big = int(choice.detail.split("; ")[1].split(" on ")[0])
    assert reached_on_big < 12


def test_targets_of_a_big_arm_choose_a_big_arm(tmp_path):
    path = tmp_path / "cell.mod"
    path.write_text(module_reached_by("abb_irb6700_200_260", seed=5))
    choice = choose(path)
    assert choice.how == "targets"
    small = {"abb_irb120_3_58", "abb_irb1200_5_90", "abb_irb1200_7_70"}
    assert choice.robot not in small
    assert choice.detail.startswith("12 of 12 reached")


def test_a_header_wins_over_the_targets(tmp_path):
    path = tmp_path / "cell.mod"
    path.write_text(module_reached_by(SMALL, header="  ! olp-robot: abb_irb1600_6_12"))
    choice = choose(path)
    assert (choice.robot, choice.how) == ("abb_irb1600_6_12", "header")


def test_a_header_naming_no_library_robot_falls_back_to_the_targets(tmp_path):
    path = tmp_path / "cell.mod"
    path.write_text(module_reached_by(SMALL, header="  ! olp-robot: abb_irb99_9_99"))
    choice = choose(path)
    assert (choice.robot, choice.how) == (SMALL, "targets")
    assert "abb_irb99_9_99" in choice.detail


def test_the_map_names_a_folder_s_robot(tmp_path):
    cell = tmp_path / "owner+cell" / "RAPID"
    cell.mkdir(parents=True)
    path = cell / "cell.mod"
    path.write_text(module_reached_by(SMALL))
    robot_map = tmp_path / "robots.map"
    robot_map.write_text("# repositories whose README names the arm\n\n"
                         "*/other+repo/*,abb_irb4600_20_250\n"
                         "*/owner+cell/*,abb_irb1200_7_70\n")
    lines = corpus_robots.read_robot_map(robot_map)
    choice = choose(path, lines)
    assert (choice.robot, choice.how, choice.detail) == ("abb_irb1200_7_70", "map", "line 4")


@pytest.mark.parametrize("text, where", [
    ("*/cell/*\n", ":1:1:"),
    ("*/cell/*, abb_irb_none\n", ":1:11:"),
])
def test_a_bad_map_line_is_refused_with_its_place(tmp_path, text, where):
    robot_map = tmp_path / "robots.map"
    robot_map.write_text(text)
    with pytest.raises(DataError, match=f"robots.map{where}"):
        corpus_robots.read_robot_map(robot_map)


def test_two_robots_named_is_a_failure_not_a_guess(tmp_path):
    path = tmp_path / "cell.mod"
    path.write_text(module_reached_by(SMALL, header="  ! olp-robot: abb_irb1600_6_12\n"
                                                    "  ! olp-robot: abb_irb2400"))
    with pytest.raises(DataError, match="more than one robot"):
        choose(path)


def test_the_benchmark_prints_the_choice_and_the_model_table(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "small.mod").write_text(module_reached_by(SMALL))
    (tmp_path / "a" / "named.mod").write_text(
        module_reached_by(BIG, seed=7, header="  ! olp-robot: abb_irb2400"))
    done = subprocess.run([sys.executable, str(BENCHMARKS / "corpus.py"), str(tmp_path / "a"),
                           "--robot", "auto"], capture_output=True, text=True, check=True)
    out = done.stdout
    assert f"small.mod: {SMALL} (targets: 12 of 12 reached" in out
    assert f"named.mod: {BIG} (header)" in out
    model = next(line for line in out.splitlines() if line.startswith(f"{SMALL}:"))
    assert "programs 1 (targets 1); target uses 12; ok 12 (100.0 %)" in model
    assert f"on {BIG}" in model
    big = next(line for line in out.splitlines() if line.startswith(f"{BIG}:"))
    assert "programs 1 (header 1); target uses 12; ok 12 (100.0 %) vs 12 (100.0 %)" in big
