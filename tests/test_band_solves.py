"""The band scan's shared factorizations (calibration/band_solves.py) against direct solves.

The band scan (calibration/cyclic_scan.py) factors each training set's normal equations
once and shares the factor between the fits, the tests' leverage and the copies of the
scan with a moved linearization (``BandScan.shifted``, the backward elimination's), and
computes the held-out residuals by one product with its columns. The truth here is
numpy's direct solve of each system and the residuals computed row by row, on a virtual
robot's band scan (pinocchio on its perturbed URDF)."""

from dataclasses import replace

import numpy as np

from olp_compensate.calibration.band_solves import Factored, Recent
from olp_compensate.calibration.cross_validation import pose_folds
from olp_compensate.calibration.cyclic_scan import scan_bands
from olp_compensate.calibration.effect_scan import EffectScan
from olp_compensate.calibration.effects import JointCompliance
from olp_compensate.calibration.identify import (IdentificationOptions, identify,
                                                 measurement_inputs)
from olp_compensate.calibration.simulate import (CYCLIC_KIND, HiddenEffect, make_virtual_robot,
                                                 random_joints, scaled_effect)
from olp_compensate.kinematics.robot import load_robot

NOISE = 0.05e-3
ROBOT = load_robot("abb_irb2400")


def test_a_singular_matrix_is_solved_by_least_squares_and_the_cache_keeps_the_recent():
    singular = np.diag([2.0, 0.0])
    factored = Factored(singular)
    assert factored.factor is None
    assert np.allclose(factored.solve(np.array([4.0, 0.0])), [2.0, 0.0])
    cache, made = Recent(size=2), []
    for key in ("a", "b", "a", "c", "a", "b"):
        cache.get_or_make(key, lambda key=key: made.append(key) or key)
    assert made == ["a", "b", "c", "b"]  # "b" was the least recently used when "c" came


def _expected(band_scan, kept, drop):
    """(per-fold held-out residuals (3m,), full-data solution) by direct solves."""
    cols, penalty, _ = band_scan._layout(kept, None, drop)
    a, r = band_scan.a[:, cols], band_scan.residual
    out = np.empty_like(r)
    for eq in band_scan.fold_eq:
        train = ~eq
        x = -np.linalg.solve(a[train].T @ a[train] + np.diag(penalty), a[train].T @ r[train])
        out[eq] = r[eq] + a[eq] @ x
    return out, -np.linalg.solve(a.T @ a + np.diag(penalty), a.T @ r)


def test_the_scans_fits_are_the_direct_solves_also_once_shifted():
    rng = np.random.default_rng([55, 1])
    virtual = make_virtual_robot(ROBOT, 5501)
    joints = random_joints(ROBOT, 200, rng)
    band = tuple((k, 1.0 if k == 12 else 0.3, float(rng.uniform(-np.pi, np.pi)))
                 for k in range(2, 25))
    hidden = scaled_effect(virtual, HiddenEffect(CYCLIC_KIND, 1, 1e-4, band=band), joints,
                           10 * NOISE)
    meas = replace(virtual, effects=(hidden,)).measure(joints, NOISE, rng)
    result = identify(ROBOT, meas, IdentificationOptions(folds=0))
    tools = {n: t.xyz_m for n, t in result.calibration.tools.items()}
    inputs = measurement_inputs(ROBOT, meas, tools, [JointCompliance(joint=0)])
    scan = EffectScan(result, meas, inputs, pose_folds(meas.pose_ids, 5))
    outcome = scan_bands(scan, ROBOT, inputs.q, 0.01)
    assert outcome.bands, "the virtual arm's band must be found for the test to mean anything"
    band_scan = outcome.scan
    kept = [(b.joint, b.ridge) for b in outcome.bands]
    drop = np.arange(3)  # three of the current unknowns left out
    step = np.zeros(band_scan.a.shape[1])
    step[drop] = rng.normal(size=3) * 1e-3
    for scan_ in (band_scan, band_scan.shifted(step), band_scan):
        for drop_ in ((), drop):
            held, x = scan_.current(kept, drop_)
            residuals, truth = _expected(scan_, kept, drop_)
            scale = np.abs(residuals).max()
            assert np.allclose(held.residuals.ravel(), residuals, rtol=0, atol=1e-9 * scale)
            assert np.allclose(x, truth, rtol=1e-6, atol=1e-8 * np.abs(truth).max())
