"""Footprint quality: per-area and per-object overlap, outline regularity, pixel scores.

All functions are pure: shapely polygons (any common frame, metres) or boolean
masks in, numbers out.

References
----------
Rutzinger, M., Rottensteiner, F., Pfeifer, N. (2009). A comparison of evaluation
techniques for building extraction from airborne laser scanning. IEEE JSTARS 2(1).
Congalton, R. G. (1991). A review of assessing the accuracy of classifications of
remotely sensed data. Remote Sensing of Environment 37(1).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = [
    "area_metrics",
    "match_objects",
    "axis_alignment",
    "pixel_metrics",
    "rasterize",
    "footprint_report",
]


def _polys(geoms):
    import shapely

    arr = np.asarray([g for g in geoms if g is not None and not g.is_empty], dtype=object)
    if len(arr):
        arr = shapely.make_valid(arr)
    return arr


def area_metrics(pred, ref) -> dict:
    """Per-area completeness, correctness and quality of predicted footprints.

    Parameters
    ----------
    pred, ref : sequence of shapely Polygon / MultiPolygon

    Returns
    -------
    dict
        ``completeness`` = TP / area(ref), ``correctness`` = TP / area(pred),
        ``quality`` = TP / area(pred ∪ ref) (the intersection over union of all
        footprints), and the areas ``tp``, ``fp``, ``fn`` in square metres.
    """
    import shapely

    p, r = _polys(pred), _polys(ref)
    up = shapely.union_all(p) if len(p) else shapely.Polygon()
    ur = shapely.union_all(r) if len(r) else shapely.Polygon()
    tp = up.intersection(ur).area
    ap, ar = up.area, ur.area
    union = ap + ar - tp
    return {
        "completeness": tp / ar if ar else 0.0,
        "correctness": tp / ap if ap else 0.0,
        "quality": tp / union if union else 0.0,
        "tp": tp, "fp": ap - tp, "fn": ar - tp,
    }


def match_objects(pred, ref, *, min_iou=0.5) -> dict:
    """One-to-one matching of predicted and reference buildings by intersection over union.

    Pairs are taken greedily by decreasing IoU (an optimal assignment for IoU >= 0.5,
    where each object can overlap at most one partner that much).

    Returns
    -------
    dict
        ``pairs`` (list of (pred index, ref index, iou)), ``matched`` count,
        ``recall`` (matched / references), ``precision`` (matched / predictions),
        ``mean_iou`` over matched pairs, ``mean_best_iou`` (each reference's best
        IoU with any prediction, 0 when none, averaged), ``hausdorff_mean`` and
        ``hausdorff_median`` (m) over matched pairs, ``best_iou`` per reference.
    """
    import shapely

    pred = [g for g in pred]
    ref = [g for g in ref]
    if min_iou <= 0 or min_iou > 1:
        raise InputError(f"min_iou must be in (0, 1], got {min_iou}")
    p = np.asarray([shapely.make_valid(g) if g is not None else shapely.Polygon() for g in pred], dtype=object)
    r = np.asarray([shapely.make_valid(g) if g is not None else shapely.Polygon() for g in ref], dtype=object)
    best = np.zeros(len(r))
    cand = []
    if len(p) and len(r):
        tree = shapely.STRtree(p)
        ri, pi = tree.query(r, predicate="intersects")
        if len(ri):
            inter = shapely.area(shapely.intersection(p[pi], r[ri]))
            union = shapely.area(p[pi]) + shapely.area(r[ri]) - inter
            iou = np.where(union > 0, inter / np.where(union > 0, union, 1), 0.0)
            np.maximum.at(best, ri, iou)
            cand = sorted(zip(iou.tolist(), pi.tolist(), ri.tolist(), strict=True), reverse=True)
    used_p, used_r, pairs = set(), set(), []
    for iou, a, b in cand:
        if iou < min_iou:
            break
        if a in used_p or b in used_r:
            continue
        used_p.add(a)
        used_r.add(b)
        pairs.append((a, b, iou))
    haus = [shapely.hausdorff_distance(p[a], r[b]) for a, b, _ in pairs]
    return {
        "pairs": pairs,
        "matched": len(pairs),
        "recall": len(pairs) / len(r) if len(r) else 0.0,
        "precision": len(pairs) / len(p) if len(p) else 0.0,
        "mean_iou": float(np.mean([t[2] for t in pairs])) if pairs else 0.0,
        "mean_best_iou": float(best.mean()) if len(best) else 0.0,
        "hausdorff_mean": float(np.mean(haus)) if haus else float("nan"),
        "hausdorff_median": float(np.median(haus)) if haus else float("nan"),
        "best_iou": best,
    }


def _edges(geom):
    import shapely

    rings = shapely.get_rings(shapely.get_parts(geom))
    segs = []
    for ring in rings:
        c = np.asarray(ring.coords)[:, :2]
        segs.append(c[1:] - c[:-1])
    return np.concatenate(segs) if segs else np.zeros((0, 2))


def axis_alignment(polygons, *, tolerance_deg=3.0) -> dict:
    """Share of outline length within ``tolerance_deg`` of each polygon's dominant axes.

    A polygon's axes are the orthogonal pair (modulo 90 degrees) that holds the most
    edge length within the tolerance, searched over the polygon's own edge
    directions, so the measure does not depend on any estimator under test.

    Returns
    -------
    dict
        ``aligned_share`` (length-weighted over all polygons), ``per_polygon`` (array).
    """
    tol = np.deg2rad(tolerance_deg)
    total_len, aligned_len, per = 0.0, 0.0, []
    for g in polygons:
        if g is None or g.is_empty:
            continue
        d = _edges(g)
        length = np.hypot(d[:, 0], d[:, 1])
        keep = length > 1e-9
        d, length = d[keep], length[keep]
        if not len(d):
            continue
        ang = np.mod(np.arctan2(d[:, 1], d[:, 0]), np.pi / 2)
        # candidate axes: every edge direction; the score is the aligned length
        diff = np.abs(ang[:, None] - ang[None, :])
        diff = np.minimum(diff, np.pi / 2 - diff)
        score = ((diff <= tol) * length[None, :]).sum(axis=1)
        best = score.max()
        per.append(best / length.sum())
        total_len += length.sum()
        aligned_len += best
    return {
        "aligned_share": aligned_len / total_len if total_len else 0.0,
        "per_polygon": np.asarray(per),
    }


def pixel_metrics(pred_mask, ref_mask) -> dict:
    """Pixel-level building / background agreement.

    Parameters
    ----------
    pred_mask, ref_mask : ndarray of bool, same shape
        True for building pixels.

    Returns
    -------
    dict
        ``overall_accuracy``, ``kappa`` (Cohen), ``producers_accuracy`` (building
        pixels of the reference found), ``users_accuracy`` (predicted building
        pixels that are building), ``fp``, ``fn``, ``tp``, ``tn`` counts and
        ``cost`` = (FP + FN) / N.
    """
    pred = np.asarray(pred_mask, dtype=bool)
    ref = np.asarray(ref_mask, dtype=bool)
    if pred.shape != ref.shape:
        raise InputError(f"masks differ in shape: {pred.shape} vs {ref.shape}")
    n = pred.size
    if n == 0:
        raise InputError("masks are empty")
    tp = int(np.count_nonzero(pred & ref))
    fp = int(np.count_nonzero(pred & ~ref))
    fn = int(np.count_nonzero(~pred & ref))
    tn = n - tp - fp - fn
    oa = (tp + tn) / n
    pe = ((tp + fp) * (tp + fn) + (fn + tn) * (fp + tn)) / (n * n)
    kappa = (oa - pe) / (1 - pe) if pe < 1 else 1.0
    return {
        "overall_accuracy": oa,
        "kappa": kappa,
        "producers_accuracy": tp / (tp + fn) if tp + fn else 0.0,
        "users_accuracy": tp / (tp + fp) if tp + fp else 0.0,
        "tp": tp, "fp": fp, "fn": fn, "tn": tn,
        "cost": (fp + fn) / n,
    }


def rasterize(polygons, bounds, cell) -> np.ndarray:
    """Boolean grid (rows north to south) of the cells whose centres lie in ``polygons``.

    ``bounds`` = (xmin, ymin, xmax, ymax) of the grid, ``cell`` its cell size.
    """
    import shapely

    xmin, ymin, xmax, ymax = bounds
    w = max(int(np.ceil((xmax - xmin) / cell)), 1)
    h = max(int(np.ceil((ymax - ymin) / cell)), 1)
    out = np.zeros((h, w), dtype=bool)
    for g in polygons:
        if g is None or g.is_empty:
            continue
        gx0, gy0, gx1, gy1 = g.bounds
        c0, c1 = max(int((gx0 - xmin) / cell), 0), min(int(np.ceil((gx1 - xmin) / cell)), w)
        r0, r1 = max(int((ymax - gy1) / cell), 0), min(int(np.ceil((ymax - gy0) / cell)), h)
        if c0 >= c1 or r0 >= r1:
            continue
        cc, rr = np.meshgrid(np.arange(c0, c1), np.arange(r0, r1))
        x = xmin + (cc + 0.5) * cell
        y = ymax - (rr + 0.5) * cell
        out[r0:r1, c0:c1] |= shapely.contains_xy(g, x, y)
    return out


def footprint_report(pred, ref, *, min_iou=0.5, tolerance_deg=3.0, pixel_cell=0.5,
                     area=None) -> dict:
    """Area, object, regularity and pixel measures together (what ``evaluate footprints`` prints).

    The pixel measures (overall accuracy, kappa, producer's and user's accuracy)
    are taken on a ``pixel_cell`` grid over ``area`` (a polygon; default the
    bounding box of all footprints).
    """
    import shapely

    out = {"area": area_metrics(pred, ref)}
    geoms = [g for g in list(pred) + list(ref) if g is not None and not g.is_empty]
    if geoms and pixel_cell:
        bounds = area.bounds if area is not None else shapely.total_bounds(np.array(geoms, dtype=object))
        pm, rm = rasterize(pred, bounds, pixel_cell), rasterize(ref, bounds, pixel_cell)
        if area is not None:
            inside = rasterize([area], bounds, pixel_cell)
            pm, rm = pm[inside], rm[inside]
        out["pixels"] = {k: v for k, v in pixel_metrics(pm, rm).items()
                         if k in ("overall_accuracy", "kappa", "producers_accuracy", "users_accuracy")}
        out["pixels"]["cell"] = pixel_cell
    m = match_objects(pred, ref, min_iou=min_iou)
    m.pop("best_iou")
    m.pop("pairs")
    out["objects"] = m
    out["objects"]["n_pred"] = sum(g is not None for g in pred)
    out["objects"]["n_ref"] = sum(g is not None for g in ref)
    out["alignment"] = {"aligned_share": axis_alignment(pred, tolerance_deg=tolerance_deg)["aligned_share"]}
    return out
