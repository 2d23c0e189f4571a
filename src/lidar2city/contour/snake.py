"""Semi-implicit snakes with GVF, regional-variance and altitudinal-variance energies.

All contours of a scene evolve together as one ragged array (vertices plus
offsets): one sparse factorisation of the block-diagonal internal-energy
system per resampling, one interpolation call per field and iteration.

Coordinates are ``(row, col)`` in pixels, pixel centres at integer positions.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy import ndimage as ndi

from ..errors import InputError

logger = logging.getLogger(__name__)

__all__ = ["evolve_contours", "resample_contour", "region_forces", "local_region_fields"]


def resample_contour(v, spacing=1.0, *, min_vertices=8, max_vertices=None) -> np.ndarray:
    """Resample a closed contour to vertices equally spaced along its length.

    Parameters
    ----------
    v : ndarray, shape (M, 2)
        Closed contour (first vertex not repeated).
    spacing : float
        Target distance between vertices (pixels).

    Returns
    -------
    ndarray, shape (K, 2) with ``K = max(min_vertices, round(length / spacing))``,
    at most ``max_vertices``.
    """
    v = np.asarray(v, dtype=np.float64)
    closed = np.vstack([v, v[:1]])
    seg = np.hypot(*np.diff(closed, axis=0).T)
    keep = np.concatenate([[True], seg > 1e-9])
    closed = closed[keep]
    seg = seg[seg > 1e-9]
    s = np.concatenate([[0.0], np.cumsum(seg)])
    length = s[-1]
    if length <= 0:
        return np.repeat(v[:1], min_vertices, axis=0)
    m = max(int(min_vertices), int(round(length / spacing)))
    if max_vertices is not None:
        m = min(m, max(int(max_vertices), int(min_vertices)))
    t = np.linspace(0.0, length, m, endpoint=False)
    return np.column_stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])])


def _untangle(contours):
    """Cut the loops of self-intersecting contours, keeping the largest part.

    A loop has the opposite orientation to its contour, so its normal forces
    point the wrong way and it would grow; cutting it at every resampling keeps
    each snake a simple ring.
    """
    import shapely

    sizes = np.array([len(c) for c in contours])
    closed = np.concatenate([np.vstack([c, c[:1]]) for c in contours])
    rings = shapely.linearrings(closed, indices=np.repeat(np.arange(len(contours)), sizes + 1))
    polys = shapely.polygons(rings)
    bad = np.flatnonzero(~shapely.is_valid(polys))
    out = list(contours)
    for i in bad:
        fixed = shapely.make_valid(polys[i])
        parts = [g for g in shapely.get_parts(fixed) if g.geom_type == "Polygon"]
        if not parts:
            continue
        ring = np.asarray(max(parts, key=lambda g: g.area).exterior.coords)[:-1]
        if len(ring) >= 3:
            out[i] = ring
    return out


class _Ragged:
    """Closed contours as one vertex array plus offsets, with cyclic neighbours."""

    def __init__(self, contours):
        self.sizes = np.array([len(c) for c in contours], dtype=np.int64)
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)])
        self.v = np.concatenate(contours).astype(np.float64) if len(contours) else np.zeros((0, 2))
        n = len(self.v)
        self.sid = np.repeat(np.arange(len(self.sizes)), self.sizes)
        start = self.offsets[:-1][self.sid]
        size = self.sizes[self.sid]
        local = np.arange(n) - start
        self.nb = {d: start + (local + d) % size for d in (-2, -1, 1, 2)}

    def resample(self, v, spacing, min_vertices, caps):
        """All contours resampled to equal spacing at once; returns a list of arrays."""
        nxt = self.nb[1]
        seg = np.hypot(*(v[nxt] - v).T)
        k = len(self.sizes)
        length = np.bincount(self.sid, weights=seg, minlength=k)
        csum = np.cumsum(seg)
        before = np.concatenate([[0.0], np.cumsum(length)[:-1]])  # arc length of earlier snakes
        key = csum - seg  # global arc position of each vertex (monotone)
        m = np.clip(np.round(length / spacing).astype(np.int64), min_vertices,
                    np.maximum(np.asarray(caps, dtype=np.int64), min_vertices))
        tid = np.repeat(np.arange(k), m)
        starts = np.concatenate([[0], np.cumsum(m)[:-1]])
        frac_pos = (np.arange(len(tid)) - starts[tid]) / m[tid]
        tkey = before[tid] + frac_pos * length[tid]
        j = np.searchsorted(key, tkey, side="right") - 1
        j = np.clip(j, self.offsets[:-1][tid], self.offsets[1:][tid] - 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(seg[j] > 0, (tkey - key[j]) / seg[j], 0.0)
        t = np.clip(t, 0.0, 1.0)
        new = v[j] + t[:, None] * (v[nxt[j]] - v[j])
        bounds = np.concatenate([[0], np.cumsum(m)])
        return [new[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]

    def split(self, v=None):
        v = self.v if v is None else v
        return [v[a:b].copy() for a, b in zip(self.offsets[:-1], self.offsets[1:], strict=True)]

    def system(self, alpha, beta, tau):
        """Factorised ``I + tau A`` (A: the cyclic pentadiagonal internal-energy matrix)."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.linalg import splu

        n = len(self.v)
        i = np.arange(n)
        a, b = tau * alpha, tau * beta
        rows = np.concatenate([i, i, i, i, i])
        cols = np.concatenate([i, self.nb[-1], self.nb[1], self.nb[-2], self.nb[2]])
        vals = np.concatenate([np.full(n, 1.0 + 2 * a + 6 * b), np.full(2 * n, -a - 4 * b),
                               np.full(2 * n, b)])
        mat = coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsc()  # duplicates summed
        return splu(mat, permc_spec="NATURAL")  # block-banded: no reordering needed

    def outward_normals(self, v):
        # tangent over a 5-vertex stencil: one noisy vertex does not flip its normal
        t = v[self.nb[1]] - v[self.nb[-1]] + v[self.nb[2]] - v[self.nb[-2]]
        # signed area in (x=col, y=row): > 0 for counter-clockwise
        x, y = v[:, 1], v[:, 0]
        cross = x * y[self.nb[1]] - x[self.nb[1]] * y
        area2 = np.bincount(self.sid, weights=cross, minlength=len(self.sizes))
        sign = np.where(area2 >= 0, 1.0, -1.0)[self.sid]
        # (tx, ty) -> outward (ty, -tx) for counter-clockwise; as (row, col) = (-tx, ty)
        nr, nc = -t[:, 1] * sign, t[:, 0] * sign
        norm = np.hypot(nr, nc)
        norm[norm == 0] = 1.0
        return np.column_stack([nr / norm, nc / norm]), 0.5 * np.abs(area2)


def _labels(contours, shape):
    """Label image: pixel centres inside contour k get k (1-based; later ones win).

    A vectorised even-odd scanline fill of all contours at once.
    """
    h, w = shape
    lab = np.zeros(shape, dtype=np.int32)
    if not len(contours):
        return lab
    rag = _Ragged(contours)
    a, b = rag.v, rag.v[rag.nb[1]]
    lo, hi = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
    # rows r whose centre line crosses the edge: lo <= r < hi
    r0 = np.clip(np.ceil(lo), 0, h).astype(np.int64)
    r1 = np.clip(np.ceil(hi), 0, h).astype(np.int64)
    n = np.maximum(r1 - r0, 0)
    if not n.sum():
        return lab
    e = np.repeat(np.arange(len(a)), n)
    rows = r0[e] + (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n))
    t = (rows - a[e, 0]) / (b[e, 0] - a[e, 0])
    x = a[e, 1] + t * (b[e, 1] - a[e, 1])
    sid = rag.sid[e]
    order = np.lexsort((x, rows, sid))
    sid, rows, x = sid[order], rows[order], x[order]
    # crossings come in pairs per (snake, row): fill between them
    x0, x1 = x[0::2], x[1::2]
    rr, ss = rows[0::2], sid[0::2]
    c0 = np.clip(np.ceil(x0), 0, w).astype(np.int64)
    c1 = np.clip(np.floor(x1) + 1, 0, w).astype(np.int64)
    m = np.maximum(c1 - c0, 0)
    if not m.sum():
        return lab
    run = np.repeat(np.arange(len(m)), m)
    cols = c0[run] + (np.arange(m.sum()) - np.repeat(np.cumsum(m) - m, m))
    lab[rr[run], cols] = ss[run] + 1
    return lab


def _sample(fields, v):
    """Bilinear values of ``fields`` (C, H, W) at ``(row, col)`` points; (C, N)."""
    _, h, w = fields.shape
    r = np.clip(v[:, 0], 0.0, h - 1.0)
    c = np.clip(v[:, 1], 0.0, w - 1.0)
    r0 = np.minimum(np.floor(r).astype(np.int64), h - 2) if h > 1 else np.zeros(len(r), np.int64)
    c0 = np.minimum(np.floor(c).astype(np.int64), w - 2) if w > 1 else np.zeros(len(c), np.int64)
    fr, fc = r - r0, c - c0
    r1 = np.minimum(r0 + 1, h - 1)
    c1 = np.minimum(c0 + 1, w - 1)
    return (fields[:, r0, c0] * ((1 - fr) * (1 - fc)) + fields[:, r0, c1] * ((1 - fr) * fc)
            + fields[:, r1, c0] * (fr * (1 - fc)) + fields[:, r1, c1] * (fr * fc))


def region_forces(contours, shape, image, ndsm, *, band=3.0, var_floor=0.25):
    """Per-contour statistics inside the contour and in a band outside it.

    Returns
    -------
    dict of ndarray, shape (K,)
        ``c_in``, ``c_out`` (mean image value inside / outside), ``m_in``,
        ``m_out``, ``v_in``, ``v_out`` (mean and variance of the nDSM,
        variances floored at ``var_floor``).
    """
    k = len(contours)
    lab = _labels(contours, shape)
    dist, idx = ndi.distance_transform_edt(lab == 0, return_indices=True)
    ring = lab[tuple(idx)] * ((dist > 0) & (dist <= band))
    out = {}
    for name, labs in (("in", lab), ("out", ring)):
        cnt = np.bincount(labs.ravel(), minlength=k + 1)[1:].astype(np.float64)
        safe = np.maximum(cnt, 1.0)
        ci = np.bincount(labs.ravel(), weights=image.ravel(), minlength=k + 1)[1:] / safe
        m = np.bincount(labs.ravel(), weights=ndsm.ravel(), minlength=k + 1)[1:] / safe
        m2 = np.bincount(labs.ravel(), weights=(ndsm * ndsm).ravel(), minlength=k + 1)[1:] / safe
        out[f"c_{name}"] = ci
        out[f"m_{name}"] = m
        out[f"v_{name}"] = np.maximum(m2 - m * m, var_floor)
        out[f"n_{name}"] = cnt
    return out


def local_region_fields(contours, shape, image, ndsm, *, sigma=3.0, var_floor=0.25,
                        min_weight=0.05) -> np.ndarray:
    """Localised inside / outside statistics around every pixel (Lankton & Tannenbaum 2008).

    With ``chi`` the union of the contours' interiors and ``G`` a Gaussian of
    ``sigma`` pixels, the local inside mean of a quantity ``q`` is
    ``G*(chi q) / G*chi`` and the outside mean ``G*((1-chi) q) / G*(1-chi)``.
    A vertex on a wall then compares the roof just behind it with the ground
    (or the neighbour) just in front of it, not with the mean of a whole,
    possibly composite, building and its whole surroundings; a low annex or a
    crown beside a tall roof gets its own local mid-height.

    Returns
    -------
    ndarray, shape (8, H, W)
        ``c_in, c_out`` (image means), ``m_in, m_out`` (nDSM means),
        ``v_in, v_out`` (nDSM variances floored at ``var_floor``), and the
        ``ok`` flag (both sides have at least ``min_weight`` of the window)
        twice (so the array samples as pairs).

    References
    ----------
    Lankton, S., Tannenbaum, A. (2008). Localizing region-based active
    contours. IEEE TIP 17(11).
    """
    chi = (_labels(contours, shape) > 0).astype(np.float64)
    out_m = 1.0 - chi

    def g(a):
        return ndi.gaussian_filter(a, sigma, mode="nearest")

    w_in, w_out = g(chi), g(out_m)
    ok = ((w_in >= min_weight) & (w_out >= min_weight)).astype(np.float64)
    si, so = np.maximum(w_in, 1e-9), np.maximum(w_out, 1e-9)
    c_in, c_out = g(chi * image) / si, g(out_m * image) / so
    m_in, m_out = g(chi * ndsm) / si, g(out_m * ndsm) / so
    q = ndsm * ndsm
    v_in = np.maximum(g(chi * q) / si - m_in ** 2, var_floor)
    v_out = np.maximum(g(out_m * q) / so - m_out ** 2, var_floor)
    return np.stack([c_in, c_out, m_in, m_out, v_in, v_out, ok, ok])


def evolve_contours(contours, gvf, image, ndsm, *, alpha=0.1, beta=0.1, gamma=1.0, mu=1.0,
                    epsilon=1.0, tau=0.5, max_step=1.0, step_decay=0.9, max_iter=200, tol=0.02,
                    spacing=1.0, resample_every=5, band=3.0, var_floor=0.25, local_sigma=0.0,
                    min_vertices=8, anchor=0.0, start_distance=None, offset=0.0,
                    callback=None) -> list:
    """Evolve closed contours by minimising the snake energy.

    Energy of a contour ``v(s)`` (Kass et al. 1988 internal terms)::

        E = integral alpha |v'|^2 + beta |v''|^2
              + gamma E_GVF + mu E_RVE + epsilon E_AVE + anchor E_start  ds

    External forces per vertex:

    * GVF: the gradient vector flow field at the vertex (Xu & Prince 1998).
    * RVE (regional variance, Chan & Vese 2001): along the outward normal,
      ``((I - c_out)^2 - (I - c_in)^2) / (c_in - c_out)^2`` clipped to [-1, 1],
      with ``c_in`` / ``c_out`` the mean image value inside / in a band outside:
      the contour grows over pixels that look like its inside, shrinks off
      pixels that look like its outside.
    * AVE (altitudinal variance): the Gaussian log-likelihood ratio of the
      nDSM height under the inside and outside height distributions (means and
      variances), divided by its value at the inside mean (where positive) or
      by its magnitude at the outside mean (where negative) and clipped to
      [-1, 1], along the normal: unlike RVE it weighs each side by its height
      variance, so a rough canopy outside a flat roof pulls less.

    Semi-implicit iteration ``(I + tau A) v_{t+1} = v_t + tau F(v_t)`` with
    ``A`` the cyclic pentadiagonal matrix of the internal energy (factorised
    once per resampling; ``alpha`` and ``beta`` act per unit vertex spacing).
    The step is ``tau / max(1, gamma + mu + epsilon)``: the converged contour
    (``A v = F``) does not depend on it, and the explicit external step stays
    stable whatever the weights.
    Every ``resample_every`` iterations the loops of self-intersecting
    contours are cut, contours are resampled to ``spacing`` and the region
    statistics are updated. The external step is limited to
    ``max_step`` pixels per iteration; the time step and that limit are
    multiplied by ``step_decay`` after every resampling period so that a
    contour oscillating about an edge settles and a contour that keeps
    shrinking (internal energy stronger than the image forces) stops. Stops when the root-mean-square vertex
    displacement of an iteration falls below ``tol`` pixels.

    Parameters
    ----------
    contours : list of ndarray, shape (M_i, 2)
        Closed ``(row, col)`` contours (first vertex not repeated).
    gvf : ndarray, shape (2, H, W)
        Gradient vector flow (row, col components), magnitudes about <= 1.
    image : ndarray, shape (H, W)
        Intensity for the regional term (orthoimage grey level or DSM), finite.
    ndsm : ndarray, shape (H, W)
        Height above ground (m), finite.
    alpha, beta, gamma, mu, epsilon : float
        The five energy weights (>= 0).
    anchor : float
        Weight (>= 0) of the anchor to the start: a normal force
        ``-anchor * clip(start_distance(v), -1, 1)`` pulling each vertex back
        to the zero level of ``start_distance``, so the image forces move a
        good start only where they outweigh it.
    start_distance : ndarray, shape (H, W), optional
        Signed distance (pixels, > 0 outside) to the initial regions' edge;
        the anchor is off without it.
    offset : float
        The image forces (GVF, regional and altitudinal) are sampled this
        many pixels outside each vertex along its outward normal, so the
        contour settles ``offset`` inside the edges they find (a
        highest-point DSM shows roofs beyond the walls); 0: at the vertex.
    callback : callable, optional
        ``callback(iteration, contours)`` after each iteration (a list of copies).

    Returns
    -------
    list of ndarray or None
        Final contours in input order; ``None`` for a contour that collapsed.

    References
    ----------
    Kass, M., Witkin, A., Terzopoulos, D. (1988). Snakes: active contour models. IJCV 1(4).
    Xu, C., Prince, J. L. (1998). Snakes, shapes, and gradient vector flow. IEEE TIP 7(3).
    Chan, T. F., Vese, L. A. (2001). Active contours without edges. IEEE TIP 10(2).
    """
    weights = {"alpha": alpha, "beta": beta, "gamma": gamma, "mu": mu, "epsilon": epsilon,
               "anchor": anchor}
    for name, w in weights.items():
        if not np.isfinite(w) or w < 0:
            raise InputError(f"weight {name} must be a finite number >= 0, got {w}")
    if tau <= 0 or spacing <= 0 or resample_every < 1 or max_iter < 0 or not offset >= 0:
        raise InputError("tau and spacing must be > 0, resample_every >= 1, max_iter and offset >= 0")
    image = np.asarray(image, dtype=np.float64)
    ndsm = np.asarray(ndsm, dtype=np.float64)
    gvf = np.asarray(gvf, dtype=np.float64)
    shape = image.shape
    if ndsm.shape != shape or gvf.shape != (2,) + shape:
        raise InputError(f"image {shape}, ndsm {ndsm.shape} and gvf {gvf.shape} do not match")
    if not len(contours):
        return []
    use_anchor = anchor > 0 and start_distance is not None
    if use_anchor:
        start_distance = np.asarray(start_distance, dtype=np.float64)
        if start_distance.shape != shape:
            raise InputError(f"start_distance {start_distance.shape} and image {shape} do not match")
        fields = np.stack([image, ndsm, gvf[0], gvf[1], start_distance])
    else:
        fields = np.stack([image, ndsm, gvf[0], gvf[1]])
    contours = [resample_contour(c, spacing, min_vertices=min_vertices) for c in contours]
    # a jagged contour must not grow without bound: at most 3 times its first vertex count
    caps = [3 * len(c) for c in contours]
    # the raster covers pixel corners -0.5 .. H - 0.5 (pixel centres at integers): a
    # contour around a region on the raster's edge runs half a pixel outside its
    # first centre and must keep that pixel
    lo = np.array([-0.5, -0.5])
    hi = np.array([shape[0] - 0.5, shape[1] - 0.5], dtype=np.float64)
    # the fixed point A v = F does not depend on the time step: scale it with the
    # external weights so the explicit external step stays stable for any weights
    tau0 = tau / max(1.0, gamma + mu + epsilon + (anchor if use_anchor else 0.0))
    tau, limit = tau0, max_step
    rag = _Ragged(contours)
    lu = rag.system(alpha, beta, tau)
    local = local_sigma > 0 and (mu > 0 or epsilon > 0)

    def update_stats(cs):
        if local:
            return local_region_fields(cs, shape, image, ndsm, sigma=local_sigma, var_floor=var_floor)
        return region_forces(cs, shape, image, ndsm, band=band, var_floor=var_floor)

    stats = update_stats(contours)
    v = rag.v
    it = 0
    for it in range(1, max_iter + 1):
        normal, _ = rag.outward_normals(v)
        # the image forces act ``offset`` pixels outside the vertex (the roof edge a
        # highest-point DSM shows lies outside the walls); the anchor at the vertex
        at = v + offset * normal if offset > 0 else v
        val, h, g_r, g_c = _sample(fields[:4], at)
        force = np.zeros_like(v)
        if gamma > 0:
            force[:, 0] += gamma * g_r
            force[:, 1] += gamma * g_c
        if mu > 0 or epsilon > 0 or use_anchor:
            push = np.zeros(len(v))
            sid = rag.sid
            if local:
                c_in, c_out, m_in, m_out, v_in, v_out, ok, _ = _sample(stats, at)
                empty = ok < 0.5
            elif mu > 0 or epsilon > 0:
                c_in, c_out = stats["c_in"][sid], stats["c_out"][sid]
                m_in, m_out = stats["m_in"][sid], stats["m_out"][sid]
                v_in, v_out = stats["v_in"][sid], stats["v_out"][sid]
                empty = (stats["n_in"][sid] == 0) | (stats["n_out"][sid] == 0)
            if use_anchor:
                push -= anchor * np.clip(_sample(fields[4:], v)[0], -1.0, 1.0)
            if mu > 0:
                contrast = np.maximum((c_in - c_out) ** 2, 1e-12)
                f_rve = ((val - c_out) ** 2 - (val - c_in) ** 2) / contrast
                f_rve[empty] = 0.0
                push += mu * np.clip(f_rve, -1.0, 1.0)
            if epsilon > 0:
                llr = (h - m_out) ** 2 / v_out - (h - m_in) ** 2 / v_in + np.log(v_out / v_in)
                # normalised by its value at the inside mean where it pushes outward (+1
                # there) and by its magnitude at the outside mean where it pulls inward
                # (-1 there): one normaliser for both sides would make the pull off a flat
                # ground (small variance) vanish next to the push over it
                d2 = (m_in - m_out) ** 2
                at_in = d2 / v_out + np.log(v_out / v_in)
                at_out = d2 / v_in - np.log(v_out / v_in)
                norm = np.where(llr > 0, at_in, at_out)
                f_ave = np.where(norm > 1e-9, llr / np.maximum(norm, 1e-9), 0.0)
                f_ave[empty] = 0.0
                push += epsilon * np.clip(f_ave, -1.0, 1.0)
            # a normal force that alternates along the contour folds it: smooth it (1-2-1)
            push = 0.5 * push + 0.25 * (push[rag.nb[-1]] + push[rag.nb[1]])
            force += push[:, None] * normal
        mag = np.hypot(force[:, 0], force[:, 1]) * tau
        over = mag > limit
        if over.any():
            force[over] *= (limit / mag[over])[:, None]
        new = lu.solve(v + tau * force)
        np.clip(new, lo, hi, out=new)
        step = float(np.sqrt(np.mean(np.sum((new - v) ** 2, axis=1))))
        v = new
        if callback is not None:
            callback(it, rag.split(v))
        if step < tol:
            break
        if it % resample_every == 0 and it < max_iter:
            tangled = _Ragged(_untangle(rag.split(v)))
            contours = tangled.resample(tangled.v, spacing, min_vertices, caps)
            rag = _Ragged(contours)
            # damping: the whole step (internal and external) shrinks every period
            decay = step_decay ** (it // resample_every)
            tau, limit = tau0 * decay, max_step * decay
            lu = rag.system(alpha, beta, tau)
            stats = update_stats(contours)
            v = rag.v
    logger.debug("snakes stopped after %d iterations", it)
    out = []
    _, area = rag.outward_normals(v)
    for c, a in zip(rag.split(v), area, strict=True):
        out.append(c if a >= 1.0 else None)
    return out
