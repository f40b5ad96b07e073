"""The effects' fitted ranges on the six-number path (KRL here; FANUC, VAL3 and URScript
share it): a target whose joints leave the range is compensated exactly as the geometric
model alone compensates it, with a note; inside, exactly as the extended model does."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.effect_ranges import with_geometric_fallback
from olp_compensate.calibration.effects import GearHarmonic
from olp_compensate.compensation.dialect_program import compensate_pose_program
from olp_compensate.programs.krl.reader import parse_krl
from olp_compensate.programs.krl.rules import KRL
from test_programs_krl import CONFIG_DAT, ROBOT, _program_joints, _targets_at, krl_module

SPLIT_Q2 = -1.2            # rad: the effect was fitted on q2 below this


def _calibrations():
    """(with fallback, extended alone, geometric alone) of the KR 16."""
    rng = np.random.default_rng(5)
    geometric = nominal_calibration(ROBOT)
    geometric = replace(geometric, values=geometric.values
                        + rng.normal(0, 3e-4, geometric.values.shape))
    extended = replace(nominal_calibration(ROBOT),
                       effects=(GearHarmonic(joint=1, order=2, values=(4e-4, -3e-4)),))
    fitted = np.clip(ROBOT.controller_ranges, -np.pi, np.pi).T.copy()
    fitted[1, 1] = SPLIT_Q2
    return with_geometric_fallback(extended, geometric, fitted), extended, geometric


def _rows(calibration, src, dat):
    program = parse_krl(src, dat, "CELL.src", "CELL.dat", CONFIG_DAT)
    _, report = compensate_pose_program(program, KRL, calibration)
    return {r.target: r for r in report.rows if r.target.startswith("XP")}


def test_krl_targets_outside_the_fitted_range_take_the_geometric_model():
    q = _program_joints(24, 11)
    src, dat = krl_module(_targets_at(q))
    with_fallback, extended, geometric = _calibrations()
    rows = _rows(with_fallback, src, dat)
    alone = {"extended": _rows(extended, src, dat), "geometric": _rows(geometric, src, dat)}
    outside = inside = 0
    for name, row in rows.items():
        if row.status not in ("ok", "singular"):
            continue
        out = np.radians(row.joints[1]) > SPLIT_Q2
        expect = alone["geometric" if out else "extended"][name]
        assert np.allclose(row.correction_mm, expect.correction_mm, atol=1e-6), name
        assert ("geometric model used" in row.note) == out, (name, row.note)
        outside += out
        inside += not out
    assert outside >= 4 and inside >= 4
