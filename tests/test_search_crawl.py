"""The configuration rule's search stops a crawling start that cannot catch up (issue 32):

- a start of a target out of reach whose score (m + 0.1 rad) falls so slowly that even a
  hundred times faster, for all its steps left, it would stay behind the best start of its
  target by more than the margin leaves the search early (:class:`~.ik.stalls.
  BehindAndStalled` given the step budget); checked against truth: every start's plain
  refinement (the whole budget, nothing dropped) ends behind the best by the margin;
- the best start of every target, and so the rule's statuses, joints and distances, are
  those of the search without the early stop, with fewer Newton steps.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from olp_compensate.calibration.simulate import random_joints
from olp_compensate.compensation import rule_search
from olp_compensate.compensation.config_rule import decide
from olp_compensate.compensation.ik import closed_form_inverse, refine, solve
from olp_compensate.compensation.ik.stalls import BEHIND_MARGIN, BehindAndStalled
from olp_compensate.compensation.pose import Compensator
from olp_compensate.kinematics.robot import load_robot
from virtual_world import identified_world

STEPS = rule_search.SEARCH_STEPS


@pytest.fixture(scope="module")
def world():
    robot = load_robot("abb_irb2400")
    virtual, cal = identified_world(robot, 3)
    return Compensator(cal)


def _beyond(comp: Compensator, n: int, seed: int) -> np.ndarray:
    """Flange poses (n, 4, 4) of random joints inside the ranges, moved away from the base
    by 3 % to 20 % (about half of them out of reach: the stretched arm falls short by up to
    some centimetres) and every fourth 2.5 times (far out of reach)."""
    robot = comp.robot
    q = robot.joints_from_controller(random_joints(robot, n, np.random.default_rng(seed),
                                                   margin=0.3))
    desired = comp.real_flange_and_jacobian(q)[0]
    scale = np.linspace(1.03, 1.2, n)
    scale[::4] = 2.5
    desired[:, :3, 3] *= scale[:, None]
    return desired


def _starts(comp: Compensator, desired: np.ndarray):
    """The search's starts (the nominal closed form of every branch, stretched), finite
    only, as flat joints (r, n) and their targets (r,)."""
    starts = closed_form_inverse(comp.family, desired, clip=True)
    k, b, n = starts.shape
    flat = starts.reshape(-1, n)
    target = np.repeat(np.arange(k), b)
    given = np.all(np.isfinite(flat), axis=1)
    return flat[given], target[given]


def _score(result) -> np.ndarray:
    score = result.position_error_m + 0.1 * result.rotation_error_rad
    return np.where(np.isfinite(score), score, np.inf)


def _best(score: np.ndarray, target: np.ndarray, k: int) -> np.ndarray:
    best = np.full(k, np.inf)
    np.minimum.at(best, target, score)
    return best


def _searched(comp, flat, desired, target, steps):
    """The search's pooled Newton with :class:`BehindAndStalled` (given the step budget
    ``steps``, or not: the stop of stalled starts alone)."""
    return refine(comp.real_flange_and_jacobian, flat, desired[target], None, 1e-9, 1e-9,
                  STEPS, pool=64, drop=BehindAndStalled(target, steps=steps))


def test_crawling_starts_that_cannot_catch_up_stop_early_and_are_truly_behind(world):
    comp = world
    desired = _beyond(comp, 48, seed=5)
    flat, target = _starts(comp, desired)
    k = len(desired)
    plain = refine(comp.real_flange_and_jacobian, flat, desired[target], None, 1e-9, 1e-9,
                   STEPS)                                    # every start, its whole budget
    before = _searched(comp, flat, desired, target, None)
    after = _searched(comp, flat, desired, target, STEPS)
    reached = np.zeros(k, bool)
    np.logical_or.at(reached, target, plain.success)
    assert 8 <= np.count_nonzero(~reached)                   # out of reach from every start
    # fewer steps, and some starts stopped by the new test alone
    assert np.sum(after.iterations) < np.sum(before.iterations)
    hopeless = after.iterations < before.iterations
    assert np.count_nonzero(hopeless) >= 20
    # truth: each start stopped early ends its plain refinement behind the best of its
    # target by more than the margin (it could never have been the one kept)
    best_plain = _best(_score(plain), target, k)
    assert np.all(_score(plain)[hopeless] > best_plain[target[hopeless]] + BEHIND_MARGIN)
    # the best start of every target: the same start, the same end, as without the stop
    for result in (before, after):
        best = _best(_score(result), target, k)
        assert np.array_equal(best, best_plain)
    kept = _score(after) == best_plain[target]
    assert np.array_equal(kept, _score(before) == best_plain[target])
    assert np.array_equal(after.q[kept], before.q[kept])
    assert list(after.reason[kept]) == list(before.reason[kept])


class _StalledOnly(BehindAndStalled):
    """:class:`BehindAndStalled` as the search used it before: no step budget."""

    def __init__(self, groups, steps=None, **kwargs):
        super().__init__(groups, **kwargs)


def test_the_rule_decides_as_without_the_early_stop(world, monkeypatch):
    comp = world
    desired = _beyond(comp, 40, seed=8)
    q = comp.robot.joints_from_controller(
        random_joints(comp.robot, 40, np.random.default_rng(9), margin=0.3))
    confdata = comp.confdata(q)
    args = (comp.family, comp.real_flange_and_jacobian, desired, confdata, comp.limits)
    solved = comp.check_axis_ranges(solve(*args, reach=comp.reach))
    assert np.count_nonzero(~solved.success) >= 20
    new = decide(comp, copy.deepcopy(solved), desired, confdata)
    monkeypatch.setattr(rule_search, "BehindAndStalled", _StalledOnly)
    old = decide(comp, copy.deepcopy(solved), desired, confdata)
    assert list(new.reason) == list(old.reason)
    assert "unreachable" in set(new.reason)
    assert np.array_equal(new.q, old.q, equal_nan=True)
    assert np.array_equal(new.position_error_m, old.position_error_m, equal_nan=True)
    assert np.array_equal(new.rotation_error_rad, old.rotation_error_rad, equal_nan=True)
