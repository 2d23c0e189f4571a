"""Active contours + GA-tuned weights on the Alexandria west half: an honest split.

The reference footprints (56 buildings) cover the middle of the west raster.
The rows of the reference's extent are split in two: the GA tunes the five
weights on the NORTH part only; pixel metrics are reported on the SOUTH part,
never seen by the tuning, for

* the initial contours (no snake),
* the default weights,
* the weights tuned on the north part,
* scikit-image's ``active_contour`` initialised with the same contours,

and, for reference, on the north part too. Then the GA runs on the whole
west half (the weights to ship as defaults).

Scoring domain (``lidar2city.contour.raster.evaluation_domain``): the reference's
bounding box grown by 3 pixels, minus 3 pixels along the (cropped) raster
border, minus the non-reference pixels of above-ground objects (nDSM > 3 m)
touching the border (buildings cut by the edge are not in the reference).

Usage::

    PYTHONPATH=src python benchmarks/bench_active_contour.py [--population 12]
        [--generations 8] [--jobs 2] [--seed 0] [--out /tmp/ac_bench] [--skip-full]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from lidar2city.contour import (
    DEFAULT_WEIGHTS,
    ActiveContourConfig,
    PixelFrame,
    contours_to_polygons,
    evaluation_domain,
    prepare_scene,
    rasterize_polygons,
    run_scene,
)
from lidar2city.contour.outlines import UNTUNED_WEIGHTS
from lidar2city.metrics.footprints import pixel_metrics
from lidar2city.tools.active_contour import load_scene_inputs, reference_mask
from lidar2city.tune.ga import tune_weights

DATA = Path(os.environ.get("LIDAR2CITY_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data")) / "alexandria"


def metrics_line(name, pred, ref, dom):
    m = pixel_metrics(pred[dom], ref[dom])
    print(f"  {name:<34s} OA {m['overall_accuracy']:.4f}  kappa {m['kappa']:.4f}  "
          f"PA {m['producers_accuracy']:.3f}  UA {m['users_accuracy']:.3f}  cost {m['cost']:.4f}")
    return m


def predict(scene, weights, cfg, frame, shape, callback=None):
    contours = run_scene(scene, weights, config=cfg, callback=callback)
    return rasterize_polygons(contours_to_polygons(contours, frame, simplify=cfg.simplify), shape, frame)


def skimage_peer(scene, frame, shape, cfg):
    """scikit-image's active_contour on the (smoothed) DSM from the same initial contours."""
    from skimage.filters import gaussian
    from skimage.segmentation import active_contour

    img = gaussian(scene.image, 1.0, preserve_range=True)
    img = (img - img.min()) / max(np.ptp(img), 1e-9)
    out = []
    for c in scene.contours:
        snake = active_contour(img, c, alpha=0.01, beta=0.1, w_line=0.0, w_edge=1.0, gamma=0.01,
                               boundary_condition="periodic", max_num_iter=500)
        out.append(snake)
    return rasterize_polygons(contours_to_polygons(out, frame, simplify=cfg.simplify), shape, frame)


def row_domains(inp, ref, split):
    """Scoring domains of the north (rows < split) and south parts of one raster."""
    dom = evaluation_domain(ref, np.nan_to_num(inp["ndsm"], nan=0.0) > 3.0)
    rows = np.arange(ref.shape[0])[:, None]
    return dom, dom & (rows < split), dom & (rows >= split)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--population", type=int, default=12)
    ap.add_argument("--generations", type=int, default=8)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="/tmp/ac_bench")
    ap.add_argument("--skip-full", action="store_true")
    ap.add_argument("--objective", choices=["cost", "kappa"], default="cost")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    inp = load_scene_inputs(DATA / "dsm_west.tif", dtm=DATA / "dtm_west.tif")
    r = inp["raster"]
    ref = reference_mask(DATA / "footprints_west.gpkg", r)
    cell = inp["cell"]
    rows = np.nonzero(ref.any(axis=1))[0]
    split = int((rows.min() + rows.max() + 1) // 2)
    print(f"raster {ref.shape} at {cell} m, reference rows {rows.min()}..{rows.max()}, split at row {split}")
    # the GA's first generation holds the configured weights: for an honest split
    # these are the hand-set, untuned ones (the shipped defaults were tuned on all of it)
    cfg = ActiveContourConfig().with_weights(UNTUNED_WEIGHTS)
    frame = PixelFrame(cell=cell)
    print(f"untuned weights {UNTUNED_WEIGHTS}")
    print(f"shipped default weights {DEFAULT_WEIGHTS}")
    print(f"GA: population {args.population}, generations {args.generations}, jobs {args.jobs}, "
          f"seed {args.seed}, objective {args.objective}")

    dom_all, dom_n, dom_s = row_domains(inp, ref, split)
    print(f"domain: {int(dom_all.sum())} px ({int(evaluation_domain(ref).sum()) - int(dom_all.sum())} px "
          f"of edge-cut objects removed); north {int(dom_n.sum())} px with {int((ref & dom_n).sum())} "
          f"reference px, south {int(dom_s.sum())} px with {int((ref & dom_s).sum())} reference px")
    dsm, ndsm = inp["dsm"], inp["ndsm"]

    t0 = time.perf_counter()
    # the scene is the whole raster (no reference involved); only north pixels are scored
    weights_n, hist_n = tune_weights(dsm, ndsm, ref, cell=cell, domain=dom_n,
                                     config=cfg, population=args.population,
                                     generations=args.generations, seed=args.seed,
                                     n_jobs=args.jobs, objective=args.objective)
    t_ga = time.perf_counter() - t0
    print(f"\nGA on the north part: {t_ga:.1f} s, {hist_n[-1]['evaluations']} evaluations, "
          f"{len(hist_n) - 1} generations")
    for rec in hist_n:
        print(f"  generation {rec['generation']:2d}  best cost {rec['best_cost']:.5f}  "
              f"mean {rec['mean']:.5f}  same {100 * rec['same']:.0f} %")
    print("  tuned weights " + ", ".join(f"{k} {v:.3f}" for k, v in weights_n.items()))

    t0 = time.perf_counter()
    scene = prepare_scene(dsm, ndsm, cell=cell, config=cfg)
    t_prep = time.perf_counter() - t0
    shape = ref.shape
    init = rasterize_polygons(contours_to_polygons(scene.contours, frame, simplify=0), shape, frame)
    t0 = time.perf_counter()
    pd = predict(scene, UNTUNED_WEIGHTS, cfg, frame, shape)
    t_def = time.perf_counter() - t0
    pship = predict(scene, DEFAULT_WEIGHTS, cfg, frame, shape)
    t0 = time.perf_counter()
    pt = predict(scene, weights_n, cfg, frame, shape)
    t_tun = time.perf_counter() - t0
    t0 = time.perf_counter()
    ps = skimage_peer(scene, frame, shape, cfg)
    t_sk = time.perf_counter() - t0
    for name, dom in (("south (held out)", dom_s), ("north (training)", dom_n)):
        print(f"\n{name}:")
        metrics_line("initial contours (no snake)", init, ref, dom)
        metrics_line("snake, untuned weights", pd, ref, dom)
        metrics_line("snake, weights tuned on north", pt, ref, dom)
        metrics_line("snake, shipped defaults (all west)", pship, ref, dom)
        metrics_line("skimage active_contour (same init)", ps, ref, dom)
    print(f"\n{len(scene.contours)} contours on the whole raster; time: scene (edges, GVF) "
          f"{t_prep:.2f} s, snakes untuned {t_def:.2f} s, tuned {t_tun:.2f} s, skimage {t_sk:.2f} s")

    # figures: GA cost and one building's contour evolution (south part, tuned weights)
    from lidar2city.io.contour_plots import plot_contour_evolution, plot_ga_history

    plot_ga_history(out / "ga_cost_north.png", hist_n, title="GA on the north part")
    areas = [len(c) for c in scene.contours]
    # a building of the south part overlapping the reference, larger than most
    inside = [i for i, c in enumerate(scene.contours)
              if c[:, 0].mean() >= split and ref[tuple(np.round(c.mean(axis=0)).astype(int))]]
    k = max(inside, key=lambda i: areas[i]) if inside else int(np.argmax(areas))
    snaps = [(0, scene.contours[k])]
    wanted = {2, 5, 10, 20, 40, 80, 150}

    def cb(it, contours):
        if it in wanted:
            snaps.append((it, contours[k]))

    final = run_scene(scene, weights_n, config=cfg, callback=cb)
    if final[k] is not None:
        snaps.append(("final", final[k]))
    c = scene.contours[k]
    r0, c0 = np.floor(c.min(axis=0)).astype(int) - 6
    r1, c1 = np.ceil(c.max(axis=0)).astype(int) + 7
    r0, c0 = max(r0, 0), max(c0, 0)
    from skimage.measure import find_contours

    refs = find_contours(ref[r0:r1, c0:c1].astype(float), 0.5)
    plot_contour_evolution(out / "contour_evolution.png", dsm[r0:r1, c0:c1],
                           [(i, s - [r0, c0]) for i, s in snaps], reference=refs,
                           title="one building (south part, weights tuned on north)")
    print(f"\nfigures: {out / 'ga_cost_north.png'}, {out / 'contour_evolution.png'}")

    if not args.skip_full:
        t0 = time.perf_counter()
        weights_all, hist_all = tune_weights(dsm, ndsm, ref, cell=cell, domain=dom_all,
                                             config=cfg, population=args.population,
                                             generations=args.generations, seed=args.seed,
                                             n_jobs=args.jobs, objective=args.objective)
        print(f"\nGA on the whole west half: {time.perf_counter() - t0:.1f} s, best cost "
              f"{hist_all[-1]['best_cost']:.5f}")
        print("  weights " + ", ".join(f"{k} {v:.3f}" for k, v in weights_all.items()))
        plot_ga_history(out / "ga_cost_west.png", hist_all, title="GA on the west half")
        pa = predict(scene, weights_all, cfg, frame, shape)
        for name, dom in (("south", dom_s), ("north", dom_n), ("whole", dom_all)):
            metrics_line(f"{name}: weights tuned on all west", pa, ref, dom)

if __name__ == "__main__":
    main()
