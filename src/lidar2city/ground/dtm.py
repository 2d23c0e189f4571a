"""Digital terrain models from ground points, and heights above them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import EmptyInputError, InputError
from ._grid import GridSpec, centre_surface, grid_spec, inpaint, sample_bilinear
from .outliers import _check_xyz

__all__ = ["Dtm", "dtm_from_ground", "height_above_ground"]


@dataclass(frozen=True, eq=False)
class Dtm:
    """A north-up terrain grid in local metric coordinates.

    Parameters
    ----------
    array : ndarray, shape (H, W), float64
        Terrain height (metres, local z) at cell centres; no NaN.
    x0 : float
        x of the left edge (metres, local).
    y_top : float
        y of the top edge (metres, local).
    cell : float
        Cell size (metres).
    measured : ndarray of bool, shape (H, W)
        True where the cell held ground points (False where interpolated).
    """

    array: np.ndarray
    x0: float
    y_top: float
    cell: float
    measured: np.ndarray

    @property
    def spec(self) -> GridSpec:
        return GridSpec(self.x0, self.y_top, self.cell, self.array.shape)

    @property
    def shape(self) -> tuple[int, int]:
        return self.array.shape

    def sample(self, xy) -> np.ndarray:
        """Terrain height at points ``xy`` (N, 2) by bilinear interpolation (clamped)."""
        xy = np.asarray(xy, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] < 2:
            raise InputError(f"xy must have shape (N, 2), got {xy.shape}")
        return sample_bilinear(self.array, self.spec, xy[:, :2])

    def world_transform(self, origin, xy_unit: float = 1.0):
        """The :class:`affine.Affine` pixel-to-world transform (CRS units).

        ``origin`` is the point cloud's local origin (CRS units), ``xy_unit``
        its metres per CRS unit.
        """
        from affine import Affine

        size = self.cell / xy_unit
        return Affine(size, 0.0, origin[0] + self.x0 / xy_unit,
                      0.0, -size, origin[1] + self.y_top / xy_unit)

    def world_heights(self, origin_z: float = 0.0, z_unit: float = 1.0) -> np.ndarray:
        """Heights in CRS vertical units (``origin_z + z / z_unit``)."""
        return origin_z + self.array / z_unit

    @classmethod
    def from_raster(cls, array, transform, origin, *, xy_unit: float = 1.0,
                    z_unit: float = 1.0) -> Dtm:
        """A local metric DTM from a north-up raster in world units (e.g. a DTM GeoTIFF).

        Parameters
        ----------
        array : ndarray, shape (H, W)
            Heights in CRS vertical units, NaN for nodata (filled by inpainting).
        transform : affine.Affine
            Pixel-to-world transform (no rotation, square pixels).
        origin : array_like, shape (3,)
            The local origin (world coordinates) of the point cloud to pair with.
        xy_unit, z_unit : float
            Metres per CRS unit.

        Raises
        ------
        InputError
            Rotated or non-square pixels, or no valid cell.
        """
        t = transform
        if t.b != 0 or t.d != 0 or t.a <= 0 or t.e >= 0 or not np.isclose(t.a, -t.e):
            raise InputError("the raster must be north-up with square pixels")
        arr = np.asarray(array, dtype=np.float64)
        if arr.ndim != 2:
            raise InputError(f"the raster must be one band (H, W), got shape {arr.shape}")
        measured = np.isfinite(arr)
        if not measured.any():
            raise EmptyInputError("the terrain raster has no valid cell")
        origin = np.asarray(origin, dtype=np.float64)
        local = (arr - origin[2]) * z_unit
        return cls(inpaint(local), float((t.c - origin[0]) * xy_unit),
                   float((t.f - origin[1]) * xy_unit), float(t.a * xy_unit), measured)


def dtm_from_ground(xyz, ground, *, cell: float = 1.0, bounds=None,
                    iterations: int = 10) -> Dtm:
    """Grid the ground points into a gap-free terrain model.

    Each cell holding ground points takes their height at its centre (their
    plane where they spread over the cell, else their mean); cells without
    any (under buildings, water, data gaps) are filled with a smooth
    (approximately harmonic, Laplace) interpolation of the measured cells,
    which keeps measured cells exactly and never overshoots them.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    ground : ndarray of bool, shape (N,)
        Ground mask.
    cell : float
        Cell size (metres).
    bounds : tuple, optional
        ``(xmin, ymin, xmax, ymax)`` to cover (local metres); default the extent
        of all points (not only the ground ones).
    iterations : int
        Relaxation sweeps per level of the inpainting.

    Returns
    -------
    Dtm

    Raises
    ------
    EmptyInputError
        If no point is ground (in the bounds).
    InputError
        Wrong shapes or a non-positive cell.

    Examples
    --------
    >>> import numpy as np
    >>> xyz = np.array([[0.5, 0.5, 1.0], [2.5, 0.5, 3.0], [1.5, 0.5, 9.0]])
    >>> dtm = dtm_from_ground(xyz, np.array([True, True, False]), cell=1.0)
    >>> dtm.array.round(2).tolist()
    [[1.0, 2.0, 3.0]]
    """
    xyz = _check_xyz(xyz)
    ground = np.asarray(ground, dtype=bool)
    if ground.shape != (len(xyz),):
        raise InputError(f"ground has shape {ground.shape}, expected ({len(xyz)},)")
    if len(xyz) == 0:
        raise EmptyInputError("no points to build a terrain model from")
    spec = grid_spec(xyz[:, :2], cell=cell, bounds=bounds)
    pts = xyz[ground]
    if bounds is not None and len(pts):
        h, w = spec.shape
        inside = ((pts[:, 0] >= spec.x0) & (pts[:, 0] < spec.x0 + w * cell)
                  & (pts[:, 1] <= spec.y_top) & (pts[:, 1] > spec.y_top - h * cell))
        pts = pts[inside]
    if len(pts) == 0:
        raise EmptyInputError("no ground points: cannot build a terrain model")
    grid = centre_surface(pts, spec)
    measured = np.isfinite(grid)
    return Dtm(inpaint(grid, iterations=iterations), spec.x0, spec.y_top, spec.cell, measured)


def height_above_ground(xyz, dtm: Dtm) -> np.ndarray:
    """Height of each point above the terrain model (metres, negative below).

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
    dtm : Dtm

    Returns
    -------
    ndarray, shape (N,), float64
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError(f"xyz must have shape (N, 3), got {xyz.shape}")
    if len(xyz) == 0:
        return np.zeros(0)
    return xyz[:, 2] - dtm.sample(xyz[:, :2])
