"""Does a LoD2.2 roof fit its points better than the LoD1.2 prism's flat roof?

The batch must give each building its better-founded model. A LoD2.2 roof
whose points lie farther from it than from the LoD1.2 prism's flat roof (a
roof fitted to a handful of points, a plane taken from facade or canopy
points) is not: the prism then stands in for it, with the reason.

The measure is vertical: each building point against the highest roof surface
over it, summarised by the median absolute distance. The 3-D point-to-surface
distance would rank a narrow prism too well (a point inside a 2.7 m wide prism
is never more than 1.35 m from a wall, however far below its roof), and the
median leaves out chimneys, canopy over the roof and facade points.
"""

from __future__ import annotations

import numpy as np

__all__ = ["rises_above_points", "roof_residuals", "worse_than_prism"]


def roof_residuals(solids, xyz) -> np.ndarray:
    """Height of each point above the highest roof surface over it (m).

    Parameters
    ----------
    solids : Solid or list of Solid
        Local metric coordinates; their ``RoofSurface`` faces are used.
    xyz : ndarray, shape (N, 3)
        Points in the same frame.

    Returns
    -------
    ndarray, shape (N,)
        ``z - z_roof``; NaN where no roof surface lies over the point.

    Examples
    --------
    >>> from shapely.geometry import box
    >>> from lidar2city.lod.prism import prism_solid
    >>> s = prism_solid(box(0, 0, 10, 10), 0.0, 5.0)
    >>> roof_residuals(s, np.array([[5.0, 5.0, 5.5], [20.0, 5.0, 1.0]])).round(2).tolist()
    [0.5, nan]
    """
    import shapely

    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    x, y = xyz[:, 0], xyz[:, 1]
    top = np.full(len(xyz), -np.inf)
    for s in solids if isinstance(solids, (list, tuple)) else [solids]:
        for f in s.surfaces:
            if f.semantic != "RoofSurface":
                continue
            ring = s.vertices[f.rings[0]]
            (x0, y0), (x1, y1) = ring[:, :2].min(axis=0), ring[:, :2].max(axis=0)
            cand = np.flatnonzero((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1))
            if not len(cand):
                continue
            poly = shapely.Polygon(ring[:, :2], [s.vertices[h][:, :2] for h in f.rings[1:]])
            inside = cand[shapely.contains_xy(poly, x[cand], y[cand])]
            # the face's plane through its (coplanar) vertices: Newell's normal
            c = ring.sum(axis=0) / len(ring)
            d = ring - c
            e = d[np.arange(1, len(d) + 1) % len(d)]
            n = (((d[:, [1, 2, 0]] - e[:, [1, 2, 0]]) * (d[:, [2, 0, 1]] + e[:, [2, 0, 1]]))
                 .sum(axis=0))
            if abs(n[2]) <= 1e-9 * np.abs(n).sum():
                continue  # a vertical face (or a degenerate one) has no height over a point
            z = c[2] - ((x[inside] - c[0]) * n[0] + (y[inside] - c[1]) * n[1]) / n[2]
            top[inside] = np.maximum(top[inside], z)
    out = xyz[:, 2] - top
    out[~np.isfinite(top)] = np.nan
    return out


def worse_than_prism(lod22, lod12, xyz, *, margin: float, sample: int = 400) -> str:
    """Why the LoD2.2 ``lod22`` fits the points ``xyz`` worse than the prism ``lod12``,
    or ``""`` when it does not.

    Worse means: the median absolute vertical distance of the points under both
    roofs to the LoD2.2 roof exceeds that to the prism's by more than ``margin`` (m).
    The medians are taken over at most ``sample`` points (every k-th: the same
    points on every run), plenty for a decision with a margin of decimetres.
    """
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if len(xyz) > sample:
        xyz = xyz[::-(-len(xyz) // sample)]
    r22 = roof_residuals(lod22, xyz)
    # the prism's roof is flat, over the same footprint: its height is enough
    z12 = max(float(s.vertices[np.concatenate([f.rings[0] for f in s.surfaces
                                                  if f.semantic == "RoofSurface"]), 2].max())
              for s in (lod12 if isinstance(lod12, (list, tuple)) else [lod12]))
    r12 = xyz[:, 2] - z12
    both = np.isfinite(r22)
    if both.sum() < 3:
        return ""
    m22, m12 = float(np.median(np.abs(r22[both]))), float(np.median(np.abs(r12[both])))
    if m22 <= m12 + margin:
        return ""
    return (f"the LoD2.2 roof fits its points worse (median vertical distance {m22:.2f} m "
            f"against the prism's {m12:.2f} m)")


def rises_above_points(lod22, xyz, *, tolerance: float) -> str:
    """Why the LoD2.2 ``lod22`` rises above every one of its points ``xyz``, or ``""``.

    A roof corner more than ``tolerance`` (m) above the highest point is a spike
    no point supports (the median of :func:`worse_than_prism` never sees one
    small face); the roof's faces are levelled where their points say so
    (:func:`lidar2city.roof.building.reconstruct_lod22`), so this is the last guard.

    Examples
    --------
    >>> from shapely.geometry import box
    >>> from lidar2city.lod.prism import prism_solid
    >>> s = prism_solid(box(0, 0, 10, 10), 0.0, 9.0)
    >>> rises_above_points(s, np.array([[5.0, 5.0, 5.0]]), tolerance=1.0)
    'the LoD2.2 roof rises 4.00 m above its highest point'
    """
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if not len(xyz):
        return ""
    top = max(float(s.vertices[:, 2].max()) for s in (lod22 if isinstance(lod22, (list, tuple)) else [lod22]))
    rise = top - float(xyz[:, 2].max())
    if rise <= tolerance:
        return ""
    return f"the LoD2.2 roof rises {rise:.2f} m above its highest point"
