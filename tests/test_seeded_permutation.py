"""The folds' permutation, computed without numpy.random, against numpy.random itself."""

import subprocess
import sys

import numpy as np
import pytest

from olp_compensate.calibration.cross_validation import FOLD_SEED, pose_folds
from olp_compensate.calibration.seeded_permutation import PYTHON_LIMIT, permutation


@pytest.mark.parametrize("seed", [0, 1, 7, 12345, 2**32 - 1, 2**32, 2**64 + 5, 2**130 + 3])
def test_same_numbers_as_numpy(seed):
    for n in (0, 1, 2, 3, 10, 100, 257, 1000, PYTHON_LIMIT, PYTHON_LIMIT + 1):
        ours = permutation(seed, n)
        theirs = np.random.default_rng(seed).permutation(n)
        assert ours.dtype == theirs.dtype
        np.testing.assert_array_equal(ours, theirs)


def test_folds_as_numpy_random_made_them():
    """Every pose in the fold numpy's seeded permutation puts it in (the printed held-out
    figures were made with those folds), rows of one pose together."""
    rng = np.random.default_rng(3)
    ids = rng.choice(np.array([f"p{i:03d}" for i in range(83)]), size=300)
    folds = pose_folds(ids, 5)
    unique = np.unique(ids)
    order = np.random.default_rng(FOLD_SEED).permutation(len(unique))
    for fold, part in enumerate(np.array_split(order, 5)):
        expected = np.isin(ids, unique[part])
        np.testing.assert_array_equal(folds[fold], expected)


def test_folds_do_not_import_numpy_random(tmp_path):
    code = ("import sys\n"
            "from olp_compensate.calibration.cross_validation import pose_folds\n"
            "pose_folds(['a', 'b', 'c', 'a', 'd'], 2)\n"
            "print('numpy.random' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
