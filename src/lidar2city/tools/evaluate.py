"""``evaluate``: compare results with reference data (footprints against a cadastre)."""

from __future__ import annotations

import logging

import numpy as np

from ..errors import CRSError, EmptyInputError, InputError

logger = logging.getLogger(__name__)

__all__ = ["evaluate_footprints", "fair_subset"]


def fair_subset(pred, ref, *, extent=None, border=0.5, hull_margin=None):
    """Restrict a comparison to where the reference is complete (the evaluation protocol).

    Two rules, each optional, both symmetric in spirit:

    * ``extent`` (the area the data covers, a shapely polygon): a reference
      that holds only the footprints *wholly inside* a tile leaves out every
      building the tile border cuts. So a predicted polygon reaching within
      ``border`` of the extent's edge is a cut building: it is dropped, and so
      are the reference footprints lying mostly (>= 50 % of their area) inside
      it (their block is cut by the border, so it cannot be scored either way).
      Predictions that overlap nothing are never dropped for that alone.
    * ``hull_margin`` (m): the reference covers only part of the data; the
      evaluation area is the convex hull of the reference buffered by
      ``hull_margin`` and predictions are clipped to it (every prediction
      inside counts, matched or not).

    Parameters
    ----------
    pred, ref : list of shapely Polygon / MultiPolygon (same frame)
    extent : shapely geometry, optional
    border : float
        Distance (m) to the extent's edge that counts as touching it.
    hull_margin : float, optional

    Returns
    -------
    pred, ref : lists
        The predictions (clipped) and references kept.
    info : dict
        ``pred_cut`` and ``ref_cut`` (dropped by the border rule), ``area``
        (m2 of the evaluation area or None).
    """
    import shapely

    pred = [g for g in pred if g is not None and not g.is_empty]
    ref = [g for g in ref if g is not None and not g.is_empty]
    info = {"pred_cut": 0, "ref_cut": 0, "area": None}
    if extent is not None:
        inner = extent.buffer(-border)
        cut = [not inner.contains(g) for g in pred]
        cut_union = shapely.union_all([g for g, c in zip(pred, cut, strict=True) if c])
        keep_ref = [g.intersection(cut_union).area < 0.5 * g.area for g in ref]
        info["pred_cut"] = int(sum(cut))
        info["ref_cut"] = int(len(ref) - sum(keep_ref))
        pred = [g for g, c in zip(pred, cut, strict=True) if not c]
        ref = [g for g, k in zip(ref, keep_ref, strict=True) if k]
    if hull_margin is not None:
        if not ref:
            raise EmptyInputError("no reference footprint left to define the evaluation area")
        area = shapely.convex_hull(shapely.union_all(ref)).buffer(hull_margin)
        if extent is not None:
            area = area.intersection(extent)
        clipped = [g.intersection(area) for g in pred if g.intersects(area)]
        pred = [_polygonal(g) for g in clipped]
        pred = [g for g in pred if g is not None]
        info["area"] = float(area.area)
    return pred, ref, info


def _polygonal(g):
    import shapely

    if g.geom_type in ("Polygon", "MultiPolygon"):
        return g if g.area > 0 else None
    parts = [p for p in getattr(g, "geoms", []) if p.geom_type == "Polygon" and p.area > 0]
    return shapely.MultiPolygon(parts) if parts else None


def _read(path, *, crs, target_crs):
    from pyproj import Transformer

    from ..crs import parse_crs
    from ..io.vector import read_footprints

    fp, src_crs = read_footprints(path, target_crs=target_crs)
    if src_crs is None and crs is not None and target_crs is not None:
        src = parse_crs(crs)
        if not src.equals(target_crs, ignore_axis_order=True):
            import shapely

            tr = Transformer.from_crs(src, target_crs, always_xy=True)
            fp.geometries[:] = [None if g is None else shapely.transform(
                g, lambda c: np.column_stack(tr.transform(c[:, 0], c[:, 1])))
                for g in fp.geometries]
    # one-part multipolygons (GeoPackage layers are often MULTIPOLYGON) as polygons, so
    # per-polygon measures see their rings
    fp.geometries[:] = [g.geoms[0] if g is not None and g.geom_type == "MultiPolygon"
                        and len(g.geoms) == 1 else g for g in fp.geometries]
    return fp, src_crs


def evaluate_footprints(pred_path, ref_path, *, crs=None, min_iou: float = 0.5,
                        tolerance_deg: float = 3.0, extent=None, border: float = 0.5,
                        hull_margin: float | None = None) -> dict:
    """Compare predicted footprints with reference footprints (any OGR sources).

    The prediction is reprojected to the reference's CRS when they differ.

    Parameters
    ----------
    pred_path, ref_path : path
    crs : str or pyproj.CRS, optional
        CRS of a file that has none.
    min_iou : float
        IoU for a one-to-one object match.
    tolerance_deg : float
        Angle tolerance of the axis alignment share.
    extent : tuple (xmin, ymin, xmax, ymax), optional
        Area the data covers, in the reference CRS: enables the border rule of
        :func:`fair_subset`.
    border : float
        Distance (m) to the extent's edge that counts as cut.
    hull_margin : float, optional
        Clip predictions to the reference's convex hull buffered by this (m).

    Returns
    -------
    dict
        ``area`` (completeness, correctness, quality, tp, fp, fn), ``objects``
        (matched, precision, recall, mean_iou, mean_best_iou, hausdorff_mean,
        hausdorff_median, n_pred, n_ref), ``alignment`` (aligned_share),
        ``protocol`` (what was kept), ``crs``.
    """
    import shapely

    from ..crs import parse_crs
    from ..io.vector import to_local
    from ..metrics.footprints import footprint_report

    if not 0 < min_iou <= 1:
        raise InputError(f"min_iou must be in (0, 1], got {min_iou}")
    user_crs = parse_crs(crs)
    ref, ref_crs = _read(ref_path, crs=None, target_crs=None)
    ref_crs = ref_crs or user_crs
    if ref_crs is not None and ref_crs.is_geographic:
        # a reference in degrees: scored in the prediction's projected CRS, onto which
        # it is reprojected (as reconstruct reprojects footprints)
        from ..io.vector import vector_crs

        pred_crs = vector_crs(pred_path) or user_crs
        if pred_crs is not None and not pred_crs.is_geographic:
            ref, _ = _read(ref_path, crs=None, target_crs=pred_crs)
            ref_crs = pred_crs
    pred, pred_crs = _read(pred_path, crs=user_crs, target_crs=ref_crs)
    if (pred_crs is None) != (ref_crs is None) and user_crs is None:
        logger.warning("one input has no CRS: assuming both are in %s",
                       (ref_crs or pred_crs).name)
    if ref_crs is not None and ref_crs.is_geographic:
        raise CRSError("the reference and the prediction are in geographic coordinates; "
                       "reproject one to a projected CRS")
    r = [g for g in ref.geometries if g is not None]
    p = [g for g in pred.geometries if g is not None]
    if not r:
        raise EmptyInputError(f"{str(ref_path)!r} holds no usable footprint")
    rb = shapely.total_bounds(np.array(r, dtype=object))
    pb = shapely.total_bounds(np.array(p, dtype=object)) if p else None
    if pb is not None and not shapely.box(*pb).intersects(shapely.box(*rb)):
        raise InputError(f"{str(pred_path)!r} and {str(ref_path)!r} do not overlap (x {pb[0]:.0f}.."
                         f"{pb[2]:.0f}, y {pb[1]:.0f}..{pb[3]:.0f} against x {rb[0]:.0f}.."
                         f"{rb[2]:.0f}, y {rb[1]:.0f}..{rb[3]:.0f}): not the same area, or not "
                         "the same CRS")
    lo = np.floor(np.array(shapely.total_bounds(np.array(r, dtype=object))[:2]))
    r = list(to_local(np.array(r, dtype=object), lo))
    p = list(to_local(np.array(p, dtype=object), lo)) if p else []
    ext = None
    if extent is not None:
        if len(extent) != 4 or not (extent[0] < extent[2] and extent[1] < extent[3]):
            raise InputError(f"extent must be xmin, ymin, xmax, ymax, got {extent}")
        ext = shapely.box(extent[0] - lo[0], extent[1] - lo[1], extent[2] - lo[0], extent[3] - lo[1])
    n_pred, n_ref = len(p), len(r)
    if ext is not None or hull_margin is not None:
        p, r, info = fair_subset(p, r, extent=ext, border=border, hull_margin=hull_margin)
    else:
        info = {"pred_cut": 0, "ref_cut": 0, "area": None}
    area = None
    if hull_margin is not None:
        area = shapely.convex_hull(shapely.union_all(r)).buffer(hull_margin)
    report = footprint_report(p, r, min_iou=min_iou, tolerance_deg=tolerance_deg, area=area)
    report["protocol"] = {"pred_total": n_pred, "ref_total": n_ref, **info,
                          "extent": list(extent) if extent is not None else None,
                          "hull_margin": hull_margin, "min_iou": min_iou}
    report["crs"] = ref_crs.name if ref_crs is not None else None
    return _plain(report)


def _plain(obj):
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None  # strict JSON has no NaN (e.g. Hausdorff without any match)
    return obj
