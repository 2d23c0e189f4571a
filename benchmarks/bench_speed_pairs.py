"""Paired runs of ``reconstruct`` on the Delft tile: this tree against another source tree.

Usage: python benchmarks/bench_speed_pairs.py OTHER_SRC [DATA_DIR] [--runs N] [--traced] [--workers N]
(OTHER_SRC: the ``src`` folder of another checkout, e.g. one of main made with
``git worktree add /tmp/main main``; DATA_DIR default $LIDAR2CITY_DATA or ../shared/data)

The command of issue 13 (LoD 1.2 + 1.3 + 2.2 with the 132 BGT footprints) is
run as a whole process with this tree's ``src`` and with OTHER_SRC in turn
(A B A B ..., after one warm-up each that also caches the bytecode), and each
pair gives the ratios A/B of user + system CPU seconds and of wall time, taken
from os.wait4's resource usage and time.perf_counter. Pairs make the ratio hold
when a shared machine's speed drifts; CPU seconds drift less than wall time.
Prints every pair, the medians, the load average before and after, and whether
the two trees wrote the same bytes. ``--traced`` pairs the same command without
footprints (traced from the points, issue 13's no-footprints target) instead;
``--workers N`` runs both with ``--workers N`` (the processes they start counted).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(cmd, env) -> tuple[float, float]:
    """``(wall seconds, user + system CPU seconds)`` of one child process (fails loudly)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(map(str, cmd))} failed:\n{err}")
    return wall, usage.ru_utime + usage.ru_stime


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("other", help="the src folder of the tree to compare with")
    ap.add_argument("data", nargs="?")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--traced", action="store_true",
                    help="without footprints: traced from the points")
    ap.add_argument("--workers", default="1", help="reconstruct's --workers for both trees")
    args = ap.parse_args()
    data = Path(args.data or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")
    d = data / "delft"
    tmp = Path(tempfile.mkdtemp())
    trees = {"A": ROOT / "src", "B": Path(args.other).resolve()}
    cmds, envs = {}, {}
    for name, src in trees.items():
        env = dict(os.environ, PYTHONPATH=str(src))
        env.pop("PYTHONDONTWRITEBYTECODE", None)  # bytecode cached, as an install has it
        envs[name] = env
        given = [] if args.traced else ["--footprints", str(d / "footprints_bgt.gpkg")]
        cmds[name] = [sys.executable, "-m", "lidar2city.cli.main", "reconstruct",
                      str(d / "ahn3_cropped_1.laz"), *given,
                      "--lod", "1.2", "--lod", "1.3", "--lod", "2.2", "-o", str(tmp / f"{name}.city.json"),
                      "--workers", args.workers]
    load0 = os.getloadavg()[0]
    for name in trees:  # warm-up: file cache and bytecode
        run(cmds[name], envs[name])
    pairs = []
    for _ in range(max(1, args.runs)):
        a = run(cmds["A"], envs["A"])
        b = run(cmds["B"], envs["B"])
        pairs.append((a, b))
        print(f"pair: A {a[1]:.2f} CPU s {a[0]:.2f} s, B {b[1]:.2f} CPU s {b[0]:.2f} s; "
              f"A/B CPU {a[1] / b[1]:.3f}, wall {a[0] / b[0]:.3f}")
    cpu = statistics.median(a[1] / b[1] for a, b in pairs)
    wall = statistics.median(a[0] / b[0] for a, b in pairs)
    same = hashlib.md5((tmp / "A.city.json").read_bytes()).hexdigest() == \
        hashlib.md5((tmp / "B.city.json").read_bytes()).hexdigest()
    what = (("without footprints (traced)" if args.traced else "132 footprints")
            + f", --workers {args.workers}")
    print(f"reconstruct LoD1.2+1.3+2.2, {what}, this tree (A) / {trees['B']} (B), "
          f"{len(pairs)} pairs: median A/B CPU {cpu:.3f}, wall {wall:.3f}; A median "
          f"{statistics.median(a[1] for a, _ in pairs):.2f} CPU s, B "
          f"{statistics.median(b[1] for _, b in pairs):.2f} CPU s; load average "
          f"{load0:.1f} -> {os.getloadavg()[0]:.1f}; same output bytes: {same}")


if __name__ == "__main__":
    main()
