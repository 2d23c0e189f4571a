"""The LoD1.3 fast paths give what the plain computations they replace give."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lidar2city._components import component_labels
from lidar2city.lod.lod13 import _merge_by_height, _neighbour_pairs


def _merge_by_height_plain(labels, pairs, mask, hv, step, percentile=70.0):
    """Every region measured again and the closest pair of neighbours merged, one merge
    per pass (the definition :func:`_merge_by_height` keeps)."""
    lab = labels.copy()
    cells = np.flatnonzero(mask.ravel())
    height = np.zeros(lab.max() + 1)
    while True:
        la, lb = lab[pairs[:, 0]], lab[pairs[:, 1]]
        diff = la != lb
        if not diff.any():
            return lab
        k, z = lab[cells], hv[cells]
        order = np.lexsort((z, k))
        k, z = k[order], z[order]
        starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
        pos = starts + (np.diff(np.r_[starts, len(k)]) - 1) * (percentile / 100.0)
        lo = np.floor(pos).astype(np.int64)
        hi = np.minimum(lo + 1, len(z) - 1)
        height[k[starts]] = z[lo] + (z[hi] - z[lo]) * (pos - lo)
        pair = {(min(a, b), max(a, b)) for a, b in zip(la[diff].tolist(), lb[diff].tolist())}
        gap, a, b = min((abs(height[a] - height[b]), a, b) for a, b in pair)
        if gap >= step:
            return lab
        lab[lab == b] = a


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(1, 30), cols=st.integers(1, 30),
       decimals=st.sampled_from([0, 1, 3]), scale=st.sampled_from([3.0, 10.0, 20.0]),
       step=st.sampled_from([1.0, 2.0, 4.0]))
def test_merge_by_height_is_the_plain_merge(seed, rows, cols, decimals, scale, step):
    # rounded heights: many equal gaps, so the tie order is exercised
    rng = np.random.default_rng(seed)
    mask = rng.random((rows, cols)) < 0.9
    hv = np.round(rng.random(rows * cols) * scale, decimals)
    pairs = _neighbour_pairs((rows, cols), mask)
    ok = np.abs(hv[pairs[:, 0]] - hv[pairs[:, 1]]) <= 1.0
    lab = component_labels(rows * cols, pairs[ok, 0], pairs[ok, 1])
    np.testing.assert_array_equal(_merge_by_height(lab, pairs, mask, hv, step),
                                  _merge_by_height_plain(lab, pairs, mask, hv, step))
