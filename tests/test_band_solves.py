"""The band scan's solves by update (calibration/band_solves.py) against the direct solve.

The scan after the bands (calibration/after_bands.py) fits every classic candidate beside
the kept bands on every training set; it adds the candidate's few columns to the
factored system without any candidate (a Schur-complement update) instead of factoring
each system whole. The truth here is the direct solve of the whole system (numpy), on a
random system and on a virtual robot's band scan (pinocchio on its perturbed URDF)."""

from dataclasses import replace

import numpy as np

from olp_compensate.calibration.after_bands import _bands_with, beside
from olp_compensate.calibration.band_solves import Factored, Recent, bordered
from olp_compensate.calibration.cross_validation import pose_folds
from olp_compensate.calibration.cyclic_scan import scan_bands
from olp_compensate.calibration.effect_scan import EffectScan, candidate_effects
from olp_compensate.calibration.effects import JointCompliance
from olp_compensate.calibration.identify import (IdentificationOptions, identify,
                                                 measurement_inputs)
from olp_compensate.calibration.simulate import (CYCLIC_KIND, HiddenEffect, make_virtual_robot,
                                                 random_joints, scaled_effect)
from olp_compensate.kinematics.robot import load_robot

NOISE = 0.05e-3
ROBOT = load_robot("abb_irb2400")


def test_a_bordered_solve_is_the_direct_solve_of_the_whole_system():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(400, 30)) * np.logspace(0, 3, 30)  # columns of unequal size
    gram, h = a.T @ a, rng.normal(size=30)
    gram[np.diag_indices(30)] += np.r_[np.zeros(25), np.full(5, 0.3)]  # a few penalized
    base, new = np.r_[0:12, 15:30], np.r_[12:15]
    base_factor = Factored(gram[np.ix_(base, base)])
    x_b = -base_factor.solve(h[base])
    x_new_b, x_c = bordered(base_factor, gram[np.ix_(base, new)], gram[np.ix_(new, new)],
                            x_b, h[new])
    truth = -np.linalg.solve(gram, h)
    assert np.allclose(x_new_b, truth[base], rtol=1e-10, atol=1e-12 * np.abs(truth).max())
    assert np.allclose(x_c, truth[new], rtol=1e-10, atol=1e-12 * np.abs(truth).max())


def test_a_singular_base_is_not_updated_and_a_factor_cache_keeps_the_recent():
    singular = Factored(np.zeros((3, 3)))
    assert singular.factor is None
    assert bordered(singular, np.ones((3, 1)), np.ones((1, 1)), np.zeros(3), np.ones(1)) is None
    cache = Recent(size=2)
    made = []
    for key in ("a", "b", "a", "c", "a", "b"):
        cache.get_or_make(key, lambda key=key: made.append(key) or key)
    assert made == ["a", "b", "c", "b"]  # "b" was the least recently used when "c" came


def test_the_candidates_fit_by_update_is_the_direct_refit_on_a_virtual_arm():
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
    bands = scan_bands(scan, ROBOT, inputs.q, 0.01)
    assert bands.bands, "the virtual arm's band must be found for the test to mean anything"
    candidates = [c for c in candidate_effects(ROBOT, False) if c.kind != "thermal_expansion"]
    setup = _bands_with(scan, bands, candidates[:6], ROBOT)
    band_scan, kept, every = setup.band_scan, setup.kept, setup.every
    for cols in setup.own:
        held, x = beside(band_scan, kept, every, cols)
        cols_all, penalty, _ = band_scan._layout(kept, None, np.setdiff1d(every, cols))
        gram, rhs = band_scan._training(frozenset())
        truth = -np.linalg.solve(gram[np.ix_(cols_all, cols_all)] + np.diag(penalty),
                                 rhs[cols_all])
        assert np.allclose(x, truth, rtol=1e-7, atol=1e-9 * np.abs(truth).max())
        direct, x_direct = band_scan.current(kept, np.setdiff1d(every, cols))
        scale = np.abs(direct.residuals).max()
        assert np.allclose(held.residuals, direct.residuals, rtol=0, atol=1e-9 * scale)
        assert abs(held.sigma2 / direct.sigma2 - 1) < 1e-9
