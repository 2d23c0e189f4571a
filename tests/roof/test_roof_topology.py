"""Label-grid roof topology helpers."""

import numpy as np


def test_merge_small_regions_window_equals_whole_grid():
    """Merging small label regions (all labels' regions found at once, each changed on a
    window around it) gives the label-by-label, whole-grid answer."""
    from scipy import ndimage

    from lidar2city.roof.topology import _merge_small_regions

    def whole_grid(grid, inside, min_cells):
        for _ in range(4):
            changed, out = False, grid.copy()
            for lab in np.unique(grid[inside]):
                comp, n = ndimage.label(grid == lab)
                sizes = np.bincount(comp.ravel())
                for c in np.flatnonzero(sizes[1:] < min_cells) + 1:
                    m = comp == c
                    neigh = grid[ndimage.binary_dilation(m) & ~m & inside]
                    neigh = neigh[neigh != lab]
                    if len(neigh):
                        out[m] = np.bincount(neigh).argmax()
                        changed = True
            grid = out
            if not changed:
                break
        return grid

    rng = np.random.default_rng(3)
    for _ in range(200):
        g = rng.integers(0, int(rng.integers(1, 7)), tuple(rng.integers(1, 25, 2)))
        inside = rng.random(g.shape) < 0.9
        g = np.where(inside, g, -1)
        k = int(rng.integers(1, 8))
        assert np.array_equal(_merge_small_regions(g, inside, k), whole_grid(g, inside, k))
