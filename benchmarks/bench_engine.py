"""reconstruct on 1 and 2 Dask workers over a synthetic multi-tile area: speed, memory, bytes.

Usage: ``PYTHONPATH=src python benchmarks/bench_engine.py [--sizes 2,4,8,12] [--workers 1,2]
[--lod 1.2 ...]``

The demo town generator (:func:`lidar2city.synthetic.make_town`, 200 x 150 m,
4 points/m², a different seed per tile) is laid out as n x n tiles (2 x 2 = 4,
4 x 4 = 16 and 8 x 8 = 64 tiles, ~15 buildings each), every tile its own LAZ
file, the footprints of all in one GeoPackage; 12 x 12 = 144 tiles (~2,200
buildings) is the area the speed-up is measured on, large enough for the
cluster's start-up to be a small share. Each area is reconstructed
(reconstruct's default LoDs, i.e. LoD1.2, unless ``--lod`` is given; blocks
of 200 m; to a streamed CityJSONSeq) in a fresh process with ``--workers 1``
(in process) and, on the largest area, with ``--workers 2`` (a local Dask
cluster). Printed per run: buildings, wall
seconds, buildings per second, the peak resident memory of the process that
ran the blocks (Linux ``VmHWM`` read in the worker after each block: its own
peak; ``ru_maxrss`` would count the size of this script, which Linux carries
over into the child it starts; with 1 worker that process is also the
client, which holds the results not yet written),
seconds per building, and the MD5 of the output (the same for every worker
count) and the CPU seconds used by the run and all the processes it started
(Dask workers included); for a cluster also the seconds to start it, the CPU
of each worker on its blocks and in all (its start-up included; a worker
forked from a server that imported Dask and NumPy does not count those imports) and
the CPU of the client process (scheduler, nannies, planning, writing), the
seconds the cluster took to close once the run was written, and the CPU of
every other process (the workers from start to exit, and the server they
were forked from). Then
the speed-up of 2 workers over 1, the ratio of their CPU seconds (the
speed-up a quiet machine can give is at most workers / that ratio), and the
load average of the machine at the time (the speed-up is depressed when
other jobs use the cores; the CPU seconds much less).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

TILE = (200.0, 150.0)
BLOCK = 200.0

CHILD = r"""
import json, os, sys, time
from lidar2city.tools.reconstruct import reconstruct

def main():
    a = json.loads(sys.argv[1])
    t0 = time.perf_counter()
    s = reconstruct(a["tiles"], a["out"], footprints=a["fp"], lods=a["lods"] or None,
                    block_size=a["block"], workers=a["workers"])
    t = os.times()
    print(json.dumps({"seconds": time.perf_counter() - t0, "total": s.total, "done": s.done,
                      "failed": s.failed, "blocks": s.blocks, "worker_mb": s.worker_peak_mb,
                      "client_cpu": t.user + t.system, "blocks_cpu": s.worker_cpu,
                      "process_cpu": s.process_cpu, "startup": s.startup_seconds,
                      "run": s.seconds}))

if __name__ == "__main__":
    main()
"""


def _town(seed, origin):
    """A town tile."""
    from lidar2city.synthetic import make_town

    return make_town(size=TILE, density=4.0, seed=seed, n_trees=10, origin=origin)


def make_area(folder: Path, n: int):
    """n x n synthetic town tiles (one LAZ each) and one footprint file; returns (tiles, fp)."""
    from lidar2city.io.las import write_points
    from lidar2city.io.vector import write_polygons

    import shapely

    tiles, geoms, ids = [], [], []
    x0, y0 = 85000.0, 447000.0
    for j in range(n):
        for i in range(n):
            origin = (x0 + i * TILE[0], y0 + j * TILE[1], 0.0)
            town = _town(1000 + j * n + i, origin)
            p = folder / f"tile_{i}_{j}.laz"
            write_points(p, town.cloud)
            tiles.append(str(p))
            # footprints in one frame: the first tile's origin
            shift = (origin[0] - x0, origin[1] - y0)
            geoms += [shapely.affinity.translate(g, *shift) for g in town.footprints.geometries]
            ids += [f"t{i}_{j}_{fid}" for fid in town.footprints.ids]
    fp = folder / "footprints.gpkg"
    from pyproj import CRS

    write_polygons(fp, geoms, {"id": ids}, origin=(x0, y0, 0.0), crs=CRS("EPSG:7415"))
    return tiles, str(fp)


def run(tiles, fp, out, workers, lods):
    args = json.dumps({"tiles": tiles, "fp": fp, "out": str(out), "lods": lods, "block": BLOCK,
                       "workers": workers})
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
        f.write(CHILD)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        r = subprocess.run([sys.executable, f.name, args], capture_output=True, text=True,
                           env=os.environ.copy())
    finally:
        os.unlink(f.name)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode:
        raise SystemExit(r.stderr)
    res = json.loads(r.stdout.strip().splitlines()[-1])
    # CPU seconds of the run and of every process it started (Dask workers included)
    res["cpu"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    res["md5"] = hashlib.md5(Path(out).read_bytes()).hexdigest()
    return res


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="2,4,8,12")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--lod", action="append", default=[],
                    help="LoDs to build (repeat); default reconstruct's own (LoD1.2)")
    a = ap.parse_args()
    sizes = [int(v) for v in a.sizes.split(",")]
    workers = [int(v) for v in a.workers.split(",")]
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} "
          f"({os.cpu_count()} cores)")
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            d = Path(tmp) / f"area{n}"
            d.mkdir()
            tiles, fp = make_area(d, n)
            for w in (workers if n == max(sizes) else [1]):
                r = run(tiles, fp, d / f"out_w{w}.city.jsonl", w, a.lod)
                rows[(n, w)] = r
                print(f"{n * n:3d} tiles, LoD {'+'.join(a.lod) or '1.2 (default)'}, "
                      f"{w} worker(s): {r['total']} buildings ({r['failed']} "
                      f"failed), {r['blocks']} blocks, {r['seconds']:.1f} s, "
                      f"{r['total'] / r['seconds']:.1f} buildings/s, "
                      f"{1000 * r['seconds'] / r['total']:.1f} ms/building, CPU {r['cpu']:.1f} s "
                      f"({1000 * r['cpu'] / r['total']:.0f} CPU-ms/building), "
                      f"peak worker memory {r['worker_mb']:.0f} MB, md5 {r['md5']}", flush=True)
                if r["process_cpu"]:
                    blocks = " / ".join(f"{v:.1f}" for v in r["blocks_cpu"].values())
                    procs = " / ".join(f"{v:.1f}" for v in r["process_cpu"].values())
                    print(f"    cluster start-up {r['startup']:.1f} s, close "
                          f"{r['seconds'] - r['run']:.2f} s; CPU per worker on its blocks "
                          f"{blocks} s, whole process {procs} s; client process "
                          f"{r['client_cpu']:.1f} s, every other process (workers, their "
                          f"server) {r['cpu'] - r['client_cpu']:.1f} s", flush=True)
                else:
                    print(f"    CPU on the blocks {sum(r['blocks_cpu'].values()):.1f} s, "
                          f"the rest (planning, writing) {r['cpu'] - sum(r['blocks_cpu'].values()):.1f} s",
                          flush=True)
    n = max(sizes)
    if (n, 1) in rows:
        base = rows[(n, 1)]
        for w in workers:
            if w != 1 and (n, w) in rows:
                r = rows[(n, w)]
                print(f"speed-up {w} workers / 1 on {n * n} tiles: "
                      f"{base['seconds'] / r['seconds']:.2f}; CPU {w} workers / 1: "
                      f"{r['cpu'] / base['cpu']:.2f}; same bytes: "
                      f"{'yes' if r['md5'] == base['md5'] else 'NO'}")
    ones = [rows[(k, 1)] for k in sizes if (k, 1) in rows]
    if len(ones) > 1:
        print("memory per worker from {} to {} tiles: {} MB".format(
            min(sizes) ** 2, n * n, " -> ".join(f"{r['worker_mb']:.0f}" for r in ones)))
        print("time per building from {} to {} tiles: {} ms".format(
            min(sizes) ** 2, n * n,
            " -> ".join(f"{1000 * r['seconds'] / r['total']:.1f}" for r in ones)))
        print("CPU per building from {} to {} tiles: {} ms".format(
            min(sizes) ** 2, n * n, " -> ".join(f"{1000 * r['cpu'] / r['total']:.0f}"
                                                 for r in ones)))
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
