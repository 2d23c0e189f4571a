"""Where the wall time of a reconstruct on a local Dask cluster goes: phases and a timeline per worker.

Usage: ``PYTHONPATH=src python benchmarks/bench_engine_timeline.py [--size 12] [--workers 2]``

The synthetic area of ``bench_engine.py`` (``--size`` x ``--size`` demo-town
tiles, blocks of 200 m, LoD1.2 to a streamed CityJSONSeq) is reconstructed in
a fresh process through the same steps as ``reconstruct`` (the planner, the
executor, the task, the in-order writer; no journal), each block wrapped to
record when it started and ended on its worker. Printed: when the plan was
made, the cluster ready (its start-up), the blocks done and the cluster closed (seconds from
the start), with the client process's CPU in each phase; per worker its
blocks, first start and last end, the seconds it was running a block and the
CPU it spent on them, its buildings, the tiles it decoded, its idle gaps
between blocks longer than 20 ms and how long it waited at the end for the
last worker; and the CPU of every process the run started (the workers and
the server they are forked from, counted once reaped); and the client's CPU
while the blocks ran by thread (Linux ``/proc/self/task``: the main thread,
which submits, receives and writes, and Dask's event loop thread, which runs
the scheduler, the nannies and the connections). The machine is shared:
the load average is printed, and wall seconds are only comparable at the same
load.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_engine import BLOCK, make_area  # noqa: E402

CHILD = r"""
import json, os, resource, sys, threading, time

from lidar2city.tools import reconstruct as R, task
from lidar2city.tools.engine import make_executor


def timed_block(spec, options):
    # runs on a worker: the block, when it started and ended, and the tiles decoded so far
    start = time.time()
    out = task.run_block(spec, options)
    out.timeline = (start, time.time(), os.getpid(), task._cache.decoded)
    return out


def threads_cpu():
    # CPU seconds of each thread of this process, by name (Linux /proc; {} elsewhere)
    names = {t.native_id: t.name for t in threading.enumerate()}
    tick, out = os.sysconf("SC_CLK_TCK"), {}
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return out
    for tid in tids:
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                stat = f.read()
        except OSError:  # the thread ended
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        name = names.get(int(tid), stat[stat.index("(") + 1:stat.rindex(")")])
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return out


def main():
    a = json.loads(sys.argv[1])
    t0, c0 = time.time(), time.process_time()
    phases = {}
    with make_executor(a["workers"], preload=task.worker_modules(("1.2",))) as ex:
        plan = R.plan_reconstruct(a["tiles"], a["out"], footprints=a["fp"], block_size=a["block"])
        phases["planned"] = (time.time() - t0, time.process_time() - c0)
        threads_before = threads_cpu()
        ordered, sink = R.InOrder(plan), R._sink(a["out"], plan)
        costs = [max(s.size, 1) for s in plan.specs]
        rows = []
        for _, out in ex.map(timed_block, plan.specs, plan.options, run_hook=task.tile_keeper,
                             costs=costs):
            if isinstance(out, BaseException):
                raise out
            for r, fields, encoded in ordered.add(out):
                sink.add(r, fields, encoded)
            start, end, pid, decoded = out.timeline
            rows.append([start - t0, end - t0, pid, decoded, out.cpu, out.index,
                         len(out.results)])
        sink.close()
        phases["blocks done"] = (time.time() - t0, time.process_time() - c0)
        ready = ex.startup_seconds
        threads = {k: v - threads_before.get(k, 0.0) for k, v in threads_cpu().items()}
    phases["closed"] = (time.time() - t0, time.process_time() - c0)
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    print(json.dumps({"phases": phases, "rows": rows, "tiles": len(a["tiles"]), "threads": threads,
                      "children_cpu": ch.ru_utime + ch.ru_stime, "ready": ready}))


if __name__ == "__main__":
    main()
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=12)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} "
          f"({os.cpu_count()} cores)")
    with tempfile.TemporaryDirectory() as tmp:
        tiles, fp = make_area(Path(tmp), a.size)
        args = json.dumps({"tiles": tiles, "fp": fp, "out": str(Path(tmp) / "out.city.jsonl"),
                           "block": BLOCK, "workers": a.workers})
        script = Path(tmp) / "child.py"
        script.write_text(CHILD)
        r = subprocess.run([sys.executable, str(script), args], capture_output=True, text=True)
    if r.returncode:
        raise SystemExit(r.stderr)
    m = json.loads(r.stdout.strip().splitlines()[-1])
    prev = 0.0
    for name, (t, c) in m["phases"].items():
        print(f"{name:12s} at {t:6.2f} s; client CPU in this phase {c - prev:.2f} s")
        prev = c
    print(f"cluster ready at {m['ready']:6.2f} s (started when the run began, while the "
          "client planned)")
    busy = sorted(((v, k) for k, v in m["threads"].items() if v >= 0.005), reverse=True)
    print("client CPU while the blocks ran, by thread: "
          + (", ".join(f"{k} {v:.2f} s" for v, k in busy) or "not measured (no /proc)")
          + " (MainThread: submitting, receiving the results, writing; IO loop: Dask's "
          "scheduler, the nannies and the client's connections)")
    by = {}
    for row in m["rows"]:
        by.setdefault(row[2], []).append(row)
    ends = {pid: max(r[1] for r in rs) for pid, rs in by.items()}
    last = max(ends.values())
    for k, (pid, rs) in enumerate(sorted(by.items(), key=lambda kv: min(r[0] for r in kv[1]))):
        rs.sort()
        gaps = [(round(b[0] - a_[1], 3)) for a_, b in zip(rs[:-1], rs[1:], strict=True)
                if b[0] - a_[1] > 0.02]
        print(f"worker {k}: {len(rs)} blocks ({min(r[5] for r in rs)}..{max(r[5] for r in rs)}), "
              f"first start {rs[0][0]:.2f} s, last end {rs[-1][1]:.2f} s, running blocks "
              f"{sum(r[1] - r[0] for r in rs):.2f} s, CPU on them {sum(r[4] for r in rs):.2f} s, "
              f"{sum(r[6] for r in rs)} buildings, {max(r[3] for r in rs)} tile decodings, "
              f"gaps > 20 ms {gaps or 'none'}, idle at the end {last - ends[pid]:.2f} s")
    print(f"tile decodings {sum(max(r[3] for r in rs) for rs in by.values())} of {m['tiles']} "
          f"tiles; CPU of the processes the run started (workers, their server) "
          f"{m['children_cpu']:.2f} s")
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
