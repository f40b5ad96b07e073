"""The configuration rule's bookkeeping done with less work, the same answers bit for bit
(issue 32, targets that fail): each faster path against the plain one it replaced, on
varied inputs.

- the first copy of each start of a search (:func:`~.rule_search._first_copies`), axis
  by axis, is the comparison of whole rows (NaN, -0.0 and repeated starts included);
- :class:`~.ik.stalls.BehindAndStalled` reducing only the targets of the starts it is
  given, its history written in place, stops the same starts as the reduction of every
  target with a stacked history, call after call, whatever the order of the starts;
- the ends the rule judges (:func:`~.rule_search._judged`) are turned in one batch as
  they were in two (reached, the other given);
- the notes of :func:`~.failures.explain_failures` (a 'branch_changed' note written once
  per pair of configurations) are those written row by row.
"""

from __future__ import annotations

import numpy as np
import pytest

from olp_compensate.calibration.simulate import random_joints
from olp_compensate.compensation import failures, rule_search
from olp_compensate.compensation.ik.stalls import BehindAndStalled
from olp_compensate.compensation.pose import Compensator
from olp_compensate.kinematics.robot import load_robot
from virtual_world import identified_world


@pytest.fixture(scope="module")
def world():
    robot = load_robot("abb_irb2400")
    virtual, cal = identified_world(robot, 3)
    return Compensator(cal)


def _plain_first_copies(starts: np.ndarray) -> np.ndarray:
    """The first copy of each start by comparing whole rows of bits (the former way)."""
    k, b, n = starts.shape
    bits = np.ascontiguousarray(starts, dtype=float).view(np.int64)
    same = np.all(bits[:, :, None, :] == bits[:, None, :, :], axis=-1)
    first = np.where(np.any(same, axis=2), np.argmax(same, axis=2), np.arange(b))
    return (first + b * np.arange(k)[:, None]).reshape(-1)


@pytest.mark.parametrize("shape", [(1, 1, 6), (7, 9, 6), (64, 8, 6), (5, 3, 1), (0, 9, 6)])
def test_first_copies_are_those_of_whole_rows(shape):
    rng = np.random.default_rng(sum(shape))
    k, b, n = shape
    starts = rng.integers(-2, 3, (k, b, n)).astype(float)   # few values: many equal rows
    if k and b > 2:
        starts[::2, 1] = starts[::2, 0]
        starts[::3, -1] = np.nan
        starts[1::3, 2] = -0.0 * starts[1::3, 0]            # -0.0 is not 0.0 in bits
        starts[1::3, 0] = 0.0 * starts[1::3, 0]
        starts[::4, 2, 0] = np.nan
    got = rule_search._first_copies(starts)
    assert np.array_equal(got, _plain_first_copies(starts))
    if k and b > 2:
        assert np.any(got != np.arange(k * b))                 # some copies found


class _PlainBehind(BehindAndStalled):
    """:class:`BehindAndStalled` with its two parts as they were: every target reduced,
    the history stacked."""

    def _best(self, target):
        return np.minimum.reduceat(self.score, self.first)[target]

    def _swap_history(self, act, steps, cost, score):
        slot = steps % self.window
        past = self.history[act, slot]
        self.history[act, slot] = np.stack([cost, score], axis=1)
        return past


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("budget", [None, 60])
def test_behind_and_stalled_stops_what_the_plain_reduction_stops(seed, budget):
    """Starts of uneven groups stepping in pools of varied sizes and orders, their errors
    falling fast, slowly or not at all, some reaching their target: the same starts stop,
    and the scores and history kept are the same bits."""
    rng = np.random.default_rng(seed)
    groups = np.repeat(np.arange(60), rng.integers(1, 10, 60))
    r = len(groups)
    fast, plain = BehindAndStalled(groups, steps=budget), _PlainBehind(groups, steps=budget)
    err = rng.normal(scale=1e-2, size=(r, 6))
    err[rng.random(r) < 0.1] *= 1e-9                  # reached (score under 1.1e-9)
    steps = np.zeros(r, int)
    stopped_any = 0
    for call in range(60):
        act = np.flatnonzero(rng.random(r) < rng.uniform(0.05, 1.0))
        if call % 3 == 0:
            act = rng.permutation(act)                # any order
        shrink = rng.choice([1.0, 1 - 1e-8, 1 - 1e-3, 0.5], size=(len(act), 1))
        err[act] *= shrink
        cost = np.einsum("ij,ij->i", err[act], err[act])
        a = fast(steps[act], act, cost, err[act])
        b = plain(steps[act], act, cost, err[act])
        assert np.array_equal(a, b), call
        stopped_any += int(a.sum())
        steps[act] += 1
    assert np.array_equal(fast.score.view(np.int64), plain.score.view(np.int64))
    assert np.array_equal(fast.history.view(np.int64), plain.history.view(np.int64))
    assert stopped_any > 0


def test_behind_and_stalled_best_is_the_reduction_of_every_target():
    rng = np.random.default_rng(3)
    groups = np.repeat(np.arange(40), rng.integers(1, 9, 40))
    drop = BehindAndStalled(groups)
    drop.score[:] = rng.normal(size=len(groups))
    drop.score[::5] = np.inf
    whole = np.minimum.reduceat(drop.score, drop.first)
    for _ in range(30):
        rows = rng.choice(len(groups), rng.integers(0, len(groups)), replace=False)
        target = drop.target[rows]
        assert np.array_equal(drop._best(target), whole[target])


def _plain_turned(comp, end_q, reason, given):
    """The ends' controller joints turned toward the ranges as they were: the reached rows,
    then the other given ones, in two batches."""
    robot = comp.robot
    reached = np.isin(reason, ("ok", "singular"))
    q = np.full(end_q.shape, np.nan)
    if np.any(reached):
        q[reached] = rule_search.turn_toward_ranges(
            robot, robot.controller_from_joints(end_q[reached]))
    q[~reached & given] = rule_search.turn_toward_ranges(
        robot, robot.controller_from_joints(end_q[~reached & given]))
    return q


@pytest.mark.parametrize("seed", [0, 1])
def test_judged_ends_are_turned_as_in_two_batches(world, seed):
    comp = world
    rng = np.random.default_rng(seed)
    r = 500
    end_q = rng.uniform(-9.0, 9.0, (r, comp.robot.n_joints))
    reason = rng.choice(np.array(["ok", "singular", "unreachable", "not_converged"]), r)
    given = rng.random(r) < 0.8
    reason[~given] = "unreachable"
    end_q[~given] = np.nan
    got = rule_search._judged(comp, end_q, reason, given)
    want = _plain_turned(comp, end_q, reason, given)
    assert np.array_equal(got.q.view(np.int64), want.view(np.int64))


def _plain_notes(comp, solution, confdata):
    """The notes of the failed rows of a decided ``solution`` written row by row."""
    q_ctrl_of, config_of = failures._turned_and_configs(
        comp, solution.q[~solution.success])
    failed = np.flatnonzero(~solution.success)
    limits = failures._Ranges.of(comp.robot)
    notes = []
    for k, row in enumerate(failed.tolist()):
        reason = str(solution.reason[row])
        config = config_of[k]
        words = failures._range_words(limits, q_ctrl_of[k][None])[0] \
            if reason == "joint_limit" and config is not None else []
        asked = failures._config_words(confdata[row])
        found = failures._config_words(config) if config is not None else "none"
        notes.append(failures._note(reason, words, config is not None,
                                    bool(solution.on_asked[row]), asked, found,
                                    float(solution.position_error_m[row]),
                                    float(solution.rotation_error_rad[row])))
    return failed, notes


def test_explained_notes_are_those_written_row_by_row(world):
    """A batch of targets that fail every way (out of reach, past the ranges on the asked
    configuration, reached only on another), asked on varied configurations."""
    comp = world
    robot = comp.robot
    ranges = robot.controller_ranges
    rng = np.random.default_rng(12)
    q_ctrl = random_joints(robot, 240, rng, margin=0.3)
    for k in range(0, 240, 2):                 # one axis of 2, 3 and 5 past an end
        axis, side = (1, 2, 4)[k % 3], (k // 2) % 2
        q_ctrl[k, axis] = ranges[axis, side] + np.radians(8.0 if side else -8.0)
    q = robot.joints_from_controller(q_ctrl)
    desired = comp.nominal_flange(q)
    desired[1::6, :3, 3] *= 2.5                # out of reach
    confdata = comp.confdata(q)
    confdata[3::4, 3] = (confdata[3::4, 3] + 2) % 8      # another configuration asked for
    # a few poses asked for on each of the eight configurations (the same one found)
    desired = np.concatenate([desired, np.repeat(desired[5:40:5], 8, axis=0)])
    again = np.repeat(confdata[5:40:5], 8, axis=0)
    again[:, 3] = np.tile(np.arange(8), 7)
    confdata = np.concatenate([confdata, again])
    _, _, solution, _ = comp.compensate_flanges(desired, None, confdata)
    reports = failures.explain_failures(comp, solution, desired, confdata)
    failed, want = _plain_notes(comp, solution, confdata)
    got = [reports[row].note for row in failed.tolist()]
    statuses = {reports[row].status for row in failed.tolist()}
    assert {"branch_changed", "joint_limit", "unreachable"} <= statuses
    changed = [row for row in failed.tolist() if reports[row].status == "branch_changed"]
    pairs = {(tuple(confdata[row]), reports[row].config) for row in changed}
    assert len(pairs) > len({found for _, found in pairs})   # one found, several asked
    assert all(type(reports[row].status) is str for row in failed.tolist())
    assert got == want
