"""Least-squares model fitting to footprint outlines (LSMDF, plan parameters).

The footprint boundary is resampled at a fixed interval; each sample is an
observation whose residual is its signed distance to the model edge it lies
closest to. Samples farther than a buffer from every model edge (footprint
parts the model does not explain) are left out. The sum of squared distances
is minimised with Levenberg-Marquardt (``scipy.optimize.least_squares``),
re-assigning samples to edges between solves until the assignment is stable.
Standard deviations come from ``(J^T J)^-1`` scaled by the residual variance.

Two plan models are provided: a rectangle (centre x, y, azimuth, length,
width) for the box / gable / hip / shed primitives, and a polygon whose
vertex coordinates are the parameters (the polygonal prism).

References
----------
The observation equation (distance of a boundary sample to the nearest model
edge, eq. 1-2 of the floating-model seed) and the Gauss-Markov estimate of the
parameter covariance: Mikhail & Ackermann, *Observations and Least Squares*
(1976), ch. 4.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from ..errors import FitError, InputError

logger = logging.getLogger(__name__)

__all__ = [
    "PlanFit",
    "resample_rings",
    "polygon_rings",
    "rectangle_corners",
    "rectangle_approx",
    "segment_distances",
    "fit_rectangle",
    "fit_polygon",
    "OutlineObservations",
    "fit_rectilinear",
    "drop_observation",
    "outline_observations",
    "solve_least_squares",
    "parameter_covariance",
]


@dataclass(frozen=True, eq=False)
class PlanFit:
    """The outcome of a plan (footprint) fit.

    Attributes
    ----------
    params : ndarray, shape (P,)
        Estimated parameters.
    std : ndarray, shape (P,)
        Their standard deviations (``sqrt(diag((J^T J)^-1) * s0^2)``).
    residuals : ndarray, shape (M,)
        Signed distances of the samples used in the last solve (metres).
    used : ndarray of bool, shape (N,)
        Which boundary samples were inside the buffer in the last solve.
    iterations : int
        Function evaluations of all solves.
    outer : int
        Re-assignment rounds.
    sigma0 : float
        Residual standard deviation (a-posteriori sigma naught), metres.
    """

    params: np.ndarray
    std: np.ndarray
    residuals: np.ndarray
    used: np.ndarray
    iterations: int
    outer: int
    sigma0: float
    extra: dict = field(default_factory=dict)


def polygon_rings(polygon) -> list[np.ndarray]:
    """Exterior (counter-clockwise) then interior (clockwise) rings, open, (K, 2) each."""
    import shapely

    polygon = shapely.geometry.polygon.orient(polygon, 1.0)
    rings = [np.asarray(polygon.exterior.coords)[:-1, :2]]
    rings += [np.asarray(r.coords)[:-1, :2] for r in polygon.interiors]
    return rings


def resample_rings(rings, interval: float) -> np.ndarray:
    """Points every ``interval`` metres along closed rings, shape (N, 2).

    Each ring is walked from its first vertex; the samples are spaced evenly
    with the spacing closest to ``interval`` that divides the ring length.
    """
    if interval <= 0:
        raise InputError(f"interval must be > 0, got {interval}")
    out = []
    for ring in rings:
        ring = np.asarray(ring, dtype=np.float64)
        closed = np.vstack([ring, ring[:1]])
        seg = np.diff(closed, axis=0)
        seglen = np.hypot(seg[:, 0], seg[:, 1])
        cum = np.concatenate([[0.0], np.cumsum(seglen)])
        total = cum[-1]
        if total <= 0:
            continue
        n = max(int(round(total / interval)), len(ring) * 2, 8)
        s = (np.arange(n) + 0.5) * (total / n)
        k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
        t = (s - cum[k]) / np.where(seglen[k] > 0, seglen[k], 1.0)
        out.append(closed[k] + t[:, None] * seg[k])
    return np.vstack(out) if out else np.empty((0, 2))


def rectangle_corners(x, y, azimuth_deg, length, width) -> np.ndarray:
    """Plan corners of a rectangle, counter-clockwise from (-l/2, -w/2), shape (4, 2)."""
    a = np.radians(azimuth_deg)
    d = np.array([np.cos(a), np.sin(a)])
    n = np.array([-np.sin(a), np.cos(a)])
    uv = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]) * [length, width]
    return np.array([x, y]) + uv[:, :1] * d + uv[:, 1:] * n


def rectangle_approx(polygon) -> np.ndarray:
    """Approximate rectangle ``(x, y, azimuth_deg, length, width)`` of a polygon.

    From the minimum rotated rectangle: centre, direction of its longer side
    (azimuth in [0, 180) degrees counter-clockwise from +x), side lengths.
    """
    import shapely

    mrr = shapely.minimum_rotated_rectangle(polygon)
    c = np.asarray(mrr.exterior.coords)[:4]
    e1, e2 = c[1] - c[0], c[2] - c[1]
    l1, l2 = np.hypot(*e1), np.hypot(*e2)
    if l1 < l2:
        e1, l1, l2 = e2, l2, l1
    az = np.degrees(np.arctan2(e1[1], e1[0])) % 180.0
    centre = c.mean(axis=0)
    return np.array([centre[0], centre[1], az, l1, l2])


def segment_distances(points, a, b) -> np.ndarray:
    """Distances of points (N, 2) to segments a->b (S, 2), shape (N, S)."""
    p = np.asarray(points, dtype=np.float64)[:, None, :]
    a = np.asarray(a, dtype=np.float64)[None]
    ab = np.asarray(b, dtype=np.float64)[None] - a
    den = np.maximum((ab ** 2).sum(-1), 1e-24)
    t = np.clip(((p - a) * ab).sum(-1) / den, 0.0, 1.0)
    proj = a + t[..., None] * ab
    return np.sqrt(((p - proj) ** 2).sum(-1))


def _nearest_edges(samples, a, b, buffer):
    """Each sample's nearest segment a->b, whether it lies within ``buffer``, and the
    assignment key (edge index, -1 when unused) whose stability ends the outer loops."""
    d = segment_distances(samples, a, b)
    edge = d.argmin(axis=1)
    used = d.min(axis=1) <= buffer
    return edge, used, np.where(used, edge, -1)


def _jacobian(fun, x, r0):
    """Forward-difference Jacobian of ``fun`` at ``x`` (the plain one, not loss-scaled)."""
    J = np.empty((len(r0), len(x)))
    for j in range(len(x)):
        h = 1e-7 * max(1.0, abs(x[j]))
        xp = x.copy()
        xp[j] += h
        J[:, j] = (fun(xp) - r0) / h
    return J


def parameter_covariance(J, scale=1.0, *, pseudo=None, rtol=1e-9):
    """Covariance of the parameters the observations determine; NaN for the others.

    ``N = J_d^T J_d`` over the data rows (all rows but ``pseudo``: prior or
    regularisation rows are no measurements) is decomposed into eigenvectors;
    directions with eigenvalue at most ``rtol`` times the largest are not
    determined by the data. A parameter with a share above 1e-6 of such a
    direction is undetermined: its row and column are NaN. The others get
    ``scale * N^+`` (the pseudo-inverse is the exact covariance of every
    parameter orthogonal to the null space).

    Parameters
    ----------
    J : ndarray (N, P)
        Jacobian of the weighted residuals.
    scale : float
        sigma0 squared.
    pseudo : slice or ndarray of bool, optional
        Rows that are pseudo-observations.

    Returns
    -------
    cov : ndarray (P, P)
    rank : int
        Number of directions the data determine.
    """
    J = np.asarray(J, dtype=np.float64)
    if pseudo is not None:
        keep = np.ones(len(J), dtype=bool)
        keep[pseudo] = False
        J = J[keep]
    w, V = np.linalg.eigh(J.T @ J)
    top = float(w.max()) if len(w) else 0.0
    det = w > rtol * top if top > 0 else np.zeros(len(w), dtype=bool)
    Vd = V[:, det]
    cov = (Vd / w[det]) @ Vd.T * scale
    undetermined = (V[:, ~det] ** 2).sum(axis=1) > 1e-6
    cov[undetermined, :] = np.nan
    cov[:, undetermined] = np.nan
    return cov, int(det.sum())


def solve_least_squares(fun, x0, *, jac=None, bounds=None, loss="linear", f_scale=1.0, x_scale=1.0,
                        max_nfev=200, full=False, sigma_floor=0.0, pseudo=None):
    """Run ``scipy.optimize.least_squares`` and derive the parameter covariance.

    Levenberg-Marquardt when unbounded with a plain quadratic loss and enough
    observations, trust-region reflective otherwise. ``jac(x)``, when given,
    is the analytic Jacobian of ``fun`` (dense array or scipy sparse matrix),
    used by the solver and for the covariance; otherwise forward differences.
    ``pseudo`` selects residual rows that are priors, not measurements: they
    steer the solution but neither count as redundancy nor determine a
    parameter (see :func:`parameter_covariance`).

    Returns
    -------
    x : ndarray (P,)
    std : ndarray (P,)
        ``sqrt(diag(N^+) * s0^2)`` with ``s0^2 = r_d^T r_d / (n_d - rank)`` over
        the data rows, s0 not below ``sigma_floor`` (an a-priori sigma the data
        cannot undercut); NaN for a parameter the data do not determine.
    residuals : ndarray (N,)
    nfev : int
    sigma0 : float
    """
    from scipy.optimize import least_squares

    x0 = np.asarray(x0, dtype=np.float64)
    n = len(fun(x0))
    p = len(x0)
    if n < p:
        raise FitError(f"{n} observations for {p} parameters")
    method = "lm" if bounds is None and loss == "linear" else "trf"
    kwargs = {}
    if bounds is not None:
        lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
        with np.errstate(invalid="ignore"):
            lo_in = np.where(np.isfinite(lo), lo + 1e-6 * (1 + np.abs(lo)), lo)
            hi_in = np.where(np.isfinite(hi), hi - 1e-6 * (1 + np.abs(hi)), hi)
        x0 = np.clip(x0, lo_in, hi_in)
        kwargs["bounds"] = (lo, hi)
    if jac is not None:
        kwargs["jac"] = jac
    res = least_squares(fun, x0, method=method, loss=loss, f_scale=f_scale, x_scale=x_scale,
                        max_nfev=max_nfev * p if method == "lm" else max_nfev, **kwargs)
    r = fun(res.x)
    if jac is None:
        J = _jacobian(fun, res.x, r)
    else:
        J = jac(res.x)
        J = J.toarray() if hasattr(J, "toarray") else np.asarray(J, dtype=np.float64)
    rw = r
    if loss != "linear":
        # rows weighted by the IRLS weights of the robust loss at the solution
        z = (r / f_scale) ** 2
        if loss == "soft_l1":
            w = 1.0 / np.sqrt(1.0 + z)
        elif loss == "huber":
            w = np.where(z <= 1.0, 1.0, 1.0 / np.sqrt(np.maximum(z, 1e-300)))
        elif loss == "cauchy":
            w = 1.0 / (1.0 + z)
        else:
            w = np.ones_like(z)
        rw = r * np.sqrt(w)
        J = J * np.sqrt(w)[:, None]
    data = np.ones(n, dtype=bool)
    if pseudo is not None:
        data[pseudo] = False
    cov, rank = parameter_covariance(J, pseudo=pseudo)
    s02 = float(rw[data] @ rw[data]) / max(int(data.sum()) - rank, 1)
    cov *= max(s02, sigma_floor ** 2)
    with np.errstate(invalid="ignore"):
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if full:
        return res.x, std, r, int(res.nfev), float(np.sqrt(s02)), cov
    return res.x, std, r, int(res.nfev), float(np.sqrt(s02))


def _rect_residuals(params, samples, edge):
    x, y, az, ln, wd = params
    a = np.radians(az)
    dx, dy = samples[:, 0] - x, samples[:, 1] - y
    u = dx * np.cos(a) + dy * np.sin(a)
    v = -dx * np.sin(a) + dy * np.cos(a)
    # edges: 0 south (v=-w/2), 1 east (u=+l/2), 2 north (v=+w/2), 3 west (u=-l/2); outward positive
    r = np.empty(len(samples))
    r[edge == 0] = -v[edge == 0] - wd / 2
    r[edge == 1] = u[edge == 1] - ln / 2
    r[edge == 2] = v[edge == 2] - wd / 2
    r[edge == 3] = -u[edge == 3] - ln / 2
    return r


@dataclass(frozen=True, eq=False)
class OutlineObservations:
    """Roof-outline points seen in the LiDAR, each tied to a model edge.

    Attributes
    ----------
    points : ndarray (M, 2)
        Estimated outline positions (local metres).
    edge : ndarray of int (M,)
        Index of the model edge each observes.
    family : ndarray of int (M,)
        Overhang group of that edge (one unknown overhang per group).
    sigma : ndarray (M,)
        A-priori standard deviations, metres.
    """

    points: np.ndarray
    edge: np.ndarray
    family: np.ndarray
    sigma: np.ndarray

    def __len__(self) -> int:
        return len(self.points)


def outline_observations(xy, a, b, *, density: float, family=None, strip: float = 1.5,
                         sigma: float = 0.05, min_piece: float = 1.5) -> OutlineObservations:
    """Find the roof outline in the LiDAR points along model edges (free edges only).

    For each edge a->b of a counter-clockwise outline (outward normal on the
    right), the points in a strip ``strip`` metres either side of it are
    split along the edge in pieces of at least ``min_piece`` metres (0.5 m kept
    clear of the corners). In each piece the outline is the second outermost
    point plus its expected gap ``2 / (density * piece length)`` (the points of
    a uniform Poisson process; the second, not the first, so one stray point
    does not decide). A piece is used only where the roof visibly ends: at
    least half the expected points inside, and an empty band of at least
    0.5 m beyond the outline within the strip (so roofs continuing across a
    shared wall into the neighbour's give no observation).

    Parameters
    ----------
    xy : ndarray (N, 2)
        Building points around the model (inside and outside the footprint).
    a, b : ndarray (E, 2)
        Edge start and end points.
    density : float
        Points per square metre on the roof.
    family : ndarray of int (E,), optional
        Overhang group per edge (default all 0).

    Returns
    -------
    OutlineObservations
        With sigma ``max(sigma, sqrt(2) / (density * piece length))``.
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    family = np.zeros(len(a), dtype=np.int64) if family is None else np.asarray(family)
    pts, edges, fams, sig = [], [], [], []
    if density <= 0 or len(xy) < 4:
        return OutlineObservations(np.empty((0, 2)), np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0))
    for k in range(len(a)):
        d = b[k] - a[k]
        L = float(np.hypot(*d))
        margin = 0.5
        usable = L - 2 * margin
        if usable < min_piece:
            continue
        d = d / L
        n = np.array([d[1], -d[0]])
        rel = xy - a[k]
        s = rel @ d
        t = rel @ n
        near = (np.abs(t) <= strip) & (s >= margin) & (s <= L - margin)
        if near.sum() < 4:
            continue
        npieces = max(1, min(int(usable // min_piece), 2))
        edges_s = np.linspace(margin, L - margin, npieces + 1)
        for j in range(npieces):
            lo, hi = edges_s[j], edges_s[j + 1]
            sel = near & (s >= lo) & (s < hi)
            plen = hi - lo
            tt = np.sort(t[sel])
            expected_inside = density * plen * strip
            if len(tt) < 3 or (tt < 0).sum() < 0.5 * expected_inside:
                continue
            gap = 1.0 / (density * plen)
            bound = tt[-2] + 2.0 * gap
            if bound > strip - 0.5 or bound < -strip + 0.5:
                continue
            pts.append(a[k] + 0.5 * (lo + hi) * d + bound * n)
            edges.append(k)
            fams.append(int(family[k]))
            sig.append(max(sigma, np.sqrt(2.0) * gap))
    if not pts:
        return OutlineObservations(np.empty((0, 2)), np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0))
    return OutlineObservations(np.asarray(pts), np.asarray(edges, dtype=np.int64),
                               np.asarray(fams, dtype=np.int64), np.asarray(sig))


def drop_observation(outline: OutlineObservations, i: int) -> OutlineObservations:
    """The outline observations without the ``i``-th."""
    keep = np.arange(len(outline)) != i
    return OutlineObservations(outline.points[keep], outline.edge[keep], outline.family[keep],
                               outline.sigma[keep])


def _compact(families):
    uniq, inv = np.unique(families, return_inverse=True)
    return len(uniq), inv


def fit_rectangle(samples, approx, *, buffer: float = 1.0, max_outer: int = 10,
                  outline: OutlineObservations | None = None, sample_sigma: float = 1.0,
                  sigma_floor: float = 0.0, callback=None) -> PlanFit:
    """Fit a rectangle to boundary samples by least squares (LSMDF).

    Parameters
    ----------
    samples : ndarray, shape (N, 2)
        Resampled footprint boundary (see :func:`resample_rings`).
    approx : array_like, shape (5,)
        Approximate ``(x, y, azimuth_deg, length, width)``.
    buffer : float, default 1.0
        Samples farther than this (metres) from every model edge are ignored.
    max_outer : int, default 10
        Maximum re-assignment rounds.
    outline : OutlineObservations, optional
        LiDAR roof-outline points (edges numbered as the rectangle's:
        0 at v = -w/2, 1 at u = +l/2, 2 at v = +w/2, 3 at u = -l/2), observing
        the model edge moved outwards by an unknown overhang per family.
    sample_sigma : float, default 1
        Standard deviation of one footprint sample (weights against ``outline``).
    sigma_floor : float, default 0
        Smallest sigma naught scaling the covariance (the a-priori sigma).
    callback : callable, optional
        Called as ``callback(round, params)`` after each solve.

    Returns
    -------
    PlanFit
        ``params = (x, y, azimuth_deg, length, width)``; with ``outline``,
        ``extra["overhang"]`` / ``extra["overhang_std"]`` per family.

    Raises
    ------
    FitError
        Fewer than 5 samples within the buffer, or fewer than 2 edges observed.
    """
    samples = np.asarray(samples, dtype=np.float64)
    nf, fam = (0, None) if outline is None or len(outline) == 0 else _compact(outline.family)
    params = np.concatenate([np.asarray(approx, dtype=np.float64), np.zeros(nf)])
    prev = None
    nfev = 0
    for k in range(1, max_outer + 1):
        c = rectangle_corners(*params[:5])
        edge, used, key = _nearest_edges(samples, c, np.roll(c, -1, axis=0), buffer)
        if prev is not None and np.array_equal(key, prev):
            break
        prev = key
        if used.sum() < 5 or len(np.unique(edge[used] % 2)) < 2:
            raise FitError(f"only {int(used.sum())} footprint samples within {buffer} m of the rectangle")
        s, e = samples[used], edge[used]

        def fun(p, s=s, e=e):
            r = _rect_residuals(p[:5], s, e) / sample_sigma
            if nf == 0:
                return r
            ro = (_rect_residuals(p[:5], outline.points, outline.edge) - p[5 + fam]) / outline.sigma
            return np.concatenate([r, ro])

        x, std, r, nfe, s0 = solve_least_squares(fun, params, sigma_floor=sigma_floor)
        nfev += nfe
        params = x
        params[3:5] = np.abs(params[3:5])
        if callback is not None:
            callback(k, params[:5].copy())
    r_fp = r[: len(s)] * sample_sigma
    extra = {}
    if nf:
        ro = _rect_residuals(params[:5], outline.points, outline.edge) - params[5 + fam]
        extra = {"overhang": params[5:].copy(), "overhang_std": std[5:].copy(), "n_outline": len(outline),
                 "outline_residuals": ro}
    return PlanFit(params[:5], std[:5], r_fp, used, nfev, k, s0, extra)


def _poly_residuals(flat, samples, i0, i1, prior, lam):
    v = flat.reshape(-1, 2)
    a, b = v[i0], v[i1]
    ab = b - a
    ln = np.maximum(np.hypot(ab[:, 0], ab[:, 1]), 1e-12)
    r = (ab[:, 0] * (samples[:, 1] - a[:, 1]) - ab[:, 1] * (samples[:, 0] - a[:, 0])) / ln
    return np.concatenate([-r, lam * (flat - prior)])


def _poly_jacobian(flat, samples, i0, i1, lam):
    """Analytic Jacobian of :func:`_poly_residuals` (dense; four non-zeros per sample row)."""
    v = flat.reshape(-1, 2)
    a, b = v[i0], v[i1]
    ab = b - a
    ln = np.maximum(np.hypot(ab[:, 0], ab[:, 1]), 1e-12)
    d = samples - a
    c = ab[:, 0] * d[:, 1] - ab[:, 1] * d[:, 0]
    q = c / (ln * ln * ln)
    # d(-c / ln) for a = (ax, ay) and b = (bx, by)
    dax = -(ab[:, 1] - d[:, 1]) / ln - q * ab[:, 0]
    day = -(d[:, 0] - ab[:, 0]) / ln - q * ab[:, 1]
    dbx = -d[:, 1] / ln + q * ab[:, 0]
    dby = d[:, 0] / ln + q * ab[:, 1]
    n = len(samples)
    J = np.zeros((n + flat.size, flat.size))
    rows = np.arange(n)
    np.add.at(J, (rows, 2 * i0), dax)
    np.add.at(J, (rows, 2 * i0 + 1), day)
    np.add.at(J, (rows, 2 * i1), dbx)
    np.add.at(J, (rows, 2 * i1 + 1), dby)
    J[n + np.arange(flat.size), np.arange(flat.size)] = lam
    return J


def fit_polygon(samples, rings, *, buffer: float = 1.0, max_outer: int = 10, prior_weight=1e-3,
                outline: OutlineObservations | None = None, sample_sigma: float = 1.0,
                sigma_floor: float = 0.0, callback=None) -> PlanFit:
    """Fit polygon vertex coordinates to boundary samples (LSMDF for prisms).

    Each sample is assigned to its nearest edge; its residual is the signed
    distance to that edge's line (positive outside for counter-clockwise
    exteriors). A weak prior (``prior_weight`` per metre) keeps vertices of
    edges without samples near their approximate position, so the normal
    matrix stays regular.

    Parameters
    ----------
    samples : ndarray, shape (N, 2)
    rings : list of ndarray (K_i, 2)
        Approximate rings (exterior counter-clockwise, holes clockwise), open.
    outline : OutlineObservations, optional
        LiDAR roof-outline points; ``edge`` numbers the edges ring after ring
        (edge i from vertex i to the next of its ring); each observes its edge
        moved outwards by an unknown overhang per family.
    sample_sigma : float, default 1
        Standard deviation of one footprint sample (weights against ``outline``).

    Returns
    -------
    PlanFit
        ``params`` are the flattened vertices of all rings; ``extra["offsets"]``
        gives ring starts, ``extra["overhang"]`` the overhangs with ``outline``.
    """
    samples = np.asarray(samples, dtype=np.float64)
    sizes = [len(r) for r in rings]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    verts = np.vstack(rings).astype(np.float64)
    i0 = np.concatenate([np.arange(o, o + s) for o, s in zip(offsets[:-1], sizes, strict=True)])
    i1 = np.concatenate([o + (np.arange(s) + 1) % s for o, s in zip(offsets[:-1], sizes, strict=True)])
    nf, fam = (0, None) if outline is None or len(outline) == 0 else _compact(outline.family)
    nv2 = verts.size
    prior = verts.ravel().copy()
    flat = np.concatenate([prior, np.zeros(nf)])
    prev = None
    nfev = 0
    r = np.empty(0)
    std = np.zeros_like(flat)
    s0 = 0.0
    used = np.zeros(len(samples), dtype=bool)
    k = 0
    lam = prior_weight / sample_sigma
    for k in range(1, max_outer + 1):
        v = flat[:nv2].reshape(-1, 2)
        edge, used, key = _nearest_edges(samples, v[i0], v[i1], buffer)
        if prev is not None and np.array_equal(key, prev):
            break
        prev = key
        if used.sum() < 3:
            raise FitError(f"only {int(used.sum())} footprint samples within {buffer} m of the polygon")
        s, e = samples[used], edge[used]

        def fun(p, s=s, e=e):
            r = _poly_residuals(p[:nv2], s, i0[e], i1[e], prior, lam)
            r[: len(s)] /= sample_sigma
            if nf == 0:
                return r
            ro = _poly_residuals(p[:nv2], outline.points, i0[outline.edge], i1[outline.edge], prior, 0.0)
            ro = (ro[: len(outline)] - p[nv2 + fam]) / outline.sigma
            return np.concatenate([r, ro])

        def jac(p, s=s, e=e):
            J = _poly_jacobian(p[:nv2], s, i0[e], i1[e], lam)
            J[: len(s)] /= sample_sigma
            J = np.pad(J, ((0, 0), (0, nf)))
            if nf == 0:
                return J
            Jo = _poly_jacobian(p[:nv2], outline.points, i0[outline.edge], i1[outline.edge], 0.0)[: len(outline)]
            Jo = np.pad(Jo, ((0, 0), (0, nf)))
            Jo[np.arange(len(outline)), nv2 + fam] = -1.0
            return np.vstack([J, Jo / np.asarray(outline.sigma, dtype=np.float64).reshape(-1, 1)])

        flat, std, rr, nfe, s0 = solve_least_squares(fun, flat, jac=jac, sigma_floor=sigma_floor,
                                                     pseudo=slice(len(s), len(s) + nv2))
        r = rr[: len(s)] * sample_sigma
        nfev += nfe
        if callback is not None:
            callback(k, flat[:nv2].copy())
    extra = {"offsets": offsets}
    if nf:
        ro = _poly_residuals(flat[:nv2], outline.points, i0[outline.edge], i1[outline.edge], prior, 0.0)
        extra.update({"overhang": flat[nv2:].copy(), "overhang_std": std[nv2:].copy(),
                      "n_outline": len(outline), "outline_residuals": ro[: len(outline)] - flat[nv2 + fam]})
    return PlanFit(flat[:nv2], std[:nv2], r, used, nfev, k, s0, extra)


def _rectilinear_setup(rings, az, tol):
    """Direction class (0-3) of every edge relative to ``az``, or None if not rectilinear."""
    classes = []
    for ring in rings:
        b = np.roll(ring, -1, axis=0)
        ang = np.degrees(np.arctan2(b[:, 1] - ring[:, 1], b[:, 0] - ring[:, 0])) - az
        m = np.round((ang % 360.0) / 90.0) % 4
        dev = np.abs(((ang - 90.0 * m) + 180.0) % 360.0 - 180.0)
        if np.any(dev > tol):
            return None
        m = m.astype(np.int64)
        if np.any((m - np.roll(m, 1)) % 2 == 0):  # consecutive edges must turn by 90 degrees
            return None
        classes.append(m)
    return classes


def _rectilinear_vertices(p, m, prev):
    az = p[0]
    c = p[1:]
    th = np.radians(az + 90.0 * m)
    n = np.column_stack([np.sin(th), -np.cos(th)])
    return c[prev][:, None] * n[prev] + c[:, None] * n


def fit_rectilinear(samples, rings, *, azimuth=None, buffer: float = 1.0, max_outer: int = 10,
                    tolerance: float = 10.0, outline: OutlineObservations | None = None,
                    sample_sigma: float = 1.0, sigma_floor: float = 0.0) -> PlanFit | None:
    """Fit a rectilinear polygon (all corners right angles) to boundary samples.

    Parameters are one azimuth and one offset per edge (the edge's line
    ``n_k . p = c_k`` with ``n_k`` the outward normal of direction
    ``azimuth + 90 m_k``); each vertex is the crossing of its two edges. Far
    fewer unknowns than free vertices, and the noise of every vertex helps
    fix the common orientation.

    Parameters
    ----------
    samples : ndarray (N, 2)
    rings : list of ndarray (K_i, 2)
        Approximate rings (exterior counter-clockwise, holes clockwise), open.
    azimuth : float, optional
        Approximate main direction (degrees); default the longest edge's.
    tolerance : float, default 10
        Largest deviation (degrees) of an approximate edge from the main
        directions; beyond it the polygon is not rectilinear (returns None).
    outline, sample_sigma
        As in :func:`fit_polygon` (edges numbered ring after ring).

    Returns
    -------
    PlanFit or None
        ``params`` the flattened vertices (like :func:`fit_polygon`), ``std``
        their standard deviations (propagated), ``extra["azimuth"]``,
        ``extra["offsets"]``; None when the rings are not rectilinear.
    """
    samples = np.asarray(samples, dtype=np.float64)
    rings = [np.asarray(r, dtype=np.float64) for r in rings]
    allv = np.vstack(rings)
    centre = allv.mean(axis=0)
    rings_c = [r - centre for r in rings]
    if azimuth is None:
        r0 = rings_c[0]
        e = np.roll(r0, -1, axis=0) - r0
        k = int(np.argmax(np.hypot(e[:, 0], e[:, 1])))
        azimuth = float(np.degrees(np.arctan2(e[k, 1], e[k, 0])))
    classes = _rectilinear_setup(rings_c, azimuth, tolerance)
    if classes is None:
        return None
    m = np.concatenate(classes)
    sizes = [len(r) for r in rings_c]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    prev = np.concatenate([o + (np.arange(n) - 1) % n for o, n in zip(offsets[:-1], sizes, strict=True)])
    nxt = np.concatenate([o + (np.arange(n) + 1) % n for o, n in zip(offsets[:-1], sizes, strict=True)])
    v0 = np.vstack(rings_c)
    mid = 0.5 * (v0 + v0[nxt])
    th = np.radians(azimuth + 90.0 * m)
    n0 = np.column_stack([np.sin(th), -np.cos(th)])
    c0 = (mid * n0).sum(axis=1)
    nf, fam = (0, None) if outline is None or len(outline) == 0 else _compact(outline.family)
    ne = len(m)
    params = np.concatenate([[azimuth], c0, np.zeros(nf)])
    smp = samples - centre
    opts = None if nf == 0 else outline.points - centre

    def edge_resid(p, pts, e):
        th = np.radians(p[0] + 90.0 * m[e])
        return pts[:, 0] * np.sin(th) - pts[:, 1] * np.cos(th) - p[1 + e]

    prev_key = None
    nfev = 0
    k = 0
    cov = None
    for k in range(1, max_outer + 1):  # noqa: B007 - k is the round count returned
        v = _rectilinear_vertices(params[: 1 + ne], m, prev)
        edge, used, key = _nearest_edges(smp, v, v[nxt], buffer)
        if prev_key is not None and np.array_equal(key, prev_key):
            break
        prev_key = key
        if used.sum() < ne + 1:
            raise FitError(f"only {int(used.sum())} footprint samples within {buffer} m of the polygon")
        s, e = smp[used], edge[used]

        def fun(p, s=s, e=e):
            r = edge_resid(p, s, e) / sample_sigma
            if nf == 0:
                return r
            ro = (edge_resid(p, opts, outline.edge) - p[1 + ne + fam]) / outline.sigma
            return np.concatenate([r, ro])

        params, std, rr, nfe, s0, cov = solve_least_squares(fun, params, full=True, sigma_floor=sigma_floor)
        nfev += nfe
    r = rr[: len(s)] * sample_sigma
    verts = _rectilinear_vertices(params[: 1 + ne], m, prev)
    # propagate the covariance of (azimuth, offsets) to the vertices
    J = np.empty((verts.size, 1 + ne))
    base = verts.ravel()
    for j in range(1 + ne):
        h = 1e-6
        pp = params[: 1 + ne].copy()
        pp[j] += h
        J[:, j] = (_rectilinear_vertices(pp, m, prev).ravel() - base) / h
    c = cov[: 1 + ne, : 1 + ne]
    undetermined = np.isnan(np.diag(c))
    cv = J @ np.nan_to_num(c) @ J.T
    vstd = np.sqrt(np.clip(np.diag(cv), 0.0, None))
    # a vertex on an edge line the samples do not fix is undetermined too
    vstd[np.any(J[:, undetermined] != 0.0, axis=1)] = np.nan
    extra = {"offsets": offsets, "azimuth": float(params[0]), "azimuth_std": float(std[0]),
             "n_params": 1 + ne}
    if nf:
        ro = edge_resid(params, opts, outline.edge) - params[1 + ne + fam]
        extra.update({"overhang": params[1 + ne:].copy(), "overhang_std": std[1 + ne:].copy(),
                      "n_outline": len(outline), "outline_residuals": ro})
    return PlanFit((verts + centre).ravel(), vstd, r, used, nfev, k, s0, extra)
