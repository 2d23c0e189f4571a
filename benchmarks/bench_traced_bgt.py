"""Traced footprints of the no-footprints reconstruct against the BGT, building by building (issue 13).

Usage: python benchmarks/bench_traced_bgt.py [DATA_DIR] [--lod 1.2 ...] [--config RUN.toml]
[--src SRC]
(default data $LIDAR2CITY_DATA or ../shared/data; LoDs default 1.2 only: the footprints
do not depend on the LoDs asked for; SRC the ``src`` folder whose lidar2city is measured,
default this checkout's; RUN.toml a run file, e.g. a ``[footprints]`` section with
``regularize = "snake"`` (reconstruct's default when tracing) and the options tried)

Runs ``reconstruct`` of the Delft tile without ``--footprints`` once in this process and
records the footprints every block traces (``lidar2city.tools.task._traced_footprints``,
the polygons the buildings are then modelled on) with the CPU seconds of that call
(``time.process_time``). Then scores them against the tile's 132 BGT footprints with the
protocol of ``bench_footprints.py`` (predictions cut by the tile border left out with the
references mostly under them; predictions clipped to the references' convex hull + 2 m):
per-area completeness / correctness / quality, one-to-one matches at IoU >= 0.5
(precision, recall, mean IoU, each reference's best IoU averaged), and how many BGT
buildings each traced footprint holds (a reference is held by the prediction covering
most of it, at least half of its area): the merged blocks of row houses are the
predictions holding several. Also the largest traced areas (LoD2.2's cost grows faster
than the roof's area) and the output's MD5 and wall / CPU time. With ``--lod 2.2`` (or
1.3) among the LoDs, the models' RMSE to the tile's building points per LoD asked for
(``evaluate_model``: median and mean over the buildings, and pooled over all their
points, which does not move when a block is cut into more buildings) and how many solids
are valid.

The BGT draws walls and splits row houses by cadastral parcel; the points show roof
edges (0.2-0.3 m outside the walls) and only the party walls where the roof changes.
A better split of the merged blocks raises the matches and the held-one share without
lowering the per-area quality.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--lod", action="append", default=None)
    ap.add_argument("--config", default=None, help="a run file (TOML) passed to reconstruct")
    ap.add_argument("--src", default=str(ROOT / "src"))
    args = ap.parse_args()
    sys.path.insert(0, args.src)
    data = Path(args.data or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")
    laz = data / "delft" / "ahn3_cropped_1.laz"
    ref_path = data / "delft" / "footprints_bgt.gpkg"

    import numpy as np
    import shapely

    import lidar2city.tools.task as task
    from lidar2city.cli.main import cli
    from lidar2city.io.las import read_las
    from lidar2city.io.vector import read_footprints, to_world
    from lidar2city.metrics.footprints import footprint_report
    from lidar2city.tools.evaluate import fair_subset

    traced, spent = [], [0.0]
    inner = task._traced_footprints

    def recorded(spec, options, cloud, classes):
        t0 = time.process_time()
        fps = inner(spec, options, cloud, classes)
        spent[0] += time.process_time() - t0
        if fps is not None:
            fr = spec.frame
            traced.extend(to_world(np.array(fps.geometries, dtype=object), fr.origin[:2],
                                   fr.xy_unit))
        return fps

    task._traced_footprints = recorded
    lods = args.lod or ["1.2"]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.city.json"
        argv = ["reconstruct", str(laz), "-o", str(out), "-q"]
        for lod in lods:
            argv += ["--lod", lod]
        if args.config:
            argv += ["--config", args.config]
        c0, w0 = time.process_time(), time.perf_counter()
        try:
            cli.main(argv, standalone_mode=False)
        finally:
            task._traced_footprints = inner
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        md5 = hashlib.md5(out.read_bytes()).hexdigest()
        quality = _model_quality(out, laz, lods)

    hdr = read_las(laz, crs="EPSG:7415").data.header
    refs, _ = read_footprints(ref_path)
    lo = np.floor(np.array([hdr.mins[0], hdr.mins[1]]))
    shift = (lambda g: shapely.transform(g, lambda c: c - lo))
    r = [shift(g) for g in refs.geometries if g is not None]
    p = [shift(g) for g in traced]
    ext = shapely.box(hdr.mins[0] - lo[0], hdr.mins[1] - lo[1], hdr.maxs[0] - lo[0],
                      hdr.maxs[1] - lo[1])
    p_in, r_in, info = fair_subset(p, r, extent=ext, border=0.5, hull_margin=2.0)
    area = shapely.convex_hull(shapely.union_all(r_in)).buffer(2.0).intersection(ext)
    rep = footprint_report(p_in, r_in, area=area)
    a, o = rep["area"], rep["objects"]
    # which prediction holds each reference (most of its area, at least half)
    held = np.zeros(len(p_in), dtype=np.int64)
    orphan = 0
    for g in r_in:
        cover = np.array([g.intersection(q).area for q in p_in]) if p_in else np.zeros(0)
        if len(cover) and cover.max() >= 0.5 * g.area:
            held[int(np.argmax(cover))] += 1
        else:
            orphan += 1
    areas = sorted((float(g.area) for g in traced), reverse=True)
    print(f"tree {args.src}")
    print(f"traced footprints: {len(traced)} in the run, {len(p_in)} scored against "
          f"{len(r_in)} BGT ({info['pred_cut']} cut by the border, {info['ref_cut']} references "
          f"under them left out)")
    print(f"per area: completeness {a['completeness']:.3f}  correctness {a['correctness']:.3f}  "
          f"quality {a['quality']:.3f}")
    print(f"objects (IoU >= 0.5): matched {o['matched']}/{o['n_ref']}  precision "
          f"{o['precision']:.3f}  recall {o['recall']:.3f}  mean IoU {o['mean_iou']:.3f}  "
          f"mean best IoU {o['mean_best_iou']:.3f}")
    hist = {k: int(v) for k, v in zip(*np.unique(held, return_counts=True), strict=True)}
    print("BGT buildings held per scored traced footprint: "
          + ", ".join(f"{k}: {v}" for k, v in sorted(hist.items()))
          + f"; references held by none {orphan}; largest held {int(held.max()) if len(held) else 0}")
    print("largest traced areas (m2): " + ", ".join(f"{x:.0f}" for x in areas[:10]))
    print(f"tracing CPU {spent[0]:.3f} s; run (LoD {' + '.join(lods)}) {wall:.2f} s wall, "
          f"{cpu:.2f} CPU s; output MD5 {md5}; load {os.getloadavg()[0]:.2f}")
    for line in quality:
        print(line)


def _model_quality(out, laz, lods):
    """Per LoD asked for: the RMSE of the models to the building points (median, mean,
    pooled over the points) and the valid solids."""
    import numpy as np

    from lidar2city.tools.evaluate_model import evaluate_model

    lines = []
    for lod in lods:
        rows, s = evaluate_model(out, [laz], crs="EPSG:7415", lod=lod)
        n = np.array([r["points"] or 0 for r in rows], dtype=np.float64)
        e = np.array([np.nan if r["rmse"] is None else r["rmse"] for r in rows])
        ok = np.isfinite(e) & (n > 0)
        pooled = float(np.sqrt((n[ok] * e[ok] ** 2).sum() / n[ok].sum())) if ok.any() else np.nan
        lines.append(f"LoD{lod}: {s['buildings']} buildings, RMSE median {s['rmse_median']:.3f} m, "
                     f"mean {s['rmse_mean']:.3f} m, pooled over {int(n[ok].sum())} points "
                     f"{pooled:.3f} m; valid {s['valid']}/{s['buildings']}")
    return lines


if __name__ == "__main__":
    main()
