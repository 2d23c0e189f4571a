"""Where the CPU of the no-footprints reconstruct of the Delft tile goes, stage by stage (issue 13).

Usage: python benchmarks/bench_traced_stages.py [DATA_DIR] [--footprints]
(default data $LIDAR2CITY_DATA or ../shared/data)

Runs ``reconstruct`` of the Delft tile (LoD 1.2 + 1.3 + 2.2) once in this fresh
process, without footprints (traced from the points; ``--footprints``: with the
132 BGT footprints), with each stage's function wrapped by a CPU clock
(``time.process_time``, no profiler: the figures are the run's own), and prints
the CPU seconds of: reading the block's points, the point roles (ground /
building), tracing the footprints (its steps: point spacing, scan-line test,
building field, regions, split at roof steps, outlines, simplification, the
snake with its simplification, the disjoint parts, the building points each holds), LoD1.2 / 1.3 per
building, LoD2.2, and the rest of the process (start-up, imports, plan,
writing), with the output's MD5. One run: CPU seconds on a shared machine move
with its load; compare the shares, or two trees in turn.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--footprints", action="store_true", help="with the BGT footprints")
    args = ap.parse_args()
    data = Path(args.data or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")
    laz = data / "delft" / "ahn3_cropped_1.laz"

    import lidar2city.footprints.extract as ext
    import lidar2city.footprints.regularizers as regs
    import lidar2city.lod.lod1 as lod1
    import lidar2city.tools.reconstruct as rec
    import lidar2city.tools.task as task
    from lidar2city.cli.main import cli

    spent: dict[str, float] = {}
    stack: list[float] = []  # the CPU of the stages nested in the running one

    def clocked(name, f):
        def g(*a, **k):
            t0 = time.process_time()
            stack.append(0.0)
            try:
                return f(*a, **k)
            finally:
                inner = stack.pop()
                dt = time.process_time() - t0
                spent[name] = spent.get(name, 0.0) + dt - inner  # own time, nested stages out
                if stack:
                    stack[-1] += dt
        return g

    wrapped = [(task, "_read_box", "read"), (rec, "point_roles", "roles"),
               (task, "_block_traced", "tracing (other)"),
               (ext, "point_spacing", "  point spacing"), (ext, "scan_line_gap", "  scan-line test"),
               (ext, "building_fraction", "  building field"),
               (ext, "building_regions", "  regions"), (ext, "cell_heights", "  cell heights"),
               (ext, "split_at_steps", "  split at steps"), (ext, "trace_regions", "  outlines"),
               (ext, "_disjoint", "  disjoint parts"),
               (task, "_points_inside", "  points inside"),
               (lod1, "reconstruct_building", "LoD1.2 / 1.3"), (rec, "add_lod22", "LoD2.2")]
    for mod, attr, name in wrapped:
        setattr(mod, attr, clocked(name, getattr(mod, attr)))
    regs.REGULARIZERS["snake"] = clocked("  snake", regs.REGULARIZERS["snake"])

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.city.json"
        argv = ["reconstruct", str(laz), "--lod", "1.2", "--lod", "1.3", "--lod", "2.2",
                "-o", str(out)]
        if args.footprints:
            argv += ["--footprints", str(data / "delft" / "footprints_bgt.gpkg")]
        cli.main(argv, standalone_mode=False)
        md5 = hashlib.md5(out.read_bytes()).hexdigest()
    ru = resource.getrusage(resource.RUSAGE_SELF)
    total = ru.ru_utime + ru.ru_stime
    tracing = sum(v for k, v in spent.items() if k.startswith("  ") or k == "tracing (other)")
    print(f"{'stage':<24}{'CPU s':>8}{'share':>8}")
    rows = ["read", "roles", "tracing (other)"] + [n for _, _, n in wrapped[3:12]] + [
        "  snake", "tracing (all)", "LoD1.2 / 1.3", "LoD2.2"]
    for name in rows:
        v = tracing if name == "tracing (all)" else spent.get(name, 0.0)
        print(f"{name:<24}{v:8.3f}{v / total:8.1%}")
    rest = total - sum(spent.values())
    print(f"{'rest (imports, write)':<24}{rest:8.3f}{rest / total:8.1%}")
    print(f"{'process (user + system)':<24}{total:8.3f}  peak RSS {ru.ru_maxrss / 1024:.0f} MB")
    print(f"output MD5 {md5}  load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
