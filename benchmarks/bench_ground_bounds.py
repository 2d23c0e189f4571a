"""Where the ground filter's ISPRS errors come from, and what other filter families give.

Usage::

    python benchmarks/bench_ground_bounds.py [--data DIR] [--no-csf]

For each ISPRS reference sample in ``DIR/isprs/reference`` prints, as total
error % (type I / type II where said):

* ``refined``: ``smrf_refined`` with its defaults (the figure of
  ``bench_ground.py``), with type I and type II;
* ``surface bound``: the same final test (points within ``threshold + scalar
  * slope`` of a surface) against the terrain interpolated from the
  *reference* ground points (:func:`~lidar2city.ground.dtm_from_ground`):
  what a perfect provisional surface would give; the gap to ``refined`` is
  the error of SMRF's surface, not of its final test;
* ``open 3 m``: type I of SMRF with the largest opening radius cut to 3 m:
  ground the opening removes at the smallest scales (steep slopes, terrace
  edges), which no larger window brings back;
* ``slope-adaptive``: SMRF whose object test allows ``slope + adapt * g``
  per unit radius, ``g`` the gradient of the fully opened surface (terrain
  slope with buildings removed), ``adapt`` 0.25 and 0.5;
* ``cell vote``: a point is ground when ``smrf_refined`` with cells of 0.75,
  1, 1.25, 1.5 and 2 m calls it ground at least twice (a multi-resolution
  combination, five filter runs);
* ``plane cleanup``: one round adding points within 0.3 m of the
  least-squares plane of their 8 nearest ground points of ``smrf_refined``
  (a surface-based cleanup that follows slopes instead of a smooth fill);
* ``csf``: the cloth simulation filter (Zhang et al. 2016) of the
  ``cloth-simulation-filter`` package, low outliers removed first, cloth
  resolution 1 m, rigidness 1 and 2, 200 iterations; skipped when the package
  is not installed (it is not a dependency of lidar2city).

And the mean over the seven samples. A minute or two (CSF is the slow part).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_ground import arg_parser, load, reference_paths  # noqa: E402
from lidar2city.ground import GroundConfig, dtm_from_ground, low_outliers, smrf_refined  # noqa: E402
from lidar2city.ground._grid import (  # noqa: E402
    gradient_magnitude,
    grid_spec,
    inpaint,
    min_surface,
    open_disk_series,
)
from lidar2city.ground.smrf_filter import _near_surface  # noqa: E402
from lidar2city.metrics.ground import ground_errors  # noqa: E402

DEFAULTS = GroundConfig(method="smrf_refined").method_params()


def surface_bound(xyz, ref):
    dtm = dtm_from_ground(xyz, ref, cell=DEFAULTS["cell"])
    return _near_surface(xyz, dtm.array, dtm.spec, threshold=DEFAULTS["threshold"],
                         scalar=DEFAULTS["scalar"])


def slope_adaptive(xyz, adapt):
    """SMRF (defaults of smrf_refined) with the object test relaxed by the terrain slope."""
    p = DEFAULTS
    cell = p["cell"]
    out = low_outliers(xyz, radius=p["outlier_radius"], depth=p["outlier_depth"])
    pts = xyz[~out]
    spec = grid_spec(pts[:, :2], cell=cell)
    base = float(pts[:, 2].min())
    zmin = min_surface(pts, spec, base=base, dtype=np.float32)
    filled = inpaint(zmin)
    pad = min(int(np.ceil(p["extend"] / cell)), *(n - 1 for n in spec.shape))
    filled = np.pad(filled, pad, mode="reflect", reflect_type="odd")
    # largest drop per unit radius over the opening series
    ratio = np.zeros(filled.shape, dtype=np.float32)
    last = filled
    radii = range(1, int(np.ceil(p["window"] / cell)) + 1)
    for radius, opened in open_disk_series(filled, radii):
        np.maximum(ratio, (last - opened) / np.float32(radius * cell), out=ratio)
        last = opened
    objects = (ratio > p["slope"] + adapt * gradient_magnitude(last, cell))
    objects = objects[pad:-pad, pad:-pad] if pad else objects
    surface = inpaint(np.where(objects | np.isnan(zmin), np.float32(np.nan), zmin))
    ground = _near_surface(xyz, surface.astype(np.float64) + base, spec,
                           threshold=p["threshold"], scalar=p["scalar"])
    return ground & ~out


def cell_vote(xyz):
    votes = sum(smrf_refined(xyz, **dict(DEFAULTS, cell=c)).astype(int)
                for c in (0.75, 1.0, 1.25, 1.5, 2.0))
    return votes >= 2


def plane_cleanup(xyz, ground, *, k=8, tolerance=0.3):
    from scipy.spatial import cKDTree

    out = low_outliers(xyz, radius=DEFAULTS["outlier_radius"], depth=DEFAULTS["outlier_depth"])
    gp = xyz[ground]
    cand = np.flatnonzero(~ground & ~out)
    _, idx = cKDTree(gp[:, :2]).query(xyz[cand, :2], k=k)
    nb = gp[idx]
    c = nb.mean(axis=1)
    a = nb - c[:, None, :]
    sxx, sxy, syy = (a[..., 0] ** 2).sum(1), (a[..., 0] * a[..., 1]).sum(1), (a[..., 1] ** 2).sum(1)
    sxz, syz = (a[..., 0] * a[..., 2]).sum(1), (a[..., 1] * a[..., 2]).sum(1)
    det = sxx * syy - sxy ** 2
    ok = det > 1e-6 * (sxx + syy) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        gx = np.where(ok, (sxz * syy - syz * sxy) / det, 0.0)
        gy = np.where(ok, (syz * sxx - sxz * sxy) / det, 0.0)
    pred = c[:, 2] + gx * (xyz[cand, 0] - c[:, 0]) + gy * (xyz[cand, 1] - c[:, 1])
    grown = ground.copy()
    grown[cand[np.abs(xyz[cand, 2] - pred) < tolerance]] = True
    return grown


def csf(xyz, rigidness):
    import CSF

    out = low_outliers(xyz, radius=DEFAULTS["outlier_radius"], depth=DEFAULTS["outlier_depth"])
    c = CSF.CSF()
    c.params.bSloopSmooth = True
    c.params.cloth_resolution = 1.0
    c.params.rigidness = rigidness
    c.params.class_threshold = 0.5
    c.params.interations = 200
    keep = np.flatnonzero(~out)
    c.setPointCloud(np.ascontiguousarray(xyz[keep]))
    g, ng = CSF.VecInt(), CSF.VecInt()
    # the package prints its progress on file descriptor 1: silence it
    sys.stdout.flush()
    saved, devnull = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        c.do_filtering(g, ng, exportCloth=False)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)
    ground = np.zeros(len(xyz), dtype=bool)
    ground[keep[np.asarray(g, dtype=np.int64)]] = True
    return ground


def main():
    ap = arg_parser(__doc__)
    ap.add_argument("--no-csf", action="store_true")
    args = ap.parse_args()
    refs = reference_paths(args.data)
    try:
        import CSF  # noqa: F401
        have_csf = not args.no_csf
    except ImportError:
        have_csf = False
        print("csf skipped: pip install cloth-simulation-filter to include it")
    cols = ["refined I", "refined II", "refined", "surface bound", "open 3 m I",
            "adapt 0.25", "adapt 0.5", "cell vote", "plane cleanup"]
    if have_csf:
        cols += ["csf rig 1", "csf rig 2"]
    print(f"{'sample':<8} " + " ".join(f"{c:>13}" for c in cols))
    rows = []
    for path in refs:
        xyz, ref = load(path)
        refined = smrf_refined(xyz, **DEFAULTS)
        e = ground_errors(refined, ref)
        small = smrf_refined(xyz, **dict(DEFAULTS, window=3.0))
        masks = [surface_bound(xyz, ref), None, slope_adaptive(xyz, 0.25),
                 slope_adaptive(xyz, 0.5), cell_vote(xyz), plane_cleanup(xyz, refined)]
        if have_csf:
            masks += [csf(xyz, 1), csf(xyz, 2)]
        row = [e["type_i"], e["type_ii"], e["total"]]
        for m in masks:
            row.append(ground_errors(small, ref)["type_i"] if m is None
                       else ground_errors(m, ref)["total"])
        rows.append(row)
        print(f"{path.name.split('-')[0]:<8} " + " ".join(f"{100 * v:>13.2f}" for v in row),
              flush=True)
    print(f"{'mean':<8} " + " ".join(f"{100 * v:>13.2f}" for v in np.mean(rows, axis=0)))


if __name__ == "__main__":
    main()
