"""CPU of the footprint tracing of the no-footprints reconstruct (Delft), replayed in two trees (issue 13).

Usage: python benchmarks/bench_traced_snake.py [OTHER_SRC] [DATA_DIR] [--repeat N] [--pairs P]
[--cache FILE]
(OTHER_SRC: the ``src`` folder of another checkout to compare with, e.g. /work/wt/base/src;
DATA_DIR default $LIDAR2CITY_DATA or ../shared/data; N = 3 passes per pair, P = 3 pairs;
FILE default a file in the temporary directory)

Records, once, the arguments of the one :func:`lidar2city.footprints.extract_footprints`
call of ``reconstruct`` of the Delft tile without ``--footprints`` (LoD 1.2, in a child
process of this tree, stopped as soon as the call is made: the points, their roles and
the ``[footprints]`` options), into FILE (kept: later runs reuse it). Then calls
``extract_footprints`` on them in fresh child processes of this tree (A) and of OTHER_SRC
(B) in turn, A B A B ..., each child making one warm-up call (imports, caches) and then N
calls, and printing the least CPU seconds (``time.process_time``) of one call, split
into the footprint snake (``regularize_polygon``, outer calls; inside it the direction
search, the candidates + distance raster, the energy tables, the solver, the rest) and
the rest of the tracing; with the number of snake polygons, of their vertices and
edges, and the MD5 of the footprints (WKB and attributes): the same MD5 in A and B means
the same traced footprints to the bit. The ratio A/B of the least CPU per pair and their
median are printed, with the load average before and after.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

RECORD = r"""
import pickle, sys
import lidar2city.footprints as F
orig = F.extract_footprints
class Done(Exception):
    pass
def rec(xyz, classification, **kw):
    with open(sys.argv[1], "wb") as f:
        pickle.dump({"xyz": xyz, "classification": classification, "kwargs": kw}, f,
                    protocol=pickle.HIGHEST_PROTOCOL)
    raise Done
F.extract_footprints = rec
from lidar2city.cli.main import cli
try:
    cli.main(["reconstruct", sys.argv[2], "--lod", "1.2", "-o", sys.argv[3]], standalone_mode=False)
except Done:
    pass
"""

REPLAY = r"""
import hashlib, json, pickle, sys, time
import numpy as np
import shapely
cache, repeat = sys.argv[1], int(sys.argv[2])
with open(cache, "rb") as f:
    rec = pickle.load(f)
import lidar2city.regularize.snake as rs
import lidar2city.snake.energies as en
import lidar2city.snake.solver as so
spent = {}
depth = [0]
nested = [0]
def clocked(name, fn, outer_only=False):
    def g(*a, **k):
        if outer_only and depth[0]:
            return fn(*a, **k)
        depth[0] += outer_only
        t = time.process_time()
        try:
            return fn(*a, **k)
        finally:
            spent[name] = spent.get(name, 0.0) + time.process_time() - t
            depth[0] -= outer_only
    return g
sizes = []
orig_rp = rs.regularize_polygon
def rp(poly, **k):
    if depth[0] == 1 and not nested[0]:
        sizes.append(sum(len(r.coords) - 1 for r in [poly.exterior, *poly.interiors]))
    nested[0] += 1
    try:
        return orig_rp(poly, **k)
    finally:
        nested[0] -= 1
rs.regularize_polygon = clocked("snake", rp, outer_only=True)
rs.dominant_direction = clocked("direction", rs.dominant_direction)
for name in ("candidate_positions", "distance_raster"):
    setattr(rs, name, clocked("candidates + raster", getattr(rs, name)))
rs.edge_energy_tables = clocked("energy tables", rs.edge_energy_tables)
rs.vertex_energy_tables = clocked("energy tables", rs.vertex_energy_tables)
rs.minimize_energy = clocked("solver", rs.minimize_energy)
from lidar2city.footprints import extract_footprints
import lidar2city.footprints.regularizers as regs
def run():
    return extract_footprints(rec["xyz"], rec["classification"], **rec["kwargs"])
run()  # warm-up: imports, caches
best = None
for _ in range(repeat):
    spent.clear()
    sizes.clear()
    t = time.process_time()
    out = run()
    total = time.process_time() - t
    if best is None or total < best[0]:
        best = (total, dict(spent), list(sizes))
h = hashlib.md5()
for f in out:
    h.update(shapely.to_wkb(f.polygon))
    h.update(json.dumps([f.status, f.reason, f.attributes], sort_keys=True).encode())
total, parts, sizes = best
print(json.dumps({"total": total, "parts": parts, "n_polys": len(sizes),
                  "n_vertices": int(sum(sizes)), "n_footprints": len(out),
                  "md5": h.hexdigest()}))
"""


def child(src, code, *argv) -> str:
    env = dict(os.environ, PYTHONPATH=str(src))
    proc = subprocess.run([sys.executable, "-c", code, *map(str, argv)], env=env,
                          capture_output=True, text=True)
    if proc.returncode:
        raise SystemExit(f"child failed ({src}):\n{proc.stderr}")
    return proc.stdout


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("other", nargs="?")
    ap.add_argument("data", nargs="?")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--cache", default=str(Path(tempfile.gettempdir()) / "bench_traced_snake.pkl"))
    args = ap.parse_args()
    data = Path(args.data or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")
    laz = data / "delft" / "ahn3_cropped_1.laz"
    cache = Path(args.cache)
    if not cache.exists():
        with tempfile.TemporaryDirectory() as tmp:
            child(ROOT / "src", RECORD, cache, laz, Path(tmp) / "out.city.json")
    with open(cache, "rb") as f:
        rec = pickle.load(f)
    print(f"recorded call: {len(rec['xyz'])} points, options {rec['kwargs']}")
    trees = {"A": ROOT / "src"} | ({"B": Path(args.other).resolve()} if args.other else {})
    load0 = os.getloadavg()[0]
    results = {k: [] for k in trees}
    for _ in range(args.pairs):
        for name, src in trees.items():
            results[name].append(json.loads(child(src, REPLAY, cache, args.repeat).strip().splitlines()[-1]))
    load1 = os.getloadavg()[0]
    for name, src in trees.items():
        r = results[name][-1]
        print(f"{name} = {src}: {r['n_footprints']} footprints, {r['n_polys']} snake polygons with "
              f"{r['n_vertices']} traced vertices; MD5 {r['md5']}")
        keys = sorted({k for x in results[name] for k in x["parts"]})
        print(f"   least CPU s per pair: total {[round(x['total'], 3) for x in results[name]]}")
        for k in keys:
            print(f"   {k:<22}{[round(x['parts'].get(k, 0.0), 3) for x in results[name]]}")
    if "B" in trees:
        ratios = [a["total"] / b["total"] for a, b in zip(results["A"], results["B"], strict=True)]
        snake = [a["parts"].get("snake", 0.0) / b["parts"]["snake"]
                 for a, b in zip(results["A"], results["B"], strict=True) if b["parts"].get("snake")]
        print(f"CPU A/B per pair: tracing {[round(r, 3) for r in ratios]} median "
              f"{statistics.median(ratios):.3f}; snake {[round(r, 3) for r in snake]} median "
              f"{statistics.median(snake):.3f}")
        same = len({x["md5"] for v in results.values() for x in v}) == 1
        print(f"same footprints in A and B: {same}")
    print(f"load average {load0:.2f} -> {load1:.2f}")


if __name__ == "__main__":
    main()
