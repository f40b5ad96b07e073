"""The controller's own model and the load, on virtual truth, side by side.

1. A virtual UR10e whose controller runs hidden factory deltas (about 1 mm and 0.06 deg a
   value, written as its calibration.conf) and whose real arm differs from both (about 1 mm
   and 0.06 deg a parameter): a URScript of targets taught on the pendant, compensated with
   ``--controller controller.json`` and without. Each written target is run through the
   controller's true model (the joints nearest those olp-fix solved), the real arm goes
   there; printed: the largest miss with, the misses without, and the difference between
   the controller's model and the data sheet at those joints (the miss without should be
   that difference).
2. ``olp-cal controller poses.csv``: 50 noise-free poses the controller reports (6 decimals,
   and 3 for comparison), the fitted model against the controller's true model at 1,000 new
   joint sets (mm, deg).
3. A virtual IRB 6400 with joint compliance on axes 2, 3, 5, identified from 90 poses with
   payloads of 0, 30, 60 kg (0.01 mm noise), a RAPID program with a 60 kg gun: the true TCP
   against the targets, compensated under the load and with ``--payload-kg 0``; then
   ``olp-cal export --format dh-table`` of that calibration: what D-H cannot hold.

Run: ``python benchmarks/controller.py [--seeds K]`` (about a minute). Exit code 0.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import io
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))          # the tests' virtual-world helpers

from olp_compensate.cli.cal import main as cal  # noqa: E402
from olp_compensate.cli.fix import main as fix  # noqa: E402


def quiet(function, *args):
    """Call ``function`` with stdout and stderr captured; (result, stdout text)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        result = function(*args)
    return result, out.getvalue()


def ur_case(seed: int, folder: Path) -> tuple[float, np.ndarray, np.ndarray]:
    """(largest miss with --controller, misses without, controller-vs-data-sheet), mm."""
    import test_controller_model as t
    from olp_compensate.io.calibration_file import write_calibration

    deltas = t.hidden_deltas(100 + seed)
    (folder / "calibration.conf").write_text(t.conf_text(deltas))
    code, _ = quiet(cal, ["controller", str(folder / "calibration.conf"), "--robot", t.NAME,
                          "-o", str(folder / "controller.json")])
    assert code == 0
    truth = t.NOMINAL.plus(deltas.theta, deltas.d, deltas.a, deltas.alpha)
    real = t.real_arm(200 + seed)
    write_calibration(folder / "real.json", real)
    tool = np.eye(4)
    tool[:3, 3] = t.TCP[:3]
    meant = truth.flange(t._path(300 + seed, 10)) @ tool
    (folder / "cell.script").write_text(t.ur_program(meant))
    misses = {}
    for label, extra in (("with", ["--controller", str(folder / "controller.json")]),
                         ("without", [])):
        out, report = folder / f"{label}.script", folder / f"{label}.csv"
        code, _ = quiet(fix, [str(folder / "cell.script"), "--model", str(folder / "real.json"),
                              "-o", str(out), "--report", str(report), *extra])
        assert code == 0
        reached = t._reached(out.read_text(), report, truth, real)
        misses[label] = np.linalg.norm(reached[:, :3, 3] - meant[:, :3, 3], axis=1) * 1e3
    rows = [r for r in csv.DictReader(open(folder / "with.csv")) if r["status"] == "ok"]
    q = np.radians([[float(r[f"q{k + 1}_deg"]) for k in range(6)] for r in rows])
    a, b = truth.flange(q) @ tool, t.NOMINAL.flange(q) @ tool
    difference = np.linalg.norm(a[:, :3, 3] - b[:, :3, 3], axis=1) * 1e3
    return float(misses["with"].max()), misses["without"], difference


def fit_case(seed: int, folder: Path, decimals: int) -> tuple[float, float, bool]:
    """(max mm, max deg) of the fitted model at 1,000 new joint sets, and 'reproduces'."""
    import test_controller_model as t
    from olp_compensate.calibration.controller_fit import controller_chain
    from olp_compensate.io.calibration_file import read_calibration
    from olp_compensate.kinematics.conventions import rotation_angle_between

    truth = t.NOMINAL.plus(*(getattr(t.hidden_deltas(400 + seed), k)
                             for k in ("theta", "d", "a", "alpha")))
    rng = np.random.default_rng(seed)
    q = rng.uniform(-math.pi, math.pi, (50, 6))
    t.reported_csv(folder / "poses.csv", q, truth.flange(q), decimals=decimals)
    code, printed = quiet(cal, ["controller", str(folder / "poses.csv"), "--robot", t.NAME,
                                "-o", str(folder / "fit.json")])
    assert code == 0
    model = read_calibration(folder / "fit.json")
    new = rng.uniform(-math.pi, math.pi, (1000, 6))
    ours, theirs = controller_chain(model).flange(new), truth.flange(new)
    mm = np.linalg.norm(ours[:, :3, 3] - theirs[:, :3, 3], axis=1).max() * 1e3
    deg = np.degrees(rotation_angle_between(ours[:, :3, :3], theirs[:, :3, :3])).max()
    return float(mm), float(deg), "reproduces every row" in printed


def load_case(folder: Path) -> tuple[float, np.ndarray, str]:
    """(max miss under the load, misses without it, mm; the export's line)."""
    import test_payload as p
    from olp_compensate.calibration.calibration import ToolPoint
    from olp_compensate.calibration.effects import JointCompliance
    from olp_compensate.calibration.identify import IdentificationOptions, identify
    from olp_compensate.calibration.simulate import (HiddenEffect, make_virtual_robot,
                                                     random_joints)
    from olp_compensate.io.calibration_file import write_calibration
    from olp_compensate.programs import loads

    virtual = make_virtual_robot(p.ROBOT, 61)
    virtual = dataclasses.replace(virtual, effects=tuple(
        HiddenEffect("joint_compliance", j, c) for j, c in p.COMPLIANCE.items()))
    rng = np.random.default_rng(61)
    q = random_joints(p.ROBOT, 90, rng)
    meas = virtual.measure(q, 0.01e-3, rng, payload_kg=rng.choice([0.0, 30.0, 60.0], len(q)))
    options = IdentificationOptions(folds=0, effects=tuple(JointCompliance(joint=j)
                                                           for j in p.COMPLIANCE))
    calibration = identify(p.ROBOT, meas, options).calibration
    tools = dict(calibration.tools)
    tools["gun"] = ToolPoint(xyz_m=calibration.tools["tcp"].xyz_m)
    calibration = dataclasses.replace(calibration, tools=tools)
    write_calibration(folder / "cal.json", calibration)
    text, tool = p._program(virtual, calibration, 62)
    (folder / "cell.mod").write_text(text)
    program = loads(text, "rapid", "cell.mod")
    meant = np.array([(calibration.device_T_base @ p.pose_of(x))[:3, 3]
                      for x in program.targets])
    misses = {}
    for label, extra in (("under", []), ("without", ["--payload-kg", "0"])):
        out, report = folder / f"{label}.mod", folder / f"{label}.csv"
        code, _ = quiet(fix, [str(folder / "cell.mod"), "--model", str(folder / "cal.json"),
                              "-o", str(out), "--report", str(report), *extra])
        assert code == 0
        reached, _ = p._reached(virtual, out.read_text(), report, tool, p.GUN_KG)
        misses[label] = np.linalg.norm(reached - meant, axis=1) * 1e3
    code, printed = quiet(cal, ["export", "--model", str(folder / "cal.json"), "--format",
                                "dh-table", "-o", str(folder / "dh.csv")])
    line = next(x for x in printed.splitlines() if "cannot hold" in x).strip()
    return float(misses["under"].max()), misses["without"], line


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        print("1. virtual UR10e, hidden controller deltas, real arm off both (10 targets each)")
        print("   seed  with --controller max  without min..max   controller-vs-data-sheet")
        for seed in range(args.seeds):
            best, without, difference = ur_case(seed, folder)
            print(f"   {seed:4d}  {best:18.4f} mm  {without.min():6.3f}..{without.max():6.3f} mm"
                  f"   {difference.min():6.3f}..{difference.max():6.3f} mm")
        print("2. controller fitted to 50 noise-free reported poses; 1,000 new joint sets")
        print("   seed  decimals  max mm      max deg     reproduces rows")
        for seed in range(args.seeds):
            for decimals in (6, 3):
                mm, deg, ok = fit_case(seed, folder, decimals)
                print(f"   {seed:4d}  {decimals:8d}  {mm:.6f}  {deg:.7f}   {ok}")
        print("3. IRB 6400 with joint compliance, RAPID program with a 60 kg gun (8 targets)")
        under, without, line = load_case(folder)
        print(f"   compensated under the load: max miss {under:.4f} mm; with --payload-kg 0: "
              f"{without.min():.3f}..{without.max():.3f} mm")
        print(f"   olp-cal export --format dh-table: {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
