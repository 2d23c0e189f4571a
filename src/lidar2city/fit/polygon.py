"""Regular outlines for raster building regions: polygon fitting with model selection.

Each building region (a boolean mask) is described by candidate polygons:

* non-regular polygons: a modified Douglas–Peucker ranking of the region's
  contour points (each point's cost and depth recorded), from which the
  cheapest vertex is removed one at a time, giving every polygon from the full
  contour down to a quadrilateral;
* regular shapes: a rectangle (initialised from the region's moments), a right
  trapezoid and a general trapezoid (initialised from the first four
  Douglas–Peucker corners), refined by shifting each edge (each half of an
  oblique side) by its mean signed distance to the region's boundary points,
  alternated with small rotations kept only when the overlap error drops;
* a composite shape (beyond the seed): a union of rectangles aligned with the
  building's main direction (L, T, U shapes and more).

The overlap error of a polygon is the area (in pixels) inside it but not in
the region plus the area in the region but not inside it — computed exactly on
the region's pixel polygon (the area-weighted version of the pixel count). The
candidate with the lowest ``error / region area + weight x complexity`` wins,
the complexity being the number of edges (non-regular and composite) or the
degrees of freedom 4 / 5 / 6 (rectangle / right trapezoid / trapezoid) plus
``oblique_leg`` per leg that is not square to the bases (an edge off the
building's two main axes), with a lower weight for regular shapes. The weight
of the regular shapes shrinks as ``sqrt(regular_cells / cells)`` on regions of
more than ``regular_cells`` cells: the error of a well-placed straight edge
through a pixel staircase grows with the perimeter (about a quarter of a cell
per cell of outline), so the error share a degree of freedom must remove falls
as one over the building's size in cells.
Courtyards (holes of the region) are fitted the same way and cut out of the
outline.

Coordinates inside are pixel corner coordinates (x = column, y = row, the pixel
(r, c) covering [c, c+1] x [r, r+1]); :func:`fit_building_outline` returns
metres.

References
----------
Gerke, M., Heipke, C., Straub, B.-M. (2001). Building extraction from aerial
imagery using a generic scene model and invariant geometric moments.
Douglas, D. H., Peucker, T. K. (1973). Algorithms for the reduction of the
number of points required to represent a digitized line or its caricature.
The Canadian Cartographer 10(2).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..config import field
from ..errors import EmptyInputError, FitError, InputError
from .lsm import segment_distances

logger = logging.getLogger(__name__)

__all__ = [
    "PolygonFitConfig",
    "SHAPE_TYPES",
    "region_contours",
    "region_polygon",
    "overlap_error",
    "douglas_peucker_ranking",
    "polygon_sequence",
    "fit_quadrilateral",
    "fit_composite",
    "select_outline",
    "fit_building_outline",
    "split_overlaps",
    "outer_edges",
    "give_overlaps",
    "inset_outer_edges",
]

#: shape type -> degrees of freedom used as its complexity (None: number of edges)
SHAPE_TYPES = {"rectangle": 4, "right_trapezoid": 5, "trapezoid": 6, "composite": None,
               "polygon": None}


@dataclass(frozen=True)
class PolygonFitConfig:
    """Options of :func:`fit_building_outline` (stage ``polygon_fit``)."""

    regular_weight: float = field(0.02, "complexity weight per degree of freedom (rectangle, "
                                         "trapezoids) and per edge (composite shapes)")
    polygon_weight: float = field(0.04, "complexity weight per edge of a non-regular polygon "
                                        "(higher than regular_weight: regular shapes are preferred)")
    shapes: tuple = field(("rectangle", "right_trapezoid", "trapezoid", "composite", "polygon"),
                          "candidate shape types")
    step: float = field(0.8, "fraction of the mean signed edge distance applied per iteration")
    max_iterations: int = field(30, "edge-shift iterations per rotation trial")
    max_rotation_deg: float = field(4.0, "first rotation step (degrees); halved down to "
                                         "min_rotation_deg")
    min_rotation_deg: float = field(0.25, "smallest rotation step (degrees)")
    max_polygon_vertices: int = field(60, "non-regular polygons with more vertices are not "
                                          "evaluated")
    oblique_leg: float = field(0.5, "extra complexity (degrees of freedom) charged per oblique "
                                    "leg of a trapezoid: a leg off the main axes must remove "
                                    "more overlap error than a degree of freedom to be kept "
                                    "(most buildings are right-angled; 0: the plain dof count)")
    min_courtyard_area: float = field(16.0, "holes of at least this area (m2) are kept as "
                                            "courtyards")
    regular_cells: float = field(40.0, "regular_weight applies as given to regions of up to "
                                       "this many cells and shrinks with the square root of "
                                       "the cell count beyond it: the overlap error of a "
                                       "straight edge through a pixel staircase grows with "
                                       "the perimeter in cells, not the area, so a large "
                                       "block affords the composite edges a small one does "
                                       "not (40 cells: 10 m2 at 0.5 m; 0: the same weight "
                                       "at every size)")
    overlap_aligned: float = field(0.9, "after the overlaps of outlines on one axis are split "
                                        "along it, an overlap of outlines on different axes "
                                        "goes whole to the outline whose region owns more of "
                                        "its pixels, when the other keeps at least this share "
                                        "of its outline within 3 degrees of its own axes (the "
                                        "cut follows the owner's edges); 0: always; above 1: "
                                        "never")
    overlap_notch: float = field(3.0, "an overlap refused by overlap_aligned still goes to the "
                                      "owner when the cut adds at most this much outline "
                                      "length (m) off the other outline's axes: a shed or "
                                      "annex on other axes that reaches into a house's "
                                      "outline loses that corner as a small notch instead "
                                      "of claiming the house's ground (the share rule alone "
                                      "refuses any notch in a small outline); 0: off")
    outline_inset: float = field(0.05, "after the fit, the outline's edges facing the background "
                                      "(not another region) are moved in by this distance (m), "
                                      "whatever their direction: the highest point per cell "
                                      "puts a roof's edge outside its walls, and a ring of "
                                      "pixels is a different distance on a 45-degree edge "
                                      "(0.71 cell) than on an axis (1 cell); 0: off")
    shared_margin: float = field(0.5, "when a region touches other regions (row houses split "
                                      "at a height step), their pixels within this distance "
                                      "(m, rounded to the nearest whole number of cells: one "
                                      "cell at 0.5 and 1 m, none at 2 m) count as its own in "
                                      "the fit: each side may place the shared wall up to a "
                                      "cell beyond the pixel staircase, so no gap opens "
                                      "between the two outlines (they may overlap by that "
                                      "much); 0: off")


# --------------------------------------------------------------------------- geometry


def region_contours(mask) -> list:
    """Sub-pixel contours of a region: the exterior first, then its holes.

    Marching squares at level 0.5 on the zero-padded mask; points lie on the
    pixel borders between inside and outside pixels.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)

    Returns
    -------
    list of ndarray, shape (n_i, 2)
        Closed rings (first point not repeated) in pixel corner coordinates
        (x, y); the exterior is the longest ring.
    """
    from skimage.measure import find_contours

    m = np.asarray(mask, dtype=bool)
    if not m.any():
        raise EmptyInputError("the region mask is empty")
    padded = np.pad(m, 1).astype(np.float64)
    rings = []
    for c in find_contours(padded, 0.5):
        xy = np.column_stack([c[:, 1], c[:, 0]]) - 0.5  # padded index -> corner coords
        if len(xy) > 1 and np.allclose(xy[0], xy[-1]):
            xy = xy[:-1]
        if len(xy) >= 3:
            rings.append(xy)
    rings.sort(key=lambda r: -abs(_signed_area(r)))
    return rings


def _signed_area(xy):
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def region_polygon(mask):
    """The exact pixel polygon of a region (shapely, pixel corner coordinates)."""
    import shapely
    from rasterio import features

    m = np.asarray(mask, dtype=np.uint8)
    polys = [shapely.geometry.shape(g) for g, v in features.shapes(m, mask=m.astype(bool)) if v]
    if not polys:
        raise EmptyInputError("the region mask is empty")
    return shapely.union_all(polys)


def overlap_error(polygons, region) -> np.ndarray:
    """Area inside each polygon but not in ``region`` plus area in ``region`` outside it.

    Parameters
    ----------
    polygons : shapely geometry or array of them
        Candidates (invalid ones are repaired first).
    region : shapely geometry
        The region's pixel polygon (:func:`region_polygon`).

    Returns
    -------
    ndarray of float
        Errors in pixels (square pixel units).
    """
    import shapely

    p = np.atleast_1d(np.asarray(polygons, dtype=object))
    bad = ~shapely.is_valid(p)
    if bad.any():
        p = p.copy()
        p[bad] = shapely.make_valid(p[bad])
    inter = shapely.area(shapely.intersection(p, region))
    return shapely.area(p) + region.area - 2.0 * inter


# ---------------------------------------------------------------------- Douglas–Peucker


def douglas_peucker_ranking(ring):
    """Cost and depth of every point of a closed ring under Douglas–Peucker splitting.

    The ring is split at its two mutually farthest points (cost infinity,
    depth 0); each piece is split recursively at its farthest point from the
    chord. A point's cost is its distance to the chord when selected, capped by
    its parent's cost so that a point is never cheaper to keep than the points
    whose chord it refines; its depth is the recursion level.

    Parameters
    ----------
    ring : ndarray, shape (n, 2)
        Closed ring, first point not repeated.

    Returns
    -------
    cost : ndarray, shape (n,)
    depth : ndarray of int, shape (n,)
    order : ndarray of int, shape (n,)
        Point indices from the most to the least important (the removal order
        reversed: cheapest cost first removed, ties removed deepest first).
    """
    pts = np.asarray(ring, dtype=np.float64)
    n = len(pts)
    if n < 3:
        raise InputError(f"a ring needs at least 3 points, got {n}")
    cost = np.zeros(n)
    depth = np.zeros(n, dtype=np.int64)
    c = pts.mean(axis=0)
    i0 = int(np.argmax(np.hypot(*(pts - c).T)))
    i1 = int(np.argmax(np.hypot(*(pts - pts[i0]).T)))
    if i1 == i0:
        i1 = (i0 + n // 2) % n
    cost[[i0, i1]] = np.inf
    stack = [(i0, i1, 1, np.inf), (i1, i0, 1, np.inf)]
    while stack:
        a, b, dep, cap = stack.pop()
        span = (b - a) % n
        if span < 2:
            continue
        idx = (a + np.arange(1, span)) % n
        d = segment_distances(pts[idx], pts[a][None], pts[b][None])[:, 0]
        k = int(np.argmax(d))
        j = int(idx[k])
        cost[j] = min(float(d[k]), cap)
        depth[j] = dep
        stack.append((a, j, dep + 1, cost[j]))
        stack.append((j, b, dep + 1, cost[j]))
    order = np.lexsort((depth, -cost))  # highest cost first; ties: shallow first
    return cost, depth, order


def polygon_sequence(ring, *, min_vertices=4, max_vertices=None):
    """Every polygon from the full ring down to ``min_vertices`` by cheapest-vertex removal.

    Returns
    -------
    coords : ndarray, shape (M, 2)
        Vertices of all polygons concatenated (ragged array).
    offsets : ndarray of int, shape (P + 1,)
        Polygon p is ``coords[offsets[p]:offsets[p+1]]``.
    counts : ndarray of int, shape (P,)
        Vertex count of each polygon (decreasing).
    """
    pts = np.asarray(ring, dtype=np.float64)
    n = len(pts)
    _, _, order = douglas_peucker_ranking(pts)
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(n)
    top = n if max_vertices is None else min(n, int(max_vertices))
    counts = np.arange(top, min(min_vertices, n) - 1, -1)
    if len(counts) == 0:
        counts = np.array([n])
    # for k vertices keep the points of rank < k, in ring order
    keep = rank[None, :] < counts[:, None]
    _, cols = np.nonzero(keep)
    coords = pts[cols]
    offsets = np.concatenate([[0], np.cumsum(counts)])
    return coords, offsets, counts


def _polygons_from_ragged(coords, offsets):
    import shapely

    closed_idx = []
    ring_offsets = [0]
    for a, b in zip(offsets[:-1], offsets[1:], strict=True):
        closed_idx.extend(range(a, b))
        closed_idx.append(a)
        ring_offsets.append(len(closed_idx))
    closed = coords[np.asarray(closed_idx)]
    ring_off = np.asarray(ring_offsets)
    poly_off = np.arange(len(offsets))
    return shapely.from_ragged_array(shapely.GeometryType.POLYGON, closed, (ring_off, poly_off))


# ------------------------------------------------------------------ regular quadrilaterals


def _frame(theta):
    e1 = np.array([np.cos(theta), np.sin(theta)])
    e2 = np.array([-np.sin(theta), np.cos(theta)])
    return e1, e2


@dataclass
class _Quad:
    """A quadrilateral with two sides parallel to e1 (v = v0, v = v1) in a rotated frame."""

    kind: str
    center: np.ndarray
    theta: float
    v0: float
    v1: float
    l0: float
    l1: float
    r0: float
    r1: float

    def vertices_uv(self):
        return np.array([[self.l0, self.v0], [self.r0, self.v0], [self.r1, self.v1],
                         [self.l1, self.v1]])

    def vertices(self):
        e1, e2 = _frame(self.theta)
        uv = self.vertices_uv()
        return self.center + uv[:, :1] * e1 + uv[:, 1:] * e2

    def polygon(self):
        import shapely

        return shapely.Polygon(self.vertices())

    def copy(self):
        return _Quad(self.kind, self.center.copy(), self.theta, self.v0, self.v1, self.l0,
                     self.l1, self.r0, self.r1)


def _to_uv(points, center, theta):
    e1, e2 = _frame(theta)
    d = points - center
    return np.column_stack([d @ e1, d @ e2])


_NEXT = np.array([1, 2, 3, 0])


def _segments_distance(p, verts):
    """Distances (n, k) of points p (n, 2) to the closed polygon's k edges."""
    return segment_distances(p, verts, np.roll(verts, -1, axis=0))


def _refine_edges(q, boundary, *, step, max_iterations, corner_margin=1.0, tol=0.01):
    """Shift edges by their mean signed distance to the boundary points (in place).

    Each boundary point belongs to its nearest edge (points within
    ``corner_margin`` of a corner are left out: marching squares cuts corners,
    which would pull edges inwards at acute angles). Bases and perpendicular
    legs move by ``step`` times the mean signed distance of their points; an
    oblique leg's two halves give the shifts of its two end vertices.
    """
    uv = _to_uv(boundary, q.center, q.theta)
    u, v = uv[:, 0], uv[:, 1]
    right_leg_free = q.kind != "rectangle"
    left_leg_free = q.kind == "trapezoid"
    for _ in range(max_iterations):
        verts = q.vertices_uv()
        edge = np.argmin(_segments_distance(uv, verts), axis=1)
        a = verts[edge]
        ab = verts[_NEXT][edge] - a
        seg_len = np.maximum(np.hypot(ab[:, 0], ab[:, 1]), 1e-12)
        along = ((uv - a) * ab).sum(axis=1) / seg_len
        ok = (along > corner_margin) & (along < seg_len - corner_margin)
        h = q.v1 - q.v0
        if h <= 1e-6 or ok.sum() < 4:
            break
        t = np.clip((v - q.v0) / h, 0.0, 1.0)
        left = q.l0 + (q.l1 - q.l0) * t
        right = q.r0 + (q.r1 - q.r0) * t
        res = np.choose(edge, [v - q.v0, u - right, v - q.v1, u - left])
        key = (edge * 2 + (t >= 0.5))[ok]
        cnt = np.bincount(key, minlength=8).astype(np.float64)
        s_res = np.bincount(key, res[ok], minlength=8)
        s_t = np.bincount(key, t[ok], minlength=8)
        tot_c = cnt[0::2] + cnt[1::2]
        tot_mean = np.where(tot_c >= 2, (s_res[0::2] + s_res[1::2]) / np.maximum(tot_c, 1), 0.0)
        shifts = {"v0": tot_mean[0], "v1": tot_mean[2]}
        for e, a0, a1, free in ((3, "l0", "l1", left_leg_free), (1, "r0", "r1", right_leg_free)):
            c_lo, c_hi = cnt[2 * e], cnt[2 * e + 1]
            if free and c_lo >= 1 and c_hi >= 1:
                # du(t) = d0 (1 - t) + d1 t must match both halves' means
                t_lo, t_hi = s_t[2 * e] / c_lo, s_t[2 * e + 1] / c_hi
                m_lo, m_hi = s_res[2 * e] / c_lo, s_res[2 * e + 1] / c_hi
                det = (1 - t_lo) * t_hi - t_lo * (1 - t_hi)
                if abs(det) > 1e-6:
                    shifts[a0] = (m_lo * t_hi - t_lo * m_hi) / det
                    shifts[a1] = ((1 - t_lo) * m_hi - (1 - t_hi) * m_lo) / det
                    continue
            shifts[a0] = shifts[a1] = tot_mean[e]
        for k, d in shifts.items():
            setattr(q, k, getattr(q, k) + step * d)
        if q.v0 > q.v1:
            q.v0, q.v1 = q.v1, q.v0
        if max(abs(d) for d in shifts.values()) < tol:
            break
    return q


class _RasterError:
    """Fast overlap error of a convex polygon, counted on supersampled pixel centres."""

    def __init__(self, mask, ss=3, pad=4):
        m = np.pad(np.asarray(mask, dtype=bool), pad)
        h, w = m.shape
        off = (np.arange(ss) + 0.5) / ss
        ys = (np.arange(h)[:, None] + off[None]).ravel() - pad
        xs = (np.arange(w)[:, None] + off[None]).ravel() - pad
        self.x, self.y = np.meshgrid(xs, ys)
        self.x, self.y = self.x.ravel(), self.y.ravel()
        self.label = np.repeat(np.repeat(m, ss, axis=0), ss, axis=1).ravel()
        self.area = 1.0 / ss**2

    def __call__(self, verts):
        v = np.asarray(verts, dtype=np.float64)
        if _signed_area(v) < 0:
            v = v[::-1]
        inside = np.ones(len(self.x), dtype=bool)
        for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
            inside &= (b[0] - a[0]) * (self.y - a[1]) - (b[1] - a[1]) * (self.x - a[0]) >= 0
        return float(np.count_nonzero(inside != self.label)) * self.area


def _rotate(q, delta):
    r = q.copy()
    r.theta = q.theta + delta
    return r


def _refine(q, boundary, raster_error, *, step, max_iterations, max_rotation_deg,
            min_rotation_deg):
    q = _refine_edges(q.copy(), boundary, step=step, max_iterations=max_iterations)
    err = raster_error(q.vertices())
    delta = np.deg2rad(max_rotation_deg)
    while delta >= np.deg2rad(min_rotation_deg) - 1e-12:
        improved = False
        for sign in (1.0, -1.0):
            # rotate about the shape's own centre
            c = q.vertices().mean(axis=0)
            cand = q.copy()
            shift = _to_uv(c[None], q.center, q.theta)[0]
            cand.center = c
            cand.v0 -= shift[1]
            cand.v1 -= shift[1]
            for a in ("l0", "l1", "r0", "r1"):
                setattr(cand, a, getattr(cand, a) - shift[0])
            cand = _rotate(cand, sign * delta)
            cand = _refine_edges(cand, boundary, step=step, max_iterations=max_iterations)
            e = raster_error(cand.vertices())
            if e < err - 1e-9:
                q, err, improved = cand, e, True
                break
        if not improved:
            delta /= 2.0
    return q, err


def _moments_rectangle(mask):
    rows, cols = np.nonzero(mask)
    p = np.column_stack([cols, rows]).astype(np.float64) + 0.5
    c = p.mean(axis=0)
    cov = np.cov((p - c).T) if len(p) > 2 else np.eye(2) / 12.0
    cov = cov + np.eye(2) / 12.0 * (len(p) <= 2)
    w, vec = np.linalg.eigh(cov)
    theta = float(np.arctan2(vec[1, 1], vec[0, 1]))  # major axis
    lu = np.sqrt(12.0 * max(w[1], 1.0 / 12.0)) / 2.0
    lv = np.sqrt(12.0 * max(w[0], 1.0 / 12.0)) / 2.0
    return _Quad("rectangle", c, theta, -lv, lv, -lu, -lu, lu, lu)


def _quad_from_corners(corners, kind):
    """A trapezoid (``kind``) initialised from four polygon corners (pixel coordinates)."""
    q = np.asarray(corners, dtype=np.float64)
    if _signed_area(q) < 0:
        q = q[::-1]
    best = None
    for s in (0, 1):
        a0, a1, b0, b1 = q[s], q[s + 1], q[(s + 2) % 4], q[(s + 3) % 4]
        da, db = a1 - a0, b0 - b1  # both bases pointing the same way
        ang = abs(np.arctan2(da[0] * db[1] - da[1] * db[0], da @ db))
        if best is None or ang < best[0]:
            best = (ang, a0, a1, b1, b0, da, db)
    _, a0, a1, b1, b0, da, db = best
    la, lb = np.hypot(*da), np.hypot(*db)
    # length-weighted mean direction of the two bases
    vec = da / max(la, 1e-12) * la + db / max(lb, 1e-12) * lb
    theta = float(np.arctan2(vec[1], vec[0]))
    center = q.mean(axis=0)
    uv = _to_uv(np.array([a0, a1, b0, b1]), center, theta)
    v0, v1 = uv[:2, 1].mean(), uv[2:, 1].mean()
    # a0 -> a1 along +u at v0; b1 -> b0 along +u at v1
    l0, r0, l1, r1 = uv[0, 0], uv[1, 0], uv[3, 0], uv[2, 0]
    if v0 > v1:
        v0, v1 = v1, v0
        l0, r0, l1, r1 = l1, r1, l0, r0
    quad = _Quad(kind, center, theta, v0, v1, l0, l1, r0, r1)
    if kind == "right_trapezoid":
        # the leg closer to perpendicular becomes the right angle (stored as the left leg)
        if abs(r1 - r0) < abs(l1 - l0):
            # mirror the frame: u -> -u swaps legs
            quad = _Quad(kind, center, theta + np.pi, -v1, -v0, -r1, -r0, -l1, -l0)
        m = 0.5 * (quad.l0 + quad.l1)
        quad.l0 = quad.l1 = m
    elif kind == "rectangle":
        quad.l0 = quad.l1 = 0.5 * (l0 + l1)
        quad.r0 = quad.r1 = 0.5 * (r0 + r1)
    return quad


def fit_quadrilateral(kind, mask, *, boundary=None, region=None, corners=None, step=0.8,
                      max_iterations=30, max_rotation_deg=4.0, min_rotation_deg=0.25):
    """Fit a rectangle, right trapezoid or trapezoid to a region.

    Parameters
    ----------
    kind : {"rectangle", "right_trapezoid", "trapezoid"}
    mask : ndarray of bool, shape (H, W)
    boundary : ndarray, shape (n, 2), optional
        Boundary points (default: the exterior of :func:`region_contours`).
    region : shapely Polygon, optional
        The region's pixel polygon (default: :func:`region_polygon`).
    corners : ndarray, shape (4, 2), optional
        Initial corners (the first four Douglas–Peucker corners). Required for
        the trapezoids; the rectangle starts from the region's moments
        (centroid, orientation and axis lengths of the equivalent rectangle)
        and, when ``corners`` are given, from them too (the better one is kept).

    Returns
    -------
    vertices : ndarray, shape (4, 2)
        Counter-clockwise in the (x right, y down) pixel frame's maths sense.
    error : float
        Overlap error (pixels).

    Raises
    ------
    FitError
        Degenerate fit.
    """
    if kind not in ("rectangle", "right_trapezoid", "trapezoid"):
        raise InputError(f"kind must be rectangle, right_trapezoid or trapezoid, got {kind!r}")
    mask = np.asarray(mask, dtype=bool)
    if boundary is None:
        boundary = region_contours(mask)[0]
    if region is None:
        region = region_polygon(mask)
    inits = []
    if kind == "rectangle":
        inits.append(_moments_rectangle(mask))
    if corners is not None:
        inits.append(_quad_from_corners(corners, kind))
    if not inits:
        raise InputError(f"a {kind} needs initial corners")
    raster_error = _RasterError(mask)
    best = None
    for q0 in inits:
        q, err = _refine(q0, boundary, raster_error, step=step, max_iterations=max_iterations,
                         max_rotation_deg=max_rotation_deg, min_rotation_deg=min_rotation_deg)
        if best is None or err < best[1]:
            best = (q, err)
    q, _ = best
    verts = q.vertices()
    if not np.isfinite(verts).all():
        raise FitError(f"{kind} fit degenerated")
    poly = q.polygon()
    if poly.area <= 0 or not poly.is_valid:
        raise FitError(f"{kind} fit degenerated")
    return verts, float(overlap_error(poly, region)[0])


# ------------------------------------------------------------------------- composite


def _dominant_direction(ring, tolerance_deg=5.0):
    """Main direction (radians, modulo 90 degrees) of a polygon's edges, length-weighted."""
    d = np.roll(ring, -1, axis=0) - ring
    length = np.hypot(d[:, 0], d[:, 1])
    keep = length > 1e-9
    d, length = d[keep], length[keep]
    ang = np.mod(np.arctan2(d[:, 1], d[:, 0]), np.pi / 2)
    tol = np.deg2rad(tolerance_deg)
    diff = np.abs(ang[:, None] - ang[None, :])
    diff = np.minimum(diff, np.pi / 2 - diff)
    score = ((diff <= tol) * length[None, :]).sum(axis=1)
    ref = ang[int(np.argmax(score))]
    near = np.minimum(np.abs(ang - ref), np.pi / 2 - np.abs(ang - ref)) <= tol
    # circular mean on the 90-degree circle
    z = np.sum(length[near] * np.exp(4j * ang[near]))
    return float(np.mod(np.angle(z) / 4.0, np.pi / 2))


def _cluster(values, gap):
    v = np.sort(np.asarray(values, dtype=np.float64))
    groups = np.split(v, np.nonzero(np.diff(v) > gap)[0] + 1)
    return np.array([g.mean() for g in groups])


def _grid_union(ucuts, vcuts, inside, center, theta):
    import shapely

    boxes = []
    for i, j in zip(*np.nonzero(inside), strict=True):
        boxes.append(shapely.box(ucuts[i], vcuts[j], ucuts[i + 1], vcuts[j + 1]))
    if not boxes:
        return None
    u = shapely.union_all(boxes)
    if u.geom_type != "Polygon":
        parts = list(getattr(u, "geoms", [u]))
        u = max(parts, key=lambda g: g.area)
    u = shapely.Polygon(u.exterior)  # courtyards are fitted separately
    u = shapely.simplify(u, 1e-6)
    e1, e2 = _frame(theta)
    return shapely.transform(u, lambda c: center + c[:, :1] * e1 + c[:, 1:] * e2)


def fit_composite(mask, *, boundary=None, region=None, theta=None, tolerance=1.0,
                  iterations=10, step=0.8):
    """A union of rectangles aligned with the building's main direction.

    The cut lines of a grid aligned with ``theta`` are placed at the clustered
    corner coordinates of the Douglas–Peucker polygon at ``tolerance`` pixels;
    grid cells at least half covered by the region form the union, and each
    cut line is then shifted by the mean signed distance of the boundary points
    nearest to the union edges lying on it.

    Returns
    -------
    polygon : shapely Polygon or None
        In pixel coordinates; None when no cell is covered.
    error : float
        Overlap error (pixels).
    """
    import shapely

    mask = np.asarray(mask, dtype=bool)
    if boundary is None:
        boundary = region_contours(mask)[0]
    if region is None:
        region = region_polygon(mask)
    cost, _, _ = douglas_peucker_ranking(boundary)
    corners = boundary[cost >= tolerance]
    if len(corners) < 4:
        corners = boundary[np.argsort(-cost)[:4]]
    if theta is None:
        theta = _dominant_direction(corners)
    center = boundary.mean(axis=0)
    uvc = _to_uv(corners, center, theta)
    uvb = _to_uv(boundary, center, theta)
    ucuts = _cluster(np.concatenate([uvc[:, 0], [uvb[:, 0].min(), uvb[:, 0].max()]]), 1.5)
    vcuts = _cluster(np.concatenate([uvc[:, 1], [uvb[:, 1].min(), uvb[:, 1].max()]]), 1.5)
    if len(ucuts) < 2 or len(vcuts) < 2:
        return None, np.inf
    reg_uv = shapely.transform(region, lambda c: _to_uv(c, center, theta))
    cells = [shapely.box(ucuts[i], vcuts[j], ucuts[i + 1], vcuts[j + 1])
             for i in range(len(ucuts) - 1) for j in range(len(vcuts) - 1)]
    cells = np.asarray(cells, dtype=object)
    cover = shapely.area(shapely.intersection(cells, reg_uv)) / np.maximum(shapely.area(cells), 1e-12)
    inside = (cover >= 0.5).reshape(len(ucuts) - 1, len(vcuts) - 1)
    if not inside.any():
        return None, np.inf
    # refine the cut positions with the boundary points nearest to each cut's edges
    for _ in range(iterations):
        poly_uv = _grid_union(ucuts, vcuts, inside, np.zeros(2), 0.0)
        if poly_uv is None:
            return None, np.inf
        ring = np.asarray(poly_uv.exterior.coords)[:-1]
        segs = [(ring[i], ring[(i + 1) % len(ring)]) for i in range(len(ring))]
        nearest = np.argmin(_segments_distance(uvb, ring), axis=1)
        moved = 0.0
        new_u, new_v = ucuts.copy(), vcuts.copy()
        for k, (a, b) in enumerate(segs):
            sel = nearest == k
            if sel.sum() < 2:
                continue
            if abs(a[0] - b[0]) < 1e-9:  # vertical edge on a u cut
                i = int(np.argmin(np.abs(ucuts - a[0])))
                m = float(np.mean(uvb[sel, 0] - a[0]))
                new_u[i] += step * m
                moved = max(moved, abs(m))
            else:
                j = int(np.argmin(np.abs(vcuts - a[1])))
                m = float(np.mean(uvb[sel, 1] - a[1]))
                new_v[j] += step * m
                moved = max(moved, abs(m))
        if np.all(np.diff(new_u) > 0.5) and np.all(np.diff(new_v) > 0.5):
            ucuts, vcuts = new_u, new_v
        else:
            break
        if moved < 1e-3:
            break
    poly = _grid_union(ucuts, vcuts, inside, center, theta)
    if poly is None or not poly.is_valid or poly.area <= 0:
        return None, np.inf
    return poly, float(overlap_error(poly, region)[0])


# ------------------------------------------------------------------------- selection


def _n_edges(poly):
    import shapely

    return int(shapely.get_num_coordinates(poly)) - 1 - len(poly.interiors)


def select_outline(mask, *, regular_weight=0.02, polygon_weight=0.04,
                   shapes=("rectangle", "right_trapezoid", "trapezoid", "composite", "polygon"),
                   step=0.8, max_iterations=30, max_rotation_deg=4.0, min_rotation_deg=0.25,
                   max_polygon_vertices=60, oblique_leg=0.5):
    """Fit every candidate shape to a (hole-free) region and pick the cheapest.

    Cost = overlap error / region area + weight x complexity (see module doc);
    a right trapezoid's complexity is ``5 + oblique_leg``, a trapezoid's
    ``6 + 2 oblique_leg``.

    Returns
    -------
    polygon : shapely Polygon
        The winner, pixel coordinates.
    shape_type : str
    info : dict
        ``cost``, ``error`` (fraction of the region area), ``complexity`` and
        ``candidates`` (type -> (cost, error fraction, complexity)).
    """
    import shapely

    unknown = set(shapes) - set(SHAPE_TYPES)
    if unknown:
        raise InputError(f"unknown shape types {sorted(unknown)}; known: {', '.join(SHAPE_TYPES)}")
    if regular_weight < 0 or polygon_weight < 0 or oblique_leg < 0:
        raise InputError("complexity weights and oblique_leg must be >= 0")
    mask = np.asarray(mask, dtype=bool)
    rings = region_contours(mask)
    boundary = rings[0]
    region = region_polygon(mask)
    if region.geom_type != "Polygon":
        region = max(region.geoms, key=lambda g: g.area)
    area = region.area
    cands = {}

    coords, offsets, counts = polygon_sequence(boundary, max_vertices=max_polygon_vertices)
    polys = _polygons_from_ragged(coords, offsets)
    valid = shapely.is_valid(polys)
    err = overlap_error(polys, region)
    corners4 = coords[offsets[-2]:offsets[-1]] if counts[-1] == 4 else None
    if "polygon" in shapes and valid.any():
        c = np.where(valid, err / area + polygon_weight * counts, np.inf)
        k = int(np.argmin(c))
        cands["polygon"] = (float(c[k]), polys[k], float(err[k]), int(counts[k]))
    fit_kw = dict(boundary=boundary, region=region, step=step, max_iterations=max_iterations,
                  max_rotation_deg=max_rotation_deg, min_rotation_deg=min_rotation_deg)
    for kind in ("rectangle", "right_trapezoid", "trapezoid"):
        if kind not in shapes or (kind != "rectangle" and corners4 is None):
            continue
        try:
            verts, e = fit_quadrilateral(kind, mask, corners=corners4, **fit_kw)
        except FitError as exc:
            logger.debug("%s fit failed: %s", kind, exc)
            continue
        dof = SHAPE_TYPES[kind] + oblique_leg * (SHAPE_TYPES[kind] - SHAPE_TYPES["rectangle"])
        cands[kind] = (e / area + regular_weight * dof, shapely.Polygon(verts), e, dof)
    if "composite" in shapes:
        thetas = [None]
        if "rectangle" in cands:
            v = np.asarray(cands["rectangle"][1].exterior.coords)
            d = v[1] - v[0]
            thetas.append(float(np.mod(np.arctan2(d[1], d[0]), np.pi / 2)))
        best = None
        for th in thetas:
            poly, e = fit_composite(mask, boundary=boundary, region=region, theta=th, step=step)
            if poly is not None and (best is None or e < best[1]):
                best = (poly, e)
        if best is not None:
            n = _n_edges(best[0])
            if n > 4:  # a four-edge union is the rectangle candidate
                cands["composite"] = (best[1] / area + regular_weight * n, best[0], best[1], n)
    if not cands:
        raise FitError("no candidate shape could be fitted")
    kind = min(cands, key=lambda k: cands[k][0])
    cost, poly, e, cx = cands[kind]
    info = {
        "cost": cost, "error": e / area, "complexity": cx,
        "candidates": {k: (v[0], v[2] / area, v[3]) for k, v in cands.items()},
    }
    return poly, kind, info


def _size_weight(weight, regular_cells, cells):
    """``weight`` scaled by ``sqrt(regular_cells / cells)`` for regions of more cells."""
    if regular_cells <= 0 or cells <= regular_cells:
        return weight
    return weight * float(np.sqrt(regular_cells / cells))


def fit_building_outline(region_mask, *, cell, offset=(0.0, 0.0), config=None, **options):
    """Regular outline of one building region, in metres.

    Parameters
    ----------
    region_mask : ndarray of bool, shape (H, W)
        One connected building region (holes are courtyards).
    cell : float
        Pixel size (m).
    offset : (x, y)
        Coordinates (m) of the mask's top-left pixel corner; rows run
        southwards (y decreases), as in north-up rasters.
    config : PolygonFitConfig, optional
        Options; keyword ``options`` override single fields.

    Returns
    -------
    polygon : shapely Polygon
        Counter-clockwise exterior, clockwise courtyards, metres.
    shape_type : str
        ``rectangle``, ``right_trapezoid``, ``trapezoid``, ``composite`` or ``polygon``.
    info : dict
        ``cost``, ``error`` (overlap error / region area), ``complexity``,
        ``candidates`` and ``courtyards`` (number kept).

    Raises
    ------
    EmptyInputError
        Empty mask.
    FitError
        No shape could be fitted.

    Examples
    --------
    >>> m = np.zeros((20, 30), bool); m[5:15, 5:25] = True
    >>> poly, kind, info = fit_building_outline(m, cell=2.0)
    >>> kind, round(poly.area)
    ('rectangle', 800)
    """
    import dataclasses

    import shapely
    from scipy import ndimage
    from shapely.geometry.polygon import orient

    cfg = config or PolygonFitConfig()
    if options:
        cfg = dataclasses.replace(cfg, **options)
    if not float(cell) > 0:
        raise InputError(f"cell must be positive, got {cell}")
    mask = np.asarray(region_mask, dtype=bool)
    if mask.ndim != 2:
        raise InputError(f"region_mask must be 2-D, got shape {mask.shape}")
    if not mask.any():
        raise EmptyInputError("the region mask is empty")
    rows, cols = np.nonzero(mask)
    r0, c0 = rows.min(), cols.min()
    sub = mask[r0:rows.max() + 1, c0:cols.max() + 1]
    lab, n = ndimage.label(sub)
    if n > 1:  # keep the largest part
        sizes = np.bincount(lab.ravel())
        sizes[0] = 0
        sub = lab == int(np.argmax(sizes))
    filled = ndimage.binary_fill_holes(sub)
    if cfg.regular_cells < 0 or cfg.shared_margin < 0:
        raise InputError(f"regular_cells and shared_margin must be >= 0, got "
                         f"{cfg.regular_cells} and {cfg.shared_margin}")
    weight = _size_weight(cfg.regular_weight, cfg.regular_cells, float(filled.sum()))
    # an oblique leg is charged at the unscaled weight: it is a preference for the
    # building's axes, not a share of the pixel noise
    oblique = cfg.oblique_leg * (cfg.regular_weight / weight if weight > 0 else 1.0)
    kw = dict(regular_weight=weight, polygon_weight=cfg.polygon_weight,
              shapes=tuple(cfg.shapes), step=cfg.step, max_iterations=cfg.max_iterations,
              max_rotation_deg=cfg.max_rotation_deg, min_rotation_deg=cfg.min_rotation_deg,
              max_polygon_vertices=cfg.max_polygon_vertices, oblique_leg=oblique)
    poly, kind, info = select_outline(filled, **kw)
    holes = filled & ~sub
    hl, nh = ndimage.label(holes)
    kept = []
    min_px = cfg.min_courtyard_area / float(cell) ** 2
    for i in range(1, nh + 1):
        h = hl == i
        if h.sum() < min_px:
            continue
        try:
            hp, _, _ = select_outline(h, **kw)
        except (FitError, EmptyInputError):
            continue
        kept.append(hp)
    if kept:
        poly = poly.difference(shapely.union_all(kept))
        if poly.geom_type != "Polygon":
            parts = [g for g in getattr(poly, "geoms", []) if g.geom_type == "Polygon"]
            poly = max(parts, key=lambda g: g.area) if parts else poly
    info["courtyards"] = len(kept)
    x0, y0 = float(offset[0]), float(offset[1])
    cell = float(cell)

    def to_m(c):
        return np.column_stack([x0 + (c[:, 0] + c0) * cell, y0 - (c[:, 1] + r0) * cell])

    out = orient(shapely.transform(poly, to_m), sign=1.0)
    return out, kind, info


def _main_axis(polygon) -> float:
    """Direction (radians, modulo 90 degrees) holding the most exterior edge length within 3 deg."""
    c = np.asarray(polygon.exterior.coords)
    d = np.diff(c, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    keep = length > 1e-9
    d, length = d[keep], length[keep]
    ang = np.mod(np.arctan2(d[:, 1], d[:, 0]), np.pi / 2)
    diff = np.abs(ang[:, None] - ang[None, :])
    diff = np.minimum(diff, np.pi / 2 - diff)
    score = ((diff <= np.deg2rad(3.0)) * length[None, :]).sum(axis=1)
    return float(ang[int(np.argmax(score))])


def split_overlaps(polygons, *, tolerance_deg=3.0) -> list:
    """Outlines whose pairwise overlaps are split along their common axis.

    Two outlines fitted on either side of a shared wall (see
    ``PolygonFitConfig.shared_margin``) overlap by up to a cell. When their
    main axes agree within ``tolerance_deg``, the overlap is cut in two by a
    line through its centroid along the common axis nearest to the overlap's
    long side, and each outline keeps the half on its own side: both then end
    on one straight wall, still on their own axes. Overlaps of outlines on
    different axes are left as they are (a cut would leave an edge off one
    polygon's axes). Pairs are taken in index order; the union of the outlines
    does not change.

    Parameters
    ----------
    polygons : sequence of shapely Polygon
    tolerance_deg : float
        Largest difference (degrees, modulo 90) between the two main axes.

    Returns
    -------
    list of shapely Polygon
        Same length and order; an outline whose split would leave nothing (or
        only slivers) keeps its shape.

    Examples
    --------
    >>> import shapely
    >>> a, b = shapely.box(0, 0, 10.5, 8), shapely.box(10, 0, 20, 8)
    >>> [round(p.area, 2) for p in split_overlaps([a, b])]
    [82.0, 78.0]
    """
    import shapely

    polys = list(polygons)
    if len(polys) < 2:
        return polys
    tol = np.deg2rad(float(tolerance_deg))
    tree = shapely.STRtree(polys)
    left, right = tree.query(polys, predicate="intersects")
    pairs = sorted({(int(a), int(b)) for a, b in zip(left, right, strict=True) if a < b})
    big = 1e6
    for a, b in pairs:
        pa, pb = polys[a], polys[b]
        over = pa.intersection(pb)
        if over.area <= 1e-9:
            continue
        ta, tb = _main_axis(pa), _main_axis(pb)
        dd = abs(ta - tb)
        if min(dd, np.pi / 2 - dd) > tol:
            continue
        corners = np.asarray(over.minimum_rotated_rectangle.exterior.coords)[:4]
        e0, e1 = corners[1] - corners[0], corners[2] - corners[1]
        long_side = e0 if np.hypot(*e0) >= np.hypot(*e1) else e1
        t_long = np.arctan2(long_side[1], long_side[0])

        def off(t):
            x = np.mod(t - t_long, np.pi)
            return min(x, np.pi - x)

        theta = min((ta, ta + np.pi / 2), key=off)
        d = np.array([np.cos(theta), np.sin(theta)])
        n = np.array([-d[1], d[0]])
        ctr = np.asarray(over.centroid.coords[0])
        half = shapely.Polygon([ctr - big * d, ctr + big * d, ctr + big * d + big * n,
                                ctr - big * d + big * n])
        side_a, side_b = over.intersection(half), over.difference(half)
        ca, cb = np.asarray(pa.centroid.coords[0]), np.asarray(pb.centroid.coords[0])
        if np.dot(ca - cb, n) < 0:
            side_a, side_b = side_b, side_a
        new = []
        for p, lose in ((pa, side_b), (pb, side_a)):
            parts = [g for g in shapely.get_parts(p.difference(lose)) if g.area > 0]
            # on a millimetre grid: the cut leaves vertices a hair's breadth from an edge,
            # which a shift to world coordinates would turn into self-intersections
            g = shapely.set_precision(max(parts, key=lambda g: g.area), 1e-3) if parts else None
            new.append(g)
        if all(g is not None and g.is_valid and g.geom_type == "Polygon" and g.area > 0
               for g in new):
            polys[a], polys[b] = new
    return polys


def outer_edges(polygon, labels, label, *, cell, probe=0.75):
    """Which edges of an outline face the background rather than another region.

    Points along each edge (one per cell, at least three) are moved
    ``probe`` cells outwards and looked up in ``labels``; an edge is outer
    when fewer than half of them fall on another region's label.

    Parameters
    ----------
    polygon : shapely Polygon
        Local metres, the raster's top-left corner at (0, 0), y northwards;
        exterior counter-clockwise, holes clockwise (interior on the left).
    labels : ndarray of int, shape (H, W)
        Region labels, 0 background.
    label : int
        The outline's own label (counts as background).
    cell : float
        Pixel size (m).

    Returns
    -------
    list of ndarray of bool
        One array per ring (exterior first), one value per edge.
    """
    lab = np.asarray(labels)
    h, w = lab.shape
    out = []
    for ring in [polygon.exterior, *polygon.interiors]:
        xy = np.asarray(ring.coords)
        a, b = xy[:-1], xy[1:]
        d = b - a
        length = np.hypot(d[:, 0], d[:, 1])
        flags = np.zeros(len(a), dtype=bool)
        for k in range(len(a)):
            if length[k] <= 1e-9:
                continue
            t = d[k] / length[k]
            n = np.array([t[1], -t[0]])  # outward: the interior is on the left
            m = max(3, int(np.ceil(length[k] / cell)))
            u = (np.arange(m) + 0.5) / m
            pts = a[k] + u[:, None] * d[k] + probe * cell * n
            col = np.floor(pts[:, 0] / cell).astype(int)
            row = np.floor(-pts[:, 1] / cell).astype(int)
            inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
            other = np.zeros(m, dtype=bool)
            other[inside] = (lab[row[inside], col[inside]] > 0) & (
                lab[row[inside], col[inside]] != label)
            flags[k] = other.mean() < 0.5
        out.append(flags)
    return out


def _offset_ring(xy, shift):
    """Ring vertices with each edge k moved inwards (to its left) by ``shift[k]``.

    A vertex is the intersection of its two edges' moved lines; between
    (nearly) parallel edges it moves by their mean shift along the normals.
    """
    a = xy[:-1]
    d = np.roll(a, -1, axis=0) - a
    length = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
    t = d / length[:, None]
    inward = np.column_stack([-t[:, 1], t[:, 0]])
    p = a + shift[:, None] * inward  # a point on each moved edge line
    tp, pp, sp, ip = np.roll(t, 1, axis=0), np.roll(p, 1, axis=0), np.roll(shift, 1), \
        np.roll(inward, 1, axis=0)
    cross = tp[:, 0] * t[:, 1] - tp[:, 1] * t[:, 0]
    q = p - pp
    lam = (q[:, 0] * t[:, 1] - q[:, 1] * t[:, 0]) / np.where(np.abs(cross) > 0.1, cross, 1.0)
    out = pp + lam[:, None] * tp
    flat = np.abs(cross) <= 0.1
    out[flat] = a[flat] + 0.5 * (shift[flat, None] * inward[flat] + sp[flat, None] * ip[flat])
    return np.vstack([out, out[:1]])


def inset_outer_edges(polygon, outer, distance):
    """The outline with its ``outer`` edges moved in by ``distance`` metres.

    Every outer edge moves along its inward normal, the others stay; each
    vertex is where its two edges' moved lines cross (mitred), so square
    corners stay square and an edge shared with a neighbour keeps its line.

    Parameters
    ----------
    polygon : shapely Polygon
        Exterior counter-clockwise, holes clockwise (the interior on the left).
    outer : list of ndarray of bool
        Per ring, per edge (:func:`outer_edges`).
    distance : float
        Metres, >= 0.

    Returns
    -------
    shapely Polygon
        The inset outline; ``polygon`` itself when nothing is outer, or when
        the inset is not a valid polygon or keeps less than half the area.

    Examples
    --------
    >>> import shapely
    >>> sq = shapely.box(0, 0, 10, 4)
    >>> flags = [np.array([False, True, True, True])]  # edge 0, x = 10, is shared
    >>> inset_outer_edges(sq, flags, 0.5).bounds
    (0.5, 0.5, 10.0, 3.5)
    """
    import shapely

    if distance < 0:
        raise InputError(f"distance must be >= 0, got {distance}")
    if distance == 0 or not any(np.any(f) for f in outer):
        return polygon
    rings = []
    for ring, flags in zip([polygon.exterior, *polygon.interiors], outer, strict=True):
        xy = np.asarray(ring.coords)
        rings.append(_offset_ring(xy, np.where(flags, float(distance), 0.0)))
    g = shapely.Polygon(rings[0], rings[1:])
    if not g.is_valid or g.area < 0.5 * polygon.area:
        return polygon
    return g


def give_overlaps(polygons, labels, ids, *, cell, min_area=1e-6, min_aligned=0.9,
                  max_notch=0.0) -> list:
    """Outlines whose remaining pairwise overlaps go to the region that owns the pixels.

    Outlines fitted to touching regions may overlap where their axes differ
    (:func:`split_overlaps` only cuts those on one axis). Each overlap goes
    whole to the outline whose region holds more of the pixels whose centres
    lie within half a cell of it (ties: the lower index); the other outline
    loses it, so the outlines tile without overlapping and the union is
    unchanged. Pairs are taken in index order.

    Parameters
    ----------
    polygons : sequence of shapely Polygon
        Local metres, the raster's top-left corner at (0, 0), y northwards.
    labels : ndarray of int, shape (H, W)
        The regions the outlines were fitted to.
    ids : sequence of int
        Each outline's label.
    cell : float
        Pixel size (m).
    min_aligned : float
        The overlap is given only when the losing outline then keeps at least
        this share of its exterior length within 3 degrees of its own main
        axes (or no less than it had): the cut follows the winner's edges.
    max_notch : float
        An overlap refused by ``min_aligned`` is still given when the cut
        adds at most this length (m) of exterior off the loser's main axes
        (a small notch); 0: never.

    Returns
    -------
    list of shapely Polygon
        Same length and order; an outline that would be left with nothing or
        several pieces of similar size keeps its shape.

    Examples
    --------
    >>> import shapely
    >>> lab = np.zeros((8, 8), int); lab[:, :5] = 1; lab[:, 5:] = 2  # the wall at x = 2.5
    >>> a = shapely.box(0, -4, 2.5, 0)
    >>> b = shapely.Polygon([(2.0, -4), (4, -4), (4, 0), (2.2, 0)])  # reaches into region 1
    >>> [round(p.area, 2) for p in give_overlaps([a, b], lab, [1, 2], cell=0.5)]
    [10.0, 6.0]
    """
    import shapely

    polys = list(polygons)
    if len(polys) < 2:
        return polys
    lab = np.asarray(labels)
    h, w = lab.shape
    tree = shapely.STRtree(polys)
    left, right = tree.query(polys, predicate="intersects")
    pairs = sorted({(int(a), int(b)) for a, b in zip(left, right, strict=True) if a < b})
    for a, b in pairs:
        pa, pb = polys[a], polys[b]
        over = pa.intersection(pb)
        if over.area <= min_area:
            continue
        x0, y0, x1, y1 = over.buffer(0.5 * cell).bounds
        c0, c1 = max(int(np.floor(x0 / cell)), 0), min(int(np.ceil(x1 / cell)), w)
        r0, r1 = max(int(np.floor(-y1 / cell)), 0), min(int(np.ceil(-y0 / cell)), h)
        if c1 <= c0 or r1 <= r0:
            continue
        rr, cc = np.mgrid[r0:r1, c0:c1]
        near = shapely.dwithin(over, shapely.points((cc + 0.5) * cell, -(rr + 0.5) * cell),
                               0.5 * cell)
        vals = lab[r0:r1, c0:c1][near]
        na, nb = int((vals == ids[a]).sum()), int((vals == ids[b]).sum())
        loser = b if na >= nb else a
        g = polys[loser].difference(over)
        parts = sorted((p for p in shapely.get_parts(g) if p.area > 0), key=lambda p: -p.area)
        if not parts or (len(parts) > 1 and parts[1].area > 0.1 * parts[0].area):
            continue
        g = shapely.set_precision(parts[0], 1e-3)
        if not (g.is_valid and g.geom_type == "Polygon" and g.area > 0):
            continue
        # the cut follows the winner's edges: kept only while the loser's outline stays
        # mostly on its own axes
        if (_aligned_share(g) >= min(min_aligned, _aligned_share(polys[loser]))
                or _off_axis_length(g) - _off_axis_length(polys[loser]) <= max_notch):
            polys[loser] = g
    return polys


def _edge_offsets(polygon):
    """Exterior edge lengths and their angles (radians) off the polygon's main axes."""
    c = np.asarray(polygon.exterior.coords)
    d = np.diff(c, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    ang = np.mod(np.arctan2(d[:, 1], d[:, 0]) - _main_axis(polygon), np.pi / 2)
    return length, np.minimum(ang, np.pi / 2 - ang)


def _aligned_share(polygon, tolerance_deg=3.0) -> float:
    """Share of the exterior length within ``tolerance_deg`` of the polygon's main axes."""
    length, off = _edge_offsets(polygon)
    if length.sum() <= 0:
        return 0.0
    return float(length[off <= np.deg2rad(tolerance_deg)].sum() / length.sum())


def _off_axis_length(polygon, tolerance_deg=3.0) -> float:
    """Exterior length (m) more than ``tolerance_deg`` off the polygon's main axes."""
    length, off = _edge_offsets(polygon)
    return float(length[off > np.deg2rad(tolerance_deg)].sum())
