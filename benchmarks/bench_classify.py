"""Building / vegetation separation on the shared real data.

Prints per file the building and vegetation precision / recall / F1 and the
time of :func:`lidar2city.classify.classify_points`, twice: with the file's
own ground class as the ground mask, and with a simple stand-in ground filter
(lowest point per 1 m cell, grey opening of 25 m, points within 0.5 m of the
opened surface and 1 m of the cell minimum) so the dependence on the ground
mask is known (the stand-in needs a tile much wider than its 25 m window: on
the 18 m x 12 m Nebraska sample it is not meaningful). Then the Delft tile
thinned at random to 1/2, 1/4 and 1/8 of its density, with and without
return numbers, for the dependence on density and on the return cue.

Reference mappings: AHN (Delft) class 6 building, class 1 "unclassified
(vegetation and other)" counted as vegetation, 9 water and 26 civil
structures ignored; ASPRS files 3/4/5 vegetation, 6 building, 7 noise ignored.

Run: ``PYTHONPATH=src python benchmarks/bench_classify.py [DATA_DIR]``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

from lidar2city.classify import classify_points
from lidar2city.io.las import read_points
from lidar2city.metrics.classification import ASPRS_MAPPING, classification_scores

AHN = {6: "building", 1: "vegetation", 2: "ground"}

FILES = [
    # path, crs, reference mapping, ignored reference codes
    ("delft/ahn3_cropped_1.laz", "EPSG:7415", AHN, (9, 26)),
    ("misc/file_with_both_wkt_and_geotiff_vlrs.las", None, ASPRS_MAPPING, (7,)),
    ("misc/autzen_trim.laz", None, None, ()),
]


def stand_in_ground(xyz, *, cell=1.0, window=25.0, tol=0.5):
    """A crude one-window morphological ground filter (not the project's ground filter)."""
    from scipy import ndimage

    ij = np.floor((xyz[:, :2] - xyz[:, :2].min(axis=0)) / cell).astype(np.int64)
    shape = ij.max(axis=0) + 1
    zmin = np.full(shape, np.inf)
    np.minimum.at(zmin, (ij[:, 0], ij[:, 1]), xyz[:, 2])
    empty = ~np.isfinite(zmin)
    _, (a, b) = ndimage.distance_transform_edt(empty, return_indices=True)
    zmin = zmin[a, b]
    w = int(window / cell) | 1
    opened = ndimage.grey_opening(zmin, size=(w, w))
    surf = opened[ij[:, 0], ij[:, 1]]
    cellmin = zmin[ij[:, 0], ij[:, 1]]
    return (xyz[:, 2] - surf < tol) & (xyz[:, 2] - cellmin < 1.0)


def main(data: Path):
    print(f"{'file':<44} {'ground':<9} {'class':<10} {'P':>6} {'R':>6} {'F1':>6} {'time s':>7}")
    for rel, crs, mapping, ignore in FILES:
        path = data / rel
        if not path.exists():
            print(f"{rel}: missing, skipped")
            continue
        cloud = read_points(path, crs=crs)
        a = cloud.attributes
        ref = a["classification"]
        rgb = None
        if all(k in a for k in ("red", "green", "blue")):
            rgb = np.column_stack([a["red"], a["green"], a["blue"]])
        for gname, ground in (("file", ref == 2), ("stand-in", stand_in_ground(cloud.xyz))):
            t0 = time.perf_counter()
            cls = classify_points(cloud.xyz, ground, return_number=a.get("return_number"),
                                  number_of_returns=a.get("number_of_returns"), rgb=rgb)
            dt = time.perf_counter() - t0
            if mapping is None:
                counts = dict(zip(*np.unique(cls, return_counts=True), strict=True))
                print(f"{rel:<44} {gname:<9} (no building/vegetation reference) classes "
                      + ", ".join(f"{int(k)}: {int(v)}" for k, v in counts.items())
                      + f"  {dt:7.2f}")
                continue
            s = classification_scores(ref, cls, mapping=mapping, predicted_mapping=ASPRS_MAPPING,
                                      ignore=ignore)
            for k in ("building", "vegetation"):
                print(f"{rel:<44} {gname:<9} {k:<10} {s.precision[k]:6.3f} {s.recall[k]:6.3f} "
                      f"{s.f1[k]:6.3f} {dt:7.2f}")
            print(f"{'':<44} {gname:<9} overall accuracy {s.overall_accuracy:.3f}, "
                  f"kappa {s.kappa:.3f}")


def density_sweep(data: Path):
    """Delft thinned at random to lower densities, with and without return numbers."""
    path = data / "delft" / "ahn3_cropped_1.laz"
    if not path.exists():
        return
    cloud = read_points(path, crs="EPSG:7415")
    a = cloud.attributes
    rng = np.random.default_rng(0)
    u = rng.random(len(cloud))
    print("\nDelft thinned at random (ground = AHN class 2):")
    print(f"{'keep':>5} {'pts/m2':>7} {'returns':<8} {'bld P':>6} {'bld R':>6} {'bld F1':>6} "
          f"{'veg P':>6} {'veg R':>6} {'veg F1':>6} {'time s':>7}")
    for keep in (1.0, 0.5, 0.25, 0.12):
        sel = u < keep
        ref = a["classification"][sel]
        for returns in (True, False):
            t0 = time.perf_counter()
            cls = classify_points(
                cloud.xyz[sel], ref == 2,
                return_number=a["return_number"][sel] if returns else None,
                number_of_returns=a["number_of_returns"][sel] if returns else None)
            dt = time.perf_counter() - t0
            s = classification_scores(ref, cls, mapping=AHN, predicted_mapping=ASPRS_MAPPING,
                                      ignore=(9, 26))
            print(f"{keep:5.2f} {16.1 * keep:7.1f} {'yes' if returns else 'no':<8} "
                  f"{s.precision['building']:6.3f} {s.recall['building']:6.3f} "
                  f"{s.f1['building']:6.3f} {s.precision['vegetation']:6.3f} "
                  f"{s.recall['vegetation']:6.3f} {s.f1['vegetation']:6.3f} {dt:7.2f}")


if __name__ == "__main__":
    default = os.environ.get("LIDAR2CITY_DATA", Path(__file__).resolve().parents[1].parent
                             / "shared" / "data")
    folder = Path(sys.argv[1] if len(sys.argv) > 1 else default)
    main(folder)
    density_sweep(folder)
