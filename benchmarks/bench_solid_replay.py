"""CPU of the LoD2.2 partition-to-solid stage (``_finish_solid``: refinement, short edges,
fixes, the solid and its repairs; and ``check_solid`` as LoD2.2 calls it), replayed on the
Delft tile's recorded calls: this tree against other trees (issue 13).

Usage: python benchmarks/bench_solid_replay.py [OTHER_SRC ...] [--data DIR] [--traced]
[--repeat N] [--rounds R] [--cache FILE]
(OTHER_SRC: the ``src`` folder of another checkout, e.g. /work/wt/base/src; DIR default
$LIDAR2CITY_DATA or ../shared/data)

First runs ``reconstruct`` of the Delft tile (LoD 1.2 + 1.3 + 2.2, with the 132 BGT
footprints, or ``--traced`` without them) once in a child process with this tree and
records the arguments of every call of ``roof.building._finish_solid`` and of
``check_solid`` made from ``roof.building`` (the written solid of each building, the
restored-facet and fixed solids; kept in ``--cache``, made again when missing). Then, in
a fresh process of each tree in turn (A B A B ..., ``--rounds`` times), replays each
stage's calls in their order ``--repeat`` times and takes the least CPU
(``time.process_time``) of one pass. The parts below are timed by wrappers on their
module attributes in the same passes (inclusive times; a part missing from a tree is
left out; the wrappers cost ~1 us a call alike in every tree). Prints per tree and stage
the least CPU, the parts' CPU of that pass, this tree's CPU over each other tree's, and a
digest of the stage's answers (solids' vertices and rings, faces' WKB, labels, planes,
issues): the same digest, the same answers to the bit.

Caches of earlier calls (``check_solid``'s verdicts of the last 8 solids, ``solid_mesh``'s
last 4 meshes) hold across the calls of a pass as in a run; the calls are unpickled anew
for every pass, so no solid object is met twice. Only CPU seconds compare on a shared
machine.
"""

from __future__ import annotations

import pickle
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from replay_common import (  # noqa: E402
    capture_delft, least_pass, replay_parser, stage_replay, time_parts)

STAGES = ("_finish_solid", "check_solid")
#: module (under lidar2city) : function, timed inclusive of what it calls
PARTS = (
    "roof.refine:refine_partition", "roof.refine:edge_types", "roof.arrangement:collapse_short_edges",
    "roof.building:_variant_solid", "roof.building:_clean_faces", "roof.building:_fix_low_faces",
    "roof.building:_fix_high_faces", "roof.building:_manifold_solid", "roof.solid:partition_edges",
    "roof.solid:partition_solid", "lod.mesh:solid_mesh", "validate.solid:_self_intersections",
    "validate.solid:_simple_faces_checks", "validate.solid:_edge_checks",
)


def capture(data: Path, out: Path, traced: bool):
    """Record the stages' calls of one Delft reconstruct (child process)."""
    import lidar2city.roof.building as building

    capture_delft(building, STAGES, data, out, traced)


def timed(cache: Path, repeat: int, result: Path):
    """Least CPU per stage and its parts' CPU in that pass, and the answers' digests (child)."""
    import collections

    import scipy.ndimage  # noqa: F401 - the pipeline's imports, not timed
    import scipy.spatial  # noqa: F401
    import shapely  # noqa: F401

    import lidar2city.roof.building as building

    acc: collections.Counter = collections.Counter()
    stage_fns = {name: getattr(building, name) for name in STAGES}
    time_parts(PARTS, ("roof.building", "roof.refine", "roof.arrangement", "roof.solid",
                       "lod.mesh", "validate.solid"), acc)
    with open(cache, "rb") as fh:
        raw = pickle.load(fh)
    out = {name: (*least_pass(stage_fns[name], raw[name], repeat, acc), len(raw[name]))
           for name in STAGES}
    with open(result, "wb") as fh:
        pickle.dump(out, fh)


def main():
    ap = replay_parser(__doc__)
    args = ap.parse_args()
    stage_replay(args, __file__, STAGES, title="partition to solid replayed",
                 cache_stem="solid_replay", capture=capture, timed=timed)

if __name__ == "__main__":
    main()
