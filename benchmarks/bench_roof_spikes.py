"""LoD2.2 roofs rising above every point of their building (roof spikes).

Usage: python benchmarks/bench_roof_spikes.py [DATA_DIR] [--over 1.0] [--sites CSite2,...]
       [--no-delft] [--no-sites]
(default data $LIDAR2CITY_DATA or ../shared/data)

For each input, ``reconstruct`` (LoD 1.2 + 2.2, one process) runs as the CLI
does; every building's highest LoD2.2 vertex is compared with the highest of
the building points its roof was fitted to (those within the ``[lod22]
overhang`` of its footprint). Printed per input: the buildings whose roof
rises more than ``--over`` metres (default 1 m), more than 2 m, and more than
the spacing-scaled tolerance ``t_step + max(spacing / 2, 2 t_step)``, ``t_step = 2
elevation_error`` (a ridge between points one spacing apart is at most half a
spacing from the nearest; a step at least; the building's point spacing
``sqrt(area / points)`` over its grown footprint; the most the roof's spike check,
``roof.building._fix_high_faces``, lets a face rise over its highest near point) above
their highest point, out of the buildings with a LoD2.2 roof (LoD1.2 fallbacks
included: their prism's roof never rises above its points), the largest rise,
the median LoD2.2 RMSE of those points (point to mesh, as ``evaluate model``:
capping a roof must not cost its fit) and the worst 5 (id, rise, roof top,
highest point, spacing, LoD2.2 fallback reason if any).

Inputs: the ISPRS raw sites in ``isprs/sites`` (classified and traced by
reconstruct, no footprints), the ISPRS sample ``isprs/reference/samp11-utm.laz`` when present,
and the Delft tile with its BGT footprints.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def option(name, default=None):
    argv = sys.argv[1:]
    return argv[argv.index(name) + 1] if name in argv and argv.index(name) + 1 < len(argv) else default


def measure(inputs, footprints=None):
    """``[(id, rise, roof_top, highest_point, fallback, spacing, rmse)]`` of every building
    with a LoD2.2 model in ``reconstruct(inputs, footprints=footprints, lods=1.2 + 2.2)``."""
    import shapely

    from lidar2city.metrics.model import model_rmse
    from lidar2city.roof.building import Lod22Config
    from lidar2city.tools import reconstruct as rec

    overhang = Lod22Config().overhang
    rows = []
    original = rec.add_lod22

    def recording(result, footprint, building_xyz, config, **kw):
        original(result, footprint, building_xyz, config, **kw)
        solids = result.solids.get("2.2")
        if solids is None:
            return
        xyz = np.asarray(building_xyz, dtype=np.float64).reshape(-1, 3)
        grown = footprint.buffer(overhang)
        near = xyz[shapely.contains_xy(grown, xyz[:, 0], xyz[:, 1])]
        if not len(near):
            return
        solids = solids if isinstance(solids, list) else [solids]
        top = max(float(s.vertices[:, 2].max()) for s in solids)
        high = float(near[:, 2].max())
        spacing = float(np.sqrt(grown.area / len(near)))
        inside = near[shapely.contains_xy(footprint, near[:, 0], near[:, 1])]
        rmse = model_rmse(inside, solids) if len(inside) else np.nan
        rows.append((result.id, top - high, top, high, result.attributes.get("lod22_fallback", ""),
                     spacing, rmse))

    rec.add_lod22 = recording  # the benchmark's probe, for this process only
    try:
        with tempfile.TemporaryDirectory() as tmp:
            rec.reconstruct(inputs, os.path.join(tmp, "out.city.json"), footprints=footprints,
                            lods=("1.2", "2.2"), workers=1)
    finally:
        rec.add_lod22 = original
    return rows


def report(name, rows, over, seconds):
    from lidar2city.roof.building import Lod22Config

    t_step = 2 * Lod22Config().elevation_error
    rise = np.array([r[1] for r in rows]) if rows else np.zeros(0)
    scaled = np.array([t_step + max(r[5] / 2, 2 * t_step) for r in rows]) if rows else np.zeros(0)
    worst = sorted(rows, key=lambda r: -r[1])[:5]
    print(f"{name}: {np.count_nonzero(rise > over)} of {len(rows)} LoD2.2 roofs rise > {over:g} m "
          f"above their highest point, {np.count_nonzero(rise > 2.0)} > 2 m, "
          f"{np.count_nonzero(rise > scaled)} > {t_step:g} m + max(spacing / 2, {2 * t_step:g} m); largest rise "
          f"{rise.max() if len(rise) else 0:+.2f} m; LoD2.2 RMSE median "
          f"{np.nanmedian([r[6] for r in rows]) if rows else np.nan:.3f} m ({seconds:.0f} s)")
    for fid, r, top, high, why, spacing, _ in worst:
        print(f"    {fid}: {r:+.2f} m (roof top {top:.2f}, highest point {high:.2f}, spacing {spacing:.2f} m)"
              + (f" [{why[:70]}]" if why else ""))


def main():
    args = [a for i, a in enumerate(sys.argv[1:]) if not a.startswith("--")
            and (i == 0 or not sys.argv[i].startswith("--"))]
    data = Path(args[0] if args else os.environ.get("LIDAR2CITY_DATA", "../shared/data"))
    over = float(option("--over", 1.0))
    sites = option("--sites")
    jobs = []
    if "--no-sites" not in sys.argv:
        for p in sorted((data / "isprs" / "sites").glob("*.laz")):
            if sites is None or p.name.split("_")[0] in sites.split(","):
                jobs.append((p.name.split("_")[0], [str(p)], None))
        samp = sorted((data / "isprs" / "reference").glob("samp11*.la[sz]"))
        if samp and (sites is None or "samp11" in sites.split(",")):
            jobs.append(("samp11", [str(samp[0])], None))
    if "--no-delft" not in sys.argv:
        delft = data / "delft"
        jobs.append(("Delft (BGT footprints)", [str(delft / "ahn3_cropped_1.laz")],
                     str(delft / "footprints_bgt.gpkg")))
    for name, inputs, fp in jobs:
        t0 = time.process_time()
        rows = measure(inputs, fp)
        report(name, rows, over, time.process_time() - t0)


if __name__ == "__main__":
    main()
