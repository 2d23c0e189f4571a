"""One large tile on 1 and 2 workers: the Delft tile's 132 buildings, against the laspy floor.

Usage: ``python benchmarks/bench_engine_tile.py [DATA_DIR] [--runs 3] [--workers 1,2,auto,default,2:dask] [--traced] [--lod 1.2,1.3,2.2]``
(default $LIDAR2CITY_DATA or ../shared/data)

A count followed by ``:fork`` or ``:dask`` (``2:dask``) runs with that local
executor (``LIDAR2CITY_LOCAL_EXECUTOR``, :func:`lidar2city.tools.engine.local_executor`):
workers forked from the run's process (the default) or a Dask ``LocalCluster``.
``default``: the command without ``--workers`` (what a user types: ``auto`` since
session 15).

``--traced``: the same without ``--footprints`` (footprints traced from the
points, 80 buildings): with ``--workers 2`` the tile's one block is traced
first by a worker, then its buildings are built in parts by both.

The Delft AHN3 tile with its 132 BGT footprints is one block of the grid:
with ``--workers 2`` the planner cuts it into parts of its footprints (strips
of equal numbers of buildings) that the two worker processes share, and the
client decodes the tile once for both while the cluster starts. Each run is the
whole command as a user types it, in a fresh process
(``lidar2city reconstruct ahn3_cropped_1.laz --footprints footprints_bgt.gpkg
--lod 1.2 --lod 1.3 --lod 2.2 -o OUT.city.json --workers N``), measured from
outside: wall seconds (cluster start-up and close included), user + system
CPU seconds of the process and of every process it started and reaped (Dask
workers and the server they are forked from), the largest peak RSS among
them, and the sum of every process's own peak (``VmHWM`` of the command's
process tree, sampled every 10 ms from /proc: what the run takes of the
user's memory; forked processes' shared pages are counted in each) and the
most they held at one moment (the sum of their ``VmRSS``, same samples; Linux
only). The laspy floor (a fresh Python running ``laspy.read`` of the tile,
as ``bench_speed.py``) and the runs alternate, ``--runs`` rounds of (floor,
1 worker, 2 workers), so that the ratios are taken round by round while the
shared machine's speed drifts. Printed per round and as medians: the wall
seconds, CPU seconds, their ratios to the floor, the speed-up of 2 workers
over 1; the MD5 of every output (the same on 1 and 2 workers); the load
average before and after.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_speed import ROOT, data_dir  # noqa: E402


def _children(pid) -> list:
    """The pids of the processes whose parent is ``pid`` (Linux /proc)."""
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(v) for v in f.read().split()]
    except OSError:
        return []


def _memory(pid) -> tuple:
    """``(peak so far, now)`` resident memory of ``pid`` (MB; VmHWM, VmRSS), zeros when gone."""
    out = {}
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith(("VmHWM:", "VmRSS:")):
                    out[line[:5]] = int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return out.get("VmHWM", 0.0), out.get("VmRSS", 0.0)


def _pss(pid) -> float:
    """Proportional set size of ``pid`` (MB; ``Pss`` of /proc/PID/smaps_rollup), 0 when gone."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            for line in f:
                if line.startswith("Pss:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def run(cmd, env) -> tuple:
    """``(wall seconds, largest peak RSS MB, user + system CPU seconds, sum of the
    process tree's peaks MB, largest sum of the tree's resident memory at one
    moment MB, largest sum of the tree's PSS at one moment MB)`` of one command
    (fails loudly)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    peaks, together, pss, done = {}, [0.0], [0.0], threading.Event()

    def sample():
        k = 0
        while not done.is_set():
            todo, now, share = [proc.pid], 0.0, 0.0
            while todo:
                pid = todo.pop()
                hwm, rss = _memory(pid)
                peaks[pid] = max(peaks.get(pid, 0.0), hwm)
                now += rss
                if k % 5 == 0:
                    share += _pss(pid)
                todo += _children(pid)
            together[0] = max(together[0], now)
            pss[0] = max(pss[0], share)
            k += 1
            done.wait(0.01)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    done.set()
    sampler.join()
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, cmd))} failed ({proc.returncode}):\n{err}")
    return (wall, usage.ru_maxrss / 1024.0, usage.ru_utime + usage.ru_stime,
            sum(peaks.values()), together[0], pss[0])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--workers", default="1,2",
                    help="comma-separated counts, auto, or default (no --workers option); "
                         "N:dask / N:fork for that executor")
    ap.add_argument("--lod", default="1.2,1.3,2.2",
                    help="the LoDs built, comma-separated (less work: where a cluster stops paying)")
    ap.add_argument("--traced", action="store_true",
                    help="no footprint file: footprints traced from the points")
    args = ap.parse_args()
    workers = [v if v in ("auto", "default") or ":" in v else int(v)
               for v in args.workers.split(",")]
    d = data_dir(args.data) / "delft"
    laz, fps = d / "ahn3_cropped_1.laz", d / "footprints_bgt.gpkg"
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # as bench_speed.py: bytecode cached
    py = sys.executable
    floor = [py, "-c", f"import laspy; laspy.read({str(laz)!r})"]
    tmp = Path(tempfile.mkdtemp())

    def command(w):
        out = tmp / f"w{str(w).replace(':', '_')}.city.json"
        given = [] if args.traced else ["--footprints", str(fps)]
        return out, [py, "-m", "lidar2city.cli.main", "reconstruct", str(laz), *given,
                     *(a for lod in args.lod.split(",") for a in ("--lod", lod)), "-o", str(out),
                     *([] if w == "default" else ["--workers", str(w).split(":")[0]])]

    def env_of(w):
        if ":" not in str(w):
            return env
        return dict(env, LIDAR2CITY_LOCAL_EXECUTOR=str(w).split(":")[1])

    print(f"{'traced footprints' if args.traced else 'given footprints'}, LoD {args.lod}; "
          f"load average before: "
          f"{' '.join(f'{v:.2f}' for v in os.getloadavg())} ({os.cpu_count()} cores)", flush=True)
    run(floor, env)  # warm the file cache and the bytecode
    for w in workers:
        run(command(w)[1], env_of(w))
    rows = {w: [] for w in workers}
    floors, md5 = [], {}
    for k in range(max(1, args.runs)):
        f = run(floor, env)
        floors.append(f)
        line = [f"round {k + 1}: floor {f[0]:.2f} s {f[2]:.2f} CPU s"]
        for w in workers:
            out, cmd = command(w)
            r = run(cmd, env_of(w))
            rows[w].append((r, f))
            md5.setdefault(w, set()).add(hashlib.md5(out.read_bytes()).hexdigest())
            line.append(f"{w} worker(s) {r[0]:.2f} s ({r[0] / f[0]:.1f}x floor) "
                        f"{r[2]:.2f} CPU s ({r[2] / f[2]:.1f}x) {r[1]:.0f} MB, all processes "
                        f"{r[3]:.0f} MB (at once {r[4]:.0f} MB, PSS {r[5]:.0f} MB)")
        if 1 in rows and len(workers) > 1:
            one = rows[1][-1][0][0]
            line += [f"speed-up {w}/1 {one / rows[w][-1][0][0]:.2f}" for w in workers if w != 1]
        print("; ".join(line), flush=True)
    f_t = statistics.median(f[0] for f in floors)
    f_c = statistics.median(f[2] for f in floors)
    print(f"laspy floor: median {f_t:.2f} s, {f_c:.2f} CPU s ({len(floors)} runs)")
    for w in workers:
        rs = rows[w]
        print(f"{w} worker(s): median {statistics.median(r[0] for r, _ in rs):.2f} s, "
              f"{statistics.median(r[2] for r, _ in rs):.2f} CPU s; time / floor median "
              f"{statistics.median(r[0] / f[0] for r, f in rs):.1f}x, CPU / floor CPU median "
              f"{statistics.median(r[2] / f[2] for r, f in rs):.1f}x; peak RSS "
              f"{max(r[1] for r, _ in rs):.0f} MB (largest process), "
              f"{max(r[3] for r, _ in rs):.0f} MB (sum of the processes' peaks), "
              f"{max(r[4] for r, _ in rs):.0f} MB (most held at one moment by all), "
              f"{max(r[5] for r, _ in rs):.0f} MB (their PSS at one moment); "
              f"md5 {' '.join(sorted(md5[w]))}")
    if 1 in rows:
        for w in workers:
            if w != 1:
                sp = [a[0][0] / b[0][0] for a, b in zip(rows[1], rows[w], strict=True)]
                cp = [b[0][2] / a[0][2] for a, b in zip(rows[1], rows[w], strict=True)]
                print(f"speed-up {w} workers / 1: median {statistics.median(sp):.2f} "
                      f"({', '.join(f'{v:.2f}' for v in sp)}); CPU {w} workers / 1 median "
                      f"{statistics.median(cp):.2f}; same bytes: "
                      f"{'yes' if md5[w] == md5[1] and len(md5[1]) == 1 else 'NO'}")
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
