"""The rows of targets not compensated held as columns (issue 32: a failed row costs a few
us): every field, every CSV line and the summaries are those the per-row
:func:`~olp_compensate.programs.object_model.rows.failure_row` gives, on modules whose
targets end joint_limit, branch_changed and unreachable, and on rows made by hand
(joints found or not, texts that need quoting)."""

from __future__ import annotations

import csv
import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.compensation.failures import FailureReport
from olp_compensate.compensation.pose import COMPENSATED, Compensator
from olp_compensate.compensation.report import ReportRows, TargetReport, config_text
from olp_compensate.compensation.report_csv import CsvRows
from olp_compensate.compensation.row_columns import RowColumns
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import loads
from olp_compensate.programs.object_model.rows import failure_row
from olp_compensate.programs.object_model.task import compensate_task
from olp_compensate.programs.rapid.module_columns import compensate_rapid_module
from test_compensate import _world

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from compensate import generate_realistic_module  # noqa: E402

FAILED = ("joint_limit", "branch_changed", "unreachable", "not_converged")


@pytest.fixture(scope="module")
def comp():
    return Compensator(_world("abb_irb2400").calibration)


def _fields(row: TargetReport) -> tuple:
    """Every field of ``row``, NaN written as the text 'nan' (NaN equals no NaN)."""
    def plain(v):
        if isinstance(v, tuple):
            return tuple(plain(x) for x in v)
        return "nan" if isinstance(v, float) and math.isnan(v) else v
    return tuple(plain(getattr(row, f.name)) for f in dataclasses.fields(TargetReport))


def _same(got: TargetReport, expected: TargetReport) -> None:
    """Every field equal; joints of a target retried in another batch than the object
    path's within 1e-6 deg (the last digit the report prints)."""
    assert _fields(dataclasses.replace(got, joints=())) == \
        _fields(dataclasses.replace(expected, joints=()))
    assert len(got.joints) == len(expected.joints)
    np.testing.assert_allclose(got.joints, expected.joints, rtol=0, atol=1e-6)


@pytest.mark.parametrize("chunk", [16, 8192])
def test_failed_rows_in_columns_are_the_object_paths_rows(comp, chunk):
    text = generate_realistic_module(90, seed=5, failing=1.0)
    (expected_text,), expected = compensate_task([loads(text, "rapid", "fail.mod")], comp)
    got_text, got = compensate_rapid_module(text, "fail.mod", comp, chunk=chunk)
    assert got_text == expected_text
    assert isinstance(got.rows, ReportRows)
    columns = got.rows.columns
    failed = [columns.row(j) for j in np.flatnonzero(~columns.compensated).tolist()]
    statuses = {r.status for r in failed}
    assert {"joint_limit", "branch_changed", "unreachable"} <= statuses
    assert all(r.status in FAILED for r in failed)
    assert len(failed) > 40                       # the table's failed rows are columns
    rows, expected_rows = list(got.rows), list(expected.rows)
    assert len(rows) == len(expected_rows)
    for a, b in zip(rows, expected_rows):
        _same(a, b)
    assert got.to_csv() == expected.to_csv()
    problems, expected_problems = got.problem_rows(), expected.problem_rows()
    assert len(problems) == len(expected_problems) == sum(not r.fine for r in expected_rows)
    for a, b in zip(problems, expected_problems):
        _same(a, b)
    assert (got.counts(), got.exit_code, got.largest_correction()) == \
        (expected.counts(), expected.exit_code, expected.largest_correction())


def test_a_module_with_some_failed_rows_reads_the_same_both_ways(comp):
    text = generate_realistic_module(120, seed=7, failing=0.3)
    (expected_text,), expected = compensate_task([loads(text, "rapid", "some.mod")], comp)
    got_text, got = compensate_rapid_module(text, "some.mod", comp, chunk=32)
    assert got_text == expected_text
    statuses = [r.status for r in got.rows]
    assert any(s in COMPENSATED for s in statuses) and any(s in FAILED for s in statuses)
    for a, b in zip(got.rows, expected.rows, strict=True):
        _same(a, b)
    assert got.to_csv() == expected.to_csv()
    assert [(r.line, r.column) for r in got.problem_rows()] == \
        [(r.line, r.column) for r in expected.problem_rows()]
    assert got.largest_correction() == expected.largest_correction()


def _hand_columns(n_joints: int) -> RowColumns:
    """Four rows by hand: two compensated, two not (one with joints, one without), with
    a name, note and configuration that need quoting in CSV."""
    nan = math.nan
    joints = np.array([[10.5, -20.25, 30.0, 0.0, 45.125, -180.0][:n_joints],
                       [1.0, 2.0, 3.0, 4.0, 5.0, 6.0][:n_joints], [nan] * n_joints,
                       [-0.0000004, 359.9999996, 1e-7, -7.5, 8.0, 9.0][:n_joints]])
    return RowColumns(
        names=["p1", 'p"2,x', "p3", "p4"], file="a, b.mod", line=np.array([3, 5, 7, 9]),
        column=np.array([1, 2, 3, 4]), status=["ok", "joint_limit", "unreachable",
                                               "branch_changed"],
        pair=np.array([0, 1, 0, 1]), pair_names=[("tool0", "wobj0"), ("t,1", 'w"1')],
        correction_mm=np.array([[0.1, 0.2, 0.3], [nan] * 3, [nan] * 3, [nan] * 3]),
        correction_deg=np.array([0.01, nan, nan, nan]),
        joint_change=np.array([0.5, nan, nan, nan]),
        config_before=["[0,0,0,0]", "[1,-1,0,1]", "", "[0,0,0,1]"],
        config_after=["[0,0,0,0]", "[1,-1,0,1]", "", "[2,0,-1,1]"], joints=joints,
        note=["", 'axis 3 = 76.55 deg is "past", far', "out of reach", "asked for [0,0,0,1]"],
        compensated=np.array([True, False, False, False]))


@pytest.mark.parametrize("n_joints", [6, 1])
def test_failed_lines_are_the_row_by_row_lines(n_joints):
    c = _hand_columns(n_joints)
    writer = CsvRows(n_joints)
    failed = np.flatnonzero(~c.compensated)
    lines = writer.failed_lines(c, failed)
    assert lines == [writer.line(c.row(j)) + "\n" for j in failed.tolist()]
    assert c.row(2).joints == () and len(c.row(1).joints) == n_joints
    assert all(map(math.isnan, (*c.row(1).correction_mm, c.row(1).correction_deg,
                                c.row(1).joint_change)))
    fields = list(csv.reader(lines))
    assert [f[7:12] for f in fields] == [[""] * 5] * 3          # no correction written
    assert [f[0] for f in fields] == ['p"2,x', "p3", "p4"] and fields[0][-1] == c.note[1]


def _reference_failure_row(row, failure, robot, configless):
    """failure_row as it was written row by row before (dataclasses.replace)."""
    if failure is None:
        return row
    note = failure.note if not row.note else f"{failure.note}; {row.note}"
    joints = ()
    if np.all(np.isfinite(failure.joints)):
        joints = tuple(robot.to_degrees_or_mm(failure.joints[None])[0].tolist())
    config = config_text(failure.config) if failure.config is not None and not configless else ""
    return dataclasses.replace(row, status=failure.status or row.status, note=note,
                               joints=joints, config_after=config)


@pytest.mark.parametrize("configless", [False, True])   # RAPID, V+ (no confdata)
@pytest.mark.parametrize("row_note", ["", "tool from calib.json"])
def test_failure_row_is_the_row_with_why(configless, row_note):
    robot = load_robot("abb_irb2400")
    row = TargetReport(target="p7", file="m.mod", line=4, column=9, status="not_converged",
                       tool="tGun", wobj="wobj0", config_before="[0,0,0,1]", note=row_note)
    q = np.radians([10.0, -20.0, 30.0, 40.0, -50.0, 60.0])
    partial = q.copy()
    partial[4] = np.nan
    cases = [None, FailureReport("axis 3 past", q, (0, 0, 1, 1), "joint_limit"),
             FailureReport("reached elsewhere", q, (1, 0, 0, 0), "branch_changed"),
             FailureReport("no closer than 2 mm", np.full(6, np.nan), None, "unreachable"),
             FailureReport("stopped short", partial, None, ""),
             FailureReport("stopped short", q, None, "")]
    for failure in cases:
        got = failure_row(row, failure, robot, configless)
        expected = _reference_failure_row(row, failure, robot, configless)
        assert _fields(got) == _fields(expected)


def test_a_retry_resumed_from_the_first_pass_is_the_retry_from_scratch(comp):
    """The solver's state kept by a pass without retries (its closed form and reach
    screen), resumed for the failed targets alone: the statuses, joints and nominal joints
    of solving them again from scratch with every stage."""
    from olp_compensate.calibration.simulate import random_joints
    from olp_compensate.compensation.ik.solver import solve_with_nominal

    robot = comp.robot
    q = robot.joints_from_controller(random_joints(robot, 80, np.random.default_rng(0),
                                                   margin=0.0))
    q[::3, 4] = 1e-3                            # near the wrist's singularity: retries
    desired = comp.nominal_flange(q)
    confdata = comp.confdata(q)
    desired[::7, :3, 3] *= 2.5                  # out of reach
    args = (comp.family, comp.real_flange_and_jacobian)
    keep: list = []
    first, _ = solve_with_nominal(*args, desired, confdata, comp.limits, reach=comp.reach,
                                  retries=False, ruled=True, keep=keep)
    failed = np.flatnonzero(~first.success)
    assert 10 < len(failed) < 80 and len(keep) == 1 and len(keep[0].start) == 80
    again = (desired[failed], confdata[failed], comp.limits)
    scratch, nominal = solve_with_nominal(*args, *again, reach=comp.reach, ruled=True)
    resumed, resumed_nominal = solve_with_nominal(*args, *again, reach=comp.reach,
                                                  ruled=True, resume=keep[0].rows(failed))
    assert list(resumed.reason) == list(scratch.reason)
    assert set(scratch.reason) >= {"ok", "unreachable", "branch_changed"}
    np.testing.assert_allclose(resumed_nominal, nominal, rtol=0, atol=1e-12)
    ok = scratch.success
    np.testing.assert_allclose(resumed.q[ok], scratch.q[ok], rtol=0, atol=1e-7)
    # the rule's final answers through the Compensator: the same statuses and joints
    final = [comp.compensate_flanges(desired[failed], desired[failed], confdata[failed],
                                     resume=state)[2]
             for state in (None, keep[0].rows(failed))]
    assert list(final[0].reason) == list(final[1].reason)
    np.testing.assert_allclose(final[1].q, final[0].q, rtol=0, atol=1e-7, equal_nan=True)
