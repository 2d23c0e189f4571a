"""CPU of the LoD2.2 solid stage (roof partition -> validated solid) in ``reconstruct``, by cProfile.

Usage: python benchmarks/bench_solid_area.py [DATA_DIR] [--other SRC] [--runs N] [--traced]

The command of issue 13 (LoD 1.2 + 1.3 + 2.2 on the Delft tile, with its 132 BGT footprints,
or without them with ``--traced``) runs in a child process under cProfile, with this tree's
``src`` and, with ``--other``, another tree's in turn (A B A B ..., ``--runs`` pairs). Each run
prints the profiled process CPU seconds, the stage's CPU seconds and its parts (cumulative
seconds of one function, summed over its calls):

- the stage: ``_finish_solid`` (refinement, fixes, the solid and its repairs) without
  ``collapse_short_edges`` (the roof partition's), plus the ``check_solid`` and
  ``_closed_shell`` calls outside it (the written solid's validation, restored facets),
  plus ``part_floor``;
- ``partition_to_solid`` (session 13): ``_part_solid`` without ``roof_lines`` but with its
  ``label_grid``, that is the arrangement partition, restored facets, ``_finish_solid``;
- ``check_solid`` in all, its mesh (``solid_mesh``) and self-intersection test,
  ``refine_partition``, ``_manifold_solid``, ``partition_solid``.

The profiler times CPU seconds (``time.process_time``) and inflates every figure (~1.5x,
more for many small calls): compare the two trees in the same call, as ratios. Medians of
the runs at the end.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import cProfile, json, pstats, resource, sys, time
from lidar2city.cli.main import main
prof = cProfile.Profile(time.process_time)  # CPU seconds: wall time means nothing under load
sys.argv = ["lidar2city", *ARGS]
prof.enable()
try:
    main()
except SystemExit:
    pass
prof.disable()
st = pstats.Stats(prof).stats
def cum(name, callers=None, exclude=()):
    total = 0.0
    for (f, _, n), (cc, nc, tt, ct, by) in st.items():
        if n != name or "lidar2city" not in f:
            continue
        if callers is None and not exclude:
            total += ct
            continue
        for (cf, _, cn), v in by.items():
            if (callers is None or cn in callers) and cn not in exclude:
                total += v[3]
    return total
outside = ("_finish_solid", "_manifold_solid", "_saddle_cut", "_valid_cut")
parts = {
    "check_solid": cum("check_solid", exclude=("solid_error_codes",)),
    "solid_mesh": cum("solid_mesh"),
    "_self_intersections": cum("_self_intersections"),
    "refine_partition": cum("refine_partition"),
    "_manifold_solid": cum("_manifold_solid"),
    "partition_solid": cum("partition_solid"),
    "arrangement_partition": cum("arrangement_partition"),
    "dissolve_cells": cum("dissolve_cells"),
    "collapse_short_edges": cum("collapse_short_edges"),
    "label_grid": cum("label_grid"),
    # session 13's stage: the roof partition to the solid, without the roof lines
    # (label_grid, in them, counted back)
    "partition_to_solid": cum("_part_solid") - cum("roof_lines") + cum("label_grid"),
}
stage = (cum("_finish_solid") - cum("collapse_short_edges")
         + cum("check_solid", exclude=outside + ("solid_error_codes",))
         + cum("_closed_shell", exclude=outside) + cum("part_floor"))
ru = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"cpu": ru.ru_utime + ru.ru_stime, "stage": stage, **parts}))
"""


def run(src: Path, args: list[str]) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    code = CHILD.replace("ARGS", repr(args))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=False)
    if out.returncode != 0:
        raise SystemExit(f"run with {src} failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--other", help="the src folder of another tree, run in turn with this one")
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--traced", action="store_true", help="without footprints (traced)")
    args = ap.parse_args()
    data = Path(args.data or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")
    d = data / "delft"
    tmp = Path(tempfile.mkdtemp())
    given = [] if args.traced else ["--footprints", str(d / "footprints_bgt.gpkg")]
    cmd = ["reconstruct", str(d / "ahn3_cropped_1.laz"), *given, "--lod", "1.2", "--lod", "1.3",
           "--lod", "2.2", "-o", str(tmp / "out.city.json"), "-q"]
    trees = {"A": ROOT / "src"}
    if args.other:
        trees["B"] = Path(args.other).resolve()
    res: dict = {k: [] for k in trees}
    print(f"load average {os.getloadavg()[0]:.1f}; A = {trees['A']}"
          + (f", B = {trees['B']}" if args.other else ""))
    for _ in range(max(1, args.runs)):
        for name, src in trees.items():
            r = run(src, cmd)
            res[name].append(r)
            print(f"{name}: process {r['cpu']:.2f} CPU s (profiled), stage {r['stage']:.3f} s; "
                  + ", ".join(f"{k} {v:.3f}" for k, v in r.items() if k not in ("cpu", "stage")))
    for name, rs in res.items():
        med = {k: statistics.median(r[k] for r in rs) for k in rs[0]}
        print(f"{name} median: process {med['cpu']:.2f} CPU s, stage {med['stage']:.3f} s "
              f"({100 * med['stage'] / med['cpu']:.1f} %)")
    if args.other:
        ratios = [a["stage"] / b["stage"] for a, b in zip(res["A"], res["B"], strict=True)]
        cpu = [a["cpu"] / b["cpu"] for a, b in zip(res["A"], res["B"], strict=True)]
        p2s = [a["partition_to_solid"] / b["partition_to_solid"]
               for a, b in zip(res["A"], res["B"], strict=True)]
        print(f"A/B partition_to_solid CPU {statistics.median(p2s):.3f} (runs "
              + ", ".join(f"{x:.3f}" for x in p2s) + ")")
        print(f"A/B stage CPU {statistics.median(ratios):.3f} (runs "
              + ", ".join(f"{x:.3f}" for x in ratios)
              + f"), profiled process CPU {statistics.median(cpu):.3f}; "
              f"load average now {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
