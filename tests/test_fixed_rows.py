"""fixed_rows (programs/number_format.py): rows of floats written by array operations,
checked against Python's own ``"%.Nf" %`` of every number, ties and hard cases included."""

from __future__ import annotations

import numpy as np
import pytest

from olp_compensate.programs.number_format import fixed_rows

HARD = [
    0.03125, -0.03125, 0.5, -0.5, 2.5, 1.5, 0.000125, -0.00005, 9.99995, 99999.99999949,
    0.0, -0.0, -1e-9, 1e-300, -1e-300, 5e-324, 0.1, 0.7, 1.0000005, 2.0000005,
    123456.7890125, 4294.9672955, 4294967295.0, 4294967296.4, 1 / 3, -2 / 3, 359.9999995,
    179.99999949999999, 0.00049999999999999995, 0.0004999999999999999,
]


def percent(values: np.ndarray, decimals: int) -> list[str]:
    return [",".join("%.*f" % (decimals, x) for x in row) for row in values.tolist()]


@pytest.mark.parametrize("decimals", [0, 1, 2, 4, 5, 6, 9])
def test_hard_numbers_are_written_as_percent_writes_them(decimals):
    values = np.array(HARD).reshape(-1, 3)
    assert fixed_rows(values, decimals) == percent(values, decimals)
    one = np.array(HARD).reshape(-1, 1)
    assert fixed_rows(one, decimals) == percent(one, decimals)


@pytest.mark.parametrize("decimals", [0, 3, 4, 5, 6])
@pytest.mark.parametrize("scale", [1e-7, 1e-3, 1.0, 180.0, 1e4, 1e7])
def test_random_numbers_are_written_as_percent_writes_them(decimals, scale):
    rng = np.random.default_rng(int(decimals * 100 + np.log10(scale) + 50))
    values = rng.normal(size=(3000, 6)) * scale
    # halves of the last decimal, as written in decimal: the hardest to round
    values[:500] = np.round(values[:500], decimals + 1)
    values[500:1000] = (np.floor(values[500:1000] * 10 ** decimals) + 0.5) / 10 ** decimals
    assert fixed_rows(values, decimals) == percent(values, decimals)


def test_numbers_too_large_or_not_finite_take_percent_and_empty_shapes_give_empty_rows():
    values = np.array([[1e16, 2.0], [np.inf, -np.nan], [3.0, -4.25]])
    assert fixed_rows(values, 4) == percent(values, 4)
    assert fixed_rows(np.zeros((0, 3)), 4) == []
    assert fixed_rows(np.zeros((2, 0)), 4) == ["", ""]


@pytest.mark.parametrize("separators, decimals", [
    ((",", ",", "],[", ",", ",", ","), [3, 3, 3, 6, 6, 6, 6]),   # a robtarget's pose
    ((", ", ",", ",", "%"), [3, 3, 4, 4, 4]),
    ((",", ","), [4, 4, 4]),
])
def test_spans_of_one_template_are_written_as_its_percent_format_writes_them(separators,
                                                                           decimals):
    from olp_compensate.programs.emit_batch import _PlainRun

    run = _PlainRun(list(range(len(decimals))), decimals, "")
    rng = np.random.default_rng(len(decimals))
    new = rng.normal(size=(500, len(decimals))) * 300
    new[:4] = np.array([0.0005, -0.00049, 2.5e-7, -0.0])[:, None]   # round to zero: unsigned
    new[:, 0] = np.round(new[:, 0], decimals[0] + 1)   # ties in the last decimal
    expected = [run.template(separators) % tuple(row) for row in run.zero_small(new).tolist()]
    assert run.written([separators] * len(new), new) == expected
