"""Footprints and LoD1 heights from the Alexandria DSM by polygon fitting.

Usage: ``PYTHONPATH=src python benchmarks/bench_dsm_fit.py [DATA_DIR]``

Evaluation protocol (the reference is incomplete: ``footprints_west.gpkg``
holds only 56 of the buildings in the west tile, those wholly inside it, and
many built-up blocks have no reference at all):

* "restricted" — predictions that intersect at least one reference footprint
  are scored against all references (completeness, correctness, quality per
  area; one-to-one IoU >= 0.5 matching). Detections of unreferenced buildings
  are not counted as false positives, but a prediction that merges a
  referenced building with an unreferenced one or with trees is scored whole.
* "hull" — every prediction intersecting the convex hull of the references,
  clipped to it, scored against the references: a pessimistic bound, since
  unreferenced buildings inside the hull count as false positives.
* alignment: share of outline length within 3 degrees of each polygon's own
  axes, over the restricted predictions.
* heights: |height - HEIGHT| over matched pairs (fitted outlines), and over all
  references when the reference footprints are extruded (``--footprints``).

Everything is run twice: with the given DTM and with the DTM built from the
DSM. The DTM built from the DSM is compared with the given one over ground
pixels (given nDSM < 0.5 m) and over all pixels. Most of the ground-pixel RMSE
comes from the elevated highway in the north-west corner, which the given DTM
keeps as terrain and the region growing leaves out (4.3 m lower there on
average); without the northern 60 rows the ground-pixel RMSE is about 1.1 m.

* registration (diagnostic): the shift of the reference footprints that best
  fits them on the nDSM is estimated from the rasters alone; the restricted
  scores against the shifted references are printed as a diagnostic (the
  headline figures use the references as they are).
* upper bound of the fitting alone ("oracle"): the reference footprints
  rasterised on the DSM grid (pixel centres inside) are fitted as if they were
  the segmented regions and scored the same way; the gap between this and the
  real run is what the segmentation loses.

Measured 2026-11-21 (2-core shared machine), see the closing note of issue 6.
First version (roof regions grown and expanded by 2 m):
given DTM: quality 0.564, 69.6 % matched, 86.0 % aligned, heights 0.28 m;
DTM from the DSM: quality 0.569, 71.4 % matched, 86.8 % aligned, heights 0.60 m.
With the saddle split (regions holding two summits separated by a saddle at
least 1 m deep are divided along the valley) and the half-height trimming
(regions cut back to half their roof height, the edge of a blurred step):
given DTM: quality 0.564, 75.0 % matched, 89.6 % aligned, heights 0.32 m;
DTM from the DSM: quality 0.572, 71.4 % matched, 86.3 % aligned, heights 0.52 m;
oracle (fitting alone): quality 0.905, 100 % matched, 94.7 % aligned;
registration: the references sit best on the nDSM moved by +0.50 m east,
-1.00 m north (our matched outlines' centroids agree: +0.62 / -0.91 m); against
the moved references the quality would be 0.597 (mean IoU 0.718 vs 0.664).
With issue 16's roof defaults (regions from 2 m high and 10 m2 / 8 pixels,
trimmed at 0.2 of the roof height, a 0.5 m edge inset that leaves 2 m grids
alone), measured 2026-11-23: given DTM: quality 0.552, 73.2 % matched, 88.0 %
aligned, heights 0.27 m; DTM from the DSM: quality 0.560, 75.0 % matched,
87.8 % aligned, heights 0.63 m.
Still short of the targets (0.75 / 85 % / 90 %): the loss is in the
segmentation of this heavily smoothed 2 m DSM, where small steep-roofed
houses look like tree crowns and touching houses of one height have no step
between them. Tried and not adopted (each traded one figure for another):
adding the elevated blobs left over by the growing as regions (44/56 matched
but hull quality 0.43 and 87 % aligned), merging touching regions without a
height step (aligned 91 %, matched 71 %), watershed on the nDSM gradient with
ground and tree markers, distance-transform neck splitting, component-tree
(threshold-decomposition) selection by rectangularity, slope-continuity
growing, per-region rectangularity filtering.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main(data=None):
    import pyogrio
    import shapely
    import shapely.affinity

    from lidar2city.io.raster import read_raster
    from lidar2city.metrics.footprints import area_metrics, axis_alignment, match_objects
    from lidar2city.segment.dsm import dtm_from_dsm
    from lidar2city.tools.dsm import footprints_from_dsm, lod1_from_dsm, outlines_from_labels

    root = Path(data or Path(__file__).resolve().parents[1].parent / "shared" / "data")
    if not (root / "alexandria").exists():
        root = Path("/work/shared/data")
    a = root / "alexandria"
    dsm, dtm, fp = a / "dsm_west.tif", a / "dtm_west.tif", a / "footprints_west.gpkg"
    meta, _, wkb, fields = pyogrio.raw.read(str(fp))
    ref = [max(shapely.get_parts(g), key=lambda p: p.area) for g in shapely.from_wkb(wkb)]
    ref_h = np.asarray(fields[list(meta["fields"]).index("HEIGHT")], dtype=float)
    hull = shapely.union_all(ref).convex_hull
    tree = shapely.STRtree(ref)

    # DTM from the DSM alone
    d, t = read_raster(dsm), read_raster(dtm)
    t0 = time.perf_counter()
    own, ground = dtm_from_dsm(d.array, cell=d.cell_size)
    dt_s = time.perf_counter() - t0
    ok = np.isfinite(t.array) & np.isfinite(own)
    gp = ok & (d.array - t.array < 0.5)
    diff = own - t.array
    print(f"DTM from DSM ({dt_s:.1f} s): ground pixels (given nDSM < 0.5 m, n={gp.sum()}): "
          f"RMSE {np.sqrt(np.mean(diff[gp] ** 2)):.2f} m, median |diff| {np.median(np.abs(diff[gp])):.2f} m; "
          f"all pixels: RMSE {np.sqrt(np.mean(diff[ok] ** 2)):.2f} m, "
          f"median |diff| {np.median(np.abs(diff[ok])):.2f} m; {100 * ground.mean():.0f} % grown as ground")

    # upper bound: the fitter on the rasterised reference footprints
    from affine import Affine
    from rasterio import features

    ref_lab = features.rasterize([(g, i + 1) for i, g in enumerate(ref)], out_shape=d.shape,
                                 transform=d.transform, fill=0, dtype="int32")
    oracle = outlines_from_labels(ref_lab, d.array - t.array, cell=d.cell_size)
    shift = Affine.translation(d.transform.c, d.transform.f)
    opred = [shapely.affinity.affine_transform(r.footprint, [1, 0, 0, 1, shift.c, shift.f])
             for r in oracle if r.ok]
    am, mo = area_metrics(opred, ref), match_objects(opred, ref, min_iou=0.5)
    print(f"oracle (reference footprints rasterised at {d.cell_size:g} m, then fitted): "
          f"quality {am['quality']:.3f}, matched {100 * mo['recall']:.1f} %, "
          f"aligned {100 * axis_alignment(opred, tolerance_deg=3.0)['aligned_share']:.1f} %")

    # registration of the references on the DSM (diagnostic): the shift, on a
    # 0.25 m lattice within 2 m, that maximises the mean given nDSM inside the
    # reference footprints (found from the rasters alone, not from our outlines)
    fine = 4
    nd_up = np.kron(np.nan_to_num(d.array - t.array), np.ones((fine, fine)))
    t_up = Affine(d.transform.a / fine, 0, d.transform.c, 0, d.transform.e / fine, d.transform.f)
    best = (-np.inf, 0.0, 0.0)
    for sx in np.arange(-2.0, 2.01, 0.25):
        for sy in np.arange(-2.0, 2.01, 0.25):
            m = features.rasterize([(shapely.affinity.translate(g, sx, sy), 1) for g in ref],
                                   out_shape=nd_up.shape, transform=t_up, fill=0,
                                   dtype="uint8").astype(bool)
            best = max(best, (float(nd_up[m].mean()), float(sx), float(sy)))
    reg_dx, reg_dy = best[1], best[2]
    print(f"registration: the references fit the nDSM best shifted by dx {reg_dx:+.2f} m, "
          f"dy {reg_dy:+.2f} m (mean nDSM inside {best[0]:.2f} m)")
    ref_shifted = [shapely.affinity.translate(g, reg_dx, reg_dy) for g in ref]

    with tempfile.TemporaryDirectory() as tmp:
        for label, dtm_in in (("given DTM", dtm), ("DTM from DSM", None)):
            out = Path(tmp) / "fp.gpkg"
            t0 = time.perf_counter()
            summary = footprints_from_dsm(dsm, dtm=dtm_in, output=out, figure=Path(tmp) / "f.png")
            el = time.perf_counter() - t0
            m2, _, w2, f2 = pyogrio.raw.read(str(out))
            names = list(m2["fields"])
            geoms = shapely.from_wkb(w2)
            status = np.asarray(f2[names.index("status")])
            heights = np.asarray(f2[names.index("height")], dtype=float)
            kinds = np.asarray(f2[names.index("shape_type")])
            good = (status == "ok") & ~shapely.is_empty(geoms)
            pred = [max(shapely.get_parts(g), key=lambda p: p.area) for g in geoms[good]]
            heights, kinds = heights[good], kinds[good]
            hits = np.unique(tree.query(pred, predicate="intersects")[0]) if pred else []
            sel = [pred[i] for i in hits]
            am = area_metrics(sel, ref)
            mo = match_objects(sel, ref, min_iou=0.5)
            al = axis_alignment(sel, tolerance_deg=3.0)
            hdiff = np.array([abs(heights[hits[p]] - ref_h[r]) for p, r, _ in mo["pairs"]])
            hdiff = hdiff[np.isfinite(hdiff)]  # two references have no HEIGHT
            clipped = [g.intersection(hull) for g in pred if g.intersects(hull)]
            ah = area_metrics(clipped, ref)
            mh = match_objects(clipped, ref, min_iou=0.5)
            types = {k: int((kinds[hits] == k).sum()) for k in sorted(set(kinds[hits]))}
            print(f"\n[{label}] {summary['buildings']} buildings fitted in {el:.1f} s "
                  f"({summary['failed']} failed); all shape types: {summary['shape_types']}")
            print(f"  restricted ({len(sel)} predictions touching a reference; types {types}):")
            print(f"    per-area completeness {am['completeness']:.3f} correctness {am['correctness']:.3f} "
                  f"quality {am['quality']:.3f}")
            print(f"    matched IoU>=0.5: {mo['matched']}/{len(ref)} = {100 * mo['recall']:.1f} % "
                  f"(mean IoU {mo['mean_iou']:.3f}, Hausdorff median {mo['hausdorff_median']:.2f} m)")
            print(f"    outline length within 3 deg of the polygon axes: {100 * al['aligned_share']:.1f} %")
            print(f"    LoD1 height of matched buildings: median |h - HEIGHT| {np.median(hdiff):.2f} m, "
                  f"mean {np.mean(hdiff):.2f} m (n={len(hdiff)})")
            print(f"  hull ({len(clipped)} predictions clipped to the references' hull): "
                  f"quality {ah['quality']:.3f} completeness {ah['completeness']:.3f} "
                  f"correctness {ah['correctness']:.3f}; matched {100 * mh['recall']:.1f} %")
            # diagnostic only: the same restricted scores against the references
            # moved by the registration shift above (not a headline figure)
            hs_ = np.unique(shapely.STRtree(ref_shifted).query(pred, predicate="intersects")[0])
            sel_ = [pred[i] for i in hs_]
            as_, ms_ = area_metrics(sel_, ref_shifted), match_objects(sel_, ref_shifted, min_iou=0.5)
            print(f"  diagnostic, references shifted by the registration offset: quality "
                  f"{as_['quality']:.3f}, matched {100 * ms_['recall']:.1f} % "
                  f"(mean IoU {ms_['mean_iou']:.3f})")
            t0 = time.perf_counter()
            res = lod1_from_dsm(dsm, dtm=dtm_in, footprints=fp)
            el = time.perf_counter() - t0
            hs = np.array([r.attributes.get("height", np.nan) for r in res["buildings"]])
            e = np.abs(hs - ref_h)
            print(f"  reference footprints extruded ({el:.1f} s, {res['ok']} solids): "
                  f"median |h - HEIGHT| {np.nanmedian(e):.2f} m, mean {np.nanmean(e):.2f} m")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
