"""Ground filtering: which points are bare earth, and terrain models from them.

Methods (:data:`GROUND_METHODS`): ``"smrf"`` (Pingel et al. 2013),
``"smrf_refined"`` (SMRF with the surface continued across the
tile edges by point reflection, optional surface-based cleanup: lower
leave-one-sample-out error on the ISPRS samples, but a building at the edge
of a small tile is reflected into a pit that can take all the ground away,
so it is not the default), ``"smrf_segments"`` (that surface with the
object segments that join the terrain smoothly - terrace tops, embankments -
given back; the same edge caveat), ``"smrf_vote"`` (each point judged from its
heights off four of those surfaces and its distance to walls by a rule fitted
on the ISPRS samples and synthetic terrains; the default of
:class:`GroundConfig`, lowest on leave-one-sample-out and on the synthetic
terrains), ``"pmf"`` (Zhang et al. 2003) and ``"ptd"`` (progressive TIN
densification, Axelsson 2000; not the default: leave-one-sample-out 5.44 %
against ``smrf_vote``'s 3.17 %, ``benchmarks/bench_ground.py --loo
--loo-methods ptd``). All set low
outliers aside first (:func:`low_outliers`). :func:`dtm_from_ground` grids ground points
into a gap-free terrain model and :func:`height_above_ground` reads it back
at points.
"""

from __future__ import annotations

import inspect
from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np

from ..config import field
from ..errors import ConfigError, InputError
from .connect_filter import connect_ground, surface_patches
from .dtm import Dtm, dtm_from_ground, height_above_ground
from .large import LARGE_REACH, large_objects
from .outliers import low_outliers
from .pmf_filter import pmf, pmf_windows
from .refined_filter import smrf_refined
from .ring_plane import RING_NEIGHBOURHOODS, ring_ratios
from .segment_filter import anchored_objects, smrf_segments, terrain_segments
from .smrf_filter import smrf, smrf_surface
from .tin_filter import ptd
from .vote_filter import (
    VETO_SLOPE,
    VOTE_ABOVE,
    VOTE_ANCHOR,
    VOTE_FILL,
    VOTE_RULE,
    VOTE_VETO,
    smrf_vote,
    vote_features,
)

__all__ = [
    "GROUND_METHODS",
    "GroundConfig",
    "ground_mask",
    "smrf",
    "smrf_surface",
    "smrf_refined",
    "smrf_segments",
    "terrain_segments",
    "anchored_objects",
    "smrf_vote",
    "vote_features",
    "connect_ground",
    "surface_patches",
    "ring_ratios",
    "large_objects",
    "LARGE_REACH",
    "VOTE_ABOVE",
    "VOTE_ANCHOR",
    "VOTE_FILL",
    "VOTE_RULE",
    "VOTE_VETO",
    "VETO_SLOPE",
    "pmf",
    "pmf_windows",
    "ptd",
    "low_outliers",
    "Dtm",
    "dtm_from_ground",
    "height_above_ground",
]

#: method name -> ground filter ``f(xyz, **params) -> bool mask``.
GROUND_METHODS = {"smrf": smrf, "smrf_refined": smrf_refined, "smrf_segments": smrf_segments,
                  "smrf_vote": smrf_vote, "pmf": pmf, "ptd": ptd}

#: per-method default of the shared ``slope`` option.
_SLOPE_DEFAULTS = {"smrf": 0.15, "smrf_refined": 0.15, "smrf_segments": 0.15, "pmf": 0.3,
                   "ptd": None}


def ground_mask(xyz, *, method: str = "smrf", **params) -> np.ndarray:
    """Ground points of ``xyz`` (N, 3) by ``method`` (see :data:`GROUND_METHODS`).

    ``params`` are the method's keyword arguments; unknown ones raise.

    Returns
    -------
    ndarray of bool, shape (N,)

    Raises
    ------
    InputError
        Unknown method or parameter, bad coordinates.
    """
    try:
        fn = GROUND_METHODS[method]
    except KeyError:
        raise InputError(
            f"method must be one of {', '.join(sorted(GROUND_METHODS))}, got {method!r}"
        ) from None
    accepted = set(inspect.signature(fn).parameters) - {"xyz"}
    unknown = sorted(set(params) - accepted)
    if unknown:
        raise InputError(f"{method} has no parameter {unknown[0]!r}; known: "
                         f"{', '.join(sorted(accepted))}")
    return fn(xyz, **params)


@dataclass(frozen=True)
class GroundConfig:
    """Configuration of the ``ground`` stage (``[ground]`` in a run TOML)."""

    method: Literal["smrf", "smrf_refined", "smrf_segments", "smrf_vote", "pmf", "ptd"] = field(
        "smrf_vote", "ground filter: smrf (Pingel 2013), smrf_refined (SMRF + edge extension and "
        "optional surface cleanup), smrf_segments (SMRF + edge extension, terrain-like object "
        "segments given back), smrf_vote (a rule learnt on labelled samples over a point's heights "
        "off four SMRF surfaces - slopes 0.1, 0.3 and 0.4 with segments given back, 0.1 plain - "
        "and its distance to walls), pmf (Zhang 2003) or ptd (TIN densification, Axelsson 2000)")
    cell: float = field(1.0, "grid cell size of the filter (m)")
    slope: float | None = field(None, "terrain slope (rise/run) the filter keeps; default 0.15 for "
                                      "smrf, smrf_refined and smrf_segments, 0.3 for pmf")
    window: float = field(24.0, "smrf: largest opening radius (m); wider objects survive")
    scalar: float = field(1.25, "smrf, ptd: extra tolerance (m) per unit of terrain slope")
    threshold: float = field(0.5, "smrf, ptd: height tolerance (m) around the provisional "
                                  "terrain (ptd: around the final TIN)")
    extend: float = field(10.0, "smrf_refined, smrf_segments: metres of surface continued beyond "
                                "the tile edges (point reflection) so slopes rising to an edge are kept")
    rounds: int = field(0, "smrf_refined: surface-based cleanup rounds")
    refine_threshold: float = field(0.3, "smrf_refined: height tolerance (m) around the terrain "
                                          "re-interpolated from the ground points")
    jump: float = field(0.6, "smrf_segments: height step (m) between two smooth segments "
                            "(per metre of segmentation cell above 1 m)")
    raised: float = field(0.6, "smrf_segments: an object segment raised above the terrain along "
                               "less than this share of its boundary is given back")
    min_cells: int = field(4, "smrf_segments: fewest cells of a segment given back")
    strong_slope: float | None = field(None, "smrf_segments: an object region stays object only "
                                             "if the opening also cuts one of its cells at this "
                                             "slope (rise/run), e.g. 0.4 with slope 0.1; default "
                                             "none: no such test")
    veto: float | None = field(VOTE_VETO, "smrf_vote: a point near the strict surface is "
                                          "object when its height off smrf_segments' slope-0.4 "
                                          "surface exceeds this many tolerances (the fitted "
                                          "value); inf: no veto")
    above: float | None = field(VOTE_ABOVE, "smrf_vote: a point off the strict surfaces but "
                                            "within tolerance of the lenient one is ground also "
                                            "near walls when every wall within 15 m rises more "
                                            "than this (m) over it (ground at the foot of "
                                            "buildings); inf: off")
    connect: int | None = field(None, "smrf_vote: rounds of segment connectivity on its mask "
                                      "(smooth patches running on from its ground given to it, "
                                      "patches raised all round and pits taken away); default "
                                      "none")
    ring: float | None = field(None, "smrf_vote: a point called object but within tolerance of "
                                     "the lenient surface is ground when within this many "
                                     "tolerances of the plane of the ground around its surface "
                                     "patch (e.g. 1.25); default none")
    ring_neighbourhood: Literal["box", "dilation"] = field(
        "box", "smrf_vote with ring: the ground around a patch its plane is fitted to, the "
        "patch's bounding box grown by 3, 6, 12, 24 m (box) or the cells within that reach of "
        "its own cells (dilation)")
    wall_anchor: float | None = field(VOTE_ANCHOR, "smrf_vote: a region the opening cuts "
                                                   "steeper than 45 degrees counts as a wall "
                                                   "only when one of its cells is cut at this "
                                                   "slope too (rise/run: a building's step, not "
                                                   "an embankment); 1 or less: every such region")
    fill: float | None = field(VOTE_FILL, "smrf_vote: on sparse surveys the empty cells of its "
                                          "minimum surface within this many point spacings of a "
                                          "point take that point's cell height before the "
                                          "inpainting of the opening's input, so a terrace "
                                          "crest stays a step (acts from 2 m spacing at 0.5); "
                                          "0: off")
    large: float | None = field(LARGE_REACH, "smrf, smrf_vote: radius (m) up to which objects "
                                             "wider than the window (large roofs, which the "
                                             "opening leaves in the terrain) are looked for on "
                                             "a 4 m grid; inf: off")
    seed_cell: float = field(20.0, "ptd: seed grid cell (m), about the largest building")
    seed_tolerance: float = field(3.0, "ptd: a seed this far (m) above its neighbours' plane "
                                       "is dropped")
    iteration_angle: float = field(20.0, "ptd: iteration angle (degrees) to the facet's "
                                         "vertices")
    iteration_distance: float = field(1.5, "ptd: iteration distance (m) to the facet plane")
    max_iterations: int = field(60, "ptd: densification iterations at most")
    max_window: float = field(33.0, "pmf: largest window side (m)")
    initial_distance: float = field(0.5, "pmf: first height threshold dh0 (m)")
    max_distance: float = field(3.0, "pmf: largest height threshold dh_max (m)")
    exponential: bool = field(True, "pmf: exponentially (else linearly) growing windows")
    outlier_radius: float = field(5.0, "low outliers: neighbourhood cell size (m)")
    outlier_depth: float = field(1.5, "low outliers: depth below all neighbours (m)")
    dtm_cell: float = field(1.0, "cell size of the DTM written with --dtm (m)")

    def __post_init__(self):
        if self.method not in GROUND_METHODS:
            raise ConfigError(f"ground.method: {self.method!r} is not one of "
                              f"{', '.join(sorted(GROUND_METHODS))}")
        for name in ("cell", "window", "threshold", "max_window", "initial_distance",
                     "max_distance", "refine_threshold", "outlier_radius", "outlier_depth",
                     "dtm_cell", "jump", "seed_cell", "seed_tolerance", "iteration_angle",
                     "iteration_distance"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"ground.{name}: must be > 0, got {getattr(self, name)!r}")
        if self.slope is not None and not self.slope > 0:
            raise ConfigError(f"ground.slope: must be > 0, got {self.slope!r}")
        if not self.extend >= 0:
            raise ConfigError(f"ground.extend: must be >= 0, got {self.extend!r}")
        if not (isinstance(self.rounds, int) and self.rounds >= 0):
            raise ConfigError(f"ground.rounds: must be an integer >= 0, got {self.rounds!r}")
        if not 0 < self.raised <= 1:
            raise ConfigError(f"ground.raised: must be in (0, 1], got {self.raised!r}")
        if not (isinstance(self.min_cells, int) and self.min_cells >= 1):
            raise ConfigError(f"ground.min_cells: must be an integer >= 1, got {self.min_cells!r}")
        if self.strong_slope is not None and not self.strong_slope > 0:
            raise ConfigError(f"ground.strong_slope: must be > 0, got {self.strong_slope!r}")
        if self.veto is not None and not self.veto > 0:
            raise ConfigError(f"ground.veto: must be > 0, got {self.veto!r}")
        if self.above is not None and not self.above > 0:
            raise ConfigError(f"ground.above: must be > 0, got {self.above!r}")
        if self.ring is not None and not self.ring > 0:
            raise ConfigError(f"ground.ring: must be > 0, got {self.ring!r}")
        if self.large is not None and not self.large > 0:
            raise ConfigError(f"ground.large: must be > 0, got {self.large!r}")
        if self.wall_anchor is not None and not self.wall_anchor > 0:
            raise ConfigError(f"ground.wall_anchor: must be > 0, got {self.wall_anchor!r}")
        if self.fill is not None and not self.fill >= 0:
            raise ConfigError(f"ground.fill: must be >= 0, got {self.fill!r}")
        if self.ring_neighbourhood not in RING_NEIGHBOURHOODS:
            raise ConfigError(f"ground.ring_neighbourhood: {self.ring_neighbourhood!r} is not one "
                              f"of {', '.join(RING_NEIGHBOURHOODS)}")
        if self.connect is not None and not (isinstance(self.connect, int) and self.connect >= 0):
            raise ConfigError(f"ground.connect: must be an integer >= 0, got {self.connect!r}")
        if not (isinstance(self.max_iterations, int) and self.max_iterations >= 0):
            raise ConfigError("ground.max_iterations: must be an integer >= 0, got "
                              f"{self.max_iterations!r}")
        if not self.iteration_angle < 90:
            raise ConfigError("ground.iteration_angle: must be below 90, got "
                              f"{self.iteration_angle!r}")
        if self.scalar < 0:
            raise ConfigError(f"ground.scalar: must be >= 0, got {self.scalar!r}")

    def method_params(self) -> dict:
        """Keyword arguments of the chosen method's function."""
        values = asdict(self)
        if values["slope"] is None:
            values["slope"] = _SLOPE_DEFAULTS.get(self.method)
        accepted = set(inspect.signature(GROUND_METHODS[self.method]).parameters)
        return {k: v for k, v in values.items() if k in accepted}
