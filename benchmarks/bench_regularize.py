"""Benchmark of footprint regularisation with the 2-D snake on perturbed Delft BGT footprints.

The 132 BGT footprints of the Delft tile are densified (a vertex every 0.5 m)
and every vertex is moved at random — ``disc``: uniformly within a disc of
0.3 m radius; ``gauss``: Gaussian, 0.3 m standard deviation per axis (a harsh
case) — or rasterised at 0.5 m and traced back (``traced``: the staircase
outline of a raster footprint), then regularised with the default options. Printed per noise model:

* length-weighted fraction of edge length within 3 degrees of each polygon's
  own dominant axes (result, BGT, noisy input);
* IoU with the original BGT footprint (mean, share of polygons >= 0.9) and
  the noisy input's IoU for reference;
* oblique walls: on the reference polygons with > 10 % of oblique length, the
  oblique share of the BGT and of the result;
* fallbacks, repairs, reduction-type totals and time per polygon.

Run: ``PYTHONPATH=src python benchmarks/bench_regularize.py [DATA_DIR]``
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
import pyogrio
import shapely

from lidar2city.regularize import aligned_fraction, dominant_direction, regularize_polygon


def load(data: Path):
    _, _, wkb, _ = pyogrio.raw.read(data / "delft" / "footprints_bgt.gpkg")
    polys = shapely.from_wkb(wkb)
    origin = shapely.get_coordinates(polys).min(axis=0)
    return [shapely.transform(p, lambda c: c - origin) for p in polys]


def traced(p, rng, cell=0.5):
    """Rasterise at ``cell`` (random sub-cell offset) and trace the cell edges back."""
    from rasterio import features
    from rasterio.transform import Affine

    minx, miny, maxx, maxy = p.bounds
    ox, oy = rng.random(2) * cell
    tr = Affine(cell, 0, minx - 2 - ox, 0, -cell, maxy + 2 + oy)
    shape = (int((maxy - miny + 5) / cell), int((maxx - minx + 5) / cell))
    mask = features.rasterize([p], out_shape=shape, transform=tr).astype(np.uint8)
    parts = [shapely.geometry.shape(g) for g, _ in features.shapes(mask, mask=mask > 0, transform=tr)]
    return max(parts, key=lambda g: g.area) if parts else p


def perturb(p, model, rng, amount=0.3, spacing=0.5):
    if model == "traced":
        return traced(p, rng)
    dense = shapely.segmentize(p, spacing)
    rings = []
    for r in [dense.exterior, *dense.interiors]:
        xy = shapely.get_coordinates(r)[:-1]
        if model == "disc":
            rad = amount * np.sqrt(rng.random(len(xy)))
            th = rng.random(len(xy)) * 2 * np.pi
            noise = np.stack([rad * np.cos(th), rad * np.sin(th)], axis=1)
        else:
            noise = rng.normal(0, amount, xy.shape)
        rings.append(xy + noise)
    noisy = shapely.make_valid(shapely.Polygon(rings[0], rings[1:]))
    if not isinstance(noisy, shapely.Polygon):
        noisy = max((g for g in getattr(noisy, "geoms", []) if isinstance(g, shapely.Polygon)),
                    key=lambda g: g.area)
    return noisy


def iou(a, b):
    return a.intersection(b).area / a.union(b).area


def weighted(values, weights):
    values, weights = np.asarray(values), np.asarray(weights)
    return float(np.sum(values * weights) / np.sum(weights))


def run(polys, model, seed=0, **options):
    rng = np.random.default_rng(seed)
    rows = []
    red = {}
    for truth in polys:
        noisy = perturb(truth, model, rng)
        t0 = time.perf_counter()
        out, info = regularize_polygon(noisy, **options)
        dt = time.perf_counter() - t0
        for k, v in info["reductions"].items():
            red[k] = red.get(k, 0) + v
        rows.append({
            "al": aligned_fraction(out, dominant_direction(out), tol_deg=3.0),
            "al_bgt": aligned_fraction(truth, tol_deg=3.0),
            "al_noisy": aligned_fraction(noisy, dominant_direction(noisy), tol_deg=3.0),
            "len": out.length, "len_bgt": truth.length,
            "iou": iou(out, truth), "iou_noisy": iou(noisy, truth),
            "fallback": info["status"] != "regularized", "repaired": info.get("repaired", False),
            "dev": info["mean_deviation_m"], "t": dt,
            "nv": info["n_vertices"], "nv_bgt": len(truth.exterior.coords) - 1
            + sum(len(r.coords) - 1 for r in truth.interiors),
        })
    return rows, red


def report(name, rows, red):
    col = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    print(f"== {name}: {len(rows)} polygons ==")
    print(f"aligned within 3 deg (length-weighted): result {weighted(col['al'], col['len']):.3f}"
          f"  reference {weighted(col['al_bgt'], col['len_bgt']):.3f}"
          f"  noisy input {weighted(col['al_noisy'], col['len_bgt']):.3f}")
    print(f"IoU with reference: mean {col['iou'].mean():.3f}  median {np.median(col['iou']):.3f}"
          f"  >= 0.9: {np.mean(col['iou'] >= 0.9):.1%}  (noisy input mean {col['iou_noisy'].mean():.3f})")
    big = col["len_bgt"] >= 50
    print(f"IoU on polygons with perimeter >= 50 m ({big.sum()}): mean {col['iou'][big].mean():.3f};"
          f" smaller ones ({(~big).sum()}): {col['iou'][~big].mean():.3f}")
    obl = col["al_bgt"] < 0.9
    if obl.any():
        print(f"oblique walls ({obl.sum()} reference polygons with > 10 % oblique length): oblique share"
              f" reference {1 - weighted(col['al_bgt'][obl], col['len_bgt'][obl]):.3f},"
              f" result {1 - weighted(col['al'][obl], col['len'][obl]):.3f}")
    print(f"vertices: result mean {col['nv'].mean():.1f}, reference mean {col['nv_bgt'].mean():.1f};"
          f" mean deviation from input {col['dev'].mean():.3f} m")
    print(f"fallbacks {int(col['fallback'].sum())}, repaired {int(col['repaired'].sum())}")
    print("reductions (total): " + ", ".join(f"{k} {v}" for k, v in red.items()))
    print(f"time per polygon: mean {col['t'].mean() * 1e3:.1f} ms, max {col['t'].max() * 1e3:.1f} ms")
    print()


def main():
    data = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(os.environ.get("LIDAR2CITY_DATA", "../shared/data"))
    polys = load(data)
    for model in ("disc", "gauss"):
        rows, red = run(polys, model)
        report(f"{model} 0.3 m, default options", rows, red)
    rows, red = run(polys, "traced")
    report("traced from a 0.5 m raster (staircase outline), default options", rows, red)
    rows, red = run(polys, "disc", refine=False)
    report("disc 0.3 m, no offset refit (paper's grid positions)", rows, red)


if __name__ == "__main__":
    main()
