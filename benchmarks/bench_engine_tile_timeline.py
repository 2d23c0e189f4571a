"""Where the wall time of ``reconstruct`` on the Delft tile goes: a timeline of the client, the server workers are forked from, and each worker.

Usage: ``python benchmarks/bench_engine_tile_timeline.py [DATA_DIR] [--workers 2] [--traced] [--log]``
(default $LIDAR2CITY_DATA or ../shared/data)

The command a user types (``lidar2city reconstruct ahn3_cropped_1.laz
--footprints footprints_bgt.gpkg --lod 1.2 --lod 1.3 --lod 2.2 -o OUT
--workers N``; ``--traced``: without the footprints) runs in a fresh process
whose functions are wrapped to note when each step ended, in seconds from the
moment this script started the process, with the client's CPU seconds then:
the imports, the start of the server the workers are forked from, the plan,
the tile decoded by the client for the workers, the cluster ready, the
output written, the command done; when the server's preload began and ended;
per task (block, part or traced block) its worker (or the client, which
computes a share of the tasks beside its workers), when the worker process
was born (/proc), the task's start and end, its CPU, the tiles it decoded
itself, the CPU the worker had spent before the task (its start-up), its
buildings. ``--log``: also Dask's and lidar2city's log lines with their times
(ms from the process start). The machine is shared: the load average is
printed, and wall seconds are only comparable at the same load.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_speed import ROOT, data_dir  # noqa: E402

CHILD = r'''
import json, os, sys, time


def main():
    t0, marks = float(sys.argv[1]), []

    def mark(name):
        marks.append((name, time.time() - t0, time.process_time()))

    mark("python started")
    import logging
    if os.environ.get("BENCH_LOG"):
        logging.basicConfig(level=logging.DEBUG,
                            format="%(relativeCreated)6d ms %(threadName)s %(name)s %(message)s")
    from lidar2city.cli import main as climain
    from lidar2city.tools import engine, reconstruct as R, task
    mark("lidar2city imported")
    engine.FORKSERVER_PRELOAD = ("bench_mark_first",) + engine.FORKSERVER_PRELOAD

    def wrap(owner, name, before=None, after=None):
        real = getattr(owner, name)

        def wrapped(*a, **k):
            if before:
                mark(before)
            out = real(*a, **k)
            if after:
                mark(after(out) if callable(after) else after)
            return out
        setattr(owner, name, wrapped)

    engine_start = engine._start_forkserver
    engine._start_forkserver = lambda preload=(): (
        mark("server start asked"), engine_start(tuple(preload) + ("bench_mark_last",)),
        mark("server started (its preload goes on)"))
    wrap(R, "plan_reconstruct", "plan begun", lambda p: f"plan done ({len(p.specs)} tasks)")
    wrap(task, "predecode", None, lambda d: f"client decoded {len(d)} tile(s) for the workers")
    real_ready = engine.DaskExecutor.ready

    def ready(self):
        waiting = self._starting is not None
        out = real_ready(self)
        if waiting:
            mark(f"cluster ready (start-up {self.startup_seconds:.2f} s)")
        return out
    engine.DaskExecutor.ready = ready

    def timed(fn):
        def run(spec, options):
            import time as t_
            start, cpu0, dec0 = t_.time(), t_.process_time(), task._cache.decoded
            out = fn(spec, options)
            with open("/proc/self/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            age = (t_.clock_gettime(t_.CLOCK_BOOTTIME)
                   - int(fields[19]) / os.sysconf("SC_CLK_TCK"))
            out.bench = (start, t_.time(), os.getpid(), t_.time() - age,
                         t_.process_time() - cpu0, cpu0, task._cache.decoded - dec0)
            return out
        return run

    # the tasks as run_block / trace_footprints run them (not the module's names,
    # which a worker would look up as these wrappers)
    def run_block(spec, options):
        task._cache.saved = dict(options.decoded)
        return task._measured(task._encoded_block, spec, options)

    def trace_footprints(spec, options):
        task._cache.saved = dict(options.decoded)
        return task._measured(task._trace_footprints, spec, options)

    task.run_block, task.trace_footprints = timed(run_block), timed(trace_footprints)
    rows = []
    for owner, name in ((R.InOrder, "add"),):
        real_add = owner.add

        def add(self, out, real_add=real_add):
            rows.append(list(out.bench) + [len(out.results), "build"])
            return real_add(self, out)
        owner.add = add
    real_map = engine.DaskExecutor.map

    def traced_map(self, fn, *a, **k):
        for i, out in real_map(self, fn, *a, **k):
            if getattr(out, "bench", None) and not out.results and fn is task.trace_footprints:
                rows.append(list(out.bench) + [len(out.footprints or ()), "trace"])
            yield i, out
    engine.DaskExecutor.map = traced_map
    wrap(R, "_sink", None, None)
    try:
        climain._STANDALONE.append(True)
        climain.cli.main(sys.argv[2:], standalone_mode=False)
    finally:
        mark("command done")
        import resource
        ch = resource.getrusage(resource.RUSAGE_CHILDREN)
        print("BENCH " + json.dumps({"marks": marks, "rows": rows, "client": os.getpid(),
                                     "children_cpu": ch.ru_utime + ch.ru_stime}),
              file=sys.stderr)


if __name__ == "__main__":
    main()
'''

MARK = """import os, time
with open(os.environ["BENCH_MARKS"], "a") as f:
    f.write(f"{time.time()} {NAME}\\n")
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--workers", default="2")
    ap.add_argument("--traced", action="store_true", help="no footprint file")
    ap.add_argument("--log", action="store_true", help="Dask's and lidar2city's log lines too")
    a = ap.parse_args()
    d = data_dir(a.data) / "delft"
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} "
          f"({os.cpu_count()} cores)")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "child.py").write_text(CHILD)
        for name in ("first", "last"):
            (tmp / f"bench_mark_{name}.py").write_text(
                MARK.replace("{NAME}", f"server preload {'begun' if name == 'first' else 'done'}"))
        marks = tmp / "marks.txt"
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "src"), str(tmp)]),
                   BENCH_MARKS=str(marks))
        env.pop("PYTHONDONTWRITEBYTECODE", None)  # as bench_engine_tile.py: bytecode cached
        if a.log:
            env["BENCH_LOG"] = "1"
        cmd = [sys.executable, str(tmp / "child.py"), "", *(["-vv"] if a.log else []),
               "reconstruct", str(d / "ahn3_cropped_1.laz"),
               *([] if a.traced else ["--footprints", str(d / "footprints_bgt.gpkg")]),
               "--lod", "1.2", "--lod", "1.3", "--lod", "2.2", "-o", str(tmp / "out.city.json"),
               "-q", "--workers", a.workers]
        t0 = time.time()
        cmd[2] = repr(t0)
        r = subprocess.run(cmd, capture_output=True, text=True, env=env)
        wall = time.time() - t0
        server = ([(float(line.split(" ", 1)[0]) - t0, line.split(" ", 1)[1].strip())
                   for line in marks.read_text().splitlines()] if marks.exists() else [])
    lines = r.stderr.splitlines()
    bench = [line for line in lines if line.startswith("BENCH ")]
    if r.returncode or not bench:
        raise SystemExit(r.stderr)
    m = json.loads(bench[-1][6:])
    events = [(t, f"client: {n} (client CPU {c:.2f} s)") for n, t, c in m["marks"]]
    events += [(t, f"server: {n}") for t, n in server]
    for t, text in sorted(events):
        print(f"{t:6.2f} s  {text}")
    print(f"{wall:6.2f} s  process ended; CPU of the processes it started (workers, their "
          f"server) {m['children_cpu']:.2f} s")
    pids = {m["client"]: "client  "}  # the client computes its share of the tasks too
    for start, end, pid, born, cpu, before, dec, n, kind in sorted(m["rows"]):
        k = pids.setdefault(pid, f"worker {len(pids) - 1}")
        print(f"{k} (born {born - t0:5.2f} s): {kind} {start - t0:5.2f}-{end - t0:5.2f} s "
              f"({end - start:4.2f} s, {cpu:4.2f} CPU s), {n} buildings, {dec} tile(s) decoded "
              f"itself, worker CPU before {before:.2f} s")
    if a.log:
        for line in lines:
            if line[:8].strip().split(" ")[0].isdigit():
                print(line[:160])
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
