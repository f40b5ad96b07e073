"""Local calibration per region (seed section 10): a virtual robot with a hidden joint
compliance, measured all over its workspace and densely inside two 400 mm cubes; the local
models must predict and compensate better than the global one inside their regions, the
dispatch must pick the right model, and calib.json must carry the regions (and read old
files as before).

Truth is the virtual robot (pinocchio on the perturbed URDF, compliance solved as a fixed
point), independent of the calibrated models. Targets are compared in the measuring
device's frame, where the global calibration places the base frame the targets are in.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from olp_compensate.calibration.calibration import (GLOBAL_MODEL, RegionBox, RegionCalibration,
                                                    nominal_calibration)
from olp_compensate.calibration.identify import IdentificationOptions
from olp_compensate.calibration.regions import identify_regions, region_box
from olp_compensate.calibration.simulate import (make_virtual_robot, random_hidden_effect,
                                                 random_joints, scaled_effect)
from olp_compensate.cli.cal import main
from olp_compensate.compensation.pose import Compensator, compensate_poses
from olp_compensate.compensation.regions import RegionalCompensator, explain_failures
from olp_compensate.errors import DataError, ModelError
from olp_compensate.io.calibration_file import (calibration_from_dict, calibration_to_dict,
                                                dumps_calibration, read_calibration,
                                                write_calibration)
from olp_compensate.io.measurements import write_measurements
from olp_compensate.kinematics.robot import load_robot

NOISE_M = 0.03e-3
COMPLIANCE_RMS_M = 1.5e-3
"""How far the hidden compliance moves the measured point, RMS over the workspace."""
CUBES = {"A": np.array([0.9, -0.3, 0.7]), "B": np.array([0.5, 0.7, 1.0])}
HALF_M = 0.2                                     # 400 mm cubes
GLOBAL_POSES, REGION_POSES, TEST_POSES = 60, 30, 50


def same_document(a, b) -> bool:
    """Two JSON documents alike but for rounding in the last digits of their numbers."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(
            same_document(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(map(same_document, a, b))
    if isinstance(a, float) or isinstance(b, float):
        return a == pytest.approx(b, rel=1e-12, abs=1e-12)
    return a == b


def rms(errors) -> float:
    return float(np.sqrt(np.mean(np.square(errors))))


class World:
    """A virtual IRB 2400 with a hidden compliance, its measurements (60 poses anywhere,
    30 in each cube), the calibration with regions, and unseen poses in each cube."""

    def __init__(self, seed: int, folds: int = 0):
        self.robot = robot = load_robot("abb_irb2400")
        virtual = make_virtual_robot(robot, seed=seed, n_points=1)
        rng = np.random.default_rng(seed)
        pool = random_joints(robot, 40000, rng, margin=0.2)
        self.nominal = nominal_calibration(robot)
        flange = self.nominal.flange_poses(pool)
        tcp = flange[:, :3, 3] + flange[:, :3, :3] @ virtual.tools["tcp"]
        effect = random_hidden_effect(robot, rng, pool[:200], kind="joint_compliance")
        effect = scaled_effect(virtual, effect, pool[:200], COMPLIANCE_RMS_M)
        self.virtual = replace(virtual, effects=(effect,))
        self.test = {}
        chosen, labels = [pool[:GLOBAL_POSES]], [""] * GLOBAL_POSES
        for name, centre in CUBES.items():
            rows = np.flatnonzero(np.all(np.abs(tcp - centre) <= HALF_M, axis=1))
            assert len(rows) >= REGION_POSES + TEST_POSES
            chosen.append(pool[rows[:REGION_POSES]])
            labels += [name] * REGION_POSES
            self.test[name] = pool[rows[REGION_POSES:REGION_POSES + TEST_POSES]]
        meas = self.virtual.measure(np.vstack(chosen), NOISE_M, rng)
        self.meas = replace(meas, extra={"region": labels})
        self.regional = identify_regions(robot, self.meas, IdentificationOptions(folds=folds))
        self.calibration = self.regional.result.calibration

    def true_error(self, calibration, joints) -> np.ndarray:
        """(m,) distance between the model's and the virtual robot's TCP, device frame, m."""
        names = ["tcp"] * len(joints)
        return np.linalg.norm(calibration.predict_points(joints, names)
                              - self.virtual.true_points(joints, names), axis=1)

    def targets(self, name: str):
        """TCP poses (base frame) of the unseen poses of cube ``name`` that lie in the
        region's box, the program's tool (the calibrated 'tcp') and their confdata."""
        tool = np.eye(4)
        tool[:3, 3] = self.calibration.tools["tcp"].xyz_m
        joints = self.test[name]
        targets = self.nominal.flange_poses(joints) @ tool
        inside = self.calibration.region(name).contains(targets[:, :3, 3])
        conf = Compensator.confdata(self.compensator("global"),
                                    self.robot.joints_from_controller(joints))
        return targets[inside], tool, conf[inside]

    def compensator(self, kind: str):
        if not hasattr(self, "_comps"):
            self._comps = {"global": Compensator(self.calibration),
                           "regional": RegionalCompensator(self.calibration)}
        return self._comps[kind]

    def reach_error(self, comp, targets, tool, conf) -> np.ndarray:
        """(m,) how far the virtual robot's TCP lands from each target, device frame, m,
        at the joints ``comp`` compensates it to."""
        batch = compensate_poses(comp, targets, tool=tool, confdata=conf)
        assert batch.success.all(), batch.status
        reached = self.virtual.true_points(batch.joints, ["tcp"] * len(targets))
        device = self.calibration.device_T_base
        wanted = targets[:, :3, 3] @ device[:3, :3].T + device[:3, 3]
        return np.linalg.norm(reached - wanted, axis=1)


@pytest.fixture(scope="module", params=[3, 6])
def world(request):
    return World(request.param, folds=5)


def test_local_models_predict_better_inside_their_regions(world):
    cal = world.calibration
    assert [r.name for r in cal.regions] == ["A", "B"]
    for name in CUBES:
        region = cal.region(name)
        joints = world.test[name]
        global_rms = rms(world.true_error(cal, joints))
        local_rms = rms(world.true_error(region.calibration, joints))
        assert local_rms < 0.7 * global_rms, (name, local_rms, global_rms)
        # the held-out figures (measured data only) tell the same story
        local = region.calibration.validation
        assert local.poses == REGION_POSES and local.heldout_rms_mm is not None
        assert local.heldout_rms_mm < region.global_heldout_rms_mm
        # the box: the region's measured points in the global base frame, grown by 50 mm
        device = cal.device_T_base
        labels = np.array(world.meas.extra["region"])
        points = (world.meas.points[labels == name] - device[:3, 3]) @ device[:3, :3]
        assert region.box.margin_m == pytest.approx(0.05)
        assert np.allclose(region.box.min_m, points.min(axis=0) - 0.05)
        assert np.allclose(region.box.max_m, points.max(axis=0) + 0.05)
        assert np.all(np.abs(region.box.centre_m - CUBES[name]) < HALF_M)


def test_regional_compensation_reaches_targets_better(world):
    for name in CUBES:
        targets, tool, conf = world.targets(name)
        assert len(targets) >= 20
        regional = world.compensator("regional")
        assert set(regional.regions_for(targets)) == {name}
        global_rms = rms(world.reach_error(world.compensator("global"), targets, tool, conf))
        local_rms = rms(world.reach_error(regional, targets, tool, conf))
        assert local_rms < 0.7 * global_rms, (name, local_rms, global_rms)


def test_forcing_the_global_model_gives_the_global_compensation(world):
    targets, tool, conf = world.targets("A")
    forced = RegionalCompensator(world.calibration, force=GLOBAL_MODEL)
    a = compensate_poses(forced, targets, tool=tool, confdata=conf)
    b = compensate_poses(world.compensator("global"), targets, tool=tool, confdata=conf)
    assert np.array_equal(a.joints, b.joints) and np.array_equal(a.poses, b.poses)


def test_dispatch_merges_rows_in_order_as_each_region_solves_them(world):
    """Interleaved rows of A, B and the global model: the merged result equals each
    model's own compensator on its rows (two code paths)."""
    comp = world.compensator("regional")
    ta, tool, ca = world.targets("A")
    tb, _, cb = world.targets("B")
    anywhere = world.meas.joints[:GLOBAL_POSES]      # the poses measured anywhere
    tcp = world.nominal.flange_poses(anywhere) @ tool
    k = int(np.flatnonzero(np.equal(world.calibration.region_for(tcp[:, :3, 3]), None))[0])
    outside = tcp[k]
    conf_outside = Compensator.confdata(
        comp, world.robot.joints_from_controller(anywhere[k:k + 1]))[0]
    targets = np.stack([ta[0], tb[0], outside, ta[1], tb[1]])
    conf = np.stack([ca[0], cb[0], conf_outside, ca[1], cb[1]])
    names = comp.regions_for(targets)
    assert names.tolist() == ["A", "B", GLOBAL_MODEL, "A", "B"]
    desired = targets @ np.linalg.inv(tool)
    tools = ["tcp"] * 5
    q, flange, solution, nominal, regional = comp.solve_regions(
        desired, desired, conf, regions=names, tools=tools)
    assert regional.regions.tolist() == names.tolist() and solution.success.all()
    for name in ("A", "B", GLOBAL_MODEL):
        rows = np.flatnonzero(names == name)
        own = comp.compensator_for(name)
        local = comp.region_desired(name, desired[rows], ["tcp"] * len(rows))
        solve = (Compensator.compensate_flanges if name == GLOBAL_MODEL
                 else type(own).compensate_flanges)
        q_own, flange_own, sol_own, nominal_own = solve(own, local, desired[rows], conf[rows])
        assert np.allclose(q[rows], q_own, atol=1e-12)
        assert np.allclose(flange[rows], flange_own, atol=1e-12)
        assert np.allclose(nominal[rows], nominal_own, atol=1e-12)
        assert solution.reason[rows].tolist() == sol_own.reason.tolist()
    # a region's tool point replaces the global one; the base frames are related through
    # the one device frame
    region = world.calibration.region("A").calibration
    shifted = comp.region_desired("A", desired[:1], ["tcp"])[0]
    back = np.linalg.inv(comp.region_base_T_base("A")) @ shifted
    global_tcp = (desired[0] @ tool)[:3, 3]
    local_tcp = back[:3, 3] + back[:3, :3] @ region.tools["tcp"].xyz_m
    assert np.allclose(global_tcp, local_tcp, atol=1e-12)
    assert np.allclose(region.device_T_base @ comp.region_base_T_base("A"),
                       world.calibration.device_T_base, atol=1e-12)


def test_failures_are_explained_on_the_model_that_solved_them(world):
    comp = RegionalCompensator(world.calibration, force="B")
    far = np.eye(4)
    far[:3, 3] = [3.0, 0.0, 0.5]                   # beyond any IRB 2400's reach
    desired = far[None]
    q, flange, solution, nominal, regional = comp.solve_regions(desired, desired, None)
    assert regional.regions.tolist() == ["B"] and not solution.success[0]
    report = explain_failures(comp, solution, desired, None, regional)[0]
    assert "out of reach" in report.note or "not solved" in report.note


def test_region_for_dispatch_rules():
    robot = load_robot("abb_irb2400")
    base = nominal_calibration(robot)
    local = nominal_calibration(robot)
    a = RegionCalibration("A", RegionBox(np.zeros(3), np.ones(3)), local)
    b = RegionCalibration("B", RegionBox(np.full(3, 0.8), np.full(3, 2.0)), local)
    cal = replace(base, regions=(a, b))
    points = np.array([[0.1, 0.1, 0.1], [1.9, 1.9, 1.9], [0.92, 0.92, 0.92],
                       [0.98, 0.98, 0.98], [0.95, 0.95, 0.95], [-1.0, 0.0, 0.0],
                       [1.0, 0.5, 0.5]])
    # where they overlap the nearest centre wins (A's at 0.5, B's at 1.4; a tie: the
    # first listed); a point on a face is inside
    assert cal.region_for(points).tolist() == ["A", "B", "A", "B", "A", None, "A"]
    assert nominal_calibration(robot).region_for(points).tolist() == [None] * 7
    comp = RegionalCompensator(cal, force="B")
    assert comp.regions_for(points).tolist() == ["B"] * 7
    assert RegionalCompensator(cal).regions_for(points[5:6]).tolist() == [GLOBAL_MODEL]
    with pytest.raises(DataError, match="region 'C'.*A, B"):
        RegionalCompensator(cal, force="C")
    with pytest.raises(DataError, match="more than once"):
        replace(base, regions=(a, a))
    with pytest.raises(DataError, match="global model"):
        RegionCalibration(GLOBAL_MODEL, RegionBox(np.zeros(3), np.ones(3)), local)
    with pytest.raises(DataError, match="min <= max"):
        RegionBox(np.ones(3), np.zeros(3))
    with pytest.raises(DataError, match="length >= 0"):
        region_box(np.zeros((2, 3)), -0.01)
    with pytest.raises(DataError, match="no region named 'C'"):
        cal.region("C")


def test_calib_json_round_trip_with_regions(world, tmp_path):
    path = tmp_path / "calib.json"
    write_calibration(path, world.calibration)
    doc = json.loads(path.read_text())
    assert [r["name"] for r in doc["regions"]] == ["A", "B"]
    assert doc["regions"][0]["volume"]["margin_mm"] == pytest.approx(50.0)
    back = read_calibration(path)
    assert len(back.regions) == 2
    for got, want in zip(back.regions, world.calibration.regions):
        assert got.name == want.name
        assert np.allclose(got.box.min_m, want.box.min_m, atol=1e-12)
        assert np.allclose(got.box.max_m, want.box.max_m, atol=1e-12)
        assert np.allclose(got.calibration.values, want.calibration.values, atol=1e-12)
        assert np.allclose(got.calibration.device_T_base, want.calibration.device_T_base,
                           atol=1e-12)
        assert np.allclose(got.calibration.tools["tcp"].xyz_m,
                           want.calibration.tools["tcp"].xyz_m, atol=1e-12)
        assert got.calibration.frozen == want.calibration.frozen
        assert got.calibration.validation == want.calibration.validation
        assert got.global_heldout_rms_mm == want.global_heldout_rms_mm
    # same predictions, same dispatch, and writing again gives the same text
    joints = world.test["A"][:5]
    assert np.allclose(back.region("A").calibration.predict_points(joints, ["tcp"] * 5),
                       world.calibration.region("A").calibration.predict_points(
                           joints, ["tcp"] * 5), atol=1e-9)
    assert same_document(json.loads(dumps_calibration(back)), doc)


def test_files_without_regions_read_and_write_as_before(world):
    plain = replace(world.calibration, regions=())
    doc = calibration_to_dict(plain)
    assert set(doc) == {"format", "version", "robot", "model", "device_T_base", "tools",
                        "effects", "validation"}
    back = calibration_from_dict(json.loads(json.dumps(doc)))
    assert back.regions == ()
    assert back.region_for(np.zeros((2, 3))).tolist() == [None, None]
    assert same_document(json.loads(dumps_calibration(back)),
                         json.loads(dumps_calibration(plain)))
    # the top level of a file with regions is the global calibration, as before
    with_regions = calibration_to_dict(world.calibration)
    assert {k: v for k, v in with_regions.items() if k != "regions"} == doc


@pytest.mark.parametrize("edit, message", [
    (lambda r: r["volume"].update(min_mm=[0, 0, 0], max_mm=[-1, 0, 0]), "min <= max"),
    (lambda r: r.update(name="global"), "regions/0/name"),
    (lambda r: r["volume"].pop("max_mm"), "regions/0/volume"),
    (lambda r: r["model"]["parameters"].pop(3), "regions/0.*missing"),
])
def test_bad_region_entries_are_refused(world, edit, message):
    doc = json.loads(json.dumps(calibration_to_dict(world.calibration)))
    edit(doc["regions"][0])
    with pytest.raises(ModelError, match=message):
        calibration_from_dict(doc)


def _csv_with_regions(world, path, labels):
    write_measurements(path, world.meas, [j.unit for j in world.robot.joints])
    lines = path.read_text().splitlines()
    header = next(k for k, line in enumerate(lines) if not line.startswith("#"))
    lines[header] += ",region"
    for k, label in enumerate(labels):
        lines[header + 1 + k] += f",{label}"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_cli_identify_per_region(world, tmp_path, capsys):
    labels = world.meas.extra["region"]
    meas = _csv_with_regions(world, tmp_path / "meas.csv", labels)
    out = tmp_path / "calib.json"
    assert main(["identify", str(meas), "--robot", "abb_irb2400", "--per-region",
                 "--folds", "3", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "region A: 30 poses" in text and "region B: 30 poses" in text
    assert "held-out: local model RMS" in text and "grown by 50.0 mm" in text
    cal = read_calibration(out)
    assert [r.name for r in cal.regions] == ["A", "B"]
    # the global model is the one identify writes without --per-region
    plain = tmp_path / "plain.json"
    assert main(["identify", str(meas), "--robot", "abb_irb2400", "--folds", "3",
                 "-o", str(plain)]) == 0
    assert np.allclose(read_calibration(plain).values, cal.values, atol=1e-12)
    assert "regions" not in json.loads(plain.read_text())


def test_cli_per_region_refuses_bad_input(world, tmp_path, capsys):
    plain = tmp_path / "plain.csv"
    write_measurements(plain, world.meas, [j.unit for j in world.robot.joints])
    assert main(["identify", str(plain), "--robot", "abb_irb2400", "--per-region"]) == 1
    assert "no 'region' column" in capsys.readouterr().err
    labels = list(world.meas.extra["region"])
    labels[:3] = ["C"] * 3                         # a region of 3 poses
    few = _csv_with_regions(world, tmp_path / "few.csv", labels)
    out = tmp_path / "calib.json"
    assert main(["identify", str(few), "--robot", "abb_irb2400", "--per-region",
                 "-o", str(out)]) == 1
    assert "region C:" in capsys.readouterr().err and not out.exists()
