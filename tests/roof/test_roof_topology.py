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
    # label grids as roofs make them: large regions (blocks of one label) with speckle,
    # holes in the footprint, ties between a small region's neighbour labels, several
    # passes (a region that took a small neighbour's label is small again)
    changed = 0
    for _ in range(60):
        h, w = (int(v) for v in rng.integers(8, 60, 2))
        n_lab = int(rng.integers(2, 9))
        blocks = rng.integers(0, n_lab, (h // 4 + 1, w // 4 + 1))
        g = np.kron(blocks, np.ones((4, 4), dtype=np.int64))[:h, :w]
        speckle = rng.random((h, w)) < float(rng.uniform(0.02, 0.3))
        g = np.where(speckle, rng.integers(0, n_lab, (h, w)), g)
        inside = rng.random((h, w)) < 0.95
        inside[: int(rng.integers(0, h // 3 + 1)), : int(rng.integers(0, w // 3 + 1))] = False
        g = np.where(inside, g, -1)
        k = int(rng.integers(2, 10))
        got = _merge_small_regions(g, inside, k)
        assert np.array_equal(got, whole_grid(g, inside, k))
        changed += not np.array_equal(got, g)
    assert changed >= 50
