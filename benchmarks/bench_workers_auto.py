"""Calibrating ``--workers auto``: the fork's start cost, the smallest run that gains from
2 workers, and 1 against 2 workers on a machine kept busy by other processes.

Usage: ``python benchmarks/bench_workers_auto.py [DATA_DIR] [--cases demo,clip10,clip30,delft,traced]
[--workers 1,2] [--busy 0,1,2,4] [--runs 3] [--start 5]``
(default $LIDAR2CITY_DATA or ../shared/data)

Inputs (made in a temporary folder, never in the repository):

- ``demo``: the town ``lidar2city demo`` writes (``make_town`` with the demo's
  size, density and seed; raw points, no classes) with its map footprints;
- ``clipN``: the N Delft BGT footprints nearest the tile's south-west corner, with
  the Delft points within 40 m of their bounding box (classified AHN3 points);
- ``delft``: the Delft tile with its 132 footprints (the issue's command);
- ``traced``: the Delft tile without footprints (traced from the points).

Each case runs ``lidar2city reconstruct IN [--footprints FP] --lod 1.2 --lod 1.3
--lod 2.2 -o OUT --workers W`` for every W of ``--workers`` (``default``: the
option not given, what a user types), in fresh processes, alternately, ``--runs``
rounds, measured from outside as ``bench_engine_tile.py`` measures (wall, CPU of
the process tree, largest process, PSS of all processes at one moment). Printed:
each setting's median wall and CPU, the wall and CPU ratios of every setting to
the first one (median of the rounds), whether every setting wrote the same bytes,
the points the tile headers declare and what ``--workers auto`` takes for them
(on a fork and on a Dask cluster), and the CPU per point of the first setting.

``--busy 0,1,2,4``: the cases again with that many busy loops
(``python -c 'while 1: pass'``, started before the case's rounds, killed after)
beside them, in this process's session (the same scheduler group as the runs).
The load average and the runnable count (``/proc/loadavg``'s 4th field) are
printed before each case.

``--start N``: the start cost of the fork executor alone, in a fresh Python that
has imported the task modules and holds the decoded Delft tile (what a run's
process holds when it forks): ``N`` maps of two trivial items on
``ForkExecutor(2)`` (one child forked, run and reaped) and on ``InProcess``, wall
and CPU seconds (this process + the child's) per map, medians.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_engine_tile import run  # noqa: E402
from bench_speed import ROOT, data_dir  # noqa: E402

sys.path.insert(0, str(ROOT / "src"))  # this tree's lidar2city for the inputs and auto's choice

LODS = ("1.2", "1.3", "2.2")


def make_demo(folder: Path) -> tuple:
    """The raw tile and map footprints ``lidar2city demo`` writes (its defaults)."""
    import numpy as np

    from lidar2city.datamodel import ASPRS
    from lidar2city.io.las import write_points
    from lidar2city.io.vector import write_polygons
    from lidar2city.synthetic import make_town

    town = make_town(size=(200.0, 150.0), density=10.0, seed=0)
    cloud = town.cloud
    raw = cloud.with_attributes(classification=np.full(len(cloud), ASPRS.UNCLASSIFIED,
                                                       dtype=np.uint8))
    laz, fps = folder / "town.laz", folder / "footprints.gpkg"
    write_points(laz, raw)
    write_polygons(fps, town.footprints.geometries,
                   {"id": town.footprints.ids, **town.footprints.attributes},
                   origin=cloud.origin, crs=cloud.crs)
    return laz, fps


def make_clip(data: Path, folder: Path, n: int, margin: float = 40.0) -> tuple:
    """The ``n`` Delft footprints nearest the tile's south-west corner and the
    points within ``margin`` of their bounding box."""
    import laspy
    import numpy as np
    import pyogrio.raw
    import shapely

    d = data / "delft"
    meta, fids, geoms, fields = pyogrio.raw.read(str(d / "footprints_bgt.gpkg"))
    polys = shapely.from_wkb(geoms)
    c = shapely.centroid(polys)
    x, y = shapely.get_x(c), shapely.get_y(c)
    keep = np.argsort((x - x.min()) ** 2 + (y - y.min()) ** 2, kind="stable")[:n]
    x0, y0, x1, y1 = shapely.total_bounds(polys[keep])
    las = laspy.read(str(d / "ahn3_cropped_1.laz"))
    inside = ((las.x >= x0 - margin) & (las.x <= x1 + margin)
              & (las.y >= y0 - margin) & (las.y <= y1 + margin))
    out = laspy.LasData(las.header)
    out.points = las.points[np.asarray(inside)]
    laz, fps = folder / f"clip{n}.laz", folder / f"clip{n}.gpkg"
    out.write(str(laz))
    pyogrio.raw.write(str(fps), geoms[keep], [f[keep] for f in fields], fields=meta["fields"],
                      geometry_type=meta["geometry_type"], crs=meta["crs"], driver="GPKG")
    return laz, fps


def count(laz) -> int:
    import laspy

    with laspy.open(str(laz)) as f:
        return int(f.header.point_count)


def start_cost(n: int, data: Path) -> None:
    """Time ``n`` trivial maps on a fork executor of 2 and in process (a fresh Python)."""
    code = f"""
import statistics, time, laspy
import lidar2city.tools.task, lidar2city.roof.building, scipy.spatial, scipy.ndimage
from lidar2city.tools.engine import InProcess
from lidar2city.tools.forked import ForkExecutor
held = laspy.read({str(data / 'delft' / 'ahn3_cropped_1.laz')!r})  # what a run holds
xyz = held.xyz
def one(i):
    return i
for name, make in (("fork, 2 workers", lambda: ForkExecutor(2)), ("in process", InProcess)):
    walls, cpus = [], []
    for _ in range({n}):
        ex = make()
        c0, t0 = time.process_time(), time.perf_counter()
        got = sorted(i for i, _ in ex.map(one, [0, 1]))
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0 + sum(ex.process_cpu().values()))
        assert got == [0, 1]
    print(f"{{name}}: a map of 2 trivial items: wall median {{statistics.median(walls) * 1e3:.1f}} ms "
          f"(min {{min(walls) * 1e3:.1f}}), CPU (this process + child) median "
          f"{{statistics.median(cpus) * 1e3:.1f}} ms over {n}", flush=True)
"""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    subprocess.run([sys.executable, "-c", code], env=env, check=True)


def auto_choice(laz, fps, executor="fork") -> int:
    """What ``--workers auto`` takes for the case on this machine (the issue's LoDs)."""
    from lidar2city.tools.reconstruct import auto_workers

    return auto_workers([laz], footprints=fps, lods=LODS, executor=executor)


def runnable() -> str:
    with open("/proc/loadavg") as f:
        v = f.read().split()
    return f"load {v[0]} {v[1]} {v[2]}, runnable {v[3]}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--cases", default="demo,clip10,clip30,delft")
    ap.add_argument("--workers", default="1,2",
                    help="comma-separated counts, auto, or default (no --workers option)")
    ap.add_argument("--busy", default="0", help="comma-separated counts of busy loops")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--start", type=int, default=0, help="maps timed for the fork's start cost")
    args = ap.parse_args()
    data = data_dir(args.data)
    if args.start:
        start_cost(args.start, data)
    cases = [c for c in args.cases.split(",") if c]
    if not cases:
        return
    workers = args.workers.split(",")
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    py = sys.executable
    tmp = Path(tempfile.mkdtemp())
    inputs = {}
    for c in cases:
        if c == "demo":
            inputs[c] = make_demo(tmp)
        elif c.startswith("clip"):
            inputs[c] = make_clip(data, tmp, int(c[4:]))
        elif c == "delft":
            inputs[c] = (data / "delft" / "ahn3_cropped_1.laz",
                         data / "delft" / "footprints_bgt.gpkg")
        elif c == "traced":
            inputs[c] = (data / "delft" / "ahn3_cropped_1.laz", None)
        else:
            raise SystemExit(f"unknown case {c!r}")

    def command(case, w):
        laz, fps = inputs[case]
        out = tmp / f"{case}_{w}.city.json"
        given = [] if fps is None else ["--footprints", str(fps)]
        opt = [] if w == "default" else ["--workers", w]
        return out, [py, "-m", "lidar2city.cli.main", "reconstruct", str(laz), *given,
                     *(a for lod in LODS for a in ("--lod", lod)), "-o", str(out), *opt]

    print(f"{os.cpu_count()} cores; workers settings {', '.join(workers)}", flush=True)
    for busy in (int(b) for b in args.busy.split(",")):
        loops = [subprocess.Popen([py, "-c", "while 1: pass"]) for _ in range(busy)]
        try:
            time.sleep(1.0 if busy else 0.0)
            for case in cases:
                laz, fps = inputs[case]
                points = count(laz)
                print(f"[{busy} busy loop(s)] {case}: {points:,} points, --workers auto takes "
                      f"{auto_choice(laz, fps)} on a fork, {auto_choice(laz, fps, 'dask')} on a "
                      f"Dask cluster; {runnable()}", flush=True)
                for w in workers:  # warm the file cache and the bytecode
                    run(command(case, w)[1], env)
                rows, md5 = {w: [] for w in workers}, {}
                for k in range(max(1, args.runs)):
                    line = []
                    for w in workers:
                        out, cmd = command(case, w)
                        r = run(cmd, env)
                        rows[w].append(r)
                        md5.setdefault(w, set()).add(
                            hashlib.md5(out.read_bytes()).hexdigest())
                        line.append(f"{w}: {r[0]:.2f} s {r[2]:.2f} CPU s PSS {r[5]:.0f} MB")
                    print(f"  round {k + 1}: " + "; ".join(line), flush=True)
                first = workers[0]
                for w in workers:
                    rs = rows[w]
                    wall = [a[0] / b[0] for a, b in zip(rs, rows[first], strict=True)]
                    cpu = [a[2] / b[2] for a, b in zip(rs, rows[first], strict=True)]
                    print(f"  {w}: median {statistics.median(r[0] for r in rs):.2f} s, "
                          f"{statistics.median(r[2] for r in rs):.2f} CPU s "
                          f"({statistics.median(r[2] for r in rs) / points * 1e6:.2f} CPU us "
                          f"a point); wall / {first}'s {statistics.median(wall):.3f} "
                          f"({', '.join(f'{v:.2f}' for v in wall)}), CPU / {first}'s "
                          f"{statistics.median(cpu):.3f}; largest process "
                          f"{max(r[1] for r in rs):.0f} MB, PSS of all "
                          f"{max(r[5] for r in rs):.0f} MB; md5 {' '.join(sorted(md5[w]))}",
                          flush=True)
                same = len({frozenset(v) for v in md5.values()}) == 1 and len(md5[first]) == 1
                print(f"  same bytes on every setting: {'yes' if same else 'NO'}; "
                      f"{runnable()}", flush=True)
        finally:
            for p in loops:
                p.kill()
                p.wait()


if __name__ == "__main__":
    main()
