"""The result of an iterative IK: joints, success and the reason, per target."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


REASONS = ("ok", "unreachable", "joint_limit", "singular", "branch_changed", "not_converged")
"""Every value :attr:`IKSolution.reason` can take."""


@dataclass
class IKSolution:
    """Result of :func:`refine` / :func:`solve` for m targets.

    q : (m, n) rad, the last iterate (valid only where ``success``).
    success : (m,) bool, True where the target is reached within tolerance, inside the
        joint limits, on the requested configuration.
    reason : (m,) str from :data:`REASONS`. 'ok'; 'singular' (reached, success True, but the
        Jacobian's smallest singular value is below ``singular_tol`` times its largest, so
        some joints, e.g. axes 4 and 6 at axis 5 = 0, are not unique); 'unreachable' (no
        solution on the requested branch, or the iteration stalled short of the target);
        'joint_limit'; 'branch_changed' (reached, but on another configuration than
        requested); 'not_converged' (iteration limit).
    iterations : (m,) int, Newton steps tried.
    position_error_m, rotation_error_rad : (m,) final errors (norms, base frame).
    on_asked : (m,) bool or None: set by the configuration rule
        (:func:`olp_compensate.compensation.config_rule.decide`), whether ``q`` is on the
        configuration asked for; None where the rule was not applied.
    """

    q: np.ndarray
    success: np.ndarray
    reason: np.ndarray
    iterations: np.ndarray
    position_error_m: np.ndarray
    rotation_error_rad: np.ndarray
    on_asked: np.ndarray | None = None
