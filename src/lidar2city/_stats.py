"""Small statistics on the hot paths, equal to numpy's to the bit without its set-up.

:func:`numpy.median` spends ~15 us a call checking dtypes and shapes and wrapping
its result; the roof steps take the median of a few hundred values thousands of
times per tile.
"""

from __future__ import annotations

import numpy as np

__all__ = ["median"]


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
