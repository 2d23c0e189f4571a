"""CPU of the LoD2.2 roof lines (:func:`lidar2city.roof.arrangement.roof_lines`), this tree
against another, on the same inputs (issue 13).

Usage: PYTHONPATH=src python benchmarks/bench_roof_lines.py BASE_SRC [DATA_DIR] [--pairs N]
       [--repeat R] [--traced] [--keep FILE]
(default data $LIDAR2CITY_DATA or ../shared/data, N = 5, R = 2)

``reconstruct`` (LoD 1.2 + 1.3 + 2.2, the 132 BGT footprints of the Delft tile) runs
once in this process and records the arguments of every ``roof_lines`` call (its
inputs, the facets' points, labels and planes, come from stages before it, the same
in both trees). Then N pairs of fresh processes, the other tree (``BASE_SRC`` on
``PYTHONPATH``) and this one in alternation (the first of each pair alternating too),
each replay every call R times (with that tree's ``[lod22]`` defaults of
``snake_window`` and ``snake_cell``) and print the least CPU (user + system,
``resource.getrusage``) of one pass over them all: the stage's cost per Delft run,
with the work of the two trees interleaved on a shared machine. Printed: each pair,
the median of the per-pair ratios (this tree / other) and the roof lines' agreement
(how many calls give the same segments and kinds, to the bit); and, of the same
passes, the CPU of the step snake's distance rasters, energy tables and solves
(``regularize.snake``'s calls of ``distance_raster``, ``edge_energy_tables`` and
``minimize_energy``) in each tree, with the medians of their ratios.

``--traced``: the same without footprints (footprints traced from the points, issue
13's no-footprints target; the roofs are larger merged blocks). ``--keep FILE``:
also write the recorded calls to FILE (a pickle, for profiling one stage alone).
"""

from __future__ import annotations

import os
import pickle
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

_REPLAY = r"""
import pickle, resource, sys
import numpy as np
import lidar2city.roof.arrangement as arrangement

def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime

from lidar2city.roof.building import Lod22Config

import time
import lidar2city.regularize.snake as snake

# the snake's parts (the step snake's distance raster, energy tables and solver), timed
# where regularize.snake calls them
parts = {}

def timed(name):
    func = getattr(snake, name)

    def run(*a, **k):
        t = time.process_time()
        try:
            return func(*a, **k)
        finally:
            parts[name] = parts.get(name, 0.0) + time.process_time() - t
    setattr(snake, name, run)

for name in ("distance_raster", "edge_energy_tables", "minimize_energy"):
    timed(name)
calls = pickle.load(open(sys.argv[1], "rb"))
repeat = int(sys.argv[2])
cfg = Lod22Config()  # this tree's defaults: the snake's window and grid step are options
for _, kw in calls:
    kw.update(snake_window=cfg.snake_window, snake_cell=cfg.snake_cell)
best = (float("inf"),)
for _ in range(repeat):
    parts.clear()
    t = cpu()
    outs = [arrangement.roof_lines(*a, **kw) for a, kw in calls]
    best = min(best, (cpu() - t, *(parts.get(n, 0.0) for n in ("distance_raster", "edge_energy_tables",
                                                                  "minimize_energy"))))
with open(sys.argv[3], "wb") as f:
    pickle.dump([([np.asarray(s).tobytes() for s in segs], kinds) for segs, kinds in outs], f)
print(*best)
"""

#: The parts of the stage timed in each replay (process CPU of the calls, summed).
_PARTS = ("distance raster", "energy tables", "solver")


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _capture(data: Path, path: Path, traced: bool = False) -> int:
    import lidar2city.roof.arrangement as arrangement
    from lidar2city.cli.main import cli

    calls, func = [], arrangement.roof_lines

    def recording(*args, **kwargs):
        calls.append((args, kwargs))
        return func(*args, **kwargs)

    tile, fp = data / "delft" / "ahn3_cropped_1.laz", data / "delft" / "footprints_bgt.gpkg"
    arrangement.roof_lines = recording
    try:
        given = [] if traced else ["--footprints", str(fp)]
        cli.main(["-q", "reconstruct", str(tile), *given, "--lod", "1.2",
                  "--lod", "1.3", "--lod", "2.2", "-o", str(path.with_suffix(".city.json"))],
                 standalone_mode=False)
    except SystemExit:
        pass
    finally:
        arrangement.roof_lines = func
    with open(path, "wb") as f:
        pickle.dump(calls, f)
    return len(calls)


def _replay(src: str, calls: Path, repeat: int, out: Path) -> float:
    env = dict(os.environ, PYTHONPATH=src)
    res = subprocess.run([sys.executable, "-c", _REPLAY, str(calls), str(repeat), str(out)],
                         env=env, capture_output=True, text=True, check=True)
    return tuple(float(x) for x in res.stdout.split("\n")[-2].split())


def main(argv: list[str]) -> int:
    pairs, repeat = 5, 2
    traced = "--traced" in argv
    argv = [a for a in argv if a != "--traced"]
    keep = None
    if "--keep" in argv:
        i = argv.index("--keep")
        keep = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    for name in ("--pairs", "--repeat"):
        if name in argv:
            i = argv.index(name)
            val = int(argv[i + 1])
            argv = argv[:i] + argv[i + 2:]
            pairs, repeat = (val, repeat) if name == "--pairs" else (pairs, val)
    if not argv:
        print(__doc__)
        return 2
    base = str(Path(argv[0]).resolve())
    data = Path(argv[1] if len(argv) > 1 else os.environ.get("LIDAR2CITY_DATA", "../shared/data"))
    ours = str(Path(__file__).resolve().parent.parent / "src")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        n = _capture(data, tmp / "calls.pkl", traced)
        if keep:
            Path(keep).write_bytes((tmp / "calls.pkl").read_bytes())
        what = "traced footprints" if traced else "132 BGT footprints"
        print(f"Delft, {what}: {n} roof_lines calls; {pairs} pairs of fresh processes, "
              f"least of {repeat} replays each; load {os.getloadavg()[0]:.1f}")
        ratios, part_ratios = [], []
        for k in range(pairs):
            order = [("base", base), ("this", ours)]
            if k % 2:
                order.reverse()
            got = {name: _replay(src, tmp / "calls.pkl", repeat, tmp / f"{name}.pkl") for name, src in order}
            ratios.append(got["this"][0] / got["base"][0])
            part_ratios.append([t / b if b > 0 else float("nan")
                                for t, b in zip(got["this"][1:], got["base"][1:], strict=True)])
            print(f"  pair {k + 1}: base {got['base'][0]:.3f} CPU s, this {got['this'][0]:.3f} CPU s, "
                  f"ratio {ratios[-1]:.3f}; " + ", ".join(
                      f"{p} {b:.3f} / {t:.3f}" for p, b, t in zip(_PARTS, got["base"][1:], got["this"][1:],
                                                                 strict=True)))
        a = pickle.load(open(tmp / "base.pkl", "rb"))
        b = pickle.load(open(tmp / "this.pkl", "rb"))
        same = sum(x == y for x, y in zip(a, b, strict=True))
    print(f"roof_lines CPU this / base: median of pairs {statistics.median(ratios):.3f}; "
          f"calls with the same lines (bits): {same} / {n}; load {os.getloadavg()[0]:.1f}")
    print("  the step snake's parts, this / base (median of pairs): " + ", ".join(
        f"{p} {statistics.median(r[i] for r in part_ratios):.3f}" for i, p in enumerate(_PARTS)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
