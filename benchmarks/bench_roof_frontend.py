"""CPU of the LoD2.2 roof front end (plane segmentation, roof lines, line arrangement, edge
refinement) and of its parts, replayed on the Delft tile's recorded calls: this tree against
other trees (issue 13).

Usage: python benchmarks/bench_roof_frontend.py [OTHER_SRC ...] [--data DIR] [--traced]
[--repeat N] [--rounds R] [--cache FILE] [--set STAGE:NAME=VALUE ...]
(OTHER_SRC: the ``src`` folder of another checkout, e.g. /work/wt/base/src; DIR default
$LIDAR2CITY_DATA or ../shared/data)

First runs ``reconstruct`` of the Delft tile (LoD 1.2 + 1.3 + 2.2, with the 132 BGT
footprints, or ``--traced`` without them) once in a child process with this tree and
records the arguments of every call of ``segment_planes``, ``roof_lines``,
``arrangement_partition`` and ``refine_partition`` that LoD2.2 makes (kept in ``--cache``,
made again when missing). Then, in a fresh process of each tree in turn (A B C A B C ...,
``--rounds`` times), replays each stage on them ``--repeat`` times and takes the least
CPU (``time.process_time``) of one pass over all its calls. In the same passes, the
named parts below are timed by wrappers put on their module attributes (inclusive
times: a part calling another counts it too, e.g. ``snake_steps`` holds
``adjust_planar_graph``; a part missing from a tree is left out). Prints per tree and
stage the least CPU over the rounds and the parts' CPU of that pass, this tree's CPU
over each other tree's per stage, and a digest of the stages' outputs per tree (the same digest: the
same answers to the bit). ``--set`` replays a stage's calls in this tree ([0]) only with
one keyword argument changed (e.g. ``--set segment_planes:k=8``, VALUE read as a Python
literal): with this tree's own ``src`` as OTHER_SRC, a paired probe of what an option
costs and whether it changes the answers.

Wall-clock timers are not used: on a shared machine only CPU seconds compare. The
wrappers cost ~1 us per wrapped call (a few thousand calls): the parts' sum is not
the stage's figure, the stage's least pass is (measured with the wrappers on in
every tree alike).
"""

from __future__ import annotations

import pickle
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from replay_common import (  # noqa: E402
    capture_delft, least_pass, replay_parser, stage_replay, time_parts)

STAGES = ("segment_planes", "roof_lines", "arrangement_partition", "refine_partition")
#: module (under lidar2city) : function, timed inclusive of what it calls
PARTS = (
    "roof.facets:local_normals", "roof.facets:_grow", "roof.facets:_refit",
    "roof.facets:_merge", "roof.facets:_absorb_small", "roof.facets:_leftover_facets",
    "roof.topology:label_grid", "roof.topology:_merge_small_regions",
    "roof.topology:boundary_chains", "roof.arrangement:chain_segments",
    "roof.arrangement:snake_steps", "regularize.snake:adjust_planar_graph",
    "roof.arrangement:_step_polyline", "roof.arrangement:_refit_lines",
    "roof.arrangement:rim_strips", "roof.arrangement:extend_to_hits",
    "roof.arrangement:arrangement_cells", "roof.arrangement:_cell_labels",
    "roof.arrangement:dissolve_cells", "roof.refine:edge_types",
)


def capture(data: Path, out: Path, traced: bool):
    """Record the stages' calls of one Delft reconstruct (child process)."""
    import lidar2city.roof.building as building

    capture_delft(building, STAGES, data, out, traced)


def _overridden(f, changed):
    """``f`` with the keyword arguments ``changed`` winning over those it is called with."""
    def g(*a, **k):
        return f(*a, **{**k, **changed})
    return g


def timed(cache: Path, repeat: int, result: Path, overrides=()):
    """Least CPU per stage and its parts' CPU in that pass, and the outputs' digests (child)."""
    import ast
    import collections

    import scipy.ndimage  # noqa: F401 - the pipeline's imports, not timed
    import scipy.spatial  # noqa: F401
    import shapely  # noqa: F401

    import lidar2city.roof.building as building

    acc: collections.Counter = collections.Counter()
    time_parts(PARTS, ("roof.building", "roof.facets", "roof.topology", "roof.arrangement",
                       "roof.refine", "regularize.snake"), acc)
    with open(cache, "rb") as fh:
        raw = pickle.load(fh)
    changed: dict = {}
    for item in overrides:
        stage, assign = item.split(":", 1)
        key, value = assign.split("=", 1)
        changed.setdefault(stage, {})[key] = ast.literal_eval(value)
    out = {}
    for name in STAGES:
        f = getattr(building, name)
        if changed.get(name):
            f = _overridden(f, changed[name])
        out[name] = (*least_pass(f, raw[name], repeat, acc), len(raw[name]))
    with open(result, "wb") as fh:
        pickle.dump(out, fh)


def main():
    ap = replay_parser(__doc__)
    ap.add_argument("--set", action="append", default=[], metavar="STAGE:NAME=VALUE",
                    help="replay STAGE's calls in this tree with keyword NAME set to VALUE")
    args = ap.parse_args()
    stage_replay(args, __file__, STAGES, title="roof front end replayed",
                 cache_stem="roof_frontend", capture=capture,
                 timed=lambda cache, repeat, result: timed(cache, repeat, result, args.set),
                 first_flags=[f"--set={s}" for s in args.set],
                 note=f"; [0] replayed with {', '.join(args.set)}" if args.set else "")

if __name__ == "__main__":
    main()
