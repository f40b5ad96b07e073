"""What real measured data brought out (issue 28), checked without the data: the tracker
table layout of the HUST set (written here with made-up numbers), several sessions in one
table, zero per-axis uncertainties, a band's lowest order on a partial turn, and a joint
whose axis runs through the measured point (a reflector on axis 6)."""

import json
from dataclasses import replace

import numpy as np

from olp_compensate.calibration.cyclic_scan import MIN_LEVER_M, lowest_order
from olp_compensate.calibration.diagnose import DiagnoseOptions, diagnose, diagnosis_to_dict
from olp_compensate.calibration.effects import CyclicError, EffectInputs, effect_from_dict
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.cli.cal import main
from olp_compensate.io.measurements import read_measurements
from olp_compensate.kinematics.robot import load_robot

HEADER = "pose;j1;j2;j3;j4;j5;j6;X;Y;Z;sx;sy;sz;T;time\n"


def comma(value: float, digits: int = 3) -> str:
    return f"{value:.{digits}f}".replace(".", ",")


def astl_table(rows, names, times, sigmas):
    lines = [";".join([name, *(comma(v) for v in r[:9]), *(comma(s) for s in sig),
                       comma(22.5 + 0.1 * k, 1), comma(t)])
             for k, (name, r, t, sig) in enumerate(zip(names, rows, times, sigmas))]
    return HEADER + "\n".join(lines) + "\n"


def made_up_rows(n: int, seed: int = 28):
    rng = np.random.default_rng(seed)
    return [np.concatenate([rng.uniform(-90, 90, 6), rng.uniform(-3500, 1500, 3)])
            for _ in range(n)]


def test_astl_table_imports_with_decimal_commas_sigmas_temperature_and_time(tmp_path, capsys):
    rows = made_up_rows(5)
    sigmas = [(0.001, 0.002, 0.002), (0.0, 0.0, 0.0), (0.003, 0.0, 0.004), (0.001,) * 3,
              (0.002, 0.002, 0.001)]
    times = [1665500808.043 + 7.5 * k for k in range(5)]
    source = tmp_path / "all.txt"
    source.write_text(astl_table(rows, [f"Calibration{k}" for k in range(5)], times, sigmas))
    out = tmp_path / "meas.csv"
    assert main(["import", str(source), "--format", "astl", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "WARNING" not in printed  # one session
    assert "1 rows give zero standard deviations" in printed
    meas = read_measurements(out, ["deg"] * 6)
    for k, r in enumerate(rows):
        assert np.allclose(np.degrees(meas.joints[k]), np.round(r[:6], 3), atol=1e-9)
        assert np.allclose(meas.points[k] * 1e3, np.round(r[6:9], 3), atol=1e-9)
    assert np.allclose(meas.temperature_c, [22.5, 22.6, 22.7, 22.8, 22.9])
    assert np.allclose(meas.time_s, times, atol=1e-6)
    expected = [f"{np.sqrt(np.mean(np.square(s))):.6g}" if any(s) else "" for s in sigmas]
    assert meas.extra["sigma_mm"] == expected
    assert list(meas.pose_ids) == [f"Calibration{k}" for k in range(5)]


def test_a_table_of_several_sessions_is_flagged_and_one_session_taken(tmp_path, capsys):
    rows = made_up_rows(6, seed=3)
    names = ["POINTS0", "POINTS1", "POINTS2", "SURFACE0", "SURFACE1", "SURFACE2"]
    day = 86400.0
    times = [1666000000.0, 1666000010.0, 1666000020.0] + [1666000000.0 + 9 * day + 10 * k
                                                          for k in range(3)]
    source = tmp_path / "all.txt"
    source.write_text(astl_table(rows, names, times, [(0.002,) * 3] * 6))
    out = tmp_path / "meas.csv"
    assert main(["import", str(source), "--format", "astl", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "WARNING: the rows form 2 sessions" in printed and "POINTS0, SURFACE0" in printed
    one = tmp_path / "surface.csv"
    assert main(["import", str(source), "--format", "astl", "--pose-prefix", "SURFACE",
                 "-o", str(one)]) == 0
    assert "WARNING" not in capsys.readouterr().out
    meas = read_measurements(one, ["deg"] * 6)
    assert list(meas.pose_ids) == names[3:]
    assert np.allclose(meas.points * 1e3, np.round(np.array(rows[3:])[:, 6:9], 3), atol=1e-9)
    assert main(["import", str(source), "--format", "astl", "--pose-prefix", "LINE",
                 "-o", str(tmp_path / "none.csv")]) != 0
    assert "no row's pose starts with 'LINE'" in capsys.readouterr().err


def test_a_band_starts_at_the_lowest_order_completing_a_period_over_the_span():
    assert lowest_order(np.radians(np.linspace(-180, 180, 50))) == 1
    assert lowest_order(np.radians(np.linspace(0, 90, 50))) == 4  # 4 x 90 deg = one turn
    assert lowest_order(np.radians(np.linspace(99.4, 124.0, 50))) == 15  # 24.6 deg: 14.6
    rng = np.random.default_rng(5)
    effect = CyclicError(joint=1, max_order=30, min_order=15, q_range=(1.7, 2.2),
                         values=tuple(rng.normal(0, 1e-5, 32)))
    assert effect.parameter_names[:2] == ("a15", "b15") and len(effect.amplitudes()) == 16
    q = np.zeros((7, 6))
    q[:, 1] = rng.uniform(1.75, 2.15, 7)
    expected = sum(effect.values[2 * i] * np.sin(k * q[:, 1])
                   + effect.values[2 * i + 1] * np.cos(k * q[:, 1])
                   for i, k in enumerate(range(15, 31)))
    assert np.allclose(effect.evaluate(EffectInputs(q=q)), expected, rtol=1e-12, atol=0)
    step = 1e-7
    shifted = q.copy()
    shifted[:, 1] += step
    numeric = (effect.evaluate(EffectInputs(q=shifted)) - effect.evaluate(EffectInputs(q=q)))
    assert np.allclose(numeric / step, effect.evaluate_dq(EffectInputs(q=q))[:, 1],
                       rtol=1e-4, atol=1e-9)
    again = effect_from_dict(json.loads(json.dumps(effect.to_dict())), 6)
    assert (again.min_order, again.max_order, again.values) == (15, 30, effect.values)
    older = {k: v for k, v in effect.to_dict().items() if k not in ("min_order", "std")}
    older["max_order"] = 16  # a file written before min_order: orders 1..16
    older["parameters"] = {f"{ab}{k}": 1e-6 * k for k in range(1, 17) for ab in "ab"}
    old_effect = effect_from_dict(older, 6)
    assert old_effect.min_order == 1 and old_effect.parameter_names[-2:] == ("a16", "b16")


def test_no_band_for_a_joint_whose_axis_runs_through_the_measured_point():
    robot = load_robot("abb_irb2400")
    rng = np.random.default_rng([28, 6])
    virtual = make_virtual_robot(robot, 2806)
    # the point 1 mm off the flange origin: on axis 6, as a reflector at the wrist
    virtual = replace(virtual, tools={"tcp": np.array([0.001, 0.0, 0.0])})
    joints = random_joints(robot, 150, rng, within_ranges=False)
    result = diagnose(robot, virtual.measure(joints, 0.05e-3, rng),
                      DiagnoseOptions(kinds=("backlash",)))
    assert result.bands.short_lever == [5]
    tested = {b["joint"] for r in diagnosis_to_dict(result)["cyclic_bands"] for b in r["bands"]}
    assert 6 not in tested and tested
    assert diagnosis_to_dict(result)["cyclic_short_lever_joints"] == [6]
    assert MIN_LEVER_M > 0.001
