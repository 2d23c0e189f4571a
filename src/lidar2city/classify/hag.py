"""Height above ground from a ground mask: a gridded DTM with filled holes.

A small, robust stand-in for the ground package's DTM: ground points are
gridded (mean height of the ground points around each grid node, unbiased
on slopes, unlike the lowest point), empty cells (under buildings, over water) are
filled with the nearest observed height relaxed into a smooth membrane
(Laplace equation with the observed cells fixed), and each point's terrain height is read
bilinearly from the grid.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..errors import EmptyInputError, InputError

logger = logging.getLogger(__name__)

__all__ = ["GroundGrid", "ground_grid", "height_above_ground"]


@dataclass(frozen=True, eq=False)
class GroundGrid:
    """A terrain grid: ``z[i, j]`` is the height at ``(x0 + j*cell, y0 + i*cell)``.

    Attributes
    ----------
    z : ndarray, shape (rows, cols)
        Terrain heights at the grid nodes (no NaN).
    x0, y0 : float
        Coordinates of node ``(0, 0)``.
    cell : float
        Node spacing (m).
    observed : ndarray of bool, shape (rows, cols)
        True where the node had ground points (False where filled).
    """

    z: np.ndarray
    x0: float
    y0: float
    cell: float
    observed: np.ndarray

    def sample(self, xy) -> np.ndarray:
        """Bilinear terrain height at ``xy`` (N, 2); clamped at the grid border."""
        from scipy.ndimage import map_coordinates

        xy = np.asarray(xy, dtype=np.float64)
        rows, cols = self.z.shape
        c = np.clip((xy[:, 0] - self.x0) / self.cell, 0, cols - 1)
        r = np.clip((xy[:, 1] - self.y0) / self.cell, 0, rows - 1)
        return map_coordinates(self.z, np.vstack([r, c]), order=1, mode="nearest")


def _fill(z, observed, *, iterations: int) -> np.ndarray:
    """Fill the unobserved nodes: nearest observed value, then harmonic relaxation.

    Jacobi iterations of the discrete Laplace equation on the unobserved nodes
    (observed ones fixed) turn the nearest-value steps into a smooth membrane
    spanning the hole, the usual fill under buildings.
    """
    from scipy import ndimage

    _, (ii, jj) = ndimage.distance_transform_edt(~observed, return_indices=True)
    z = z[ii, jj]
    free = ~observed
    for _ in range(iterations):
        p = np.pad(z, 1, mode="edge")
        avg = 0.25 * (p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:])
        z = np.where(free, avg, z)
    return z


def ground_grid(xyz, ground, *, cell: float = 1.0, extent=None,
                fill_iterations: int = 200) -> GroundGrid:
    """Grid the ground points (mean per node cell) and fill the empty cells.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Coordinates in metres.
    ground : ndarray of bool, shape (N,)
        Ground mask.
    cell : float
        Grid spacing (m).
    extent : tuple (xmin, ymin, xmax, ymax), optional
        Area to cover; defaults to the bounds of the ground points (points
        outside read the border heights).
    fill_iterations : int
        Relaxation sweeps smoothing the filled holes.

    Raises
    ------
    EmptyInputError
        If no point is ground.
    InputError
        If the shapes disagree or ``cell`` is not positive.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    ground = np.asarray(ground, dtype=bool)
    if ground.shape != (len(xyz),):
        raise InputError(f"ground mask has shape {ground.shape}, expected ({len(xyz)},)")
    if not cell > 0:
        raise InputError(f"cell must be positive, got {cell}")
    if not ground.any():
        raise EmptyInputError("no ground points: cannot compute heights above ground")
    if extent is None:  # points beyond the ground's extent read the border value
        g2 = xyz[ground, :2]
        extent = (*g2.min(axis=0), *g2.max(axis=0))
    x0, y0 = float(extent[0]), float(extent[1])
    cols = int(np.floor((extent[2] - x0) / cell)) + 2
    rows = int(np.floor((extent[3] - y0) / cell)) + 2
    if rows * cols > 100_000_000:
        raise InputError(f"the ground spans {rows * cell:.0f} m x {cols * cell:.0f} m, too large "
                         f"for one DTM grid of {cell:g} m cells; split the input into tiles")
    g = xyz[ground]
    # nodes are cell centres of the binning lattice shifted by half a cell
    j = np.clip(np.floor((g[:, 0] - x0) / cell + 0.5).astype(np.int64), 0, cols - 1)
    i = np.clip(np.floor((g[:, 1] - y0) / cell + 0.5).astype(np.int64), 0, rows - 1)
    key = i * cols + j
    count = np.bincount(key, minlength=rows * cols)
    total = np.bincount(key, g[:, 2], minlength=rows * cols)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(count > 0, total / np.maximum(count, 1), np.nan).reshape(rows, cols)
    observed = np.isfinite(z)
    if not observed.all():
        z = _fill(z, observed, iterations=fill_iterations)
    return GroundGrid(z, x0, y0, float(cell), observed)


def height_above_ground(xyz, ground, *, cell: float = 1.0) -> np.ndarray:
    """Height of every point above the terrain interpolated from the ground points.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Coordinates in metres.
    ground : ndarray of bool, shape (N,)
        Ground mask.
    cell : float
        DTM grid spacing (m).

    Returns
    -------
    ndarray, shape (N,)
        ``z - dtm(x, y)`` in metres (negative below the terrain).

    Examples
    --------
    >>> xyz = np.array([[0., 0., 1.], [1., 0., 1.], [0., 1., 1.], [0.5, 0.5, 4.]])
    >>> height_above_ground(xyz, np.array([True, True, True, False])).round(2)
    array([0., 0., 0., 3.])
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    grid = ground_grid(xyz, ground, cell=cell)
    return xyz[:, 2] - grid.sample(xyz[:, :2])
