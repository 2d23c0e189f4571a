"""The segment refinement of SMRF's surface (``smrf_segments``) measured against smrf_refined.

Usage::

    python benchmarks/bench_ground_segments.py [--data DIR] [--no-loo]

``smrf_segments`` (:mod:`lidar2city.ground.segment_filter`) takes SMRF's
object cells (with the minimum surface continued 10 m across the tile edges,
as ``smrf_refined``), cuts them into smooth segments on cells of about the
measured point spacing and gives back to the terrain every segment raised
above it along less than a share ``raised`` of its boundary (a terrace top or
ground between buildings on a slope joins the terrain along much of it, a
building is raised all round); the surface is inpainted from the terrain
cells and SMRF's final test run against it.

Prints, per ISPRS sample in ``DIR/isprs/reference``: type I / type II / total
error % of ``smrf_refined`` and ``smrf_segments`` (defaults), their means;
the mean total error over the synthetic terrains of
:mod:`lidar2city.synthetic_terrain`; the small-tile case of ``tests/ground``
(a 10 m tile with a 4 m building in its middle: share of points right); then,
unless ``--no-loo``, the leave-one-sample-out check of ``bench_ground.py
--loo`` over the segment parameters only (jump and raised, 9 sets, SMRF's
parameters at their defaults; smrf_refined has nothing to choose there: its
mean). ``bench_ground.py --loo`` runs the check over SMRF's parameters (81
sets). A minute or two.

The hysteresis option (``strong_slope``, off by default) is measured beside
them as ``hysteresis``: ``smrf_segments`` at slope 0.1 (the slope the
leave-one-out grid chooses on all seven samples) with ``strong_slope`` 0.4,
an object region with no cell the opening cuts at 0.4 (no wall, no crown
edge) given back. ``--strong-loo`` adds the leave-one-out check of
``bench_ground.py --loo`` (81 sets over slope, window, scalar, threshold)
with ``strong_slope`` 0.4, to compare with ``bench_ground.py --loo
--loo-methods smrf_segments`` (a few more minutes).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_ground import (  # noqa: E402
    LOO_GRID,
    arg_parser,
    leave_one_out_method,
    load,
    reference_paths,
    synthetic_scenes,
)
from lidar2city.ground import GroundConfig, smrf_refined, smrf_segments  # noqa: E402
from lidar2city.metrics.ground import ground_errors  # noqa: E402

REFINED = GroundConfig(method="smrf_refined").method_params()
SEGMENTS = GroundConfig(method="smrf_segments").method_params()
HYSTERESIS = dict(SEGMENTS, slope=0.1, strong_slope=0.4)


def small_tile():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 10, (20000, 2))
    z = np.where((np.abs(xy[:, 0] - 5) < 2) & (np.abs(xy[:, 1] - 5) < 2), 7.0, 1.0)
    return np.column_stack([xy, z]), z == 1.0


def main():
    ap = arg_parser(__doc__)
    ap.add_argument("--no-loo", action="store_true")
    ap.add_argument("--strong-loo", action="store_true")
    args = ap.parse_args()
    refs = reference_paths(args.data)
    samples = {p.name.split("-")[0]: load(p) for p in refs}
    methods = {"refined": lambda xyz: smrf_refined(xyz, **REFINED),
               "segments": lambda xyz: smrf_segments(xyz, **SEGMENTS),
               "hysteresis": lambda xyz: smrf_segments(xyz, **HYSTERESIS)}
    print(f"smrf_segments defaults: {SEGMENTS}")
    print(f"{'sample':<8} " + " ".join(f"{m + ' ' + c:>17}" for m in methods
                                       for c in ("I", "II", "total")))
    rows = []
    for name, (xyz, ref) in samples.items():
        row = []
        for fn in methods.values():
            e = ground_errors(fn(xyz), ref)
            row += [e["type_i"], e["type_ii"], e["total"]]
        rows.append(row)
        print(f"{name:<8} " + " ".join(f"{100 * v:>17.2f}" for v in row), flush=True)
    print(f"{'mean':<8} " + " ".join(f"{100 * v:>17.2f}" for v in np.mean(rows, axis=0)))
    scenes = synthetic_scenes()
    for m, fn in methods.items():
        syn = np.mean([ground_errors(fn(s.xyz), s.ground)["total"] for s in scenes.values()])
        xyz, truth = small_tile()
        print(f"{m}: synthetic terrains mean total {100 * syn:.2f} % ({len(scenes)} scenes); "
              f"small tile with a building {100 * (fn(xyz) == truth).mean():.1f} % right")
    if not args.no_loo:
        leave_one_out_method("smrf_segments (SMRF defaults)", smrf_segments, SEGMENTS,
                             {"jump": (0.5, 0.6, 0.75), "raised": (0.5, 0.6, 0.7)},
                             samples, scenes)
    if args.strong_loo:
        leave_one_out_method("smrf_segments strong_slope=0.4", smrf_segments, HYSTERESIS,
                             LOO_GRID["smrf_segments"], samples, scenes)


if __name__ == "__main__":
    main()
