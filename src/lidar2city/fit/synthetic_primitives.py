"""Synthetic scenes of primitive buildings with known parameters (for tests and benchmarks).

Buildings of random kind, size and azimuth are laid out on a jittered grid;
airborne LiDAR is simulated as points uniformly distributed in plan at a
given density on the roofs and on the ground around them, with Gaussian
height noise; footprints are the true outlines with Gaussian noise on every
vertex (each coordinate). Everything depends only on ``seed``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..datamodel import ASPRS, Footprints, PointCloud
from .primitives import (
    BoxPrimitive,
    GablePrimitive,
    HipPrimitive,
    PrismPrimitive,
    ShedPrimitive,
)

__all__ = ["SyntheticScene", "synthetic_scene", "ROOF_KINDS"]

ROOF_KINDS = ("box", "gable", "hip", "shed", "prism")


@dataclass(frozen=True, eq=False)
class SyntheticScene:
    """A synthetic scene.

    Attributes
    ----------
    points : ndarray, shape (N, 3)
        Local metric coordinates.
    classification : ndarray of uint8, shape (N,)
        6 on roofs, 2 on the ground.
    footprints : list of shapely Polygon
        Noisy footprints, one per building.
    ids : list of str
    truth : list of Primitive
        The true models (their ``params``, ``kind``).
    corners : list of ndarray (K, 3)
        True 3-D corners per building (the true solids' vertices).
    """

    points: np.ndarray
    classification: np.ndarray
    footprints: list
    ids: list
    truth: list
    corners: list

    def cloud(self) -> PointCloud:
        """The points as a :class:`PointCloud` (origin 0, no CRS)."""
        return PointCloud(self.points, attributes={"classification": self.classification})

    def footprint_set(self) -> Footprints:
        """The noisy footprints as :class:`Footprints`."""
        return Footprints(list(self.footprints), list(self.ids))


def _truth_model(kind, rng, x, y, sizes, z0):
    import shapely

    lmin, lmax, wmin, wmax, hmin, hmax = sizes
    length = rng.uniform(lmin, lmax)
    width = rng.uniform(wmin, min(wmax, length))
    height = rng.uniform(hmin, hmax)
    az = rng.uniform(0.0, 360.0 if kind == "shed" else 180.0)
    p = {"x": x, "y": y, "z": z0, "azimuth": az, "length": length, "width": width, "height": height}
    if kind == "box":
        return BoxPrimitive(p)
    if kind == "gable":
        p["roof_height"] = math.tan(math.radians(rng.uniform(25, 50))) * width / 2
        return GablePrimitive(p)
    if kind == "hip":
        slope = math.radians(rng.uniform(25, 45))
        p["roof_height"] = math.tan(slope) * width / 2
        p["hip_length"] = min(width / 2 * rng.uniform(0.6, 1.0), length / 2 - 1.0)
        return HipPrimitive(p)
    if kind == "shed":
        p["roof_height"] = math.tan(math.radians(rng.uniform(10, 25))) * width
        return ShedPrimitive(p)
    # L-shaped prism: a rectangle with one corner cut away
    a, b = rng.uniform(0.3, 0.6), rng.uniform(0.35, 0.6)
    uv = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5 - b], [0.5 - a, 0.5 - b],
                   [0.5 - a, 0.5], [-0.5, 0.5]]) * [length, width]
    t = math.radians(az)
    rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    ring = uv @ rot.T + [x, y]
    c = shapely.Polygon(ring).centroid  # the prism's datum point is its centroid, as when fitted
    return PrismPrimitive({"x": c.x, "y": c.y, "z": z0, "azimuth": 0.0, "height": height}, rings=[ring])


def synthetic_scene(n_buildings: int = 25, *, seed: int = 0, density: float = 8.0,
                    height_noise: float = 0.05, footprint_noise: float = 0.10,
                    kinds=ROOF_KINDS, sizes=(8.0, 20.0, 6.0, 12.0, 3.0, 9.0),
                    spacing: float = 32.0, ground_z: float = 0.0) -> SyntheticScene:
    """Generate a scene of primitive buildings with LiDAR and noisy footprints.

    Parameters
    ----------
    n_buildings : int
    seed : int
        Seed of ``np.random.default_rng``.
    density : float, default 8
        Points per square metre (roofs and ground).
    height_noise : float, default 0.05
        Standard deviation of the point heights, metres.
    footprint_noise : float, default 0.10
        Standard deviation of each footprint vertex coordinate, metres.
    kinds : sequence of str
        Building kinds drawn uniformly (cycled, then shuffled, so all appear).
    sizes : (lmin, lmax, wmin, wmax, hmin, hmax)
        Ranges of length, width and eave height, metres.
    spacing : float
        Grid spacing of the building centres, metres.
    ground_z : float
        Ground height.

    Returns
    -------
    SyntheticScene
    """
    import shapely

    rng = np.random.default_rng(seed)
    kinds = list(kinds)
    order = [kinds[i % len(kinds)] for i in range(n_buildings)]
    rng.shuffle(order)
    ncol = max(int(math.ceil(math.sqrt(n_buildings))), 1)
    truth, footprints, corners, ids = [], [], [], []
    roof_pts = []
    for i, kind in enumerate(order):
        cx = (i % ncol + 0.5) * spacing + rng.uniform(-1.5, 1.5)
        cy = (i // ncol + 0.5) * spacing + rng.uniform(-1.5, 1.5)
        model = _truth_model(kind, rng, cx, cy, sizes, ground_z)
        outline = model.outline()
        poly = shapely.Polygon(outline)
        n = rng.poisson(density * poly.area)
        lo, hi = outline.min(axis=0), outline.max(axis=0)
        m = int(n * (hi - lo).prod() / poly.area) + 16
        xy = rng.uniform(lo, hi, size=(m, 2))
        xy = xy[shapely.contains_xy(poly, xy[:, 0], xy[:, 1])][:n]
        z = model.roof_z(xy)[0] + rng.normal(0.0, height_noise, len(xy))
        roof_pts.append(np.column_stack([xy, z]))
        noisy = outline + rng.normal(0.0, footprint_noise, outline.shape)
        footprints.append(shapely.Polygon(noisy))
        truth.append(model)
        corners.append(model.corners())
        ids.append(f"b{i:04d}")
    extent = np.array([ncol * spacing, math.ceil(n_buildings / ncol) * spacing])
    ng = rng.poisson(density * extent.prod())
    gxy = rng.uniform([0, 0], extent, size=(ng, 2))
    inside = np.zeros(ng, dtype=bool)
    for m in truth:
        p = shapely.Polygon(m.outline())
        inside |= shapely.contains_xy(p, gxy[:, 0], gxy[:, 1])
    gxy = gxy[~inside]
    ground = np.column_stack([gxy, ground_z + rng.normal(0.0, height_noise, len(gxy))])
    roofs = np.vstack(roof_pts) if roof_pts else np.empty((0, 3))
    points = np.vstack([roofs, ground])
    cls = np.concatenate([np.full(len(roofs), ASPRS.BUILDING, np.uint8),
                          np.full(len(ground), ASPRS.GROUND, np.uint8)])
    return SyntheticScene(points, cls, footprints, ids, truth, corners)
