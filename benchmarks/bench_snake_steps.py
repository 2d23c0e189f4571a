"""CPU cost of the 2-D snake in reconstruct (issue 13 with issue 12) on the Delft tile.

Usage: python benchmarks/bench_snake_steps.py [DATA_DIR] [--repeat N] [--traced]
(default data $LIDAR2CITY_DATA or ../shared/data, N = 5)

Runs ``reconstruct`` (LoD 1.2 + 1.3 + 2.2; the 132 BGT footprints, or with
``--traced`` none: blocks traced and their footprints regularised by the snake) once
in this process with the LoD2.2 roof lines
(:func:`lidar2city.roof.arrangement.roof_lines`: the label grid's boundary chains
made straight polylines), its step-edge snake
(:func:`lidar2city.roof.arrangement.snake_steps`) and every snake solve
(``lidar2city.regularize.snake._frame_solve``: candidates, distance raster, energy
tables and the graph-reduction minimum, for the step edges and the traced
footprints alike) timed (``resource.getrusage`` user + system CPU of the process),
then calls each again N times on the arguments that run gave it and prints the
least CPU of one pass over all of them: the snake's cost per Delft run, little
affected by other processes on the machine (run it on two checkouts to compare
them). It also prints the whole run's CPU, the snake's share of it, whether the
replays gave the same results as the run, and the MD5 of the output file (the
bytes must not change when only the snake's speed does).
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

    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(
            _same(x, y) for x, y in zip(a, b, strict=True))
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.shape == b.shape and a.tobytes() == b.tobytes()
    if hasattr(a, "states"):  # a solver's solution
        return _same(a.states, b.states) and a.energy == b.energy and a.reductions == b.reductions
    return a == b


class _Timed:
    """Wraps ``module.name``: CPU spent in it (outermost calls) and its calls."""

    def __init__(self, module, name):
        self.module, self.name, self.func = module, name, getattr(module, name)
        self.spent, self.calls, self.depth = 0.0, [], 0

    def __call__(self, *args, **kwargs):
        self.depth += 1
        t = _cpu()
        try:
            out = self.func(*args, **kwargs)
        finally:
            self.depth -= 1
        if not self.depth:
            self.spent += _cpu() - t
            self.calls.append((args, kwargs, out))
        return out

    def __enter__(self):
        setattr(self.module, self.name, self)
        return self

    def __exit__(self, *exc):
        setattr(self.module, self.name, self.func)

    def replay(self, repeat):
        best, same = float("inf"), True
        for _ in range(repeat):
            t = _cpu()
            res = [self.func(*a, **kw) for a, kw, _ in self.calls]
            best = min(best, _cpu() - t)
            same = same and all(_same(r, o) for r, (_, _, o) in zip(res, self.calls, strict=True))
        return best, same


def main(argv: list[str]) -> int:
    repeat = 5
    if "--repeat" in argv:
        i = argv.index("--repeat")
        repeat = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    traced = "--traced" in argv
    argv = [a for a in argv if a != "--traced"]
    data = Path(argv[0] if argv else os.environ.get("LIDAR2CITY_DATA", "../shared/data"))
    tile, fp = data / "delft" / "ahn3_cropped_1.laz", data / "delft" / "footprints_bgt.gpkg"

    import lidar2city.regularize.snake as snake
    import lidar2city.roof.arrangement as arrangement
    from lidar2city.cli.main import cli

    with tempfile.TemporaryDirectory() as tmp, _Timed(arrangement, "roof_lines") as lines, \
            _Timed(arrangement, "snake_steps") as steps, _Timed(snake, "_frame_solve") as solves:
        out = Path(tmp) / "delft.city.json"
        args = ["-q", "reconstruct", str(tile)] + ([] if traced else ["--footprints", str(fp)])
        t = _cpu()
        try:
            cli.main(args + ["--lod", "1.2", "--lod", "1.3", "--lod", "2.2", "-o", str(out)],
                     standalone_mode=False)
        except SystemExit:
            pass
        whole = _cpu() - t
        digest = hashlib.md5(out.read_bytes()).hexdigest()
    what = "traced footprints" if traced else "132 footprints"
    print(f"Delft reconstruct LoD 1.2+1.3+2.2, {what}: whole run {whole:.2f} CPU s in this process")
    for label, timed in (("roof_lines", lines), ("snake_steps", steps),
                         ("snake solves (_frame_solve)", solves)):
        best, same = timed.replay(repeat)
        print(f"{label}: {timed.spent:.3f} CPU s in the run ({100 * timed.spent / whole:.1f} %), "
              f"{len(timed.calls)} calls; least of {repeat} replays {best:.3f} CPU s; "
              f"replays identical to the run: {same}")
    print(f"output MD5 {digest}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
