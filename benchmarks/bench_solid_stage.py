"""CPU of the LoD2.2 solid stage per building, against the building's size (no profiler).

Usage: python benchmarks/bench_solid_stage.py [DATA_DIR] [--other SRC] [--traced] [--top N]

The command of issue 13 (LoD 1.2 + 1.3 + 2.2 on the Delft tile, with its 132 BGT footprints,
or without them with ``--traced``) runs in a child process with this tree's ``src`` (and,
with ``--other``, another tree's after it). Each call of ``reconstruct_lod22``, of
``_finish_solid`` (the roof partition refined, fixed and made a solid), of ``check_solid``
(validation) and of ``nudge_on_grid`` is timed in CPU seconds (``time.process_time``; nested
calls are counted in their caller's time only), per building. The stage of
``bench_solid_area.py``: ``_finish_solid`` plus the validation outside it.

Prints, per tree: the totals, the buildings with the largest LoD2.2 CPU (footprint area,
surfaces of the solid written, LoD2.2 CPU, stage CPU and its share), and the slope of
log(CPU) over log(area) (least squares over the buildings of at least 20 m2) for the
LoD2.2 total, the stage and the rest: a slope above 1 is a cost growing faster than the
roof's size.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time
import lidar2city.roof.building as B
import lidar2city.roof.solid as S
import lidar2city.validate.solid as V

stack = []  # the timed calls running: an inner one is counted in the outer one only
rows = []
cur = None

def timed(name, fn):
    def wrapper(*args, **kwargs):
        global cur
        if stack:
            return fn(*args, **kwargs)
        stack.append(name)
        t = time.process_time()
        try:
            return fn(*args, **kwargs)
        finally:
            stack.pop()
            if cur is not None:
                cur[name] = cur.get(name, 0.0) + time.process_time() - t
    return wrapper

real_lod22 = B.reconstruct_lod22

def lod22(footprint, *args, **kwargs):
    global cur
    outer = cur
    cur = {"area": float(footprint.area)}
    t = time.process_time()
    try:
        res = real_lod22(footprint, *args, **kwargs)
        cur["surfaces"] = sum(len(s.surfaces) for s in res.solids)
        return res
    finally:
        cur["lod22"] = time.process_time() - t
        if outer is None:
            rows.append(cur)
        cur = outer

B.reconstruct_lod22 = lod22
B._finish_solid = timed("finish", B._finish_solid)
B.check_solid = timed("check", V.check_solid)
B.nudge_on_grid = timed("nudge", S.nudge_on_grid)
from lidar2city.cli.main import main
sys.argv = ["lidar2city", *ARGS]
try:
    main()
except SystemExit:
    pass
print(json.dumps(rows))
"""


def run(src: Path, args: list[str]) -> list[dict]:
    env = dict(os.environ, PYTHONPATH=str(src))
    out = subprocess.run([sys.executable, "-c", CHILD.replace("ARGS", repr(args))], env=env,
                         capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise SystemExit(f"run with {src} failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def slope(x, y):
    import numpy as np

    x, y = np.log(np.asarray(x, float)), np.log(np.maximum(np.asarray(y, float), 1e-6))
    return float(np.polyfit(x, y, 1)[0])


def report(name, rows, top):
    for r in rows:
        r["stage"] = r.get("finish", 0.0) + r.get("check", 0.0) + r.get("nudge", 0.0)
        r["rest"] = r["lod22"] - r["stage"]
    tot = {k: sum(r.get(k, 0.0) for r in rows) for k in ("lod22", "stage", "finish", "check", "nudge")}
    print(f"{name}: {len(rows)} buildings; LoD2.2 {tot['lod22']:.2f} CPU s, stage {tot['stage']:.2f} "
          f"({100 * tot['stage'] / max(tot['lod22'], 1e-9):.0f} %): _finish_solid {tot['finish']:.2f}, "
          f"check_solid outside it {tot['check']:.2f}, nudge_on_grid {tot['nudge']:.2f}")
    print("  area m2  surfaces  LoD2.2 s  stage s  share")
    for r in sorted(rows, key=lambda r: -r["lod22"])[:top]:
        print(f"  {r['area']:7.0f}  {r.get('surfaces', 0):8d}  {r['lod22']:8.3f}  {r['stage']:7.3f}  "
              f"{100 * r['stage'] / max(r['lod22'], 1e-9):4.0f} %")
    big = [r for r in rows if r["area"] >= 20]
    if len(big) >= 3:
        a = [r["area"] for r in big]
        print(f"  log-log slope over area ({len(big)} buildings >= 20 m2): LoD2.2 "
              f"{slope(a, [r['lod22'] for r in big]):.2f}, stage {slope(a, [r['stage'] for r in big]):.2f}, "
              f"rest {slope(a, [r['rest'] for r in big]):.2f}; stage over surfaces "
              f"{slope([max(r.get('surfaces', 1), 1) for r in big], [r['stage'] for r in big]):.2f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--other", help="the src folder of another tree, run after this one")
    ap.add_argument("--traced", action="store_true", help="without footprints (traced)")
    ap.add_argument("--top", type=int, default=10)
    args = ap.parse_args()
    data = Path(args.data or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")
    d = data / "delft"
    tmp = Path(tempfile.mkdtemp())
    given = [] if args.traced else ["--footprints", str(d / "footprints_bgt.gpkg")]
    cmd = ["reconstruct", str(d / "ahn3_cropped_1.laz"), *given, "--lod", "1.2", "--lod", "1.3",
           "--lod", "2.2", "-o", str(tmp / "out.city.json"), "-q",
           "--workers", "1"]  # the timers are this process's: no worker forked (auto)
    print(f"load average {os.getloadavg()[0]:.1f}")
    trees = {"A": ROOT / "src"}
    if args.other:
        trees["B"] = Path(args.other).resolve()
    for name, src in trees.items():
        report(f"{name} ({src})", run(src, cmd), args.top)
    print(f"load average now {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
