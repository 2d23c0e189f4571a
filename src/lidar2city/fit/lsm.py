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

from ..errors import FitError

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
    "solve_least_squares",
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
        raise ValueError(f"interval must be > 0, got {interval}")
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


def _jacobian(fun, x, r0):
    """Forward-difference Jacobian of ``fun`` at ``x`` (the plain one, not loss-scaled)."""
    J = np.empty((len(r0), len(x)))
    for j in range(len(x)):
        h = 1e-7 * max(1.0, abs(x[j]))
        xp = x.copy()
        xp[j] += h
        J[:, j] = (fun(xp) - r0) / h
    return J


def solve_least_squares(fun, x0, *, bounds=None, loss="linear", f_scale=1.0, x_scale=1.0,
                        max_nfev=200):
    """Run ``scipy.optimize.least_squares`` and derive the parameter covariance.

    Levenberg-Marquardt when unbounded with a plain quadratic loss and enough
    observations, trust-region reflective otherwise.

    Returns
    -------
    x : ndarray (P,)
    std : ndarray (P,)
        ``sqrt(diag((J^T J)^+ * s0^2))`` with ``s0^2 = r^T r / (n - P)``.
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
    res = least_squares(fun, x0, method=method, loss=loss, f_scale=f_scale, x_scale=x_scale,
                        max_nfev=max_nfev * p if method == "lm" else max_nfev, **kwargs)
    r = fun(res.x)
    dof = max(n - p, 1)
    s02 = float(r @ r) / dof
    J = _jacobian(fun, res.x, r)
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
        s02 = float(rw @ rw) / dof
        J = J * np.sqrt(w)[:, None]
    cov = np.linalg.pinv(J.T @ J) * s02
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
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


def fit_rectangle(samples, approx, *, buffer: float = 1.0, max_outer: int = 10,
                  callback=None) -> PlanFit:
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
    callback : callable, optional
        Called as ``callback(round, params)`` after each solve.

    Returns
    -------
    PlanFit
        ``params = (x, y, azimuth_deg, length, width)``.

    Raises
    ------
    FitError
        Fewer than 5 samples within the buffer, or fewer than 2 edges observed.
    """
    samples = np.asarray(samples, dtype=np.float64)
    params = np.asarray(approx, dtype=np.float64).copy()
    prev = None
    nfev = 0
    for k in range(1, max_outer + 1):
        c = rectangle_corners(*params)
        d = segment_distances(samples, c, np.roll(c, -1, axis=0))
        edge = d.argmin(axis=1)
        used = d.min(axis=1) <= buffer
        key = np.where(used, edge, -1)
        if prev is not None and np.array_equal(key, prev):
            break
        prev = key
        if used.sum() < 5 or len(np.unique(edge[used] % 2)) < 2:
            raise FitError(f"only {int(used.sum())} footprint samples within {buffer} m of the rectangle")
        s, e = samples[used], edge[used]
        x, std, r, nf, s0 = solve_least_squares(lambda p, s=s, e=e: _rect_residuals(p, s, e), params)
        nfev += nf
        params = x
        if params[3] < 0:
            params[3] = -params[3]
        if params[4] < 0:
            params[4] = -params[4]
        if callback is not None:
            callback(k, params.copy())
    return PlanFit(params, std, r, used, nfev, k, s0)


def _poly_residuals(flat, samples, i0, i1, prior, lam):
    v = flat.reshape(-1, 2)
    a, b = v[i0], v[i1]
    ab = b - a
    ln = np.maximum(np.hypot(ab[:, 0], ab[:, 1]), 1e-12)
    r = (ab[:, 0] * (samples[:, 1] - a[:, 1]) - ab[:, 1] * (samples[:, 0] - a[:, 0])) / ln
    return np.concatenate([-r, lam * (flat - prior)])


def fit_polygon(samples, rings, *, buffer: float = 1.0, max_outer: int = 10, prior_weight=1e-3,
                callback=None) -> PlanFit:
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

    Returns
    -------
    PlanFit
        ``params`` are the flattened vertices of all rings; ``extra["offsets"]``
        gives ring starts.
    """
    samples = np.asarray(samples, dtype=np.float64)
    sizes = [len(r) for r in rings]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    verts = np.vstack(rings).astype(np.float64)
    i0 = np.concatenate([np.arange(o, o + s) for o, s in zip(offsets[:-1], sizes, strict=True)])
    i1 = np.concatenate([o + (np.arange(s) + 1) % s for o, s in zip(offsets[:-1], sizes, strict=True)])
    prior = verts.ravel().copy()
    flat = prior.copy()
    prev = None
    nfev = 0
    r = np.empty(0)
    std = np.zeros_like(flat)
    s0 = 0.0
    used = np.zeros(len(samples), dtype=bool)
    k = 0
    for k in range(1, max_outer + 1):
        v = flat.reshape(-1, 2)
        d = segment_distances(samples, v[i0], v[i1])
        edge = d.argmin(axis=1)
        used = d.min(axis=1) <= buffer
        key = np.where(used, edge, -1)
        if prev is not None and np.array_equal(key, prev):
            break
        prev = key
        if used.sum() < 3:
            raise FitError(f"only {int(used.sum())} footprint samples within {buffer} m of the polygon")
        s, e = samples[used], edge[used]
        fun = lambda p, s=s, e=e: _poly_residuals(p, s, i0[e], i1[e], prior, prior_weight)  # noqa: E731
        flat, std, rr, nf, s0 = solve_least_squares(fun, flat)
        r = rr[: len(s)]
        nfev += nf
        if callback is not None:
            callback(k, flat.copy())
    return PlanFit(flat, std, r, used, nfev, k, s0, {"offsets": offsets})
