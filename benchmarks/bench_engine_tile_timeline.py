"""Where the wall time of ``reconstruct`` on the Delft tile goes: a timeline of the client, the server workers are forked from, and each worker.

Usage: ``python benchmarks/bench_engine_tile_timeline.py [DATA_DIR] [--workers 2] [--traced] [--log] [--src OTHER_SRC]``
(default $LIDAR2CITY_DATA or ../shared/data; ``LIDAR2CITY_LOCAL_EXECUTOR=dask`` in the
environment: the Dask cluster instead of workers forked from the client)

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
        marks.append((name, time.time() - t0, time.process_time(), time.thread_time()))

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

    if os.environ.get("BENCH_ONE"):  # the plan of N workers, every part in this process
        def no_cluster(self):
            raise RuntimeError("no cluster (--one-process)")
        engine.DaskExecutor._start = no_cluster
        engine._start_forkserver = lambda preload=(): None
    engine_start = engine._start_forkserver
    engine._start_forkserver = lambda preload=(): (
        mark("server start asked"), engine_start(tuple(preload) + ("bench_mark_last",)),
        mark("server started (its preload goes on)"))
    wrap(R, "plan_reconstruct", "plan begun", lambda p: f"plan done ({len(p.specs)} tasks)")
    wrap(task, "predecode", None, lambda d: f"client decoded {len(d)} tile(s) for the workers")
    wrap(task, "hold_tiles", None,
         lambda n: f"client decoded {n} tile(s) held for the workers it forks")
    real_start = engine.DaskExecutor._start

    def start(self):  # in the thread that starts the cluster: its CPU so far
        try:
            return real_start(self)
        finally:
            mark(f"cluster started by the client's start thread ({time.thread_time():.2f} "
                 "CPU s of that thread)")
    engine.DaskExecutor._start = start
    real_ready = engine.DaskExecutor.ready

    def ready(self):
        waiting = self._starting is not None
        out = real_ready(self)
        if waiting:
            mark(f"cluster ready (start-up {self.startup_seconds:.2f} s)")
        return out
    engine.DaskExecutor.ready = ready

    from lidar2city.tools import forked
    real_fork = forked._fork_children

    def fork_children(*a, **k):
        mark("fork: children being forked")
        try:
            return real_fork(*a, **k)
        finally:
            mark("fork: children forked")
    forked._fork_children = fork_children

    def timed(fn):
        def run(spec, *args):
            import time as t_
            import resource as r_
            import gc as g_
            import pickle as p_
            mods0 = len(sys.modules)
            gcs0 = sum(st["collections"] for st in g_.get_stats())
            start, cpu0, dec0 = t_.time(), t_.process_time(), task._cache.decoded

            def sched():  # this thread's time on a core, waiting for one (s)
                with open("/proc/thread-self/schedstat") as f:
                    return [int(v) / 1e9 for v in f.read().split()[:2]]
            u0, s0 = r_.getrusage(r_.RUSAGE_THREAD), sched()
            out = fn(spec, *args)
            u1, s1 = r_.getrusage(r_.RUSAGE_THREAD), sched()
            th = (u1.ru_utime - u0.ru_utime, u1.ru_stime - u0.ru_stime,
                  u1.ru_minflt - u0.ru_minflt,
                  sum(st["collections"] for st in g_.get_stats()) - gcs0, s1[1] - s0[1])
            with open("/proc/self/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            age = (t_.clock_gettime(t_.CLOCK_BOOTTIME)
                   - int(fields[19]) / os.sysconf("SC_CLK_TCK"))
            end, cpu1 = t_.time(), t_.process_time()
            # what sending the output back costs a forked worker (pickling; measured
            # after the task's own times were taken, so not counted in them)
            p0 = t_.process_time()
            size = len(p_.dumps([(0, out)], protocol=p_.HIGHEST_PROTOCOL))
            pick = t_.process_time() - p0
            out.bench = (start, end, os.getpid(), end - age, cpu1 - cpu0, cpu0,
                         task._cache.decoded - dec0, th + (len(sys.modules) - mods0, pick, size),
                         getattr(spec, "index", getattr(spec, "block", 0)))
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
    if hasattr(task, "trace_outlines"):  # a traced block's outlines shared by the workers
        real_regularise = task.regularise_parts

        def trace_outlines(spec, options, least=None):
            task._cache.saved = dict(options.decoded)
            return task._measured(task._trace_outlines, spec, options,
                                  task.STAGED_LEAST if least is None else least)

        def regularise_parts(item):
            return real_regularise(item)

        task.trace_outlines = timed(trace_outlines)
        task.regularise_parts = timed(regularise_parts)

    def first_pass(fn, out):  # the row of a traced block's first pass, or of its outlines
        if not getattr(out, "bench", None):
            return None
        if fn is task.trace_footprints and not out.results:
            return list(out.bench) + [len(out.footprints or ()), "trace"]
        if fn is getattr(task, "trace_outlines", None):
            n = len(out.staged.outlines) if out.staged is not None else len(out.footprints)
            return list(out.bench) + [n, "trace"]
        if fn is getattr(task, "regularise_parts", None):
            return list(out.bench) + [len(out.footprints), "outlines"]
        return None
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
            row = first_pass(fn, out)
            if row is not None:
                rows.append(row)
            yield i, out
    engine.DaskExecutor.map = traced_map
    real_fmap = forked.ForkExecutor.map

    def traced_fmap(self, fn, *a, **k):
        for i, out in real_fmap(self, fn, *a, **k):
            row = first_pass(fn, out)
            if row is not None:
                rows.append(row)
            yield i, out
    forked.ForkExecutor.map = traced_fmap
    real_loads, loads_cpu = forked.pickle.loads, [0.0, 0]

    class TimedPickle:  # the results unpickled by this process's feeder threads
        dumps = staticmethod(forked.pickle.dumps)
        HIGHEST_PROTOCOL = forked.pickle.HIGHEST_PROTOCOL

        @staticmethod
        def loads(data):
            t = time.thread_time()
            try:
                return real_loads(data)
            finally:
                loads_cpu[0] += time.thread_time() - t
                loads_cpu[1] += len(data)
    forked.pickle = TimedPickle
    wrap(R._Collect, "close", "output being written", "output written")
    wrap(R._Stream, "close", "output being written", "output written")
    wrap(engine.DaskExecutor, "process_cpu", None, "workers' CPU asked")
    wrap(engine.DaskExecutor, "_close", "cluster closing", "cluster closed")
    try:
        climain._STANDALONE.append(True)
        climain.cli.main(sys.argv[2:], standalone_mode=False)
    finally:
        mark("command done")
        import resource
        ch = resource.getrusage(resource.RUSAGE_CHILDREN)
        print("BENCH " + json.dumps({"marks": marks, "rows": rows, "client": os.getpid(),
                                     "children_cpu": ch.ru_utime + ch.ru_stime,
                                     "loads": loads_cpu}),
              file=sys.stderr)


if __name__ == "__main__":
    main()
'''

MARK = """import os, time
with open(os.environ["BENCH_MARKS"], "a") as f:
    f.write(f"{time.time()} {NAME}\\n")
"""



class Child:
    """One instrumented run of the command, started now (:data:`CHILD`); ``result()``
    waits for it: ``(wall seconds, the child's report, the server's marks)``."""

    def __init__(self, d, *, workers="2", traced=False, log=False, one_process=False, src=None):
        self.dir = tempfile.TemporaryDirectory()
        tmp = Path(self.dir.name)
        (tmp / "child.py").write_text(CHILD)
        for name in ("first", "last"):
            (tmp / f"bench_mark_{name}.py").write_text(
                MARK.replace("{NAME}", f"server preload {'begun' if name == 'first' else 'done'}"))
        self.marks = tmp / "marks.txt"
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(src or ROOT / "src"), str(tmp)]),
                   BENCH_MARKS=str(self.marks))
        env.pop("PYTHONDONTWRITEBYTECODE", None)  # as bench_engine_tile.py: bytecode cached
        if log:
            env["BENCH_LOG"] = "1"
        if one_process:
            env["BENCH_ONE"] = "1"
        self.t0 = time.time()
        cmd = [sys.executable, str(tmp / "child.py"), repr(self.t0), *(["-vv"] if log else []),
               "reconstruct", str(d / "ahn3_cropped_1.laz"),
               *([] if traced else ["--footprints", str(d / "footprints_bgt.gpkg")]),
               "--lod", "1.2", "--lod", "1.3", "--lod", "2.2", "-o", str(tmp / "out.city.json"),
               "-q", "--workers", str(workers)]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env)

    def result(self):
        _, err = self.proc.communicate()
        wall = time.time() - self.t0
        server = ([(float(line.split(" ", 1)[0]) - self.t0, line.split(" ", 1)[1].strip())
                   for line in self.marks.read_text().splitlines()] if self.marks.exists() else [])
        self.dir.cleanup()
        lines = err.splitlines()
        bench = [line for line in lines if line.startswith("BENCH ")]
        if self.proc.returncode or not bench:
            raise SystemExit(err)
        return wall, json.loads(bench[-1][6:]), server, lines


def tasks(m, t0=0.0) -> list:
    """Per task of a child's report: a dict of its process (``client`` or
    ``worker K``), part index, start / end (s from the start), CPU seconds of its
    process and of its thread (user, system), page faults, the seconds its thread
    waited for a core (runnable, not running: /proc's schedstat) and was blocked
    (neither: the interpreter lock, I/O)."""
    pids, out = {m["client"]: "client"}, []
    for start, end, pid, born, cpu, before, dec, th, index, n, kind in sorted(m["rows"]):
        who = pids.setdefault(pid, f"worker {len(pids) - 1}")
        wall = end - start
        out.append({"who": who, "index": index, "kind": kind, "start": start - t0,
                    "end": end - t0, "born": born - t0, "cpu": cpu, "user": th[0],
                    "sys": th[1], "faults": th[2], "collections": th[3], "wait": th[4],
                    "blocked": wall - th[0] - th[1] - th[4], "buildings": n, "decoded": dec,
                    "before": before, "modules": th[5], "pickle": th[6], "bytes": th[7]})
    return out


def summary(m, t0=0.0) -> dict:
    """The run's phases, from a child's report: the serial part before the parts
    start (the fork), each process's parts (CPU and wall), the tail (how long the
    process that ended its parts first waited for the other's), the serial part
    after the last part (the output written, the command's end), what moving the
    results cost (pickling in the child, unpickling here), and the modules the
    processes imported while running parts (imports made by both, after the fork,
    are paid twice). Under load, CPU seconds say more than wall seconds: an
    idle-machine estimate of the wall time is printed from them (serial wall,
    then the busier process's CPU seconds of parts, then the serial end)."""
    marks = {n: (t, c) for n, t, c, _ in m["marks"]}
    ts = tasks(m, t0)
    builds = [t for t in ts if t["kind"] == "build"]
    if not builds:
        return {}
    start = min(t["start"] for t in builds)
    who = sorted({t["who"] for t in builds})
    ends = {w: max(t["end"] for t in builds if t["who"] == w) for w in who}
    cpu = {w: sum(t["cpu"] for t in builds if t["who"] == w) for w in who}
    first_mods = {w: min(builds, key=lambda t, w=w: (t["who"] != w, t["start"]))["modules"]
                  for w in who}
    last = max(ends.values())
    done = marks.get("command done", (last, 0))[0]
    # the last fork: the parts' (a traced run's outlines may have forked before)
    fork = marks.get("fork: children forked", marks.get("fork: children being forked"))
    trace = [t for t in ts if t["kind"] == "trace"]
    shared = [t for t in ts if t["kind"] == "outlines"]
    # CPU seconds of this process before the parts (its decoding runs on two threads:
    # an upper bound of the wall time an idle machine takes) and for the output
    before = (fork or marks.get("client decoded 1 tile(s) held for the workers it forks",
                                (start, 0.0)))[1]
    if shared:
        # outlines shared by the workers between two forks: the client's CPU at the
        # first, the busier process's pieces, then the client's assembly until the last
        forks = [c for n, _, c, _ in m["marks"] if n == "fork: children forked"]
        mine = sum(t["cpu"] for t in shared if t["who"] == "client")
        busier = max(sum(t["cpu"] for t in shared if t["who"] == w)
                     for w in {t["who"] for t in shared})
        before = forks[0] + busier + max(0.0, forks[-1] - forks[0] - mine)
    writing = marks.get("output being written")
    after_cpu = (marks["command done"][1] - writing[1]) if writing and "command done" in marks \
        else done - last
    out = {"parts start": start, "tail": last - min(ends.values()), "after": done - last,
           "cpu": cpu, "estimate": before + max(cpu.values()) + after_cpu,
           "run cpu": marks.get("command done", (0, 0.0))[1] + m["children_cpu"]}
    print(f"phases: parts start at {start:.2f} s (fork at "
          f"{'-' if fork is None else f'{fork[0]:.2f} s'}"
          f"{', after a traced first pass of ' + format(sum(t['cpu'] for t in trace), '.2f') + ' CPU s' if trace else ''}"
          f"{_shared_phase(shared)}); "
          f"parts' CPU s by process: " + ", ".join(f"{w} {cpu[w]:.2f}" for w in who)
          + f" (imbalance {max(cpu.values()) - min(cpu.values()):.2f} CPU s); "
          f"last part ends {last:.2f} s, the first process to finish waited {out['tail']:.2f} s "
          f"for it; after it {out['after']:.2f} s (output, end)")
    print("results moved: pickled " + f"{sum(t['bytes'] for t in builds) / 1024:.0f} KB in "
          f"{sum(t['pickle'] for t in builds):.3f} CPU s (all parts), unpickled here "
          f"{m.get('loads', [0, 0])[1] / 1024:.0f} KB in {m.get('loads', [0.0])[0]:.3f} CPU s; "
          "modules imported by each process's first part: "
          + ", ".join(f"{w} {first_mods[w]}" for w in who))
    print(f"idle-machine estimate: {out['estimate']:.2f} s (this process's CPU s before the "
          f"parts {before:.2f}{' (its outlines: the busier side)' if shared else ''}"
          f" + the busier process's parts {max(cpu.values()):.2f} + the "
          f"output's {after_cpu:.2f}); the run's CPU s {out['run cpu']:.2f} (all processes)")
    return out


def _shared_phase(rows) -> str:
    """The phase of a traced block's outlines regularised in pieces by the workers:
    ``who CPU s (pieces)`` per process, from the first piece's start to the last's end."""
    if not rows:
        return ""
    who = sorted({t["who"] for t in rows})
    return (", its outlines regularised " + "; ".join(
        f"{w} {sum(t['cpu'] for t in rows if t['who'] == w):.2f} CPU s "
        f"({sum(t['who'] == w for t in rows)} pieces)" for w in who)
        + f" from {min(t['start'] for t in rows):.2f} to {max(t['end'] for t in rows):.2f} s")


def pairs(d, a) -> None:
    """``--pairs N --src OTHER_SRC``: the phases of OTHER_SRC's run and this tree's, in
    turn, N rounds; medians of the idle-machine estimate, the tail and the run's CPU."""
    import statistics

    got = {"other": [], "this": []}
    for k in range(a.pairs):
        for name, src in (("other", a.src), ("this", None)):
            child = Child(d, workers=a.workers, traced=a.traced, src=src)
            wall, m, _, _ = child.result()
            print(f"round {k + 1}, {name} ({src or 'this tree'}), {wall:.2f} s at load "
                  f"{os.getloadavg()[0]:.2f}:")
            got[name].append(summary(m, child.t0))
    for name, rows in got.items():
        print(f"{name}: idle-machine estimate median "
              f"{statistics.median(r['estimate'] for r in rows):.2f} s "
              f"({', '.join(format(r['estimate'], '.2f') for r in rows)}); parts' CPU imbalance "
              f"median {statistics.median(max(r['cpu'].values()) - min(r['cpu'].values()) for r in rows):.2f} s; "
              f"the run's CPU median {statistics.median(r['run cpu'] for r in rows):.2f} s")
    ratio = [t["estimate"] / o["estimate"] for o, t in zip(got["other"], got["this"], strict=True)]
    print(f"estimate this / other: median {statistics.median(ratio):.3f} "
          f"({', '.join(format(v, '.3f') for v in ratio)})")
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--workers", default="2")
    ap.add_argument("--traced", action="store_true", help="no footprint file")
    ap.add_argument("--log", action="store_true", help="Dask's and lidar2city's log lines too")
    ap.add_argument("--src", help="run another tree's source (its src folder, e.g. main's, "
                                  "to compare the phases), not this tree's")
    ap.add_argument("--one-process", action="store_true",
                    help="the plan of --workers N (its parts), no cluster: every part in the "
                         "client, one after the other (each part's CPU without a second process)")
    ap.add_argument("--pairs", type=int, default=0,
                    help="with --src: N rounds of OTHER_SRC then this tree, only the phases "
                         "printed per run and their medians (the idle-machine estimate from "
                         "CPU seconds compares the two under load)")
    a = ap.parse_args()
    d = data_dir(a.data) / "delft"
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} "
          f"({os.cpu_count()} cores)")
    if a.pairs:
        pairs(d, a)
        return
    child = Child(d, workers=a.workers, traced=a.traced, log=a.log, one_process=a.one_process,
                  src=a.src)
    t0 = child.t0
    wall, m, server, lines = child.result()
    events = [(t, f"client: {n} (client CPU {c:.2f} s, its thread {th:.2f})")
              for n, t, c, th in m["marks"]]
    events += [(t, f"server: {n}") for t, n in server]
    for t, text in sorted(events):
        print(f"{t:6.2f} s  {text}")
    print(f"{wall:6.2f} s  process ended; CPU of the processes it started (workers, their "
          f"server) {m['children_cpu']:.2f} s")
    sums = {}
    for t in tasks(m, t0):
        s = sums.setdefault(t["who"], dict.fromkeys(
            ("n", "wall", "cpu", "thread", "sys", "faults", "wait", "blocked"), 0))
        s["n"] += 1
        s["wall"] += t["end"] - t["start"]
        s["thread"] += t["user"] + t["sys"]
        for key in ("cpu", "sys", "faults", "wait", "blocked"):
            s[key] += t[key]
        print(f"{t['who']:8s} (born {t['born']:5.2f} s): {t['kind']} {t['index']} "
              f"{t['start']:5.2f}-{t['end']:5.2f} s ({t['end'] - t['start']:4.2f} s, "
              f"{t['cpu']:4.2f} CPU s; its thread {t['user']:4.2f} user {t['sys']:4.2f} sys, "
              f"{t['faults']} page faults, {t['collections']} collections, waited for a core {t['wait']:4.2f} s, blocked "
              f"{t['blocked']:4.2f} s), {t['buildings']} buildings, {t['decoded']} tile(s) "
              f"decoded itself, worker CPU before {t['before']:.2f} s, {t['modules']} modules "
              f"imported, its output pickled {t['bytes'] / 1024:.0f} KB in {t['pickle']:.3f} CPU s")
    for who, s in sums.items():
        print(f"{who}: {s['n']} task(s), {s['wall']:.2f} s, {s['cpu']:.2f} CPU s of the process, "
              f"{s['thread']:.2f} CPU s of the task's thread ({s['sys']:.2f} in the kernel, "
              f"{s['faults']} page faults), waited for a core {s['wait']:.2f} s, blocked (not "
              f"runnable: the interpreter lock, I/O) {s['blocked']:.2f} s")
    summary(m, t0)
    if a.log:
        for line in lines:
            if line[:8].strip().split(" ")[0].isdigit():
                print(line[:160])
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
