"""How far one SMRF parameter set is from the best per sample, and what a perfect surface repair gives.

Usage::

    python benchmarks/bench_ground_slope.py [--data DIR]

Issue 18 asks for a leave-one-sample-out total error of at most 3 % on the
seven shared ISPRS samples. This script measures two bounds of the SMRF
family (``smrf_refined`` and ``smrf_segments``) on ``DIR/isprs/reference``:

* **slope chosen per sample with hindsight**: the total error % of each
  sample for SMRF's ``slope`` in :data:`SLOPES` (every other parameter at
  its default), the best slope of each sample and the mean of those bests.
  No single parameter set, and so no leave-one-out choice, can beat that
  mean along this axis; the samples disagree on the direction (flat urban
  samp31 and rural samp51 want 0.1, samp61's steep-sided embankments want
  0.3-0.4), which is what the leave-one-out check punishes.
* **restoration oracle**: SMRF's (``smrf_refined``'s) object cells whose
  lowest point is reference ground given back to the terrain before the
  surface is inpainted and the final test run (a perfect version of any
  "give back terrain-like object cells" step such as ``smrf_segments``), and, second, also the terrain cells whose lowest point is a
  reference object taken out (a perfect surface on SMRF's grid).

Then the same slope table for ``smrf_segments`` with its hysteresis option
(``strong_slope`` 0.4), and a leave-one-sample-out check of terrain-slope
estimators (:func:`estimator_check`): is there a statistic of the tile
(percentiles of the gradient of SMRF's provisional surface, the share of
object cells) from which a threshold rule, chosen on the six other samples
plus the synthetic terrains, predicts each held-out sample's slope?

A few minutes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_ground import arg_parser, load, reference_paths, synthetic_scenes  # noqa: E402
from lidar2city.ground import (  # noqa: E402
    GroundConfig,
    low_outliers,
    smrf_refined,
    smrf_segments,
    smrf_surface,
)
from lidar2city.ground._grid import cell_of, gradient_magnitude, inpaint, min_surface  # noqa: E402
from lidar2city.ground.smrf_filter import _near_surface  # noqa: E402
from lidar2city.metrics.ground import ground_errors  # noqa: E402

REFINED = GroundConfig(method="smrf_refined").method_params()
SEGMENTS = GroundConfig(method="smrf_segments").method_params()
SLOPES = (0.1, 0.15, 0.2, 0.25, 0.3, 0.4)


def slope_table(samples, name, fn):
    """Print total error % per sample and slope of ``fn(xyz, slope=s)``; return the rows."""
    print(f"\n{name}: total error % by SMRF slope (other parameters at their defaults)")
    print(f"{'sample':<8} " + " ".join(f"{s:>6g}" for s in SLOPES) + f" {'best':>6} {'at':>5}")
    rows = []
    for n, (xyz, ref) in samples.items():
        row = [100 * ground_errors(fn(xyz, slope=s), ref)["total"] for s in SLOPES]
        rows.append(row)
        i = int(np.argmin(row))
        print(f"{n:<8} " + " ".join(f"{v:>6.2f}" for v in row)
              + f" {row[i]:>6.2f} {SLOPES[i]:>5g}", flush=True)
    rows = np.array(rows)
    means = rows.mean(axis=0)
    print(f"{'mean':<8} " + " ".join(f"{v:>6.2f}" for v in means))
    print(f"{name}: best single slope {SLOPES[int(np.argmin(means))]:g} mean "
          f"{means.min():.2f} %; slope chosen per sample with hindsight mean "
          f"{rows.min(axis=1).mean():.2f} % (max {rows.min(axis=1).max():.2f} %)")
    return rows


def terrain_features(xyz):
    """Statistics of a tile a slope estimator could read: percentiles of the gradient of
    SMRF's provisional surface (defaults of ``smrf_refined``) over the filled cells, and the
    share of filled cells the opening judges object."""
    p = REFINED
    out = low_outliers(xyz, radius=p["outlier_radius"], depth=p["outlier_depth"])
    surface, objects, spec = smrf_surface(xyz, cell=p["cell"], slope=p["slope"],
                                          window=p["window"], exclude=out, extend=p["extend"])
    pts = xyz[~out]
    filled = ~np.isnan(min_surface(pts, spec, base=float(pts[:, 2].min()), dtype=np.float32))
    grad = gradient_magnitude(surface, spec.cell)[filled]
    feats = {f"grad p{q}": float(np.percentile(grad, q)) for q in (50, 90, 95)}
    feats["object share"] = float(objects[filled].mean())
    return feats


def estimator_check(samples, rows, scenes, syn_rows):
    """Leave-one-sample-out check of slope estimators ``slope = hi if feature < t else lo``
    (or ``>``), the rule chosen on the six other samples plus the synthetic terrains
    (their mean one more sample) among every feature, threshold (midpoints of the
    seven samples' values) and pair ``lo < hi`` of :data:`SLOPES`; prints the predicted and
    hindsight slopes and the held-out total error %."""
    names = list(samples)
    feats = {n: terrain_features(xyz) for n, (xyz, _) in samples.items()}
    syn_feats = [terrain_features(s.xyz) for s in scenes.values()]
    keys = list(feats[names[0]])
    print("\nterrain-slope estimators (smrf_segments): features per sample and the best slope")
    print(f"{'sample':<8} " + " ".join(f"{k:>12}" for k in keys) + f" {'best slope':>10}")
    for n, row in zip(names, rows):
        print(f"{n:<8} " + " ".join(f"{feats[n][k]:>12.3f}" for k in keys)
              + f" {SLOPES[int(np.argmin(row))]:>10g}")
    rules = []
    for k in keys:
        vals = np.sort([feats[n][k] for n in names])
        for t in (vals[1:] + vals[:-1]) / 2:
            for i in range(len(SLOPES)):
                for j in range(i + 1, len(SLOPES)):
                    for below_high in (True, False):
                        def pick(f, k=k, t=t, i=i, j=j, below_high=below_high):
                            return j if (f[k] < t) == below_high else i
                        real = np.array([row[pick(feats[n])] for n, row in zip(names, rows)])
                        syn = np.mean([row[pick(f)] for f, row in zip(syn_feats, syn_rows)])
                        rules.append((f"{k} {'<' if below_high else '>'} {t:.3f}: {SLOPES[j]:g} "
                                      f"else {SLOPES[i]:g}", pick, real, syn))
    held = []
    for h, n in enumerate(names):
        keep = np.arange(len(names)) != h
        name, pick, real, _ = min(rules, key=lambda r: np.mean(np.r_[r[2][keep], r[3]]))
        held.append(real[h])
        print(f"{n:<8} held-out {real[h]:5.2f} %  predicted slope {SLOPES[pick(feats[n])]:g}, "
              f"hindsight {SLOPES[int(np.argmin(rows[h]))]:g}  (rule {name})")
    print(f"slope estimator leave-one-out mean total {np.mean(held):.2f} %, max {np.max(held):.2f} % "
          f"(constant default slope: {np.mean(rows[:, SLOPES.index(SEGMENTS['slope'])]):.2f} %)")


def lowest_labels(pts, ref, spec):
    """Reference label of the lowest point of each cell (-1 where empty), shape ``spec.shape``."""
    r, c = cell_of(pts[:, :2], spec)
    flat = r * spec.shape[1] + c
    order = np.lexsort((pts[:, 2], flat))
    first = np.r_[True, flat[order][1:] != flat[order][:-1]]
    lab = np.full(spec.shape[0] * spec.shape[1], -1)
    lab[flat[order][first]] = ref[order][first]
    return lab.reshape(spec.shape)


def oracle(xyz, ref, *, remove_missed):
    """smrf_refined with its object cells corrected by the reference (see the module doc)."""
    p = REFINED
    out = low_outliers(xyz, radius=p["outlier_radius"], depth=p["outlier_depth"])
    pts, rf = xyz[~out], ref[~out]
    _, objects, spec = smrf_surface(xyz, cell=p["cell"], slope=p["slope"], window=p["window"],
                                    exclude=out, extend=p["extend"])
    base = float(pts[:, 2].min())
    zmin = min_surface(pts, spec, base=base, dtype=np.float32)
    lab = lowest_labels(pts, rf, spec)
    kept = objects & (lab != 1)
    if remove_missed:
        kept |= lab == 0
    surface = inpaint(np.where(kept | np.isnan(zmin), np.float32(np.nan), zmin))
    ground = _near_surface(xyz, surface.astype(np.float64) + base, spec,
                           threshold=p["threshold"], scalar=p["scalar"])
    return ground & ~out


def main():
    args = arg_parser(__doc__).parse_args()
    samples = {p.name.split("-")[0]: load(p) for p in reference_paths(args.data)}
    slope_table(samples, "smrf_refined", lambda xyz, slope: smrf_refined(
        xyz, **dict(REFINED, slope=slope)))
    rows = slope_table(samples, "smrf_segments", lambda xyz, slope: smrf_segments(
        xyz, **dict(SEGMENTS, slope=slope)))
    slope_table(samples, "smrf_segments strong_slope=0.4", lambda xyz, slope: smrf_segments(
        xyz, **dict(SEGMENTS, slope=slope, strong_slope=0.4)))
    scenes = synthetic_scenes()
    syn_rows = [[100 * ground_errors(smrf_segments(s.xyz, **dict(SEGMENTS, slope=slope)),
                                     s.ground)["total"] for slope in SLOPES]
                for s in scenes.values()]
    estimator_check(samples, rows, scenes, syn_rows)
    print("\nrestoration oracle: total error % (type I / type II) of smrf_refined with its "
          "object cells corrected by the reference")
    print(f"{'sample':<8} {'refined':>18} {'give back ground':>18} {'+ take out objects':>19}")
    rows = []
    for n, (xyz, ref) in samples.items():
        es = [ground_errors(m, ref) for m in (smrf_refined(xyz, **REFINED),
                                              oracle(xyz, ref, remove_missed=False),
                                              oracle(xyz, ref, remove_missed=True))]
        rows.append([e["total"] for e in es])
        cells = [f"{100 * e['total']:.2f} ({100 * e['type_i']:.1f}/{100 * e['type_ii']:.1f})"
                 for e in es]
        print(f"{n:<8} " + " ".join(f"{c:>18}" for c in cells), flush=True)
    m = 100 * np.mean(rows, axis=0)
    print(f"{'mean':<8} {m[0]:>18.2f} {m[1]:>18.2f} {m[2]:>18.2f}")


if __name__ == "__main__":
    main()
