"""Levenberg-Marquardt (olp_compensate.calibration.lm) on small problems with known minima."""

import numpy as np
from scipy.optimize import least_squares

from olp_compensate.calibration.lm import levenberg_marquardt


def _rosenbrock(x):
    return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])


def _rosenbrock_jacobian(x):
    return np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])


def test_reaches_the_minimum_and_rejected_trials_cost_no_jacobian():
    calls = {"fun": 0, "residuals": 0}

    def fun(x):
        calls["fun"] += 1
        return _rosenbrock(x), _rosenbrock_jacobian(x)

    def residuals(x):
        calls["residuals"] += 1
        return _rosenbrock(x)

    # little damping at first and slow growth (lambda = 2.5): runs of rejected trials
    x0, settings = np.array([-1.2, 1.0]), {"mu0": 1e-8, "growth": 2.5}
    result = levenberg_marquardt(fun, x0, residuals=residuals, **settings)
    assert result.success
    np.testing.assert_allclose(result.x, [1.0, 1.0], atol=1e-8)
    assert result.evaluations == calls["fun"] + calls["residuals"]
    assert calls["residuals"] > 0
    plain = levenberg_marquardt(lambda x: (_rosenbrock(x), _rosenbrock_jacobian(x)), x0,
                                **settings)
    np.testing.assert_allclose(plain.x, result.x, atol=1e-12)
    assert calls["fun"] < plain.evaluations  # the same path, fewer Jacobians
    np.testing.assert_allclose(result.jacobian, _rosenbrock_jacobian(result.x))
    np.testing.assert_allclose(result.normal, result.jacobian.T @ result.jacobian)


def test_agrees_with_scipy_on_a_noisy_fit_and_takes_a_given_start():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 3, 60)
    y = 2.0 * np.exp(-1.3 * t) + 0.5 + rng.normal(0, 1e-3, t.size)

    def residuals(x):
        return x[0] * np.exp(-x[1] * t) + x[2] - y

    def fun(x):
        e = np.exp(-x[1] * t)
        return residuals(x), np.column_stack([e, -x[0] * t * e, np.ones_like(t)])

    x0 = np.array([1.0, 1.0, 0.0])
    ours = levenberg_marquardt(fun, x0, residuals=residuals, initial=fun(x0))
    peer = least_squares(residuals, x0, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    np.testing.assert_allclose(ours.x, peer.x, rtol=1e-8)
    assert ours.cost <= peer.cost * (1 + 1e-10)
    assert "predicted decrease" in ours.message or "decrease" in ours.message
