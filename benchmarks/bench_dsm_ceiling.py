"""What the Alexandria 2 m DSM can support: reference-guided upper bounds.

Usage: ``PYTHONPATH=src python benchmarks/bench_dsm_ceiling.py [DATA_DIR]``

Issues 6 and 7 ask for per-area quality >= 0.75 (polygon fitting) and pixel
kappa >= 0.85 (active contours) against ``footprints_west.gpkg``. This script
measures how far the DSM itself lets any method go, by giving the
segmentation information no method has: the reference footprints.

* threshold: every pixel with nDSM > t is building (no segmentation at all).
* reference-guided segmentation, buffer b: for each reference footprint, the
  pixels within b metres of it whose nDSM reaches half the reference's own
  median nDSM, and of those the connected piece overlapping the footprint
  most. The pieces are then fitted by our polygon fitter (the same code as
  ``footprints --dsm``), and also scored as raw pixels. With b = 1 m (half a
  pixel) the segmentation is essentially the reference itself cut by the
  height test; with b = 2 m (one pixel) the segmentation knows each
  building's position to a pixel and its height; b = 3 m is looser still.
* ours: the shipped ``footprints --dsm`` segmentation (roof regions) fitted.

Scores: the restricted per-area quality and IoU >= 0.5 matching of
``bench_dsm_fit.py`` (predictions touching a reference), the outline
alignment within 3 degrees, and pixel kappa on the reference-neighbourhood
domain of ``bench_active_contour.py`` (10 m around the references, minus
above-ground objects holding no reference pixel).

Measured 2026-11-21 (see the notes of issues 6 and 7):
threshold nDSM > 3 / 4 / 5 m: kappa 0.544 / 0.595 / 0.599;
reference-guided b = 1 m, fitted: quality 0.795, matched 55/56, kappa 0.843;
reference-guided b = 2 m, fitted: quality 0.742, matched 52/56, kappa 0.794;
reference-guided b = 3 m, fitted: quality 0.705, matched 48/56, kappa 0.757;
ours (roof regions, fitted): quality 0.564, matched 42/56, kappa 0.571.
So the kappa target of issue 7 (0.85) is above what the DSM supports even
when the segmentation is handed the reference to within half a pixel, and
the quality target of issue 6 (0.75) is reached only when it is handed each
building's position to within a pixel and its height.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np


def main(data=None):
    import pyogrio
    import shapely
    from rasterio import features
    from scipy import ndimage

    from lidar2city.io.raster import read_raster
    from lidar2city.metrics.footprints import (
        area_metrics,
        axis_alignment,
        match_objects,
        pixel_metrics,
    )
    from lidar2city.segment.dsm import roof_regions
    from lidar2city.tools.active_contour import scoring_domain
    from lidar2city.tools.dsm import outlines_from_labels

    root = Path(data or os.environ.get("LIDAR2CITY_DATA",
                                       Path(__file__).resolve().parents[2] / "shared" / "data"))
    a = root / "alexandria"
    d, t = read_raster(a / "dsm_west.tif"), read_raster(a / "dtm_west.tif")
    tr = d.transform
    dsm = np.asarray(d.array, dtype=np.float64)
    ndsm = dsm - t.array
    nd0 = np.nan_to_num(ndsm, nan=0.0)
    ref = [max(shapely.get_parts(g), key=lambda p: p.area)
           for g in shapely.from_wkb(pyogrio.raw.read(str(a / "footprints_west.gpkg"))[2])]

    def raster(geoms):
        if not geoms:
            return np.zeros(dsm.shape, bool)
        return features.rasterize([(g, 1) for g in geoms], out_shape=dsm.shape,
                                  transform=tr, fill=0, dtype="uint8").astype(bool)

    ref_mask = raster(ref)
    domain = scoring_domain(ref_mask, nd0 > 3.0, "reference", cell=d.cell_size)
    ref_tree = shapely.STRtree(ref)

    def kappa(mask):
        return pixel_metrics(mask[domain], ref_mask[domain])["kappa"]

    def score(name, labels, pixels_too=False):
        res = outlines_from_labels(labels, ndsm, cell=d.cell_size)
        pred = [shapely.affinity.translate(r.footprint, tr.c, tr.f) for r in res if r.ok]
        hits = np.unique(ref_tree.query(pred, predicate="intersects")[0]) if pred else []
        sel = [pred[i] for i in hits]
        am, mo = area_metrics(sel, ref), match_objects(sel, ref, min_iou=0.5)
        al = axis_alignment(sel, tolerance_deg=3.0)["aligned_share"]
        extra = f"; raw pixels kappa {kappa(labels > 0):.3f}" if pixels_too else ""
        print(f"  {name:<40s} quality {am['quality']:.3f}  matched {mo['matched']}/{len(ref)}  "
              f"aligned {100 * al:.1f} %  kappa {kappa(raster(pred)):.3f}{extra}")

    print(f"{len(ref)} reference footprints, {int(domain.sum())} pixels in the kappa domain")
    print("threshold (every pixel above t is building):")
    for thr in (3.0, 4.0, 5.0):
        print(f"  nDSM > {thr:g} m: kappa {kappa(nd0 > thr):.3f}")

    print("reference-guided segmentation, fitted:")
    for buf in (1.0, 2.0, 3.0):
        labels = np.zeros(dsm.shape, np.int32)
        for i, r in enumerate(ref):
            inside = raster([r])
            if not inside.any():
                continue
            h = float(np.median(nd0[inside]))
            cand = raster([r.buffer(buf)]) & (nd0 >= 0.5 * h) & (labels == 0)
            pieces, n = ndimage.label(cand)
            if n == 0:
                continue
            overlap = np.bincount(pieces[inside], minlength=n + 1)
            overlap[0] = 0
            labels[pieces == np.argmax(overlap)] = i + 1
        score(f"buffer {buf:g} m", labels, pixels_too=True)

    print("ours:")
    labels, _ = roof_regions(dsm, ndsm, cell=d.cell_size)
    score("roof regions (footprints --dsm)", labels)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
