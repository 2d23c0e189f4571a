"""lidar2city._stats: numpy's statistics, the same values."""

import numpy as np
import pytest

from lidar2city._stats import median


def _same(a, b):
    return type(a) is type(b) and np.signbit(a) == np.signbit(b) and (
        a == b or (np.isnan(a) and np.isnan(b)))


def test_median_equals_numpy_to_the_bit():
    """Odd and even lengths, ties, signed zeros (numpy's mean turns -0.0 into +0.0), NaNs."""
    rng = np.random.default_rng(5)
    for _ in range(3000):
        m = int(rng.integers(1, 60))
        a = rng.normal(size=m) * 10.0 ** int(rng.integers(-3, 6))
        r = rng.random()
        if r < 0.3:
            a = np.round(a, 1)
        elif r < 0.4:
            a = np.round(a * 1e-3, 0)  # zeros of both signs
        elif r < 0.45:
            a[:] = -0.0
        elif r < 0.55:
            a[rng.integers(0, m, 2)] = np.nan
        assert _same(median(a), np.median(a)), a


@pytest.mark.parametrize("a", [np.zeros(0), np.arange(5), np.ones((2, 3)),
                               np.arange(4, dtype=np.float32)])
def test_median_leaves_other_inputs_to_numpy(a):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the empty array's mean
        assert _same(median(a), np.median(a))


def test_percentile_equals_numpy_to_the_bit():
    """Any length, percentiles at, between and on the order statistics, ties, NaNs."""
    from lidar2city._stats import percentile

    rng = np.random.default_rng(7)
    for _ in range(3000):
        m = int(rng.integers(1, 60))
        a = rng.normal(size=m) * 10.0 ** int(rng.integers(-3, 6))
        r = rng.random()
        if r < 0.3:
            a = np.round(a, 1)
        elif r < 0.4:
            a[rng.integers(0, m, 2)] = np.nan
        q = [70.0, 10.0, 0.0, 100.0, 50, float(rng.uniform(0, 100))][int(rng.integers(0, 6))]
        assert _same(percentile(a, q), np.percentile(a, q)), (a, q)


@pytest.mark.parametrize("a, q", [(np.zeros(0), 70.0), (np.arange(5), 70.0),
                                  (np.ones((2, 3)), 10.0), (np.arange(4.0), [10, 70])])
def test_percentile_leaves_other_inputs_to_numpy(a, q):
    from lidar2city._stats import percentile

    if a.size == 0:
        with pytest.raises(IndexError):
            np.percentile(a, q)
        with pytest.raises(IndexError):
            percentile(a, q)
        return
    np.testing.assert_array_equal(percentile(a, q), np.percentile(a, q))
