"""Where two processes lose CPU against one: each part of the Delft tile's block, its CPU in one process, in two plain processes at once, and on 2 workers.

Usage: ``python benchmarks/bench_engine_tile_cpu.py [DATA_DIR] [--rounds 3] [--traced]``
(default $LIDAR2CITY_DATA or ../shared/data)

``--workers 2`` cuts the tile's one block into parts of its footprints that
the client and one worker process share (:mod:`lidar2city.tools.engine`). Per
round, in fresh processes (the instrumented command of
``bench_engine_tile_timeline.py``):

- ``one``: the plan of 2 workers, no cluster: the client runs all the parts,
  one after the other (what each part costs alone);
- ``pair``: two such runs started together (two plain processes, no Dask, each
  running every part: the floor of what a part costs when two processes
  compute at once on this machine: shared caches, memory bandwidth, the
  cores' siblings);
- ``dask``: ``--workers 2`` as a user runs it (the client and one worker).

Per part and mode: the CPU seconds of the thread that ran it (user + system,
``getrusage(RUSAGE_THREAD)``; medians over the rounds), and over the parts of
each process the seconds its thread waited for a core (runnable but not
running: another process had it, /proc's ``schedstat``) and was blocked
(neither running nor runnable: the interpreter lock held by another thread,
I/O). The sums say how much more CPU the parts take in two processes than in
one, and whether Dask adds to what any two processes cost. The load average
is printed: with other work on the machine, wall seconds go to "waited for a
core", CPU seconds stay comparable.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_engine_tile_timeline import Child, tasks  # noqa: E402
from bench_speed import data_dir  # noqa: E402


def _load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--traced", action="store_true", help="no footprint file")
    a = ap.parse_args()
    d = data_dir(a.data) / "delft"
    print(f"load average before: {_load()} ({os.cpu_count()} cores)", flush=True)
    Child(d, traced=a.traced, one_process=True).result()  # warm the file cache, the bytecode
    per = {}  # (mode, part) -> [thread CPU s]
    sums = {}  # mode -> [(thread CPU, wait, blocked, process CPU, faults)]
    for k in range(max(1, a.rounds)):
        runs = {"one": [Child(d, traced=a.traced, one_process=True).result()]}
        pair = [Child(d, traced=a.traced, one_process=True) for _ in range(2)]
        runs["pair"] = [c.result() for c in pair]
        runs["dask"] = [Child(d, traced=a.traced).result()]
        line = [f"round {k + 1} (load {os.getloadavg()[0]:.2f})"]
        for mode, results in runs.items():
            rows = [t for _, m, _, _ in results for t in tasks(m)]
            for t in rows:
                per.setdefault((mode, t["index"]), []).append(t["user"] + t["sys"])
            total = (sum(t["user"] + t["sys"] for t in rows), sum(t["wait"] for t in rows),
                     sum(t["blocked"] for t in rows), sum(t["cpu"] for t in rows),
                     sum(t["faults"] for t in rows))
            if mode == "pair":  # each of the two ran every part: per part, the mean of them
                total = tuple(v / 2 for v in total)
            sums.setdefault(mode, []).append(total)
            line.append(f"{mode} {total[0]:.2f} CPU s (waited {total[1]:.2f} s, blocked "
                        f"{total[2]:.2f} s)")
        print("; ".join(line), flush=True)
    parts = sorted({p for _, p in per})
    print("part: thread CPU s, median of the rounds (one / pair / dask) and dask / one")
    for p in parts:
        one, two, dask = (statistics.median(per[(m, p)]) for m in ("one", "pair", "dask"))
        print(f"  part {p}: {one:.3f} / {two:.3f} / {dask:.3f}  x{dask / one:.2f}")
    med = {m: [statistics.median(v[i] for v in sums[m]) for i in range(5)] for m in sums}
    for m in ("one", "pair", "dask"):
        v = med[m]
        ratio = "" if m == "one" else f"; x{v[0] / med['one'][0]:.3f} of one"
        print(f"{m}: all parts {v[0]:.2f} CPU s of their threads ({v[3]:.2f} of their "
              f"processes, {v[4]:.0f} page faults), waited for a core {v[1]:.2f} s, blocked "
              f"{v[2]:.2f} s{ratio}")
    print(f"load average after: {_load()}")


if __name__ == "__main__":
    main()
