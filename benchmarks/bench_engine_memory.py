"""Where the memory of an in-process reconstruct goes as the area grows (Linux, glibc).

Usage: ``PYTHONPATH=src python benchmarks/bench_engine_memory.py [--sizes 2,4,8,12] [--repeat 1]``

The synthetic areas of ``bench_engine.py`` (n x n demo-town tiles, blocks of
200 m, LoD1.2 to a streamed CityJSONSeq) are reconstructed with ``--workers 1``
in a fresh process each. Printed per area, over its blocks (after each one):
the peak resident memory (``VmHWM``: the process's own peak; ``ru_maxrss``,
carried over ``exec``, would count this script's size), the largest resident memory between
blocks, the most bytes the C heap had in use (glibc ``mallinfo2().uordblks``:
live arrays and objects) and the most it held free (``fordblks``: freed memory
glibc keeps, not given back to the system), the most decoded tile points kept
between blocks for later blocks (in unlinked scratch files, not in memory),
the tiles decoded (each tile once when the scratch budget holds the strip of
tiles a row of blocks leaves to the next), and the most results waiting for
earlier footprints of the file's order (the footprints are written tile by
tile, the blocks run row by row), and the most points a block read.
``--repeat K`` reconstructs the same area K times in the one process and
prints the peak after each: a peak that still rises on the same blocks is the
heap's fragmentation, not live data.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_engine import BLOCK, make_area  # noqa: E402

CHILD = r"""
import ctypes, json, resource, sys
from lidar2city.tools import reconstruct as R, task

class MallInfo2(ctypes.Structure):
    _fields_ = [(k, ctypes.c_size_t) for k in
                "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()]

libc = ctypes.CDLL("libc.so.6")
libc.mallinfo2.restype = MallInfo2
a = json.loads(sys.argv[1])
plan = R.plan_reconstruct(a["tiles"], a["out"], footprints=a["fp"], block_size=a["block"])
# results waiting for earlier footprints when the blocks finish in plan order
waiting, nxt, most = set(), 0, 0
for spec in plan.specs:
    waiting.update(spec.footprints.positions)
    while nxt in waiting:
        waiting.discard(nxt)
        nxt += 1
    most = max(most, len(waiting))
top = {"rss": 0.0, "inuse": 0.0, "free": 0.0, "cache": 0, "largest": 0}

def seen(done, total):
    m = libc.mallinfo2()
    rss = int(open("/proc/self/statm").read().split()[1]) * resource.getpagesize() / 2**20
    for k, v in (("rss", rss), ("inuse", m.uordblks / 2**20), ("free", m.fordblks / 2**20),
                 ("cache", task._cache.points()), ("largest", task._cache.largest)):
        top[k] = max(top[k], v)

peaks = []
for _ in range(a["repeat"]):
    R.reconstruct(a["tiles"], a["out"], footprints=a["fp"], block_size=a["block"],
                  block_progress=seen)
    peaks.append(task._peak_mb())  # VmHWM: ru_maxrss would count this script's own size
print(json.dumps({"blocks": len(plan.specs), "buildings": plan.total, "waiting": most,
                  "peaks": peaks, "tiles": len(a["tiles"]), "decoded": task._cache.decoded,
                  **top}))
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="2,4,8,12")
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for n in [int(v) for v in a.sizes.split(",")]:
            d = Path(tmp) / f"area{n}"
            d.mkdir()
            tiles, fp = make_area(d, n)
            args = json.dumps({"tiles": tiles, "fp": fp, "out": str(d / "out.city.jsonl"),
                               "block": BLOCK, "repeat": a.repeat})
            r = subprocess.run([sys.executable, "-c", CHILD, args], capture_output=True,
                               text=True)
            if r.returncode:
                raise SystemExit(r.stderr)
            m = json.loads(r.stdout.strip().splitlines()[-1])
            print(f"{n * n:3d} tiles, {m['blocks']} blocks, {m['buildings']} buildings: peak "
                  f"{' -> '.join(f'{v:.0f}' for v in m['peaks'])} MB; between blocks at most: "
                  f"resident {m['rss']:.0f} MB, C heap in use {m['inuse']:.0f} MB, C heap "
                  f"free (kept by glibc) {m['free']:.0f} MB; tile points kept for later blocks "
                  f"(scratch files) {m['cache'] / 1e6:.2f} M, {m['decoded']} decodings of "
                  f"{m['tiles']} tiles; largest block read {m['largest']:,} points; "
                  f"{m['waiting']} results waiting for earlier footprints",
                  flush=True)


if __name__ == "__main__":
    main()
