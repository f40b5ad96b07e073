"""Every compensation applies the one rule on the parts of a calibration fitted in a joint
range (issue 28 items 1 and 3): the library's ``compensate_poses``/``compensate_pose`` and
the service's ``compensate_poses`` as olp-fix does. Outside the range a named effect was
fitted on, a target gets exactly what the geometric fallback alone gives, with a note;
inside, the extended model's answer; the residual map only inside its region.

The truth is a virtual arm built from its parts: a geometric model (the nominal arm with
0.3 mm-scale parameter errors), a gear harmonic of joint 2 fitted below q2 = 0.1 rad, and
a residual map drawn at random over a box inside that range; each answer is checked by
the forward kinematics of the model that must hold there, and against the same targets
compensated on that model alone."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.effect_ranges import with_geometric_fallback
from olp_compensate.calibration.effects import GearHarmonic
from olp_compensate.calibration.remainder import ResidualMap
from olp_compensate.calibration.simulate import random_joints
from olp_compensate.cli.cal import main
from olp_compensate.compensation.pose import Compensator, compensate_pose, compensate_poses
from olp_compensate.compensation.residual_map import EDGE
from olp_compensate.io.calibration_file import calibration_to_dict
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.service.calls import Service

ROBOT = load_robot("abb_irb2400")
SPLIT_Q2 = 0.1          # rad: the effect was fitted on q2 below this
USED = "geometric model used"
OUTSIDE = "where the named effects were fitted: geometric model used"
APPLIED = "residual map applied"


def _residual_map(rng, q_ctrl: np.ndarray) -> ResidualMap:
    """A map (about 0.1-0.3 mm) over the box q1 below its median, q2 below SPLIT_Q2 - 0.2."""
    q_range = np.column_stack([ROBOT.lower_limits, ROBOT.upper_limits])
    q_range[0, 1] = np.median(q_ctrl[:, 0])
    q_range[1, 1] = SPLIT_Q2 - 0.2
    n_in, features = 12, 20
    rmap = ResidualMap(kinds=("revolute",) * 6, center=np.zeros(6), span=np.ones(6),
                       frequencies=rng.standard_normal((n_in, features)),
                       phases=rng.uniform(0, 2 * np.pi, features), weights=np.zeros((1, 3)),
                       length=1.0, penalty=1.0, q_range=q_range)
    p = rmap.features(np.zeros((1, 6))).shape[1]
    return replace(rmap, weights=rng.normal(0, 1e-4, (p, 3)))


class Cell:
    """The calibrations (full, extended alone, geometric alone), 40 flange targets with
    their configurations and a tool, and a calib.json in ``root`` for the service."""

    def __init__(self, root):
        rng = np.random.default_rng([28, 1, 3])
        geometric = nominal_calibration(ROBOT)
        geometric = replace(geometric, values=geometric.values
                            + rng.normal(0, 3e-4, geometric.values.shape))
        effect = GearHarmonic(joint=1, order=2, values=(4e-4, -3e-4))
        self.extended = replace(nominal_calibration(ROBOT), effects=(effect,))
        fitted = np.clip(ROBOT.controller_ranges, -np.pi, np.pi).T.copy()
        fitted[1, 1] = SPLIT_Q2
        joints = random_joints(ROBOT, 40, rng)
        self.map = _residual_map(rng, joints)
        self.full = replace(with_geometric_fallback(self.extended, geometric, fitted),
                            residual_map=self.map)
        self.geometric = geometric
        self.tool = np.eye(4)
        self.tool[:3, 3] = 0.02, -0.01, 0.15
        nominal = nominal_calibration(ROBOT)
        self.targets = nominal.flange_poses(joints) @ self.tool
        self.confdata = Compensator(nominal).confdata(ROBOT.joints_from_controller(joints))
        self.root = root
        (root / "calib.json").write_text(json.dumps(calibration_to_dict(self.full)))

    def solve(self, calibration):
        return compensate_poses(calibration, self.targets, tool=self.tool,
                                confdata=self.confdata)

    def reached(self, calibration, joints: np.ndarray) -> np.ndarray:
        """(m, 3) where ``calibration`` (its fallback left out) puts the tool, base, m."""
        flange = replace(calibration, geometric_fallback=None).flange_poses(joints)
        return (flange @ self.tool)[:, :3, 3]


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    return Cell(tmp_path_factory.mktemp("cell"))


def test_compensate_poses_takes_the_geometric_model_outside_and_the_map_inside(cell):
    full = cell.solve(cell.full)
    geo = cell.solve(cell.geometric)
    ext = cell.solve(cell.extended)
    ok = full.success
    assert ok.all() and geo.success.all() and ext.success.all()
    notes = full.model_notes
    outside = cell.full.outside_fitted(full.joints)
    in_map = ~outside & cell.map.inside(full.joints)
    plain = ~outside & ~in_map
    assert outside.sum() >= 8 and in_map.sum() >= 4 and plain.sum() >= 8
    # outside the fitted range: the geometric model alone, to 1e-6 mm, with the note
    assert np.abs(full.poses[outside] - geo.poses[outside]).max() < 1e-9
    reach = cell.reached(cell.geometric, full.joints[outside])
    assert np.abs(reach - cell.targets[outside, :3, 3]).max() < 1e-9
    # ... which is not the extended model's answer there (the test can tell them apart)
    assert np.abs(ext.poses[outside, :3, 3] - geo.poses[outside, :3, 3]).max() > 1e-5
    for i in np.flatnonzero(outside):
        assert OUTSIDE in notes[i] and "q2 = " in notes[i], notes[i]
        assert "residual map" not in notes[i] or "not applied" in notes[i]
    # inside the range, outside the map's region: the extended model's answer
    assert np.abs(full.poses[plain] - ext.poses[plain]).max() < 1e-9
    for i in np.flatnonzero(plain):
        assert notes[i] == "outside the joint region of the residual map: not applied"
    # inside the map's region: the extended arm plus the map reaches the target
    assert all(notes[i] == APPLIED for i in np.flatnonzero(in_map))
    truth = cell.reached(cell.extended, full.joints[in_map]) + cell.map.predict(
        full.joints[in_map])
    miss = np.linalg.norm(truth - cell.targets[in_map, :3, 3], axis=1)
    before = np.linalg.norm(cell.reached(cell.extended, ext.joints[in_map])
                            + cell.map.predict(ext.joints[in_map])
                            - cell.targets[in_map, :3, 3], axis=1)
    assert before.max() > 5e-5 and miss.max() < 0.1 * before.max()


def test_compensate_pose_of_one_target_carries_the_same_note(cell):
    full = cell.solve(cell.full)
    outside = np.flatnonzero(cell.full.outside_fitted(full.joints))
    for i in outside[:2]:
        one = compensate_pose(cell.full, cell.targets[i], tool=cell.tool,
                              config=cell.confdata[i])
        assert one.success and one.model_note == full.model_notes[i] and one.note == ""
        assert np.abs(one.pose - full.poses[i]).max() < 1e-12


def test_the_service_answers_what_the_library_does_with_the_notes(cell):
    full = cell.solve(cell.full)
    poses = [{"target": t.tolist(), "tool": cell.tool.tolist(), "config": c.tolist()}
             for t, c in zip(cell.targets, cell.confdata)]
    answers = Service(cell.root).call("compensate_poses", {
        "calibration": "calib.json", "units": "m", "poses": poses})["poses"]
    outside = cell.full.outside_fitted(full.joints)
    for i, answer in enumerate(answers):
        assert answer["status"] == str(full.status[i]) and answer["note"] == ""
        assert answer["model_note"] == full.model_notes[i]
        assert np.abs(np.array(answer["pose"]) - full.poses[i]).max() < 1e-9
        assert (USED in answer["model_note"]) == outside[i]
    assert sum(USED in a["model_note"] for a in answers) >= 8
    assert sum(a["model_note"] == APPLIED for a in answers) >= 4


def _predict(cal, joints: np.ndarray, folder) -> tuple[set, np.ndarray]:
    """olp-cal predict of controller joints (m, n) rad on ``cal`` (its tools left out):
    the rows (0-based) it says lie outside the fitted ranges, and the flange points
    (m, 3) m, device frame."""
    import contextlib
    import io

    path = folder / "predict_calib.json"
    path.write_text(json.dumps(calibration_to_dict(replace(cal, tools={}))))
    lines = ["q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg"]
    lines += [",".join(f"{v:.12f}" for v in row) for row in np.degrees(joints)]
    (folder / "joints.csv").write_text("\n".join(lines) + "\n")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["predict", "--model", str(path), str(folder / "joints.csv"), "-o",
                     str(folder / "out.csv")]) == 0
    said = {int(ln.split("line ")[1].split(":")[0]) - 2 for ln in printed.getvalue().splitlines()
            if ln.startswith("note: line") and OUTSIDE in ln}
    rows = [ln.split(",") for ln in (folder / "out.csv").read_text().splitlines()[1:]]
    return said, np.array([[float(v) for v in r[-3:]] for r in rows]) * 1e-3


def test_predict_and_compensate_poses_agree_on_the_rows_outside(cell, tmp_path):
    """olp-cal predict at the joints compensate_poses gives: the same rows outside the
    fitted range (one test, ``Calibration.outside_fitted``), and the tool on its target."""
    full = cell.solve(cell.full)
    said, flange = _predict(cell.full, full.joints, tmp_path)
    compensated = {i for i, n in enumerate(full.model_notes) if OUTSIDE in n}
    assert said == compensated and len(said) >= 8
    # predict's flange point at those joints is the flange the target needs (device frame
    # = base): exact where a single model holds, within the map pass's second order inside
    wanted = (cell.targets @ np.linalg.inv(cell.tool))[:, :3, 3]
    miss = np.linalg.norm(flange - wanted, axis=1) * 1e3
    in_map = np.array([n == APPLIED for n in full.model_notes])
    assert miss[~in_map].max() < 1e-5 and miss[in_map].max() < 0.05


def test_a_target_on_the_edge_takes_the_geometric_model_and_says_so(cell, tmp_path):
    """Targets the nominal arm reaches at q2 = SPLIT_Q2 (ten at 0.05 rad below): the extended model's solution lies
    just outside the range, the geometric model's (mostly) just inside. There no answer
    holds for both models; the geometric one is written with the edge note, and predict at
    its joints (inside) names the same rows outside as compensate_poses does."""
    rng = np.random.default_rng([28, 4])
    joints = random_joints(ROBOT, 30, rng)
    joints[:, 1] = SPLIT_Q2
    joints[20:, 1] = SPLIT_Q2 - 0.05       # and some plainly inside (not in the map's box)
    nominal = nominal_calibration(ROBOT)
    targets = nominal.flange_poses(joints) @ cell.tool
    conf = Compensator(nominal).confdata(ROBOT.joints_from_controller(joints))
    full, geo, ext = (compensate_poses(c, targets, tool=cell.tool, confdata=conf)
                      for c in (cell.full, cell.geometric, cell.extended))
    assert full.success.all()
    edge = (ext.joints[:, 1] > SPLIT_Q2) & (geo.joints[:, 1] <= SPLIT_Q2)
    assert edge.sum() >= 10
    for i in np.flatnonzero(edge):
        assert full.model_notes[i].startswith(EDGE) and "q2 = " in full.model_notes[i]
        assert OUTSIDE not in full.model_notes[i]
    used = np.array([USED in n for n in full.model_notes])
    assert np.array_equal(used, ext.joints[:, 1] > SPLIT_Q2)
    assert np.abs(full.poses[used] - geo.poses[used]).max() < 1e-9
    assert np.abs(full.poses[~used] - ext.poses[~used]).max() < 1e-9
    said, _ = _predict(cell.full, full.joints, tmp_path)
    assert said == {i for i, n in enumerate(full.model_notes) if OUTSIDE in n}


def test_the_robodk_post_solves_its_targets_by_the_same_rule(cell):
    """The post's batch (RoboDK's targets in mm, its joints in degrees choosing the
    configuration) gives compensate_poses's targets and notes."""
    from olp_compensate.robodk import _solve_targets, _Target

    full = cell.solve(cell.full)
    nominal = Compensator(nominal_calibration(ROBOT))
    joints = np.degrees(ROBOT.controller_from_joints(nominal.solve_nominal(
        cell.targets @ np.linalg.inv(cell.tool), cell.confdata)))
    tool = cell.tool.copy()
    tool[:3, 3] *= 1e3
    targets = []
    for k, (target, q) in enumerate(zip(cell.targets, joints)):
        pose = target.copy()
        pose[:3, 3] *= 1e3
        targets.append(_Target(k, 0, 1, pose, q, np.eye(4), tool, ""))
    results = _solve_targets(Compensator(cell.full), targets)
    assert [r.model_note for r in results] == list(full.model_notes)
    got = np.array([r.pose_mm for r in results])
    assert np.abs(got[:, :3, 3] * 1e-3 - full.poses[:, :3, 3]).max() < 1e-9
    assert sum(OUTSIDE in r.model_note for r in results) >= 8


def test_a_map_over_the_whole_range_is_not_applied_where_the_geometric_model_is(cell):
    """The residual map corrects the extended model's residual: on a row solved on the
    geometric fallback it is not applied, even inside its region, and the row's stated
    accuracy is the geometric solve's."""
    everywhere = replace(cell.map, q_range=np.column_stack([ROBOT.lower_limits - 1,
                                                            ROBOT.upper_limits + 1]))
    full = cell.solve(replace(cell.full, residual_map=everywhere))
    geo = cell.solve(cell.geometric)
    outside = cell.full.outside_fitted(full.joints)
    assert outside.sum() >= 8 and full.success.all()
    assert np.abs(full.poses[outside] - geo.poses[outside]).max() < 1e-9
    assert np.array_equal(full.position_error_m[outside], geo.position_error_m[outside])
    for i in np.flatnonzero(outside):
        assert "residual map not applied" in full.model_notes[i], full.model_notes[i]
    assert all(full.model_notes[i] == APPLIED for i in np.flatnonzero(~outside))
