"""Per-row uncertainties (sigma_mm, sigma_deg columns, as olp-cal camera measure writes
them) weight identification: rows a device says are poor count less."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.measurements import row_sigma_scales
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.errors import DataError
from olp_compensate.kinematics.robot import load_robot

ROBOT = load_robot("abb_irb2400")


def _campaign(seed: int):
    """60 poses: 30 measured at 0.02 mm, 30 at 0.5 mm noise (each row knows its sigma)."""
    virtual = make_virtual_robot(ROBOT, seed)
    rng = np.random.default_rng(seed)
    good = virtual.measure(random_joints(ROBOT, 30, rng), 0.02e-3, rng)
    poor = virtual.measure(random_joints(ROBOT, 30, rng), 0.5e-3, rng)
    both = {f.name: (None if getattr(good, f.name) is None or not isinstance(
        getattr(good, f.name), np.ndarray) else np.concatenate([getattr(good, f.name),
                                                                 getattr(poor, f.name)]))
            for f in dataclasses.fields(good)}
    meas = dataclasses.replace(good, **{k: v for k, v in both.items() if v is not None})
    meas = dataclasses.replace(meas, pose_ids=np.array([f"{k}" for k in range(60)],
                                                       dtype=object),
                               extra={"sigma_mm": ["0.02"] * 30 + ["0.5"] * 30})
    return virtual, meas


def _error_at_new_poses(virtual, calibration) -> float:
    test = random_joints(ROBOT, 400, np.random.default_rng(99))
    names = ["tcp"] * len(test)
    diff = calibration.predict_points(test, names) - virtual.true_frames(test, names)[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum(diff ** 2, axis=1))))


@pytest.mark.parametrize("seed", [1, 2])
def test_rows_with_large_sigma_count_less(seed):
    virtual, meas = _campaign(seed)
    options = IdentificationOptions(folds=0)
    weighted = identify(ROBOT, meas, options).calibration
    unweighted = identify(ROBOT, dataclasses.replace(meas, extra={}), options).calibration
    assert _error_at_new_poses(virtual, weighted) < 0.7 * _error_at_new_poses(virtual, unweighted)


def test_scales_are_the_default_sigma_over_the_rows_and_bad_cells_are_refused():
    _, meas = _campaign(3)
    position, rotation = row_sigma_scales(meas, 0.05e-3, np.radians(0.01))
    # stated sigmas combine with the default 0.05 mm in quadrature
    assert np.allclose(position[:30], 0.05 / np.hypot(0.02, 0.05))
    assert np.allclose(position[30:], 0.05 / np.hypot(0.5, 0.05))
    assert np.allclose(rotation, 1.0)                   # no sigma_deg column: the default
    assert row_sigma_scales(dataclasses.replace(meas, extra={}), 0.05e-3, 1e-4) is None
    bad = dataclasses.replace(meas, extra={"sigma_mm": ["0.02"] * 59 + ["-1"]})
    with pytest.raises(DataError, match="sigma_mm"):
        row_sigma_scales(bad, 0.05e-3, 1e-4)


def test_stated_sigmas_add_to_the_default_in_quadrature():
    """A made-up tracker table: sigmas 0.0005-0.2 mm (a 160000-fold weight spread as
    stated). Each row's sigma is sqrt(stated^2 + 0.05^2) mm: rows stating far less than
    the default weigh alike (within 1 %), rows stating more keep (0.05 / sigma)^2 nearly
    as stated, an empty cell weighs as a row stating nothing extra."""
    _, meas = _campaign(4)
    stated = np.geomspace(0.0005, 0.2, 59)
    cells = [f"{v:.6g}" for v in stated] + [""]
    meas = dataclasses.replace(meas, extra={"sigma_mm": cells})
    position, _ = row_sigma_scales(meas, 0.05e-3, 1e-4)
    weight = position ** 2
    low = stated < 0.005
    assert np.all(weight[:59][low] > 0.99) and weight[59] == 1.0
    assert np.all(np.diff(weight[:59]) < 0)                     # more stated, less weight
    assert np.isclose(weight[58], 1 / (1 + (0.2 / 0.05) ** 2), rtol=1e-5)
    assert np.allclose(position[:59], 0.05 / np.sqrt(stated ** 2 + 0.05 ** 2), rtol=1e-5)
