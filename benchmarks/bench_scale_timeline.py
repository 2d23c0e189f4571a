"""Where the wall time of ``reconstruct`` on n x n copies of the Delft tile goes: a timeline of each process.

Usage: ``python benchmarks/bench_scale_timeline.py [DATA_DIR] [--size 4] [--workers 2]
[--keep DIR] [--src OTHER_SRC] [--pairs N] [--tasks]``

The area is :mod:`bench_scale`'s (``--size`` n: n x n copies of the Delft tile,
each its own LAZ, the 132 BGT footprints shifted likewise; 1: the tile itself),
built in ``--keep DIR`` (kept, reused when there) or a temporary folder. The
command is the one ``bench_scale.py`` runs (``reconstruct TILES --crs EPSG:7415
--footprints FP --lod 1.2 --lod 1.3 --lod 2.2 --workers W -q -o OUT.city.jsonl``),
in a fresh process instrumented as :mod:`bench_engine_tile_timeline` does (its
``CHILD``): the marks of the parent's serial phases (imports, the plan, tiles
decoded and held for the workers, the fork, the output), each task (block or
part) with its process, start / end, CPU and the tiles it decoded itself, and
here also the parent's cumulative thread CPU in the journal's saves, in putting
results in order and in writing them (the stream's ``add``), which it does
between its own blocks.

Printed: the serial phases; per process its tasks, CPU, busy wall, the tiles it
decoded and its idle time (from the fork, or its birth, to the last task's end,
minus its tasks' wall); the tail (how long the first process to finish its
tasks waited for the last task to end); an idle-machine estimate from CPU
seconds (:func:`bench_engine_tile_timeline.summary`). ``--workers 1`` gives the
CPU of the same work in one process (the ratio of the runs' CPU is what 2
workers cost more). ``--src OTHER --pairs N``: OTHER's run, then this tree's, N
rounds, and the medians. The machine is shared: the load average is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_engine_tile_timeline as tl  # noqa: E402
from bench_scale import make_area  # noqa: E402
from bench_speed import ROOT, data_dir  # noqa: E402

#: the parent's extra accounting: cumulative thread CPU of a few of its calls
EXTRA = r'''
    ACC = {}

    def acc(owner, name, label):
        real = getattr(owner, name)

        def wrapped(*a, **k):
            w0, c0 = time.time(), time.thread_time()
            try:
                return real(*a, **k)
            finally:
                got = ACC.setdefault(label, [0, 0.0, 0.0])
                got[0] += 1
                got[1] += time.thread_time() - c0
                got[2] += time.time() - w0
        setattr(owner, name, wrapped)

    from lidar2city.io import journal as J_
    acc(J_.Journal, "save", "journal saves")
    acc(R.InOrder, "add", "results put in order")
    acc(R._Stream, "add", "stream writes")
    acc(R, "index_footprints", "footprints indexed (plan)")
    from lidar2city.io import las as L_
    acc(L_, "scan_tiles", "tile headers scanned (plan)")
    wrap(forked, "_preload", "preload begun", "preload done")
'''

ACC_OUT = r'''
        for k_, v_ in ACC.items():
            marks.append((f"acc {k_}: {v_[0]} calls, {v_[1]:.3f} thread CPU s, "
                          f"{v_[2]:.3f} wall s", -1.0, 0.0, 0.0))
        mark("command done")'''


def child_code() -> str:
    """:data:`bench_engine_tile_timeline.CHILD` with :data:`EXTRA`'s accounting."""
    code = tl.CHILD
    anchor = "    try:\n        climain._STANDALONE.append(True)"
    assert anchor in code and '        mark("command done")' in code
    code = code.replace(anchor, EXTRA + anchor)
    return code.replace('        mark("command done")', ACC_OUT, 1)


def area(d: Path, n: int, keep: Path | None) -> tuple[list, Path]:
    tile, fp = d / "ahn3_cropped_1.laz", d / "footprints_bgt.gpkg"
    if n == 1:
        return [str(tile)], fp
    folder = (keep or Path(tempfile.mkdtemp(prefix="bench_scale_timeline_"))) / f"area{n}"
    want = [folder / f"delft_{i}_{j}.laz" for i in range(n) for j in range(n)]
    if not (folder / "footprints.gpkg").exists() or not all(p.exists() for p in want):
        folder.mkdir(parents=True, exist_ok=True)
        return make_area(tile, fp, n, folder)
    return [str(p) for p in want], folder / "footprints.gpkg"


def run(tiles, fp, workers: str, src=None) -> tuple:
    """One instrumented run: ``(wall s, the child's report, t0)``."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "child.py").write_text(child_code())
        for name in ("first", "last"):  # the Dask server's preload marks (unused by the fork)
            (tmp / f"bench_mark_{name}.py").write_text(tl.MARK.replace("{NAME}", name))
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(src or ROOT / "src"), str(tmp)]),
                   BENCH_MARKS=str(tmp / "marks.txt"))
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        t0 = time.time()
        cmd = [sys.executable, str(tmp / "child.py"), repr(t0), "reconstruct", *tiles,
               "--crs", "EPSG:7415", "--footprints", str(fp), "--lod", "1.2", "--lod", "1.3",
               "--lod", "2.2", "-o", str(tmp / "out.city.jsonl"), "-q", "--workers", workers]
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=env)
        wall = time.time() - t0
        bench = [line for line in proc.stderr.splitlines() if line.startswith("BENCH ")]
        if proc.returncode or not bench:
            raise SystemExit(proc.stderr)
        import hashlib

        md5 = hashlib.md5((tmp / "out.city.jsonl").read_bytes()).hexdigest()
    return wall, json.loads(bench[-1][6:]), t0, md5


def report(m, t0, wall, show_tasks=False) -> dict:
    """Print the phases of one run; returns the figures the pairs compare."""
    for name, t, c, th in m["marks"]:
        if t < 0:
            print(f"          parent: {name}")
        else:
            print(f"{t:7.2f} s  parent: {name} (parent CPU {c:.2f} s)")
    ts = tl.tasks(m, t0)
    fork = {n: t for n, t, _, _ in m["marks"]}.get("fork: children forked")
    who = sorted({t["who"] for t in ts})
    per = {}
    for w in who:
        mine = [t for t in ts if t["who"] == w]
        begin = min(t["start"] for t in mine)
        end = max(t["end"] for t in mine)
        busy = sum(t["end"] - t["start"] for t in mine)
        since = fork if fork is not None else begin
        per[w] = {"cpu": sum(t["cpu"] for t in mine), "end": end, "busy": busy,
                  "idle": end - since - busy, "decoded": sum(t["decoded"] for t in mine),
                  "tasks": len(mine), "buildings": sum(t["buildings"] for t in mine),
                  "first": begin}
        print(f"{w:8s}: {len(mine)} tasks, {per[w]['buildings']} buildings, first starts "
              f"{begin:.2f} s, last ends {end:.2f} s, busy {busy:.2f} s, idle between and "
              f"before its tasks {per[w]['idle']:.2f} s, tasks' CPU {per[w]['cpu']:.2f} s, "
              f"{per[w]['decoded']} tile(s) decoded itself")
        if show_tasks:
            for t in mine:
                print(f"    {t['kind']} {t['index']:3d} {t['start']:7.2f}-{t['end']:7.2f} s "
                      f"{t['cpu']:5.2f} CPU s, {t['buildings']} buildings, {t['decoded']} "
                      "decoded")
    last = max(p["end"] for p in per.values())
    tail = last - min(p["end"] for p in per.values())
    s = tl.summary(m, t0)
    run_cpu = s.get("run cpu", 0.0)
    print(f"wall {wall:.2f} s; tail {tail:.2f} s; after the last task {wall - last:.2f} s; "
          f"the run's CPU {run_cpu:.2f} s; tiles decoded by tasks "
          f"{sum(p['decoded'] for p in per.values())}")
    return {"wall": wall, "tail": tail, "cpu": run_cpu, "estimate": s.get("estimate", 0.0)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--size", type=int, default=4, help="n of the n x n copies")
    ap.add_argument("--workers", default="2")
    ap.add_argument("--keep", help="build the area in this folder, or reuse it from there")
    ap.add_argument("--src", help="another tree's src folder (with --pairs: run in turn)")
    ap.add_argument("--pairs", type=int, default=0)
    ap.add_argument("--tasks", action="store_true", help="print every task")
    a = ap.parse_args()
    d = data_dir(a.data) / "delft"
    tiles, fp = area(d, a.size, Path(a.keep) if a.keep else None)
    subprocess.run([sys.executable, "-c", "import laspy, sys\nfor p in sys.argv[1:]: "
                    "laspy.read(p)", *tiles], check=True)  # the file cache warm
    print(f"{a.size}x{a.size}: {len(tiles)} tiles; load average before: "
          f"{' '.join(f'{v:.2f}' for v in os.getloadavg())}", flush=True)
    rounds = max(1, a.pairs)
    trees = ([("other", a.src)] if a.src else []) + ([("this", None)]
                                                      if a.pairs or not a.src else [])
    got = {name: [] for name, _ in trees}
    for k in range(rounds):
        for name, src in trees:
            wall, m, t0, md5 = run(tiles, fp, a.workers, src)
            print(f"--- round {k + 1}, {name} ({src or 'this tree'}), workers {a.workers}: "
                  f"{wall:.2f} s, MD5 {md5}, load {os.getloadavg()[0]:.2f}", flush=True)
            got[name].append(report(m, t0, wall, a.tasks))
    if len(trees) > 1:
        for name, rows in got.items():
            print(f"{name}: wall median {statistics.median(r['wall'] for r in rows):.2f} s, "
                  f"run CPU median {statistics.median(r['cpu'] for r in rows):.2f} s, tail "
                  f"median {statistics.median(r['tail'] for r in rows):.2f} s, estimate median "
                  f"{statistics.median(r['estimate'] for r in rows):.2f} s")
        ratio = [t["cpu"] / o["cpu"] for o, t in zip(got["other"], got["this"], strict=True)]
        wr = [t["wall"] / o["wall"] for o, t in zip(got["other"], got["this"], strict=True)]
        print(f"this / other: CPU median {statistics.median(ratio):.3f} "
              f"({', '.join(f'{v:.3f}' for v in ratio)}); wall median "
              f"{statistics.median(wr):.3f} ({', '.join(f'{v:.3f}' for v in wr)})")
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
