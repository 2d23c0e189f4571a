"""``lidar2city rasterize`` on the Delft AHN3 tile against the shared 0.5 m rasters.

Usage: ``PYTHONPATH=src python benchmarks/bench_rasterize.py [DATA_DIR]``

The shared ``delft/dsm_50cm.tif`` and ``dtm_50cm.tif`` were made from
``ahn3_cropped_1.laz`` by taking the highest point per 0.5 m cell (noise left
out, empty cells from the nearest filled one) and the mean of the ground
points per cell with gaps interpolated. This script makes the same products
with ``rasterize_files`` and prints the grids' agreement and the per-pixel
differences, and the time against reading the tile alone (laspy), measured
in the same run.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main(data=None):
    import laspy

    from lidar2city.io.raster import read_raster
    from lidar2city.tools.rasterize import rasterize_files

    root = Path(data) if data else Path(__file__).resolve().parents[2] / "shared" / "data"
    if not (root / "delft").exists():
        root = Path("/work/shared/data")
    laz = root / "delft" / "ahn3_cropped_1.laz"
    t0 = time.perf_counter()
    laspy.read(laz)
    t_read = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        for product in ("dsm", "dtm"):
            out = Path(tmp) / f"{product}.tif"
            t0 = time.perf_counter()
            s = rasterize_files(laz, out, product=product, cell=0.5, crs="EPSG:28992")
            el = time.perf_counter() - t0
            ours, shared = read_raster(out), read_raster(root / "delft" / f"{product}_50cm.tif")
            same_grid = ours.transform == shared.transform and ours.shape == shared.shape
            d = np.abs(ours.array - shared.array)
            ok = np.isfinite(d)
            print(f"{product}: {s['shape'][1]} x {s['shape'][0]} cells, same grid as the shared "
                  f"raster: {same_grid}; |ours - shared| max {d[ok].max():.4f} m, median "
                  f"{np.median(d[ok]):.4f} m, 95th percentile {np.percentile(d[ok], 95):.4f} m, "
                  f"identical (< 1 mm) {100 * np.mean(d[ok] < 1e-3):.1f} % of {ok.sum()} cells; "
                  f"{el:.2f} s ({el / t_read:.1f}x reading the tile with laspy)")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
