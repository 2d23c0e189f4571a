"""Footprints from the Delft AHN3 tile against the BGT: per-area and per-object scores, regularity, time.

Run: ``PYTHONPATH=src python benchmarks/bench_footprints.py`` (data from $LIDAR2CITY_DATA
or ../shared/data).

Evaluation protocol (the reference covers only part of the tile, so scoring
every prediction against it would count correct buildings as false):

* the BGT file holds the footprints *wholly inside* the tile; a predicted
  polygon reaching within 0.5 m of the tile border is a building cut by the
  border: it is left out, and so are the reference footprints lying mostly
  inside it (their block is cut, it cannot be scored either way);
* the BGT extract covers only the middle blocks: predictions are clipped to
  the convex hull of the reference buffered by 2 m (every prediction inside
  counts, whether it overlaps a reference or not);
* then per-area completeness / correctness / quality (IoU of all
  footprints), one-to-one matches at IoU >= 0.5, Hausdorff distance of the
  matches and the axis alignment share (metrics.footprints). The raw scores
  (every prediction against every reference, no protocol) are printed too.

Row houses sharing walls come out as one block per row (points alone do not
show party walls), so per-object matching against the BGT's one polygon per
house is low by construction; the per-area figures are the measure of outline
quality. ``edge_offset = -0.2`` shows the effect of the roof overhang (LiDAR
sees the eaves, the BGT draws the walls).
"""

from __future__ import annotations

import importlib.util
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("LIDAR2CITY_DATA", ROOT.parent / "shared" / "data"))


def main() -> int:
    from lidar2city.io.las import read_las
    from lidar2city.tools.evaluate import evaluate_footprints
    from lidar2city.tools.footprints import footprints_job, load_footprints_config

    tile = DATA / "delft" / "ahn3_cropped_1.laz"
    ref = DATA / "delft" / "footprints_bgt.gpkg"
    if not tile.exists():
        print(f"data not found at {DATA}")
        return 1
    hdr = read_las(tile, crs="EPSG:7415").data.header
    extent = (hdr.mins[0], hdr.mins[1], hdr.maxs[0], hdr.maxs[1])
    snake = importlib.util.find_spec("lidar2city.regularize") is not None and \
        importlib.util.find_spec("lidar2city.regularize.snake") is not None
    runs = [("none", 0.0), ("none", -0.2)]
    if snake:
        runs += [("snake", 0.0), ("snake", -0.2)]
    else:
        print("snake regulariser not importable: lidar2city.regularize.snake missing; "
              "only --regularize none measured")
    print(f"Delft AHN3 tile {tile.name} (EPSG:7415) vs {ref.name} (BGT, 132 footprints)")
    header = (f"{'regularize':10s} {'offset':>6s} {'n':>4s} {'compl':>6s} {'corr':>6s} {'quality':>7s} "
              f"{'matched':>11s} {'prec':>5s} {'recall':>6s} {'mIoU':>5s} {'bestIoU':>7s} "
              f"{'Haus':>5s} {'align':>6s} {'raw Q':>6s} {'time':>6s}")
    print(header)
    with tempfile.TemporaryDirectory() as tmp:
        for reg, offset in runs:
            out = Path(tmp) / f"fp_{reg}_{offset}.gpkg"
            cfg = load_footprints_config(regularize=reg, edge_offset=offset)
            t0 = time.perf_counter()
            summary = footprints_job([tile], out, crs="EPSG:7415", config=cfg)
            dt = time.perf_counter() - t0
            rep = evaluate_footprints(out, ref, extent=extent, hull_margin=2.0)
            raw = evaluate_footprints(out, ref)
            a, o, p = rep["area"], rep["objects"], rep["protocol"]
            print(f"{reg:10s} {offset:6.2f} {o['n_pred']:4d} {a['completeness']:6.3f} "
                  f"{a['correctness']:6.3f} {a['quality']:7.3f} {o['matched']:4d}/{o['n_ref']:<3d}   "
                  f"{o['precision']:5.3f} {o['recall']:6.3f} {o['mean_iou']:5.3f} "
                  f"{o['mean_best_iou']:7.3f} {o['hausdorff_mean']:5.2f} "
                  f"{100 * rep['alignment']['aligned_share']:5.1f}% {raw['area']['quality']:6.3f} "
                  f"{dt:5.2f}s")
            if reg != "none":
                r = summary["reductions"]
                print(f"{'':10s} snake reductions over {summary['buildings']} footprints: "
                      f"I {r['I']}  II {r['II']}  III {r['III']}  IV {r['IV']}; "
                      f"unregularised {summary['unregularised']}")
    print(f"protocol: {p['pred_cut']} of {p['pred_total']} predictions cut by the tile border, "
          f"{p['ref_cut']} of {p['ref_total']} references in cut blocks left out; "
          f"evaluation area {p['area']:.0f} m2 (reference hull + 2 m)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
