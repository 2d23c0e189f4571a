"""CPU cost of the LoD2.2 step-edge snake (issue 13 with issue 12) on the Delft tile.

Usage: python benchmarks/bench_snake_steps.py [DATA_DIR] [--repeat N]
(default data $LIDAR2CITY_DATA or ../shared/data, N = 5)

Runs ``reconstruct`` (LoD 1.2 + 1.3 + 2.2, the 132 BGT footprints) once in this
process with :func:`lidar2city.roof.arrangement.snake_steps` timed
(``resource.getrusage`` user + system CPU of the process), then calls ``snake_steps``
again N times on the arguments that run gave it and prints the least CPU of one
pass over all of them: the snake's cost per Delft run, little affected by other
processes on the machine (run it on two checkouts to compare them). It also
prints the whole run's CPU, the snake's share of it, whether the replays gave the
same polylines as the run, and the MD5 of the output file (the bytes must not
change when only the snake's speed does).
"""

from __future__ import annotations

import hashlib
import os
import resource
import sys
import tempfile
from pathlib import Path


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _same(a, b) -> bool:
    import numpy as np

    return len(a) == len(b) and all(
        (x is None and y is None) or (x is not None and y is not None and np.array_equal(x, y))
        for x, y in zip(a, b, strict=True))


def main(argv: list[str]) -> int:
    repeat = 5
    if "--repeat" in argv:
        i = argv.index("--repeat")
        repeat = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    data = Path(argv[0] if argv else os.environ.get("LIDAR2CITY_DATA", "../shared/data"))
    tile, fp = data / "delft" / "ahn3_cropped_1.laz", data / "delft" / "footprints_bgt.gpkg"

    import lidar2city.roof.arrangement as arrangement
    from lidar2city.cli.main import cli

    calls, spent = [], [0.0]
    snake_steps = arrangement.snake_steps

    def timed(*args, **kwargs):
        t = _cpu()
        out = snake_steps(*args, **kwargs)
        spent[0] += _cpu() - t
        calls.append((args, kwargs, out))
        return out

    arrangement.snake_steps = timed
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "delft.city.json"
        t = _cpu()
        try:
            cli.main(["-q", "reconstruct", str(tile), "--footprints", str(fp), "--lod", "1.2", "--lod", "1.3",
                      "--lod", "2.2", "-o", str(out)], standalone_mode=False)
        except SystemExit:
            pass
        whole = _cpu() - t
        digest = hashlib.md5(out.read_bytes()).hexdigest()
    arrangement.snake_steps = snake_steps
    best, same = float("inf"), True
    for _ in range(repeat):
        t = _cpu()
        res = [snake_steps(*a, **kw) for a, kw, _ in calls]
        best = min(best, _cpu() - t)
        same = same and all(_same(r, o) for r, (_, _, o) in zip(res, calls, strict=True))
    print(f"Delft reconstruct LoD 1.2+1.3+2.2: whole run {whole:.2f} CPU s in this process, "
          f"snake_steps {spent[0]:.3f} CPU s in it ({100 * spent[0] / whole:.1f} %), {len(calls)} calls")
    print(f"snake_steps per Delft run, least of {repeat} replays: {best:.3f} CPU s; "
          f"replays identical to the run: {same}")
    print(f"output MD5 {digest}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
