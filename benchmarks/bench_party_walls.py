"""What the points show at the BGT's party walls of the Delft tile: the roof step across each wall.

Usage: python benchmarks/bench_party_walls.py [DATA_DIR] [--offset M] [--cell M]
(default data $LIDAR2CITY_DATA or ../shared/data; offset 0.75 m, cell 0.5 m)

The traced path splits a block of buildings where its roof jumps (``footprints.split_step``,
2 m by default): row houses come out as one footprint per block of one height. This
measures whether a smaller step could find the BGT's party walls at all. The highest
building point (class 6) per ``cell`` is taken as the roof; every wall two BGT
footprints share (a common boundary of at least 2 m) is sampled every 0.25 m, and at each
sample the roof is read ``offset`` metres to either side, along the wall's normal. A
wall's step is the median over its samples of the height difference (cells without a
point left out; a wall with fewer than 4 samples read on both sides is not counted).
Prints how many walls step by more than 0.25 / 0.5 / 1 / 1.5 / 2 m, and, for comparison,
the same statistic across lines drawn inside each footprint, parallel to its longest
party wall and halfway to the opposite one (no wall: a split there would be a false
one).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--offset", type=float, default=0.75)
    ap.add_argument("--cell", type=float, default=0.5)
    args = ap.parse_args()
    data = Path(args.data or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")

    import numpy as np
    import shapely

    from lidar2city.io.las import read_las
    from lidar2city.io.vector import read_footprints

    las = read_las(data / "delft" / "ahn3_cropped_1.laz", crs="EPSG:7415").data
    origin = np.floor(np.array([las.header.mins[0], las.header.mins[1]]))
    xyz = np.column_stack([np.asarray(las.x) - origin[0], np.asarray(las.y) - origin[1],
                           np.asarray(las.z)])[np.asarray(las.classification) == 6]
    fps, _ = read_footprints(data / "delft" / "footprints_bgt.gpkg", origin=origin)
    polys = [g for g in fps.geometries if g is not None]

    cell = args.cell
    lo = xyz[:, :2].min(axis=0)
    ij = np.floor((xyz[:, :2] - lo) / cell).astype(np.int64)
    shape = ij.max(axis=0) + 1
    roof = np.full(int(shape[0] * shape[1]), -np.inf)
    np.maximum.at(roof, ij[:, 0] * shape[1] + ij[:, 1], xyz[:, 2])
    roof[~np.isfinite(roof)] = np.nan
    roof = roof.reshape(shape)

    def height(pts):
        k = np.floor((pts - lo) / cell).astype(np.int64)
        ok = (k >= 0).all(axis=1) & (k < shape).all(axis=1)
        out = np.full(len(pts), np.nan)
        out[ok] = roof[k[ok, 0], k[ok, 1]]
        return out

    def step_across(line):
        """Median roof step across a line (None when too few samples are read)."""
        n = max(int(line.length / 0.25), 1)
        t = (np.arange(n) + 0.5) / n
        p = shapely.get_coordinates(shapely.line_interpolate_point(line, t, normalized=True))
        q = shapely.get_coordinates(shapely.line_interpolate_point(
            line, np.clip(t + 0.05 / max(line.length, 1e-9), 0, 1), normalized=True))
        d = q - p
        d /= np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
        nrm = np.column_stack([-d[:, 1], d[:, 0]])
        dh = np.abs(height(p + args.offset * nrm) - height(p - args.offset * nrm))
        dh = dh[np.isfinite(dh)]
        return float(np.median(dh)) if len(dh) >= 4 else None

    tree = shapely.STRtree(polys)
    a_idx, b_idx = tree.query(polys, predicate="intersects")
    walls, inner = [], []
    longest: dict = {}
    for a, b in zip(a_idx.tolist(), b_idx.tolist(), strict=True):
        if a >= b:
            continue
        shared = shapely.line_merge(shapely.intersection(polys[a].boundary, polys[b].boundary))
        parts = [g for g in shapely.get_parts(shared) if g.geom_type == "LineString"]
        if not parts:
            continue
        line = max(parts, key=lambda g: g.length)
        if line.length < 2.0:
            continue
        s = step_across(line)
        if s is not None:
            walls.append(s)
        for i in (a, b):
            if line.length > longest.get(i, (0.0, None))[0]:
                longest[i] = (line.length, line)
    for i, (_, line) in longest.items():
        # halfway across the footprint from its longest party wall, parallel to it
        c = shapely.get_coordinates(line)
        d = c[-1] - c[0]
        nrm = np.array([-d[1], d[0]]) / max(np.hypot(*d), 1e-12)
        mid = c.mean(axis=0)
        inside = 1.0 if polys[i].contains(shapely.Point(mid + 0.5 * nrm)) else -1.0
        # the footprint's width across the wall, measured along the normal
        ray = shapely.LineString([mid, mid + inside * 200.0 * nrm]).intersection(polys[i])
        width = ray.length if not ray.is_empty else 0.0
        if width < 3.0:
            continue
        shifted = shapely.affinity.translate(line, *(inside * 0.5 * width * nrm))
        clipped = shifted.intersection(polys[i].buffer(-0.5))
        parts = [g for g in shapely.get_parts(clipped) if g.geom_type == "LineString"]
        if parts:
            s = step_across(max(parts, key=lambda g: g.length))
            if s is not None:
                inner.append(s)

    def row(name, v):
        v = np.asarray(v)
        shares = ", ".join(f"> {t:g} m: {np.count_nonzero(v > t)}" for t in (0.25, 0.5, 1.0, 1.5, 2.0))
        print(f"{name}: {len(v)} lines; median step {np.median(v):.2f} m, 90th pct "
              f"{np.percentile(v, 90):.2f} m; {shares}")

    print(f"Delft AHN3 roof (highest building point per {cell:g} m cell), read {args.offset:g} m "
          "either side of each line")
    row("BGT party walls", walls)
    row("lines halfway inside footprints (no wall)", inner)


if __name__ == "__main__":
    main()
