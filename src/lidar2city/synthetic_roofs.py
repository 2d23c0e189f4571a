"""Synthetic roofs whose wireframes are known exactly, sampled as noisy roof-only point clouds.

A roof is a set of *parts*; each part is a footprint polygon and a few planes,
and its roof height is the lowest of its planes (so a gable is two planes, a hip
four, a half-hip four with raised ends, a mansard eight: four steep ones below
four shallow ones). Where parts overlap the higher one wins (valleys of L/T/U
shapes, dormers on a slope, stepped parts, parapets around a flat roof). The
exact roof faces are the cells of the arrangement of every part outline and
every pair of planes' intersection line, each on its winning plane, merged
where the plane is the same; the wireframe comes from those faces with the same
code that scores a model (:func:`lidar2city.metrics.wireframe.faces_wireframe`).

Kinds: ``gable``, ``hip``, ``half_hip``, ``mansard``, ``L``, ``T``, ``U``
(gables meeting in valleys), ``dormer`` (gable with two dormers), ``stepped``
(a low flat part beside a higher gable), ``parapet`` (flat roof with a raised
rim). Sizes, slopes and the orientation are drawn from ``rng``; the noise is
3-5 cm (Gaussian) and the points lie on a jittered grid of the given density.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ROOF_KINDS", "RoofSample", "roof_parts", "roof_faces", "roof_sample"]

ROOF_KINDS = ("gable", "hip", "half_hip", "mansard", "L", "T", "U", "dormer", "stepped", "parapet")


@dataclass(frozen=True, eq=False)
class RoofSample:
    """A sampled synthetic roof: footprint, points (N, 3), floor height, exact faces and wireframe."""

    kind: str
    footprint: object
    xyz: np.ndarray
    ground_z: float
    faces: list
    face_planes: np.ndarray
    wireframe: object


def _rect(u0, u1, v0, v1):
    from shapely.geometry import Polygon

    return Polygon([(u0, v0), (u1, v0), (u1, v1), (u0, v1)])


def _ramp(axis, edge, z0, slope):
    """Plane rising from height z0 at the line ``axis-coordinate == edge`` inwards with ``slope``
    (tan); ``axis`` 0 = u, 1 = v; inwards is towards -sign(edge)."""
    s = -np.sign(edge) * slope
    a, b = (s, 0.0) if axis == 0 else (0.0, s)
    return np.array([a, b, z0 - s * edge])


def _gable(u0, u1, v0, v1, eave, slope, along=0):
    """Gable over a rectangle with its ridge along u (along=0) or v (along=1)."""
    if along == 0:
        c = (v0 + v1) / 2
        planes = [_ramp(1, v0 - c, eave, slope), _ramp(1, v1 - c, eave, slope)]
        planes = [p + np.array([0, 0, -p[1] * c]) for p in planes]
    else:
        c = (u0 + u1) / 2
        planes = [_ramp(0, u0 - c, eave, slope), _ramp(0, u1 - c, eave, slope)]
        planes = [p + np.array([0, 0, -p[0] * c]) for p in planes]
    return _rect(u0, u1, v0, v1), np.array(planes)


def _hip(u0, u1, v0, v1, eave, slope, end_eave=None, end_slope=None):
    _, side = _gable(u0, u1, v0, v1, eave, slope)
    c = (u0 + u1) / 2
    ez = eave if end_eave is None else end_eave
    es = slope if end_slope is None else end_slope
    ends = [_ramp(0, u0 - c, ez, es), _ramp(0, u1 - c, ez, es)]
    ends = [p + np.array([0, 0, -p[0] * c]) for p in ends]
    return _rect(u0, u1, v0, v1), np.vstack([side, ends])


def _flat(poly, z):
    return poly, np.array([[0.0, 0.0, z]])


def roof_parts(kind, rng):
    """Parts ``[(polygon, planes (P, 3)), ...]`` of one roof kind, in its own frame (metres)."""
    L = rng.uniform(10, 16)
    W = rng.uniform(7, 10)
    eave = rng.uniform(5, 7)
    slope = np.tan(np.radians(rng.uniform(30, 45)))
    if kind == "gable":
        return [_gable(0, L, 0, W, eave, slope)]
    if kind == "hip":
        return [_hip(0, L, 0, W, eave, slope)]
    if kind == "half_hip":
        rise = slope * W / 2
        return [_hip(0, L, 0, W, eave, slope, end_eave=eave + rng.uniform(0.45, 0.6) * rise,
                     end_slope=np.tan(np.radians(rng.uniform(40, 55))))]
    if kind == "mansard":
        steep, shallow = np.tan(np.radians(rng.uniform(60, 70))), np.tan(np.radians(rng.uniform(15, 22)))
        inset = rng.uniform(1.2, 1.8)
        lo = _hip(0, L, 0, W, eave, steep)[1]
        hi = _hip(0, L, 0, W, eave + steep * inset - shallow * inset, shallow)[1]
        return [(_rect(0, L, 0, W), np.vstack([lo, hi]))]
    if kind in ("L", "T", "U"):
        w2 = rng.uniform(6, W)
        depth = rng.uniform(6, 9)
        main = _gable(0, L, 0, W, eave, slope)
        wings = {"L": [L - w2], "T": [(L - w2) / 2], "U": [0.0, L - w2]}[kind]
        parts = [main]
        for u in wings:
            parts.append(_gable(u, u + w2, W / 2, W + depth, eave, slope, along=1))
        return parts
    if kind == "dormer":
        main = _gable(0, L, 0, W, eave, slope)
        parts = [main]
        dw = rng.uniform(2.2, 3.0)
        ddepth = rng.uniform(2.0, 2.8)
        d_eave = eave + slope * rng.uniform(0.6, 0.9) * ddepth
        for u in (L * 0.28, L * 0.72):
            parts.append(_gable(u - dw / 2, u + dw / 2, 0, ddepth, d_eave, np.tan(np.radians(35)), along=1))
        return parts
    if kind == "stepped":
        low = rng.uniform(3, 4)
        L2 = rng.uniform(5, 8)
        return [_flat(_rect(L, L + L2, 0, W * rng.uniform(0.7, 1.0)), low), _gable(0, L, 0, W, eave, slope)]
    if kind == "parapet":
        z = rng.uniform(6, 12)
        rim = rng.uniform(0.4, 0.6)
        outer = _rect(0, L, 0, W)
        return [_flat(outer, z), _flat(outer.difference(outer.buffer(-rim, join_style="mitre")),
                                       z + rng.uniform(0.5, 0.9))]
    raise ValueError(f"kind: must be one of {ROOF_KINDS}, got {kind!r}")


def _envelope(parts, xy):
    """Roof height (N,) and winning (part, plane) of each point: max over parts of min over planes."""
    import shapely

    n = len(xy)
    best = np.full(n, -np.inf)
    who = np.full((n, 2), -1, dtype=np.int64)
    for pi, (poly, planes) in enumerate(parts):
        inside = shapely.dwithin(poly, shapely.points(xy), 1e-9)
        z = xy[:, 0:1] * planes[:, 0] + xy[:, 1:2] * planes[:, 1] + planes[:, 2]
        k = z.argmin(axis=1)
        zmin = z[np.arange(n), k]
        win = inside & (zmin > best + 1e-9)
        best[win] = zmin[win]
        who[win] = np.column_stack([np.full(win.sum(), pi), k[win]])
    return best, who


def roof_faces(parts):
    """Exact roof faces of parts: ``(footprint, faces, planes (F, 3))``."""
    import shapely

    from .roof.arrangement import arrangement_cells, dissolve_cells

    footprint = shapely.set_precision(shapely.union_all([p for p, _ in parts], grid_size=1e-6), 0)
    planes = np.vstack([pl for _, pl in parts])
    x0, y0, x1, y1 = footprint.bounds
    big = 2 * np.hypot(x1 - x0, y1 - y0)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    lines = [np.asarray(r.coords) for p, _ in parts for r in shapely.get_rings(p)]
    for i in range(len(planes)):
        for j in range(i + 1, len(planes)):
            g = planes[i, :2] - planes[j, :2]
            n = np.hypot(*g)
            if n < 1e-9:
                continue
            g = g / n
            c = (planes[i, 2] - planes[j, 2]) / n
            foot = np.array([cx, cy]) - (g @ (cx, cy) + c) * g
            u = np.array([-g[1], g[0]])
            lines.append(np.vstack([foot - big * u, foot + big * u]))
    cells = arrangement_cells(footprint, lines)
    reps = np.array([c.representative_point().coords[0] for c in cells])
    _, who = _envelope(parts, reps)
    offsets = np.cumsum([0] + [len(pl) for _, pl in parts])
    idx = offsets[who[:, 0]] + who[:, 1]
    # the same plane in two parts is one label
    uniq, lab = np.unique(np.round(planes[idx], 9), axis=0, return_inverse=True)
    faces, face_labels = dissolve_cells(cells, lab.ravel())
    return footprint, faces, uniq[face_labels]


def roof_sample(kind, *, density=8.0, seed=0, noise=(0.03, 0.05)) -> RoofSample:
    """One noisy roof-only cloud of a roof kind, rotated and placed at random, with its truth.

    Parameters
    ----------
    kind : str
        One of :data:`ROOF_KINDS`.
    density : float
        Points per m2.
    seed : int
        Seeds everything (shape, orientation, sampling, noise).
    noise : (float, float)
        The Gaussian noise sigma (m) is drawn from this range.

    Returns
    -------
    RoofSample
        In local metres, floor at 0.
    """
    import shapely
    from shapely import affinity

    from .metrics.wireframe import faces_wireframe

    if density <= 0:
        raise ValueError(f"density: must be > 0, got {density}")
    rng = np.random.default_rng(seed)
    parts = roof_parts(kind, rng)
    theta = rng.uniform(0, 180)
    cx, cy = rng.uniform(-50, 50, 2)

    def move(g):
        # on a micrometre grid, so parts sharing an edge still share it exactly
        snapped = shapely.set_precision(affinity.translate(affinity.rotate(g, theta, origin=(0, 0)), cx, cy), 1e-6)
        return shapely.set_precision(snapped, 0)  # the coordinates stay, the fixed precision goes

    # planes in the moved frame: z(R^-1 (p - t)) with R the rotation by theta
    t = np.radians(theta)
    R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    moved = []
    for poly, planes in parts:
        ab = planes[:, :2] @ R.T  # gradient rotates with the frame
        c = planes[:, 2] - ab @ np.array([cx, cy])
        moved.append((move(poly), np.column_stack([ab, c])))
    footprint, faces, face_planes = roof_faces(moved)
    step = 1 / np.sqrt(density)
    x0, y0, x1, y1 = footprint.bounds
    gx, gy = np.meshgrid(np.arange(x0, x1, step), np.arange(y0, y1, step))
    xy = np.column_stack([gx.ravel(), gy.ravel()]) + rng.uniform(0, step, (gx.size, 2))
    xy = xy[shapely.contains_xy(footprint, xy[:, 0], xy[:, 1])]
    z, _ = _envelope(moved, xy)
    z = z + rng.normal(0, rng.uniform(*noise), len(z))
    lifted = [[np.column_stack([r, r @ pl[:2] + pl[2]]) for r in
               (np.asarray(ring.coords)[:-1] for ring in shapely.get_rings(f))]
              for f, pl in zip(faces, face_planes, strict=True)]
    return RoofSample(kind, footprint, np.column_stack([xy, z]), 0.0, faces, face_planes,
                      faces_wireframe(lifted))
