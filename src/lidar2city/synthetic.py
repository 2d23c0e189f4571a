"""A synthetic town with known ground truth, for the demo and the tests.

:func:`make_town` builds terrain with slope, buildings with flat, shed, gable
and hip roofs of several sizes and orientations, an L-shaped building, a
courtyard block and a stepped building, trees with multiple returns, wall
points and a few noise points, sampled as an airborne scan at a given density.
Everything is returned with its truth: the class of every point, footprints,
roof planes per part, ridge lines and ground heights.

Pure: no files, randomness only through ``seed``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .datamodel import ASPRS, Footprints, PointCloud
from .errors import InputError

__all__ = ["RoofPart", "TruthBuilding", "SyntheticTown", "make_town", "roof_height",
           "building_like_graph"]


@dataclass(frozen=True, eq=False)
class RoofPart:
    """A part of a building: a footprint polygon and roof planes.

    The roof height at (x, y) is ``min_k (a_k x + b_k y + c_k)`` over the planes,
    which gives flat (one plane), shed (one sloped plane), gable (two) and hip
    (four) roofs with their ridges where planes meet.
    """

    polygon: object
    planes: np.ndarray  # (k, 3): a, b, c of z = a x + b y + c


@dataclass(frozen=True, eq=False)
class TruthBuilding:
    """Ground truth of one synthetic building."""

    id: str
    roof_type: str
    parts: list
    ground_z: float
    ridges: list = field(default_factory=list)  # list of ((x0, y0, z0), (x1, y1, z1))

    @property
    def footprint(self):
        import shapely

        return shapely.union_all([p.polygon for p in self.parts])

    def roof_z(self, xy) -> np.ndarray:
        """Roof heights at ``xy`` (N, 2); NaN outside the footprint."""
        return roof_height(self.parts, xy)


@dataclass(frozen=True, eq=False)
class SyntheticTown:
    """A synthetic scene: points with truth classes, footprints and building truth."""

    cloud: PointCloud
    footprints: Footprints
    buildings: list
    terrain: tuple  # (a, b, c, amplitude, wavelength)
    n_trees: int = 0

    def terrain_z(self, xy) -> np.ndarray:
        return _terrain(np.asarray(xy, dtype=float), self.terrain)


def _terrain(xy, params):
    a, b, c, amp, wl = params
    x, y = xy[..., 0], xy[..., 1]
    return a * x + b * y + c + amp * np.sin(2 * np.pi * x / wl) * np.cos(2 * np.pi * y / (1.3 * wl))


def roof_height(parts, xy) -> np.ndarray:
    """Roof heights of a list of :class:`RoofPart` at ``xy`` (N, 2); NaN outside all parts."""
    import shapely

    xy = np.asarray(xy, dtype=float)
    z = np.full(len(xy), np.nan)
    for part in parts:
        inside = shapely.contains_xy(part.polygon, xy[:, 0], xy[:, 1])
        if inside.any():
            p = part.planes
            zz = (xy[inside, 0:1] * p[:, 0] + xy[inside, 1:2] * p[:, 1] + p[:, 2]).min(axis=1)
            z[inside] = np.fmax(z[inside], zz)
    return z


def _frame(cx, cy, theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([c, s]), np.array([-s, c]), np.array([cx, cy])


def _rect(cx, cy, length, width, theta):
    from shapely.geometry import Polygon

    u, v, o = _frame(cx, cy, theta)
    pts = [o + su * length / 2 * u + sv * width / 2 * v for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return Polygon(pts)


def _plane_through(u_dir, o, z0, slope):
    """Plane z = z0 + slope * ((p - o) . u_dir) as (a, b, c)."""
    a, b = slope * u_dir
    return np.array([a, b, z0 - a * o[0] - b * o[1]])


def _gable(cx, cy, length, width, theta, eave, slope):
    u, v, o = _frame(cx, cy, theta)
    hw = width / 2
    # z = eave + slope * (hw - |v.(p-o)|) = min of two planes
    planes = np.array([_plane_through(v, o, eave + slope * hw, -slope),
                       _plane_through(-v, o, eave + slope * hw, -slope)])
    ridge_z = eave + slope * hw
    ridge = (tuple(o - length / 2 * u) + (ridge_z,), tuple(o + length / 2 * u) + (ridge_z,))
    return planes, [ridge]


def _hip(cx, cy, length, width, theta, eave, slope):
    u, v, o = _frame(cx, cy, theta)
    hl, hw = length / 2, width / 2
    planes = np.array([
        _plane_through(v, o, eave + slope * hw, -slope),
        _plane_through(-v, o, eave + slope * hw, -slope),
        _plane_through(u, o, eave + slope * hl, -slope),
        _plane_through(-u, o, eave + slope * hl, -slope),
    ])
    ridge_z = eave + slope * hw
    half = max(hl - hw, 0.0)
    ridge = (tuple(o - half * u) + (ridge_z,), tuple(o + half * u) + (ridge_z,))
    return planes, [ridge]


def _flat(z):
    return np.array([[0.0, 0.0, z]])


def _shed(cx, cy, theta, low, slope, width):
    u, v, o = _frame(cx, cy, theta)
    return np.array([_plane_through(v, o, low + slope * width / 2, slope)])


def _layout(rng, size):
    """Building specifications placed on a loose grid of lots."""
    from shapely.geometry import Polygon

    w, h = size
    specs = []
    lots_x = np.arange(25.0, w - 20.0, 38.0)
    lots_y = np.arange(25.0, h - 20.0, 38.0)
    lots = [(x, y) for y in lots_y for x in lots_x]
    kinds = ["gable", "hip", "flat", "L", "gable", "courtyard", "shed", "stepped", "hip", "gable",
             "flat", "gable"]
    for i, (lx, ly) in enumerate(lots):
        kind = kinds[i % len(kinds)]
        theta = rng.uniform(0, np.pi / 2) if i % 3 else 0.0
        cx, cy = lx + rng.uniform(-2, 2), ly + rng.uniform(-2, 2)
        length, width = rng.uniform(12, 22), rng.uniform(8, 11)
        slope = np.tan(np.deg2rad(rng.uniform(25, 45)))
        eave = rng.uniform(4.5, 7.5)
        specs.append((f"b{i:02d}", kind, cx, cy, length, width, theta, eave, slope, Polygon))
    return specs


def _build(spec, rng, terrain):
    import shapely
    from shapely.geometry import Polygon

    bid, kind, cx, cy, length, width, theta, eave, slope, _ = spec
    u, v, o = _frame(cx, cy, theta)
    ridges = []
    if kind in ("gable", "hip", "flat", "shed"):
        poly = _rect(cx, cy, length, width, theta)
        ground = float(_terrain(np.asarray(poly.exterior.coords), terrain).min())
        z_eave = ground + eave
        if kind == "gable":
            planes, ridges = _gable(cx, cy, length, width, theta, z_eave, slope)
        elif kind == "hip":
            planes, ridges = _hip(cx, cy, length, width, theta, z_eave, slope)
        elif kind == "shed":
            planes = _shed(cx, cy, theta, z_eave, np.tan(np.deg2rad(12)), width)
        else:
            planes = _flat(z_eave + rng.uniform(0, 3))
        parts = [RoofPart(poly, planes)]
    elif kind == "L":
        a = _rect(cx, cy, 20, 8, theta)
        b = _rect(*(o + 6 * u + 8 * v), 8, 16 + 8 * 0, theta)
        poly = shapely.union_all([a, b]).simplify(1e-6)
        ground = float(_terrain(np.asarray(poly.exterior.coords), terrain).min())
        parts = [RoofPart(poly, _flat(ground + eave + 2))]
    elif kind == "courtyard":
        outer = _rect(cx, cy, 24, 24, theta)
        inner = _rect(cx, cy, 10, 10, theta)
        poly = Polygon(outer.exterior.coords, [inner.exterior.coords])
        ground = float(_terrain(np.asarray(outer.exterior.coords), terrain).min())
        parts = [RoofPart(poly, _flat(ground + eave + 3))]
    elif kind == "stepped":
        low = _rect(*(o - 4 * u), 10, 12, theta)
        high = _rect(*(o + 5 * u), 8, 12, theta)
        # the corners of both parts (they only touch: their union may come out as
        # two polygons where the shared edge is off by a rounding error)
        corners = np.vstack([np.asarray(low.exterior.coords), np.asarray(high.exterior.coords)])
        ground = float(_terrain(corners, terrain).min())
        parts = [RoofPart(low, _flat(ground + 4.0)), RoofPart(high, _flat(ground + 10.0))]
    else:  # pragma: no cover - internal table
        raise InputError(f"unknown building kind {kind!r}")
    return TruthBuilding(bid, kind, parts, ground, ridges)


def _jittered_grid(rng, x0, y0, x1, y1, density):
    step = 1.0 / np.sqrt(density)
    xs = np.arange(x0, x1, step)
    ys = np.arange(y0, y1, step)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    pts += rng.uniform(-0.45 * step, 0.45 * step, pts.shape)
    return pts


def make_town(*, size=(200.0, 150.0), density=10.0, seed=0, noise_sigma=0.05,
              n_trees=25, origin=(85000.0, 447000.0, 0.0), crs="EPSG:7415") -> SyntheticTown:
    """Generate a synthetic town.

    Parameters
    ----------
    size : (float, float)
        Extent in metres (x, y).
    density : float
        Last-return points per square metre.
    seed : int
        Seed of the random generator: the same seed gives the same town.
    noise_sigma : float
        Standard deviation of the height noise (m).
    n_trees : int
        Number of trees.
    origin : (float, float, float)
        World coordinates of the local origin (CRS units).
    crs : str or None
        CRS of the world coordinates (default RD New + NAP).

    Returns
    -------
    SyntheticTown
        Points (truth classes in ``attributes['classification']``, with
        ``return_number`` and ``number_of_returns``), footprints and truth.

    Examples
    --------
    >>> town = make_town(size=(80, 60), density=4, seed=1)
    >>> len(town.buildings) > 0
    True
    """
    import shapely

    from .crs import parse_crs

    if density <= 0 or noise_sigma < 0 or min(size) < 40:
        raise InputError("density must be > 0, noise_sigma >= 0 and size at least 40 m x 40 m")
    rng = np.random.default_rng(seed)
    w, h = size
    terrain = (0.02, -0.012, 1.0, 0.4, 60.0)
    buildings = [_build(s, rng, terrain) for s in _layout(rng, size)]
    # keep buildings wholly inside the scene with a margin
    scene = shapely.geometry.box(3, 3, w - 3, h - 3)
    buildings = [b for b in buildings if scene.contains(b.footprint)]

    xy = _jittered_grid(rng, 0, 0, w, h, density)
    z = _terrain(xy, terrain)
    cls = np.full(len(xy), ASPRS.GROUND, dtype=np.uint8)
    bid = np.full(len(xy), -1)
    for i, b in enumerate(buildings):
        rz = b.roof_z(xy)
        inside = np.isfinite(rz)
        z[inside] = rz[inside]
        cls[inside] = ASPRS.BUILDING
        bid[inside] = i
    z = z + rng.normal(0, noise_sigma, len(z))
    rn = np.ones(len(xy), dtype=np.uint8)
    nr = np.ones(len(xy), dtype=np.uint8)

    extra_xyz, extra_cls, extra_rn, extra_nr = [], [], [], []
    # walls: sparse points on the facades (airborne scans see a few)
    for b in buildings:
        fp = b.footprint
        rings = [fp.exterior, *fp.interiors] if fp.geom_type == "Polygon" else \
            [r for g in fp.geoms for r in (g.exterior, *g.interiors)]
        for ring in rings:
            n = max(int(ring.length * 0.3), 1)
            d = rng.uniform(0, ring.length, n)
            pts = np.array([ring.interpolate(t).coords[0] for t in d])
            pts += rng.normal(0, 0.05, pts.shape)
            top = np.nan_to_num(b.roof_z(pts - 0.3 * (pts - np.asarray(fp.centroid.coords[0]))
                                         / np.maximum(np.linalg.norm(pts - np.asarray(fp.centroid.coords[0]), axis=1, keepdims=True), 1e-9)),
                                nan=b.ground_z + 3)
            zz = rng.uniform(b.ground_z + 0.5, np.maximum(top - 0.3, b.ground_z + 0.6))
            extra_xyz.append(np.column_stack([pts, zz]))
            extra_cls.append(np.full(n, ASPRS.BUILDING))
            extra_rn.append(np.ones(n))
            extra_nr.append(np.ones(n))
    # trees: ellipsoidal crowns, first returns on the crown, later returns inside and on the ground
    footprints_union = shapely.union_all([b.footprint.buffer(3) for b in buildings])
    placed = 0
    tries = 0
    while placed < n_trees and tries < 50 * n_trees:
        tries += 1
        tx, ty = rng.uniform(5, w - 5), rng.uniform(5, h - 5)
        r = rng.uniform(2.0, 4.5)
        if footprints_union.distance(shapely.geometry.Point(tx, ty)) < r:
            continue
        placed += 1
        height = rng.uniform(6, 14)
        gz = float(_terrain(np.array([tx, ty]), terrain))
        near = np.hypot(xy[:, 0] - tx, xy[:, 1] - ty) < r
        k = int(near.sum())
        if k == 0:
            continue
        dx, dy = xy[near, 0] - tx, xy[near, 1] - ty
        rr = np.sqrt(np.clip(1 - (dx * dx + dy * dy) / (r * r), 0, 1))
        crown_top = gz + height - 0.5 * r + 0.5 * r * rr + rng.normal(0, 0.4, k)
        # the first return hits the crown; 40% get a second return inside, 50% of those reach ground
        z_first = crown_top
        cls[near] = ASPRS.HIGH_VEGETATION
        z[near] = z_first
        second = rng.random(k) < 0.4
        ground_hit = second & (rng.random(k) < 0.5)
        nr[near] = np.where(second, 2, 1)
        inner = second & ~ground_hit
        s_xy = np.column_stack([xy[near][second, 0], xy[near][second, 1]])
        s_z = np.where(ground_hit[second], gz + rng.normal(0, noise_sigma, second.sum()),
                       rng.uniform(gz + 2.0, crown_top[second]))
        s_cls = np.where(ground_hit[second], ASPRS.GROUND, ASPRS.HIGH_VEGETATION)
        extra_xyz.append(np.column_stack([s_xy, s_z]))
        extra_cls.append(s_cls)
        extra_rn.append(np.full(len(s_z), 2))
        extra_nr.append(np.full(len(s_z), 2))
        del inner
    # noise: a few isolated high and low points
    n_noise = max(int(len(xy) * 2e-4), 2)
    nxy = rng.uniform([0, 0], [w, h], (n_noise, 2))
    nz = _terrain(nxy, terrain) + np.where(rng.random(n_noise) < 0.5, -rng.uniform(5, 20, n_noise),
                                           rng.uniform(40, 80, n_noise))
    extra_xyz.append(np.column_stack([nxy, nz]))
    extra_cls.append(np.full(n_noise, ASPRS.NOISE))
    extra_rn.append(np.ones(n_noise))
    extra_nr.append(np.ones(n_noise))

    xyz = np.vstack([np.column_stack([xy, z]), *extra_xyz])
    classes = np.concatenate([cls, *extra_cls]).astype(np.uint8)
    returns = np.concatenate([rn, *extra_rn]).astype(np.uint8)
    n_returns = np.concatenate([nr, *extra_nr]).astype(np.uint8)
    order = np.lexsort((xyz[:, 1], xyz[:, 0]))  # a scan order independent of generation order
    cloud = PointCloud(
        xyz[order], np.asarray(origin, float), parse_crs(crs), 1.0, 1.0,
        {"classification": classes[order], "return_number": returns[order],
         "number_of_returns": n_returns[order]},
    )
    fps = Footprints([b.footprint for b in buildings], [b.id for b in buildings],
                     {"roof_type": [b.roof_type for b in buildings]})
    return SyntheticTown(cloud, fps, buildings, terrain, placed)


def building_like_graph(n, extra, rng) -> list:
    """Edges of a random planar graph shaped like a building topology: a spanning tree of a
    Delaunay graph of ``n`` random points plus ``extra`` of its other edges (cycles).

    Serves the snake solver's tests and benchmark.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import minimum_spanning_tree
    from scipy.spatial import Delaunay

    pts = rng.random((n, 2))
    tri = Delaunay(pts)
    ed = sorted({tuple(sorted((int(s[i]), int(s[(i + 1) % 3])))) for s in tri.simplices for i in range(3)})
    ea = np.array(ed)
    w = np.linalg.norm(pts[ea[:, 0]] - pts[ea[:, 1]], axis=1)
    mst = minimum_spanning_tree(coo_matrix((w, (ea[:, 0], ea[:, 1])), shape=(n, n))).tocoo()
    tree = set(zip(np.minimum(mst.row, mst.col).tolist(), np.maximum(mst.row, mst.col).tolist(),
                   strict=True))
    rest = [e for e in ed if e not in tree]
    pick = rng.choice(len(rest), size=min(extra, len(rest)), replace=False)
    return sorted(tree) + [rest[i] for i in pick]
