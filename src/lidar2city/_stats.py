"""Small statistics on the hot paths, equal to numpy's to the bit without its set-up.

:func:`numpy.median` spends ~15 us a call checking dtypes and shapes and wrapping
its result; the roof steps take the median of a few hundred values thousands of
times per tile.
"""

from __future__ import annotations

import numpy as np

__all__ = ["median", "percentile"]


def median(values):
    """``np.median(values)`` of a 1-D float64 array, the same value.

    The middle element (odd length) or the mean of the two middle ones, ``(0 + a + b) / 2``
    as ``np.mean`` computes it, from one ``np.partition`` at the positions numpy's
    median partitions at; NaN when any value is NaN (NaNs sort last), as numpy
    returns it. Anything else (other dtypes or shapes, an empty array) goes to
    :func:`numpy.median` itself.

    Examples
    --------
    >>> median(np.array([3.0, 1.0, 2.0, 10.0])) == np.median([3.0, 1.0, 2.0, 10.0])
    True
    """
    a = values if isinstance(values, np.ndarray) else np.asarray(values)
    n = a.size
    if a.dtype != np.float64 or a.ndim != 1 or n == 0:
        return np.median(a)
    half = n // 2
    part = np.partition(a, [half - 1, half, n - 1] if n % 2 == 0 else [half, n - 1])
    if np.isnan(part[-1]):
        return np.float64(np.nan)
    # np.mean of the middle one or two: a sum from +0.0 (so -0.0 comes out +0.0), over the count
    if n % 2:
        return 0.0 + part[half]
    return (0.0 + part[half - 1] + part[half]) / 2


def percentile(values, q: float):
    """``np.percentile(values, q)`` (its default, linear method) of a 1-D float64 array, the
    same value.

    The values at the floor and the ceiling of the virtual index ``(n - 1) q / 100`` from
    one ``np.partition`` at the positions numpy's percentile partitions at (so ties, signed
    zeros included, resolve alike), interpolated as numpy's ``_lerp`` does (from the lower
    one when the fraction is under 1/2, back from the upper one otherwise); NaN when any
    value is NaN. Anything else (other dtypes or shapes, an empty array, ``q`` outside
    [0, 100] or not a number) goes to :func:`numpy.percentile` itself.

    Examples
    --------
    >>> z = np.array([3.0, 1.0, 2.0, 10.0, 7.5])
    >>> percentile(z, 70.0) == np.percentile(z, 70.0)
    True
    """
    a = values if isinstance(values, np.ndarray) else np.asarray(values)
    n = a.size
    if (a.dtype != np.float64 or a.ndim != 1 or n == 0 or isinstance(q, bool)
            or not isinstance(q, (int, float)) or not 0 <= q <= 100):
        return np.percentile(a, q)
    v = (n - 1) * (float(q) / 100)
    # numpy's indices: the last one for a position at or past it (its fraction then
    # measured from -1), else the floor and the next
    lo = -1 if v >= n - 1 else int(np.floor(v))
    hi = -1 if lo == -1 else lo + 1
    part = np.partition(a, np.unique(np.array([0, -1, lo, hi])))
    if np.isnan(part[-1]):
        return np.float64(np.nan)
    below, above = part[lo], part[hi]
    t = np.float64(v - lo)
    d = above - below
    return above - d * (1 - t) if t >= 0.5 else below + d * t
