"""Corner (vertex) metrics of building models against reference models.

Predicted corners are matched one-to-one to reference corners of the same
building within a 3-D distance tolerance (minimum total distance, Hungarian
assignment). From the matches:

- **correctness** = matched / predicted corners, **completeness** = matched /
  reference corners (the floating-model seed's Table 1);
- the coordinate differences predicted - reference of the matched corners:
  their mean and RMSE in X, Y and Z, and the planimetric RMSE
  ``sqrt(mean(dx^2 + dy^2))`` (Table 2).

Buildings are paired by identifier, or by plan overlap of their corners'
convex hulls when identifiers differ.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..errors import InputError

__all__ = ["CornerMetrics", "match_corners", "corner_metrics", "pair_buildings"]


@dataclass(frozen=True)
class CornerMetrics:
    """Corner correctness / completeness and coordinate differences.

    Counts are over all paired buildings; unpaired predicted (reference)
    buildings count all their corners as unmatched predicted (reference) ones.
    Means and RMSEs are in the coordinates' units (metres) and NaN with no match.
    """

    tolerance: float
    n_predicted: int
    n_reference: int
    n_matched: int
    correctness: float
    completeness: float
    mean_x: float
    mean_y: float
    mean_z: float
    rmse_x: float
    rmse_y: float
    rmse_z: float
    rmse_xy: float
    buildings_paired: int
    buildings_predicted: int
    buildings_reference: int
    per_building: list = field(default_factory=list)

    def as_dict(self) -> dict:
        return asdict(self)


def match_corners(pred, ref, *, tolerance: float = 0.5):
    """One-to-one matches of predicted to reference corners within ``tolerance``.

    Parameters
    ----------
    pred : ndarray, shape (P, 3)
    ref : ndarray, shape (R, 3)
    tolerance : float
        Largest 3-D distance of a match.

    Returns
    -------
    ip, ir : ndarray of int
        Indices of matched predicted and reference corners.
    dist : ndarray
        Their distances.

    Notes
    -----
    The assignment minimises the sum of distances over pairs within the
    tolerance (pairs beyond it cost more than any feasible set of matches),
    so a corner never takes a neighbour's partner when both can be matched.
    """
    from scipy.optimize import linear_sum_assignment

    pred = np.asarray(pred, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(ref, dtype=np.float64).reshape(-1, 3)
    if len(pred) == 0 or len(ref) == 0:
        e = np.empty(0, dtype=np.int64)
        return e, e, np.empty(0)
    d = np.sqrt(((pred[:, None, :] - ref[None, :, :]) ** 2).sum(-1))
    big = tolerance * (min(len(pred), len(ref)) + 1) + 1.0
    cost = np.where(d <= tolerance, d, big)
    ip, ir = linear_sum_assignment(cost)
    ok = d[ip, ir] <= tolerance
    return ip[ok], ir[ok], d[ip, ir][ok]


def _hull(c):
    import shapely

    return shapely.MultiPoint(np.asarray(c)[:, :2]).convex_hull


def pair_buildings(pred: dict, ref: dict, *, by: str = "auto", min_overlap: float = 0.3):
    """Pairs ``(pred_id, ref_id)`` of buildings.

    Parameters
    ----------
    pred, ref : dict of str to ndarray (K, 3)
        Corners per building id.
    by : {'auto', 'id', 'overlap'}
        ``id``: same identifiers; ``overlap``: each predicted building with the
        reference building whose corner hull overlaps it most (intersection
        over the smaller area >= ``min_overlap``), one-to-one; ``auto``: ids
        when they share any, overlap otherwise.
    """
    if by not in ("auto", "id", "overlap"):
        raise InputError(f"by must be 'auto', 'id' or 'overlap', got {by!r}")
    common = [k for k in pred if k in ref]
    if by == "id" or (by == "auto" and common):
        return [(k, k) for k in common]
    import shapely
    from scipy.optimize import linear_sum_assignment

    pk, rk = list(pred), list(ref)
    if not pk or not rk:
        return []
    ph = [_hull(pred[k]) for k in pk]
    rh = [_hull(ref[k]) for k in rk]
    tree = shapely.STRtree(rh)
    score = np.zeros((len(pk), len(rk)))
    for i, g in enumerate(ph):
        for j in tree.query(g, predicate="intersects"):
            inter = g.intersection(rh[j]).area
            denom = min(g.area, rh[j].area)
            score[i, j] = inter / denom if denom > 0 else 0.0
    ii, jj = linear_sum_assignment(-score)
    return [(pk[i], rk[j]) for i, j in zip(ii, jj, strict=True) if score[i, j] >= min_overlap]


def corner_metrics(pred: dict, ref: dict, *, tolerance: float = 0.5, by: str = "auto",
                   min_overlap: float = 0.3) -> CornerMetrics:
    """Corner correctness, completeness and coordinate differences over buildings.

    Parameters
    ----------
    pred, ref : dict of str to ndarray (K, 3)
        Corners per building id (predicted and reference).
    tolerance : float, default 0.5
        Largest 3-D distance of a corner match, metres.
    by, min_overlap
        Building pairing, see :func:`pair_buildings`.

    Returns
    -------
    CornerMetrics

    Examples
    --------
    >>> import numpy as np
    >>> ref = {"a": np.array([[0, 0, 0], [10, 0, 0], [10, 5, 0.0]])}
    >>> pred = {"a": ref["a"] + [0.1, 0.0, 0.0]}
    >>> m = corner_metrics(pred, ref)
    >>> m.completeness, round(m.rmse_x, 3)
    (1.0, 0.1)
    """
    if tolerance <= 0:
        raise InputError(f"tolerance must be > 0, got {tolerance}")
    pairs = pair_buildings(pred, ref, by=by, min_overlap=min_overlap)
    n_pred = sum(len(np.asarray(v).reshape(-1, 3)) for v in pred.values())
    n_ref = sum(len(np.asarray(v).reshape(-1, 3)) for v in ref.values())
    diffs, per = [], []
    for pk, rk in pairs:
        p = np.asarray(pred[pk], dtype=np.float64).reshape(-1, 3)
        r = np.asarray(ref[rk], dtype=np.float64).reshape(-1, 3)
        ip, ir, _ = match_corners(p, r, tolerance=tolerance)
        d = p[ip] - r[ir]
        diffs.append(d)
        per.append({
            "predicted": pk, "reference": rk, "n_predicted": len(p), "n_reference": len(r),
            "n_matched": len(ip),
            "rmse_xy": float(np.sqrt(np.mean((d[:, :2] ** 2).sum(1)))) if len(d) else float("nan"),
            "rmse_z": float(np.sqrt(np.mean(d[:, 2] ** 2))) if len(d) else float("nan"),
        })
    d = np.vstack(diffs) if diffs else np.empty((0, 3))
    n = len(d)
    nan = float("nan")
    mean = d.mean(axis=0) if n else np.full(3, nan)
    rmse = np.sqrt((d ** 2).mean(axis=0)) if n else np.full(3, nan)
    return CornerMetrics(
        tolerance=float(tolerance), n_predicted=int(n_pred), n_reference=int(n_ref),
        n_matched=int(n),
        correctness=n / n_pred if n_pred else nan,
        completeness=n / n_ref if n_ref else nan,
        mean_x=float(mean[0]), mean_y=float(mean[1]), mean_z=float(mean[2]),
        rmse_x=float(rmse[0]), rmse_y=float(rmse[1]), rmse_z=float(rmse[2]),
        rmse_xy=float(np.sqrt((d[:, :2] ** 2).sum(1).mean())) if n else nan,
        buildings_paired=len(pairs), buildings_predicted=len(pred), buildings_reference=len(ref),
        per_building=per,
    )
