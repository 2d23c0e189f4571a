"""Roof facet segmentation: region growing with plane fitting (z = a x + b y + c).

References
----------
Main seed framework, step 2, eq. 1 (planar roof facets z = ax + by + c).
Rabbani, T., van den Heuvel, F., Vosselman, G. (2006). Segmentation of point
clouds using smoothness constraint. IAPRS 36(5).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from .._stats import median
from ..errors import InputError

logger = logging.getLogger(__name__)

__all__ = ["Plane", "fit_plane", "local_normals", "segment_planes"]


class Plane:
    """A roof plane ``z = a x + b y + c`` fitted by least squares.

    Use :meth:`from_points`; it returns a falsy :class:`Plane` with ``reason``
    set when the points cannot define a plane.
    """

    __slots__ = ("a", "b", "c", "rms", "n", "reason")

    def __init__(self, a=0.0, b=0.0, c=0.0, rms=np.inf, n=0, reason=""):
        self.a, self.b, self.c, self.rms, self.n, self.reason = a, b, c, rms, n, reason

    def __bool__(self):
        return not self.reason

    def __repr__(self):
        return f"Plane(a={self.a:.4f}, b={self.b:.4f}, c={self.c:.3f}, rms={self.rms:.3f}, n={self.n})"

    @classmethod
    def from_points(cls, xyz):
        """Least-squares plane of points (N, 3); falsy with a reason for < 3 or collinear points."""
        xyz = np.asarray(xyz, dtype=np.float64)
        if len(xyz) < 3:
            return cls(reason=f"too few points ({len(xyz)} < 3)")
        p = fit_plane(xyz)
        if p is None:
            return cls(reason="points are collinear")
        a, b, c = p
        r = xyz[:, 2] - (a * xyz[:, 0] + b * xyz[:, 1] + c)
        return cls(a, b, c, float(np.sqrt(np.mean(r * r))), len(xyz))

    @property
    def params(self) -> np.ndarray:
        return np.array([self.a, self.b, self.c])

    def z(self, xy) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        return self.a * xy[..., 0] + self.b * xy[..., 1] + self.c

    def residuals(self, xyz) -> np.ndarray:
        """Perpendicular (3-D) distances of points (N, 3) to the plane."""
        xyz = np.asarray(xyz, dtype=np.float64)
        return (xyz[:, 2] - self.z(xyz[:, :2])) / np.sqrt(1 + self.a ** 2 + self.b ** 2)

    @property
    def slope_deg(self) -> float:
        return float(np.degrees(np.arctan(np.hypot(self.a, self.b))))

    @property
    def azimuth_deg(self) -> float:
        """Direction the facet faces (down-slope), degrees clockwise from north (+y)."""
        return float(np.degrees(np.arctan2(-self.a, -self.b)) % 360.0)


def fit_plane(xyz) -> np.ndarray | None:
    """Least-squares ``(a, b, c)`` of z = a x + b y + c, or None when degenerate."""
    xyz = np.asarray(xyz, dtype=np.float64)
    m = xyz.mean(axis=0)
    d = xyz - m
    sxx, sxy, syy = d[:, 0] @ d[:, 0], d[:, 0] @ d[:, 1], d[:, 1] @ d[:, 1]
    sxz, syz = d[:, 0] @ d[:, 2], d[:, 1] @ d[:, 2]
    det = sxx * syy - sxy ** 2
    if det <= 1e-12 * max(sxx * syy, 1e-300):
        return None
    a, b = _solve2(float(sxx), float(sxy), float(syy), float(sxz), float(syz))
    return np.array([a, b, m[2] - a * m[0] - b * m[1]])


def _solve2(a00, a01, a11, r0, r1):
    """``np.linalg.solve([[a00, a01], [a01, a11]], [r0, r1])`` of a well-conditioned
    symmetric 2 x 2 system, as LAPACK's LU with partial pivoting computes it (pivot row
    scaled by the reciprocal of the pivot, then the triangular solves): the same doubles
    without the ~10 us of its array set-up (fitted thousands of times per tile). Falls
    back to numpy for anything not finite."""
    p00, p01, p10, p11, q0, q1 = a00, a01, a01, a11, r0, r1
    if abs(p10) > abs(p00):  # the larger first column entry pivots (the first on ties)
        p00, p01, p10, p11, q0, q1 = p10, p11, p00, p01, q1, q0
    lower = p10 * (1.0 / p00)
    u11 = p11 - lower * p01
    x1 = (q1 - lower * q0) / u11
    x0 = (q0 - p01 * x1) / p00
    if u11 == 0.0 or not (math.isfinite(x0) and math.isfinite(x1)):
        x0, x1 = np.linalg.solve(np.array([[a00, a01], [a01, a11]]), np.array([r0, r1])).tolist()
    return x0, x1


def local_normals(xyz, neighbors) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (N, 3), z >= 0, and local RMS flatness (N,) from kNN index rows (N, k).

    The normal is the eigenvector of the smallest eigenvalue of each point's neighbourhood
    covariance and the flatness the root of that eigenvalue, both in closed form for all
    points at once (:func:`_smallest_eigenpairs`) rather than by LAPACK per 3 x 3 matrix.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    k = neighbors.shape[1]
    # the covariance's six entries, one coordinate at a time: (N, k) gathers and row sums
    cx, cy, cz = (xyz[:, i][neighbors] for i in range(3))
    for c in (cx, cy, cz):
        c -= c.mean(axis=1, keepdims=True)
    cov = [np.einsum("nk,nk->n", u, w) / k
           for u, w in ((cx, cx), (cx, cy), (cx, cz), (cy, cy), (cy, cz), (cz, cz))]
    lam, normals = _smallest_eigenpairs(*cov)
    normals *= np.where(normals[:, 2:3] < 0, -1.0, 1.0)
    return normals, np.sqrt(np.maximum(lam, 0.0))


def _smallest_eigenpairs(xx, xy, xz, yy, yz, zz):
    """Smallest eigenvalue (N,) and a unit eigenvector of it (N, 3) of symmetric 3 x 3 matrices
    given by their six entries (N,) each.

    The eigenvalue by the trigonometric solution of the characteristic cubic; the vector as
    the largest of the cross products of two rows of ``A - lambda I`` (each orthogonal to
    the null vector). Where the smallest eigenvalue is double (a line or a point: no
    defined normal) the vector is any one of its eigenvectors, ``(0, 0, 1)`` when the
    matrix is a multiple of the identity. Agrees with ``numpy.linalg.eigh`` to ~1e-6
    degrees and ~1e-11 m on roof neighbourhoods (``benchmarks/bench_facets.py``).

    References
    ----------
    Smith, O. K. (1961). Eigenvalues of a symmetric 3 x 3 matrix. Comm. ACM 4(4), 168.
    """
    q = (xx + yy + zz) / 3.0
    a, b, c = xx - q, yy - q, zz - q
    p = np.sqrt((a * a + b * b + c * c + 2.0 * (xy * xy + xz * xz + yz * yz)) / 6.0)
    ok = p > 0
    ps = np.where(ok, p, 1.0)
    det = a * (b * c - yz * yz) - xy * (xy * c - yz * xz) + xz * (xy * yz - b * xz)
    phi = np.arccos(np.clip(det / (2.0 * ps * ps * ps), -1.0, 1.0)) / 3.0
    lam = np.where(ok, q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0), q)
    a, b, c = xx - lam, yy - lam, zz - lam
    # rows (a, xy, xz), (xy, b, yz), (xz, yz, c): their three cross products
    v01 = np.stack([xy * yz - xz * b, xz * xy - a * yz, a * b - xy * xy], axis=1)
    v02 = np.stack([xy * c - xz * yz, xz * xz - a * c, a * yz - xy * xz], axis=1)
    v12 = np.stack([b * c - yz * yz, yz * xz - xy * c, xy * yz - b * xz], axis=1)
    n01, n02, n12 = ((v * v).sum(axis=1) for v in (v01, v02, v12))
    vec = np.where((n01 >= n02)[:, None], v01, v02)
    nv = np.maximum(n01, n02)
    vec = np.where((n12 > nv)[:, None], v12, vec)
    nv = np.sqrt(np.maximum(nv, n12))
    good = nv > 0
    vec /= np.where(good, nv, 1.0)[:, None]
    vec[~good] = (0.0, 0.0, 1.0)
    return lam, vec


def _grow(xyz, nbrs, normals, order, usable, dist_tol, cos_tol, min_points):
    """Region growing from the flattest seeds; ``(labels, number of regions)``.

    A plain Python loop (~0.1 s for Delft's 75 000 roof points, as fast as the
    former numba kernel with its per-call overhead) without numba's ~140 MB of
    import and JIT-cache memory. The arithmetic is the same IEEE double
    sequence, so the labels are identical.
    """
    n, k = nbrs.shape
    # memoryviews: Python numbers made on access, none held per point (a traced block of
    # row houses has ~1e5 points: lists of its neighbour indices would take ~50 MB)
    X, Y, Z, NX, NY, NZ = (memoryview(np.ascontiguousarray(a, dtype=np.float64))
                           for a in (xyz[:, 0], xyz[:, 1], xyz[:, 2],
                                     normals[:, 0], normals[:, 1], normals[:, 2]))
    NB = memoryview(np.ascontiguousarray(nbrs, dtype=np.int64).reshape(-1))
    # -1: free; -3: never grown (not usable), so one test serves both
    labels = np.where(np.asarray(usable, dtype=bool), -1, -3).tolist()
    next_label = 0
    sqrt = math.sqrt
    for s in order.tolist():
        if labels[s] != -1:
            continue
        # seed plane from the seed's normal through the seed point
        nz = NZ[s]
        if nz < 1e-3:
            continue
        a = -NX[s] / nz
        b = -NY[s] / nz
        c = Z[s] - a * X[s] - b * Y[s]
        norm = sqrt(a * a + b * b + 1.0)  # plane normal (-a, -b, 1) normalised
        lab = next_label
        labels[s] = lab
        queue = [s]
        head = 0
        count = 1
        sx, sy, sz = X[s], Y[s], Z[s]
        sxx = sx * sx
        sxy = sx * sy
        syy = sy * sy
        sxz = sx * sz
        syz = sy * sz
        refit_at = 8
        while head < len(queue):
            i = queue[head] * k
            head += 1
            for j in NB[i:i + k]:
                if labels[j] != -1:
                    continue
                x, y, z = X[j], Y[j], Z[j]
                if abs(z - (a * x + b * y + c)) / norm > dist_tol:
                    continue
                if (-a * NX[j] - b * NY[j] + NZ[j]) / norm < cos_tol:
                    continue
                labels[j] = lab
                queue.append(j)
                count += 1
                sx += x
                sy += y
                sz += z
                sxx += x * x
                sxy += x * y
                syy += y * y
                sxz += x * z
                syz += y * z
                if count >= refit_at:
                    refit_at = int(count * 1.5) + 1
                    mx, my, mz = sx / count, sy / count, sz / count
                    cxx = sxx / count - mx * mx
                    cxy = sxy / count - mx * my
                    cyy = syy / count - my * my
                    cxz = sxz / count - mx * mz
                    cyz = syz / count - my * mz
                    det = cxx * cyy - cxy * cxy
                    if det > 1e-9:
                        a = (cxz * cyy - cyz * cxy) / det
                        b = (cyz * cxx - cxz * cxy) / det
                        c = mz - a * mx - b * my
                        norm = sqrt(a * a + b * b + 1.0)
        if count < min_points:
            for m in queue:
                labels[m] = -2  # tried, too small: may join a neighbour later
        else:
            next_label += 1
    out = np.array(labels, dtype=np.int64)
    out[out < 0] = -1
    return out, next_label


def _group_planes(x, y, z, group, n_groups):
    """Least-squares planes z = a x + b y + c of the points of every group at once.

    ``x, y, z`` (N,) the points' coordinates, ``group`` (N,) each one's group
    0..n_groups-1. Returns ``(a, b, c, fitted)``, each (K,): the arithmetic of
    :func:`fit_plane` (means, then sums of centred products, the same degeneracy test)
    done for all groups by weighted bincounts, with the 2 x 2 normal equations solved by
    Cramer's rule; ``fitted`` is False (and the plane 0) where :func:`fit_plane` would
    give None (fewer than 2 distinct points, collinear points).
    """
    n = np.bincount(group, minlength=n_groups).astype(np.float64)
    ns = np.where(n > 0, n, 1.0)
    mx, my, mz = (np.bincount(group, weights=u, minlength=n_groups) / ns for u in (x, y, z))
    dx, dy, dz = x - mx[group], y - my[group], z - mz[group]
    sxx, sxy, syy, sxz, syz = (np.bincount(group, weights=u * w, minlength=n_groups)
                               for u, w in ((dx, dx), (dx, dy), (dy, dy), (dx, dz), (dy, dz)))
    det = sxx * syy - sxy * sxy
    fitted = (n > 0) & (det > 1e-12 * np.maximum(sxx * syy, 1e-300))
    safe = np.where(fitted, det, 1.0)
    a = np.where(fitted, (sxz * syy - syz * sxy) / safe, 0.0)
    b = np.where(fitted, (syz * sxx - sxz * sxy) / safe, 0.0)
    c = np.where(fitted, mz - a * mx - b * my, 0.0)
    return a, b, c, fitted


def _refit(xyz, labels, n_labels, trim, prev=None):
    """Trimmed least-squares plane of every facet, (K, 3).

    Per facet: the plane of its points; then, twice at most, the plane of those within
    ``trim`` of it (stopping when all are, or fewer than 3). A facet with no plane
    (collinear points) is level at its median height. All facets at once
    (:func:`_group_planes`), a fixed number of array passes whatever their number.

    ``prev``: optional ``(labels, planes)`` of an earlier segmentation of the same points;
    a facet with the very point set of one of those keeps its plane (the same arithmetic
    on the same points in the same order), and only the others are fitted; the same
    labels (``planes`` an earlier result of this function for them) give those planes.
    """
    if prev is not None and n_labels == len(prev[1]) and np.array_equal(labels, prev[0]):
        return prev[1].copy()  # no facet changed since (``prev`` as this function fitted it)
    planes = np.zeros((n_labels, 3))
    todo = labels >= 0
    if prev is not None:
        src = _same_facets(prev[0], labels, len(prev[1]), n_labels)
        if src is not None:
            kept = src >= 0
            planes[kept] = prev[1][src[kept]]
            todo &= ~kept[labels.clip(0)]
    on = np.flatnonzero(todo)
    if not len(on):
        return planes
    lab = labels[on]
    x, y, z = (np.ascontiguousarray(xyz[on, i]) for i in range(3))
    a, b, c, fitted = _group_planes(x, y, z, lab, n_labels)
    count = np.bincount(lab, minlength=n_labels)
    active = fitted.copy()
    for _ in range(2):
        if not active.any():
            break
        keep = np.abs(z - x * a[lab] - y * b[lab] - c[lab]) / np.sqrt(1 + a * a + b * b)[lab] <= trim
        kept = np.bincount(lab[keep], minlength=n_labels)
        active &= (kept < count) & (kept >= 3)
        if not active.any():
            break
        sel = np.flatnonzero(keep & active[lab])
        a2, b2, c2, ok = _group_planes(x[sel], y[sel], z[sel], lab[sel], n_labels)
        a, b, c = (np.where(active, new, old) for new, old in ((a2, a), (b2, b), (c2, c)))
        fitted[active & ~ok] = False
        active &= ok
    fit = count > 0
    planes[fit] = np.stack([a, b, c], axis=1)[fit]
    for k in np.flatnonzero(fit & ~fitted).tolist():
        planes[k] = (0.0, 0.0, float(np.median(z[lab == k])))
    return planes


#: Largest (old facets + 1) x (new facets + 1) table :func:`_same_facets` builds
_SAME_TABLE = 1 << 22


def _same_facets(old, new, n_old, n_new):
    """For every facet of labelling ``new`` (N,), the facet of ``old`` (N,) with exactly its
    points, or -1; None when the table of the two would be too large."""
    if (n_old + 1) * (n_new + 1) > _SAME_TABLE:
        return None
    table = np.bincount((old + 1) * (n_new + 1) + (new + 1),
                        minlength=(n_old + 1) * (n_new + 1)).reshape(n_old + 1, n_new + 1) > 0
    inner = table[1:, 1:]
    src = inner.argmax(axis=0)
    single = (table[:, 1:].sum(axis=0) == 1) & inner[src, np.arange(n_new)]
    whole = table[1:, :].sum(axis=1) == 1  # an old facet whose points all went to one place
    return np.where(single & whole[src], src, -1)


def _point_plane_dist(xyz, planes):
    """(N, K) perpendicular distances of points to planes."""
    num = xyz[:, 2:3] - xyz[:, 0:1] * planes[:, 0] - xyz[:, 1:2] * planes[:, 1] - planes[:, 2]
    return np.abs(num) / np.sqrt(1 + planes[:, 0] ** 2 + planes[:, 1] ** 2)


def _pair_dist(xyz, planes):
    """Perpendicular distances (N,) of points (N, 3) to planes (N, 3), pair by pair: the
    doubles of :func:`_point_plane_dist`'s matrix at those pairs."""
    num = xyz[:, 2] - xyz[:, 0] * planes[:, 0] - xyz[:, 1] * planes[:, 1] - planes[:, 2]
    return np.abs(num) / np.sqrt(1 + planes[:, 0] ** 2 + planes[:, 1] ** 2)


def _facet_moments(xyz, labels, n_labels):
    """Point moments ``(n, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)`` of every facet, (K, 10)."""
    on = labels >= 0
    lab = labels[on]
    x, y, z = xyz[on, 0], xyz[on, 1], xyz[on, 2]
    # one bincount per moment adds each facet's points in point order, as np.add.at does
    cols = [np.bincount(lab, minlength=n_labels).astype(np.float64)]
    cols += [np.bincount(lab, weights=w, minlength=n_labels)
             for w in (x, y, z, x * x, x * y, x * z, y * y, y * z, z * z)]
    return np.stack(cols, axis=1)


def _moment_fit(mom):
    """From moments (..., 10): ``(rms, det, cxx * cyy)``, the perpendicular RMS of the points
    about their least-squares plane z = a x + b y + c (inf where ``det`` <= 1e-12)."""
    n, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = np.moveaxis(mom, -1, 0)
    mx, my, mz = sx / n, sy / n, sz / n
    cxx, cxy, cxz = sxx / n - mx * mx, sxy / n - mx * my, sxz / n - mx * mz
    cyy, cyz, czz = syy / n - my * my, syz / n - my * mz, szz / n - mz * mz
    det = cxx * cyy - cxy * cxy
    safe = np.where(det > 1e-12, det, 1.0)
    a = (cxz * cyy - cyz * cxy) / safe
    b = (cyz * cxx - cxz * cxy) / safe
    var = czz - a * cxz - b * cyz
    rms = np.where(det > 1e-12, np.sqrt(np.maximum(var, 0.0) / (1 + a * a + b * b)), np.inf)
    return rms, det, cxx * cyy


def _union_rms(xyz, labels, n_labels, ii, jj, mom=None):
    """Vertical RMS of the least-squares plane through the points of facets ii[m] and jj[m]."""
    mom = _facet_moments(xyz, labels, n_labels) if mom is None else mom
    return _moment_fit(mom[ii] + mom[jj])[0]


#: Labelled points from which :func:`_merge` screens its candidate unions by their moments
_SCREEN_POINTS = 2000


def _merge(xyz, labels, planes, nbrs, dist_tol, cos_merge, coplanar=True):
    """Merge adjacent regions whose union still fits one plane (greedy, best pairs first)."""
    n_labels = len(planes)
    if n_labels < 2:
        return labels, n_labels
    # the neighbour edges whose ends differ (gathered as int32: half the bytes), then those
    # between two facets
    lab = labels.astype(np.int32) if n_labels < 2 ** 31 else labels
    lj = lab[nbrs]
    edge = np.flatnonzero(lj != lab[:, None])
    li, lj = lab[edge // nbrs.shape[1]], lj.ravel()[edge]
    m = (li >= 0) & (lj >= 0)
    # the distinct (low, high) label pairs in lexicographic order, as np.unique(axis=0)
    # gives them, from one integer key (several times faster than sorting rows)
    lo, hi = np.minimum(li[m], lj[m]), np.maximum(li[m], lj[m])
    base = max(n_labels, int(hi.max()) + 1 if len(hi) else 0)
    key = np.unique(lo.astype(np.int64) * base + hi)
    pairs = np.column_stack([key // base, key % base])
    normals = np.column_stack([-planes[:, 0], -planes[:, 1], np.ones(n_labels)])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    cos = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]) if len(pairs) else np.zeros(0)
    n_touch = len(pairs)
    # each facet's points, ascending (as a mask selects them)
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n_labels + 1))
    if coplanar:
        # facets apart from each other on one plane (the sides of a parapet rim, pieces of a
        # facet cut by clutter) are one facet too. A narrow strip's fitted orientation says
        # little, so such pairs are chosen by the fit of their union (from moments), tried
        # after the touching pairs, best fit first
        ii, jj = np.triu_indices(n_labels, 1)
        touching = np.zeros((n_labels, n_labels), dtype=bool)
        touching[pairs[:, 0], pairs[:, 1]] = True
        far = np.flatnonzero(~touching[ii, jj])
        mom = _facet_moments(xyz, labels, n_labels)
        rms = _union_rms(xyz, labels, n_labels, ii[far], jj[far], mom)
        fit = rms <= dist_tol / 2
        far, rms = far[fit], rms[fit]
        if len(far):  # else no coplanar candidate: nothing to measure
            # and one of the two planes (the better supported) carries the other's points: two
            # level strips at different heights fit one tilted plane, but neither carries the other;
            # a narrow strip's fitted tilt is poorly known, so level pieces at one height are one plane
            # each facet's points (ascending, as a mask selects them), median height and level
            # spread, once per facet rather than once per candidate pair
            facet: dict = {}

            def points_of(k):
                if k not in facet:
                    p = xyz[order[bounds[k]:bounds[k + 1]]]
                    zk = median(p[:, 2])
                    facet[k] = (p, zk, np.sqrt(np.mean((p[:, 2] - zk) ** 2)))
                return facet[k]

            fi, fj = ii[far], jj[far]
            half = dist_tol / 2
            zmed, spread = np.zeros(n_labels), np.zeros(n_labels)
            for k in np.unique(np.concatenate([fi, fj])).tolist():
                _, zmed[k], spread[k] = points_of(k)
            ok = (np.abs(zmed[fi] - zmed[fj]) <= half) & (spread[fi] <= half) & (spread[fj] <= half)
            # else the median distance of each facet's points to the other's plane, for both
            # facets of every such pair: per facet, one matrix against all its partners' planes
            rest = np.flatnonzero(~ok)
            own, other = np.concatenate([fi[rest], fj[rest]]), np.concatenate([fj[rest], fi[rest]])
            med = np.empty(len(own))
            for a in np.unique(own).tolist():
                sel = np.flatnonzero(own == a)
                pa = points_of(a)[0]
                step = max(1, _MEDIAN_CHUNK // max(len(pa), 1))
                for s0 in range(0, len(sel), step):
                    part = sel[s0:s0 + step]
                    med[part] = _column_medians(_point_plane_dist(pa, planes[other[part]]))
            # min() of the two medians as Python takes it (the first unless the second is less)
            mi, mj = med[:len(rest)], med[len(rest):]
            ok[rest] = np.where(mj < mi, mj, mi) <= half
            far, rms = far[ok], rms[ok]
            pairs = np.vstack([pairs, np.column_stack([ii[far], jj[far]])]).astype(np.int64)
            cos = np.concatenate([cos, cos_merge - 1.0 - rms])
    parent = list(range(n_labels))
    merged = False

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    # the points of each merged group (ascending), kept with its root
    group = {k: order[bounds[k]:bounds[k + 1]] for k in range(n_labels)}
    # large facets: a union whose moments put its RMS far over the limit fails the exact
    # test too (the moments' rounding is ~1e-10 of it where the plane is well posed), so
    # it is rejected without fitting its points; the merges are those of fitting every one
    screen = (bounds[n_labels] - bounds[0]) >= _SCREEN_POINTS
    if screen:
        gmom = dict(enumerate(mom if coplanar else _facet_moments(xyz, labels, n_labels)))
    # the candidates, best first: touching pairs close enough in orientation, coplanar ones
    cand = np.argsort(-cos, kind="stable")
    cand = cand[(cos[cand] >= cos_merge) | (cand >= n_touch)]
    for pa, pb in pairs[cand].tolist():
        a, b = find(pa), find(pb)
        if a == b:
            continue
        if screen:
            union = gmom[a] + gmom[b]
            est, det, scale = _moment_fit(union)
            if det > 1e-6 * scale and est > 1.5 * (dist_tol / 2):
                continue
        members = np.sort(np.concatenate([group[a], group[b]]))
        pts = xyz[members]
        p = fit_plane(pts)
        if p is None:
            continue
        r = _point_plane_dist(pts, p[None])[:, 0]
        if np.sqrt(np.mean(r * r)) <= dist_tol / 2 and _quantile_le(r, 0.95, dist_tol):
            parent[b] = a
            group[a] = members
            del group[b]
            merged = True
            if screen:
                gmom[a] = union
    if not merged:  # every facet its own root: the labels as they were
        return np.where(labels >= 0, labels, -1).astype(np.int64, copy=False), n_labels
    roots = np.array([find(x) for x in range(n_labels)])
    uniq, new = np.unique(roots, return_inverse=True)
    out = np.where(labels >= 0, new[labels.clip(0)], -1)
    return out, len(uniq)


def quantile_side(values, q, limit):
    """Whether ``np.quantile(values, q) <= limit`` (True / False) for a 1-D float64 array
    when one ``np.partition`` decides it, else None (ask numpy).

    numpy's linear quantile lies between the two order statistics it interpolates
    (up to a rounding): when both are clearly on one side of ``limit`` (by a relative
    1e-9) the answer is theirs; anything closer, NaN, an empty array or another dtype
    gives None. Taken per chain and per facet merge, where ``np.quantile``'s set-up
    costs more than its work.
    """
    a = values
    n = a.size if isinstance(a, np.ndarray) else 0
    if not n or a.dtype != np.float64 or a.ndim != 1:
        return None
    k = min(int(math.floor((n - 1) * q)), n - 1)
    part = np.partition(a, [k, n - 1] if k + 1 >= n else [k, k + 1, n - 1])
    if np.isnan(part[-1]):
        return None
    lo, hi = float(part[k]), float(part[min(k + 1, n - 1)])
    big, small = max(lo, hi), min(lo, hi)
    margin = 1e-9 * max(abs(limit), abs(big), abs(small))
    if big < limit - margin:
        return True
    if small > limit + margin:
        return False
    return None


def _quantile_le(values, q, limit) -> bool:
    """``np.quantile(values, q) <= limit``, by :func:`quantile_side` where it decides."""
    side = quantile_side(values, q, limit)
    return bool(np.quantile(values, q) <= limit) if side is None else side


#: point-plane distances per block of :func:`_column_medians` in the coplanar merge
_MEDIAN_CHUNK = 1 << 18


def _column_medians(d):
    """:func:`lidar2city._stats.median` of every column of ``d`` (n, m), the same values: one
    ``np.partition`` along the rows at the same positions (an order statistic does not
    depend on how it is selected), the middle one or ``(0 + a + b) / 2``; NaN for a column
    holding NaN."""
    n = d.shape[0]
    if n == 0:
        return np.array([median(c) for c in d.T])
    half = n // 2
    part = np.partition(d, [half - 1, half, n - 1] if n % 2 == 0 else [half, n - 1], axis=0)
    out = 0.0 + part[half] if n % 2 else (0.0 + part[half - 1] + part[half]) / 2
    return np.where(np.isnan(part[-1]), np.nan, out)


def _absorb_small(xyz, labels, planes, nbrs, dist_tol, small):
    """Dissolve small facets whose points mostly fit an adjacent facet's plane (ridge slivers)."""
    n_labels = len(planes)
    counts = np.bincount(labels[labels >= 0], minlength=n_labels)
    changed = False
    for lab in np.argsort(counts):
        if counts[lab] >= small or counts[lab] == 0:
            continue
        sel = np.flatnonzero(labels == lab)
        adj = np.unique(labels[nbrs[sel]])
        adj = adj[(adj >= 0) & (adj != lab) & (counts[adj] > counts[lab])]
        if not len(adj):
            continue
        d = _point_plane_dist(xyz[sel], planes[adj])
        best = d.argmin(axis=1)
        if np.mean(d[np.arange(len(sel)), best] <= dist_tol) >= 0.8:
            labels[sel] = np.where(d[np.arange(len(sel)), best] <= dist_tol, adj[best], -1)
            counts[adj] += np.bincount(best, minlength=len(adj))
            counts[lab] = 0
            changed = True
    if not changed:
        return labels, n_labels
    uniq = np.unique(labels[labels >= 0])
    remap = np.full(n_labels, -1)
    remap[uniq] = np.arange(len(uniq))
    return np.where(labels >= 0, remap[labels.clip(0)], -1), len(uniq)


def _leftover_facets(xyz, labels, planes, nbrs, usable, dist_tol, min_points):
    """Give connected clusters of unassigned roof points a facet of their own.

    Rough or curved patches (roof gardens, vaulted roofs, clutter) defeat region
    growing; left unassigned they would be covered by a neighbour's plane far
    from them. A cluster of half the smallest facet (6 points at least) gets its least-squares
    plane, or a horizontal one at its median height when no plane fits it.
    """
    from .._components import component_labels

    free = (labels < 0) & usable
    if free.sum() < max(min_points // 2, 6):
        return labels, planes
    idx = np.flatnonzero(free)
    pos = np.full(len(labels), -1)
    pos[idx] = np.arange(len(idx))
    rows = np.repeat(np.arange(len(idx)), nbrs.shape[1])
    cols = pos[nbrs[idx].ravel()]
    ok = cols >= 0
    # only link points at similar heights (no jumps across steps)
    dz = np.abs(xyz[idx[rows[ok]], 2] - xyz[idx[cols[ok]], 2])
    link = dz < 3 * dist_tol
    comp = component_labels(len(idx), rows[ok][link], cols[ok][link])
    n_comp = int(comp.max()) + 1
    sizes = np.bincount(comp, minlength=n_comp)
    planes = list(planes)
    labels = labels.copy()
    for c in np.flatnonzero(sizes >= max(min_points // 2, 6)):
        members = idx[comp == c]
        pts = xyz[members]
        p = fit_plane(pts)
        if p is not None:
            r = _point_plane_dist(pts, p[None])[:, 0]
            if np.sqrt(np.mean(r * r)) > 2 * dist_tol:
                p = None
        if p is None:
            p = np.array([0.0, 0.0, float(np.median(pts[:, 2]))])
        labels[members] = len(planes)
        planes.append(p)
    return labels, np.asarray(planes).reshape(-1, 3)


def segment_planes(xyz, *, k=10, dist_tol=0.2, angle_tol=20.0, min_points=None,
                   min_area=1.0, merge_angle=10.0, wall_slope=75.0):
    """Segment roof points into planar facets by region growing with plane fitting.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Building points of one building, local metres.
    k : int
        Neighbours per point for normals and growing.
    dist_tol : float
        Largest distance (m) of a point to its facet's plane; about 2-3 times the
        data's elevation noise.
    angle_tol : float
        Largest angle (degrees) between a point's normal and the facet's.
    min_points : int, optional
        Smallest facet; default from ``min_area`` and the point density.
    min_area : float
        Smallest facet area (m2) used to derive ``min_points``.
    merge_angle : float
        Adjacent facets closer than this in orientation are merged when their
        union still fits one plane within ``dist_tol``.
    wall_slope : float
        Points whose local normal is steeper than this (degrees) are walls, not roof.

    Returns
    -------
    labels : ndarray of int, shape (N,)
        Facet index 0..K-1, or -1 for points on no facet (walls, clutter).
    planes : ndarray, shape (K, 3)
        ``(a, b, c)`` of each facet's plane z = a x + b y + c.

    References
    ----------
    Main seed framework, eq. 1; Rabbani et al. (2006).
    """
    from scipy.spatial import cKDTree

    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError(f"xyz must have shape (N, 3), got {xyz.shape}")
    n = len(xyz)
    if n < 3:
        return np.full(n, -1), np.zeros((0, 3))
    k = int(min(k, n - 1))
    center = xyz.mean(axis=0)
    local = xyz - center
    # 3-D neighbours: 2-D ones mix stacked layers (a low roof under a high eave) and
    # tilt their normals to walls
    tree = cKDTree(local)
    _, nbrs = tree.query(local, k=k + 1)
    nbrs = np.asarray(nbrs, dtype=np.int64)
    normals, flat = local_normals(local, nbrs)
    if min_points is None:
        hull_area = max(_area_estimate(local[:, :2]), 1.0)
        density = n / hull_area
        min_points = max(int(round(min_area * density)), 6)
    usable = normals[:, 2] >= np.cos(np.radians(wall_slope))
    order = np.argsort(flat, kind="stable")
    labels, n_labels = _grow(local, nbrs[:, 1:], normals, order, usable,
                             dist_tol, np.cos(np.radians(angle_tol)), int(min_points))
    if n_labels == 0:
        return labels, np.zeros((0, 3))
    # after each step only the facets it changed are fitted again: ``fitted`` holds the
    # labels (a copy: some steps relabel in place) and planes of the last fit
    planes = _refit(local, labels, n_labels, dist_tol)
    fitted = (labels.copy(), planes)
    cos_merge = np.cos(np.radians(merge_angle))
    labels, n_labels = _merge(local, labels, planes, nbrs[:, 1:], dist_tol, cos_merge, coplanar=False)
    planes = _refit(local, labels, n_labels, dist_tol, fitted)
    fitted = (labels.copy(), planes)
    labels, n_labels = _absorb_small(local, labels, planes, nbrs[:, 1:], dist_tol, 3 * int(min_points))
    planes = _refit(local, labels, n_labels, dist_tol, fitted)
    fitted = (labels.copy(), planes)
    # small facets that no neighbour absorbs: those on one plane apart from each other join
    labels, n_labels = _merge(local, labels, planes, nbrs[:, 1:], dist_tol, cos_merge)
    planes = _refit(local, labels, n_labels, dist_tol, fitted)
    fitted = (labels.copy(), planes)
    # unassigned points join the nearest-fitting adjacent facet when close to its plane
    un = np.flatnonzero(labels < 0)
    if len(un) and n_labels:
        # each point against the facets among its neighbours' only: the nearest plane,
        # the lowest facet on ties
        nb_labels = labels[nbrs[un, 1:]]
        rows = np.repeat(np.arange(len(un)), nb_labels.shape[1])
        cols = nb_labels.ravel()
        ok = cols >= 0
        key = np.unique(rows[ok] * n_labels + cols[ok])
        rows, cols = key // n_labels, key % n_labels
        d = _pair_dist(local[un[rows]], planes[cols])
        first = np.lexsort((d, rows))
        first = first[np.r_[True, rows[first[1:]] != rows[first[:-1]]][:len(first)]]
        take = first[d[first] <= dist_tol]
        labels[un[rows[take]]] = cols[take]
        planes = _refit(local, labels, n_labels, dist_tol, fitted)
        fitted = (labels.copy(), planes)
    n_before = len(planes)
    labels, planes = _leftover_facets(local, labels, planes, nbrs[:, 1:], usable, dist_tol,
                                      int(min_points))
    if len(planes) > n_before:
        # leftover clusters on the plane of a facet (or of each other) join it; their own
        # planes (untrimmed) are not in ``fitted``: fitted like any changed facet
        labels, n_labels = _merge(local, labels, planes, nbrs[:, 1:], dist_tol, cos_merge)
        planes = _refit(local, labels, n_labels, dist_tol, fitted)
    # back to the caller's frame: z = a (x - cx) + b (y - cy) + c + cz
    out = planes.copy()
    out[:, 2] = planes[:, 2] + center[2] - planes[:, 0] * center[0] - planes[:, 1] * center[1]
    return labels, out


def _area_estimate(xy, cell=0.5):
    """Area (m2) of the ``cell`` grid cells holding points of ``xy`` (N, 2)."""
    ij = np.floor((xy - xy.min(axis=0)) / cell).astype(np.int64)
    key = ij[:, 0] * (ij[:, 1].max() + 1) + ij[:, 1]
    if len(key) and key.max() < 8 * len(key) + 1024:  # a small grid: count the filled cells
        return int(np.count_nonzero(np.bincount(key))) * cell * cell
    return len(np.unique(key)) * cell * cell
