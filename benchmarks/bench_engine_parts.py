"""The parts of the Delft tile as ``--workers N`` cuts them: each part's CPU seconds, and the workers' ends as the executor deals them.

Usage: ``python benchmarks/bench_engine_parts.py [DATA_DIR] [--traced] [--workers 2] [--src OTHER_SRC]``
(default $LIDAR2CITY_DATA or ../shared/data)

In a fresh process (this tree's ``src``, or OTHER_SRC's), with the task
modules imported first (so that no part pays for them), the run is planned
for ``--workers`` processes (``--traced``: no footprint file, the block traced
first, as ``trace_then_split`` does for that many workers), the shared tile
is held as the fork executor holds it, and every part is run in turn in this
one process: its CPU seconds, buildings and expected work (``BlockSpec.work``)
are printed, with the CPU seconds of the same buildings as one block (the plan
of one process: what cutting the block into parts costs). Then the executor's
dealing (:class:`lidar2city.tools.engine.RunDealer`, one queue or shares as
``run_blocks`` asks for) is replayed on those CPU seconds, this process and
``N - 1`` workers starting together: the busier worker's CPU seconds (the
parallel section of an idle machine) and how long the first to finish waits
for the last. The parts' CPU seconds are measured one after the other, not two
at once: what two processes at once cost each other is not in them.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_speed import ROOT, data_dir  # noqa: E402

CHILD = r'''
import contextlib, json, sys, time
from lidar2city.tools import engine, reconstruct as R, task
import importlib
for name in engine.worker_modules(("1.2", "1.3", "2.2")):
    importlib.import_module(name)
laz, fps, workers = sys.argv[1], (sys.argv[2] or None), int(sys.argv[3])


class Stub(engine.InProcess):  # the first pass of a traced block, cut for N workers
    pass


Stub.workers = workers


def planned(n):
    plan = R.plan_reconstruct([laz], "/dev/null.city.json", footprints=fps,
                              lods=["1.2", "1.3", "2.2"], workers=n)
    stack = contextlib.ExitStack()
    tiles = [t for s in plan.specs for t in s.tiles]
    task.hold_tiles(list({t.path: t for t in tiles}.values()), stack)
    t = time.process_time()
    if plan.trace_first:
        plan = R.trace_then_split(Stub(), plan)
    return plan, stack, time.process_time() - t


def run(plan):
    rows = []
    for s in plan.specs:
        t = time.process_time()
        out = task.run_block(s, plan.options)
        rows.append([s.index, len(out.results), s.work, time.process_time() - t])
    return rows


whole, stack, _ = planned(1)
run(whole)  # warm: the first block's caches
one = run(whole)
stack.close()
plan, stack, trace = planned(workers)
rows = run(plan)
dealt = getattr(R, "dealt_one_by_one", None)
balance = dealt(plan, plan.specs) if dealt is not None else bool(plan.parts)
print("BENCH " + json.dumps({"one": one, "rows": rows, "balance": balance, "trace": trace,
                             "costs": [s.work for s in plan.specs]}))
'''


def replay(cpu, costs, workers: int, balance: bool, src) -> dict:
    """The executor's dealing of runs of these parts (as ``ForkExecutor.map`` cuts and
    deals them) replayed on their CPU seconds, every process starting at 0."""
    sys.path.insert(0, str(src))
    from lidar2city.tools.engine import RunDealer, runs_of

    n = len(cpu)
    runs = [(i, i + 1) for i in range(n)] if balance else runs_of(n, workers, costs)
    dealer = RunDealer(len(runs), workers - 1, balance=balance)
    clock = [0.0] * workers  # this process last, as in ForkExecutor.map
    taken = [[] for _ in range(workers)]
    done = [False] * workers
    while not all(done):
        k = min((c, k) for k, c in enumerate(clock) if not done[k])[1]
        r, _ = dealer.mine() if k == workers - 1 else dealer.theirs(k)
        if r is None:
            done[k] = True
            continue
        a, b = runs[r]
        clock[k] += sum(cpu[a:b])
        taken[k].append(r)
    return {"busiest": max(clock), "wait": max(clock) - min(clock), "clock": clock,
            "taken": taken}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--traced", action="store_true", help="no footprint file")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--src", help="another tree's src folder (default this tree's)")
    a = ap.parse_args()
    d = data_dir(a.data) / "delft"
    src = Path(a.src) if a.src else ROOT / "src"
    env = dict(os.environ, PYTHONPATH=str(src))
    print(f"{src}; load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    out = subprocess.run([sys.executable, "-c", CHILD, str(d / "ahn3_cropped_1.laz"),
                          "" if a.traced else str(d / "footprints_bgt.gpkg"), str(a.workers)],
                         env=env, capture_output=True, text=True, check=False)
    got = [line for line in out.stdout.splitlines() if line.startswith("BENCH ")]
    if out.returncode or not got:
        raise SystemExit(out.stderr)
    m = json.loads(got[-1][6:])
    rows = m["rows"]
    for index, n, work, cpu in rows:
        print(f"part {index}: {n} buildings, expected work {work:.1f}, {cpu:.2f} CPU s")
    one = sum(r[3] for r in m["one"])
    parts = sum(r[3] for r in rows)
    print(f"{len(rows)} parts: {parts:.2f} CPU s; the same buildings as the plan of one "
          f"process ({len(m['one'])} block(s)): {one:.2f} CPU s (parts / whole {parts / one:.3f})"
          + (f"; the parts' traced first pass {m['trace']:.2f} CPU s (the whole block "
             "traces its footprints itself)" if a.traced else ""))
    r = replay([row[3] for row in rows], m["costs"], a.workers, m["balance"], src)
    print(f"dealt {'one by one' if m['balance'] else 'in shares'} to {a.workers} processes: "
          f"the busier {r['busiest']:.2f} CPU s (half of all the parts {parts / a.workers:.2f}), "
          f"the first to finish waits {r['wait']:.2f} s; parts by process "
          + "; ".join(f"{'this' if k == a.workers - 1 else f'worker {k}'} {t}"
                      for k, t in enumerate(r["taken"])))
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
