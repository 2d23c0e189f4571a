"""Building / vegetation separation of a point cloud with a known ground.

The method composes the classic cues (Rottensteiner & Briese 2002;
Rabbani et al. 2006; Vosselman 2009):

0. **Survey cues** (:mod:`.cues`): the return fields are read the way the
   survey wrote them (multi-echo, first/last-pulse pairs, single, constant,
   absent or inconsistent) and logged with the spacing and intensity; a
   first-pulse point repeating its last pulse is left out and takes its class.
1. **Height above ground** from a DTM gridded from the ground points
   (:mod:`.hag`); only points at least ``min_height`` above it can be roofs
   or high vegetation.
2. **Noise**: points far from any other point (isolated, e.g. birds or
   multipath) and points far below the terrain.
3. **Local PCA** of every object point's k-neighbourhood: normal and
   residual, the roughness index. Clouds denser than ``feature_spacing``
   are thinned to one point per voxel for the features (each point then
   takes its nearest kept point's), and on sparse clouds the planarity
   thresholds and the closing radius grow with the measured spacing, so
   the same defaults serve 2 to 100+ pts/m2.
4. **Planar region growing**: regions are connected components of the
   kNN edges joining locally coplanar points (:mod:`.regions`). Roof facets
   become large planar regions; vegetation breaks into small incoherent ones.
   Regions that are large, fit a plane, are not steep and are mostly made of
   single / last returns are roof seeds (a region that fits no plane, such as
   a steep roof face grown into its facade, is as steep as its surface over
   its footprint, not as its best-fit plane) — unless their points' mean local
   residual is more than ``max_region_roughness`` of the planarity threshold
   (feature spacing up to 0.5 m): a smooth crown grows a large region of
   points that barely pass it, a roof's points lie well inside it. On a
   noisy survey the limit is raised to 1.25 times the survey's noise, the
   terrain's median local residual (flat roofs are as rough as the terrain).
5. **Morphology on a grid**: clusters of touching roof seed cells smaller
   than ``min_seed_cluster_area`` or with more than
   ``max_cluster_multi_return`` multi-echo seeds (smooth patches in crowns)
   are dropped; the remaining seed cells are closed, small holes filled,
   and connected building areas dropped when smaller than
   ``min_building_area``, narrower than ``min_building_width`` everywhere
   (bridges, walls), long and narrow (``max_linear_aspect``: footbridges and
   viaducts clear of the ground) or too sparsely covered by seeds (``min_seed_coverage``:
   trees give scattered planar patches, roofs are covered).
6. **Point decision**: object points inside a building area and not above
   the roof as vegetation (rough, multi-return, optionally green) are
   building — so walls, roof edges, chimneys and dormers (small clusters
   above the roof) join their building; at its edge nothing above the roof
   does. Other points are vegetation — high,
   medium or low by their height — when they look like vegetation or lie on
   no sizeable plane, and "other" (1) when they lie on one (vehicles, sheds,
   fences, decks).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..config import field
from ..datamodel import ASPRS
from ..errors import ConfigError, InputError
from ..ground.dtm import dtm_from_ground, height_above_ground
from .cues import survey_cues
from .features import block_sample, local_shape, point_spacing, scan_line_gap, surface_noise
from .regions import planar_regions

logger = logging.getLogger(__name__)

__all__ = ["ClassifyConfig", "classify_points", "greenness"]


#: Floors of the planarity thresholds as multiples of the feature point spacing
#: (they bind below about 4 pts/m2, keeping sparse data as separable as dense).
_RESIDUAL_PER_SPACING = 0.4
_DISTANCE_PER_SPACING = 0.8
_ROUGH_PER_SPACING = 0.3
_CLOSING_PER_SPACING = 4.0
#: Largest building grid (cells) before asking for tiling (~1 GB of grids).
_MAX_CELLS = 100_000_000
#: Height above the terrain (m) under which a region point touches the ground.
_CONTACT_HEIGHT = 0.5
#: A roof seed facet covers at least this many feature spacings squared.
_FACET_POINTS = 8.0
#: Feature spacing (m) above which the region roughness cue
#: (max_region_roughness) is not used: on sparser data a k-neighbourhood spans
#: roof detail and the planarity threshold grows with the spacing, so a roof's
#: mean residual is no longer well inside it (ISPRS Stuttgart, 1 pt/m2: the cue
#: dropped roof regions whose pulses are 85 % one-echo).
_ROUGHNESS_MAX_SPACING = 0.5
#: The region roughness limit is at least this many times the survey's noise
#: (the median local residual of the terrain, thinned as the features are): a
#: flat roof's mean residual is about that noise, up to 1.12 times it where the
#: thinning keeps two stacked points per column (synthetic town, 5 cm noise,
#: 50 pts/m2: roof regions 0.028-0.042 m, terrain 0.0376 m, smooth crown
#: regions 0.044-0.063 m, nine in ten over 0.051 m). Delft's terrain (0.012 m)
#: and Nebraska's (0.006 m) leave the configured limit as it is...
_ROUGHNESS_PER_NOISE = 1.25
#: ... and at most this fraction of max_residual.
_ROUGHNESS_MAX_FRACTION = 0.7
#: Terrain points (about; half of them after the thinning of a dense survey) on which
#: the noise is measured.
_NOISE_POINTS = 50_000


@dataclass(frozen=True)
class ClassifyConfig:
    """Parameters of :func:`classify_points` (config stage ``classify``). Lengths in metres."""

    min_height: float = field(2.0, "Height above ground (m) from which points can be roofs or high vegetation.")
    medium_height: float = field(0.5, "Height above ground (m) separating low (3) from medium (4) vegetation.")
    wall_min_height: float = field(0.5, "Lowest height above ground (m) of wall points joined to a building.")
    dtm_cell: float = field(1.0, "Cell size (m) of the DTM gridded from the ground points.")
    feature_spacing: float = field(0.2, "Denser object points are thinned to one per voxel of this size (m) for the local features.")
    k: int = field(8, "Neighbours of the local PCA; thinning to feature_spacing bounds its size in metres on dense data.")
    max_residual: float = field(0.08, "Largest local plane residual (m) of a point in a planar region (at least 0.4 spacing).")
    max_angle: float = field(20.0, "Largest normal angle (degrees) between neighbours of one planar region.")
    max_distance: float = field(0.15, "Largest distance (m) of a neighbour to a point's tangent plane in region growing (at least 0.8 spacing).")
    min_facet_area: float = field(3.0, "Smallest area (m2) of a planar region seeding a building (at least 8 spacings squared).")
    max_facet_rms: float = field(0.08, "Largest RMS residual (m) of a seed region's fitted plane (unless the region is large).")
    large_region_area: float = field(10.0, "Regions at least this large (m2) seed buildings whatever their plane fit (roof facets chained over ridges).")
    max_facet_slope: float = field(70.0, "Steepest seed region (degrees): its plane's slope, or when it fits no plane (a roof face grown into its facade) the mean slope of its surface over its footprint; steeper ones are walls, not roofs.")
    max_ground_contact: float = field(0.05, "Largest fraction of a seed region's points within 0.5 m of the terrain (planes reaching the ground are ramps and bridge decks).")
    max_linearity: float = field(0.85, "Largest mean linearity of a seed region's neighbourhoods (power lines are linear).")
    max_region_roughness: float = field(0.5, "Largest mean local residual of a seed region's points, as a fraction of max_residual (smooth crowns gather points that barely pass it; roofs lie well inside), raised on noisy surveys to 1.25 times the terrain's median local residual (at most 0.7); 1 disables.")
    max_multi_return: float = field(0.5, "Largest fraction of multi-return points in a seed region.")
    max_cluster_multi_return: float = field(0.3, "Largest fraction of multi-echo points among the seed points of a cluster of touching seed cells (canopy patches); 1 disables.")
    min_seed_cluster_area: float = field(7.5, "Smallest area (m2) of roof seed cells in a cluster of touching seed cells (smooth patches in crowns); 0 disables.")
    cell: float = field(0.5, "Cell size (m) of the building grid (raised to 1.5 spacing on sparse data).")
    closing_radius: float = field(1.0, "Radius (m) of the morphological closing of roof seed cells (at least 4 spacings).")
    max_hole_area: float = field(10.0, "Holes (m2) in building areas up to this size are filled.")
    min_seed_coverage: float = field(0.5, "Smallest fraction of a building area's elevated cells holding roof seed points.")
    min_building_width: float = field(3.0, "Building areas narrower than this everywhere (m) are dropped (bridges, walls).")
    max_linear_aspect: float = field(8.0, "Building areas narrower than linear_max_width and longer than this many times their width are linear structures (bridges, viaducts, covered walkways), not buildings; 0 disables.")
    linear_max_width: float = field(6.0, "Widest (m) a linear structure can be (see max_linear_aspect).")
    min_building_area: float = field(15.0, "Smallest building area (m2); smaller ones are dropped.")
    max_roof_object_area: float = field(4.0, "Rough clusters above a roof up to this area (m2), mostly single returns, stay building (chimneys, dormers).")
    edge_buffer: float = field(0.5, "Points this close (m) outside a building area (walls, eaves) can join it (at least one cell).")
    roof_tolerance: float = field(1.0, "Points more than this (m) above the roof seeds of their cell are tested as vegetation.")
    rough_residual: float = field(0.1, "Local residual (m) above which a point is rough, a vegetation cue (at least 0.3 spacing).")
    green_threshold: float = field(0.05, "Excess-green index above which a point is green (used only with RGB).")
    isolation_radius: float = field(2.0, "A point off the terrain (beyond medium_height) with fewer than 2 neighbours within this radius (m, at least 4 spacings) is noise.")
    noise_below: float = field(1.5, "Points more than this (m) below the terrain are noise.")
    max_height: float = field(300.0, "Points more than this (m) above the terrain are noise.")

    def __post_init__(self):
        for name in ("min_height", "dtm_cell", "feature_spacing", "max_residual", "max_distance",
                     "cell", "isolation_radius", "noise_below", "max_height", "rough_residual"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"classify.{name} must be positive, got {getattr(self, name)!r}")
        for name in ("medium_height", "wall_min_height", "min_facet_area", "max_facet_rms",
                     "closing_radius", "max_hole_area", "min_building_area",
                     "min_seed_cluster_area", "min_building_width", "roof_tolerance",
                     "edge_buffer", "max_roof_object_area", "max_linear_aspect", "linear_max_width"):
            if getattr(self, name) < 0:
                raise ConfigError(f"classify.{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0 < self.max_angle < 90:
            raise ConfigError(f"classify.max_angle must be in (0, 90), got {self.max_angle!r}")
        if not 0 < self.max_facet_slope <= 90:
            raise ConfigError(f"classify.max_facet_slope must be in (0, 90], got {self.max_facet_slope!r}")
        if not 0 <= self.max_ground_contact <= 1:
            raise ConfigError(f"classify.max_ground_contact must be in [0, 1], got {self.max_ground_contact!r}")
        if not 0 <= self.max_linearity <= 1:
            raise ConfigError(f"classify.max_linearity must be in [0, 1], got {self.max_linearity!r}")
        if not 0 <= self.max_cluster_multi_return <= 1:
            raise ConfigError("classify.max_cluster_multi_return must be in [0, 1], "
                              f"got {self.max_cluster_multi_return!r}")
        if not 0 < self.max_region_roughness <= 1:
            raise ConfigError("classify.max_region_roughness must be in (0, 1], "
                              f"got {self.max_region_roughness!r}")
        if not 0 <= self.max_multi_return <= 1:
            raise ConfigError(f"classify.max_multi_return must be in [0, 1], got {self.max_multi_return!r}")
        if not 4 <= self.k <= 100:
            raise ConfigError(f"classify.k must be in [4, 100], got {self.k!r}")
        if self.medium_height > self.min_height:
            raise ConfigError("classify.medium_height must not exceed classify.min_height")


def greenness(rgb) -> np.ndarray:
    """Excess-green index ``(2G - R - B) / (R + G + B)`` in [-1, 2] (Woebbecke et al. 1995).

    Parameters
    ----------
    rgb : ndarray, shape (N, 3)
        Red, green, blue (any scale; 8 or 16 bit).
    """
    rgb = np.asarray(rgb, dtype=np.float64)
    total = rgb.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        g = np.where(total > 0, (2 * rgb[:, 1] - rgb[:, 0] - rgb[:, 2]) / total, 0.0)
    return g


def _check(xyz, ground, hag, return_number, number_of_returns, rgb):
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError(f"xyz must have shape (N, 3), got {xyz.shape}")
    if not np.isfinite(xyz).all():
        raise InputError("xyz contains NaN or infinite coordinates")
    n = len(xyz)
    ground = np.asarray(ground)
    if ground.shape != (n,):
        raise InputError(f"ground mask has shape {ground.shape}, expected ({n},)")
    if ground.dtype != bool:
        raise InputError(f"ground must be a boolean mask, got dtype {ground.dtype}")
    out = [xyz, ground]
    for name, arr, shp in (("hag", hag, (n,)), ("return_number", return_number, (n,)),
                           ("number_of_returns", number_of_returns, (n,)), ("rgb", rgb, (n, 3))):
        if arr is not None:
            arr = np.asarray(arr)
            if arr.shape != shp:
                raise InputError(f"{name} has shape {arr.shape}, expected {shp}")
            if name == "hag" and not np.isfinite(arr).all():
                raise InputError("hag contains NaN or infinite values")
        out.append(arr)
    return out


def _linear_structures(labels, n, cell, max_aspect, max_width) -> np.ndarray:
    """Which of the ``n`` labelled areas are long and narrow: ``width < max_width`` and
    ``length > max_aspect * width``, with the length along the principal axis and the
    width the area divided by it (metres)."""
    rows, cols = np.nonzero(labels)
    lab = labels[rows, cols]
    out = np.zeros(n, dtype=bool)
    order = np.argsort(lab, kind="stable")
    starts = np.searchsorted(lab[order], np.arange(1, n + 2))
    for i in range(n):
        idx = order[starts[i]:starts[i + 1]]
        if len(idx) < 3:
            continue
        xy = np.column_stack([cols[idx], rows[idx]]).astype(np.float64) * cell
        xy -= xy.mean(axis=0)
        _, vec = np.linalg.eigh(xy.T @ xy)
        length = float(np.ptp(xy @ vec[:, 1])) + cell
        # the mean width (area / length): the spread across the axis would count
        # the stair steps of a diagonal strip of cells
        width = len(idx) * cell * cell / length
        out[i] = width < max_width and length > max_aspect * width
    return out


def _voxel_thin(xyz, size: float) -> np.ndarray:
    """Indices of one point per cubic voxel of ``size`` metres, sorted.

    Voxels sit on a grid anchored at the local origin and a voxel keeps its
    lowest point (then the least x, y): the same points are kept whatever
    the extent or the order of the input (a tile alone, or with neighbours).
    """
    v = np.floor(xyz / size).astype(np.int64)
    v -= v.min(axis=0)
    dims = v.max(axis=0) + 1
    key = (v[:, 0] * dims[1] + v[:, 1]) * dims[2] + v[:, 2]
    order = np.lexsort((xyz[:, 1], xyz[:, 0], xyz[:, 2], key))
    first = np.ones(len(order), dtype=bool)
    first[1:] = key[order[1:]] != key[order[:-1]]
    return np.sort(order[first])


def _disk(radius_cells: float) -> np.ndarray:
    r = int(np.ceil(radius_cells))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return (xx * xx + yy * yy) <= radius_cells * radius_cells + 1e-9


def _footprint_nz(p, lab, nz, n_regions, cell) -> np.ndarray:
    """Mean vertical component of the local normals over each region's footprint.

    Seen from above a wall is a line of cells and a roof face covers its area:
    each occupied ``cell`` (m) of a region counts once, with the least steep
    local normal among its points, so a facade chained to its roof face does not
    make the face pass for a wall however densely the facade is sampled.
    """
    ij = np.floor(p[:, :2] / cell).astype(np.int64)
    ij -= ij.min(axis=0)
    ni, nj = int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1
    key = (lab * ni + ij[:, 0]) * nj + ij[:, 1]
    cells, inv = np.unique(key, return_inverse=True)
    best = np.full(len(cells), -np.inf)
    np.maximum.at(best, inv, nz)
    owner = cells // (ni * nj)
    count = np.bincount(owner, minlength=n_regions)
    return np.bincount(owner, best, minlength=n_regions) / np.maximum(count, 1)


def _drop_seed_clusters(seed, pi, pj, multi, shape, cell, *, min_area, max_multi):
    """``seed`` without the seed clusters that are too small or canopy.

    Clusters are the connected components (8-neighbourhood) of the seed cells
    dilated by one cell. A cluster is dropped when its seed cells cover less
    than ``min_area`` (m2: a smooth patch in a crown, a car roof) or when more
    than ``max_multi`` of its seed points are multi-echo (a canopy gives smooth
    patches too, but many of its pulses go on through it; a roof's seeds are
    single echoes but for eaves and overhanging branches).
    """
    from scipy import ndimage

    if not seed.any():
        return seed
    grid = np.zeros(shape, bool)
    grid[pi[seed], pj[seed]] = True
    lab, n = ndimage.label(ndimage.binary_dilation(grid), structure=np.ones((3, 3), bool))
    area = np.bincount(lab.ravel(), grid.ravel(), minlength=n + 1) * cell * cell
    s_lab = lab[pi[seed], pj[seed]]
    s_multi = (np.bincount(s_lab, multi[seed], minlength=n + 1)
               / np.maximum(np.bincount(s_lab, minlength=n + 1), 1))
    drop = (area < min_area) | (s_multi > max_multi)
    drop[0] = False
    out = seed.copy()
    out[np.flatnonzero(seed)[drop[s_lab]]] = False
    logger.debug("%d of %d seed clusters dropped (%d small, %d multi-echo)", int(drop.sum()), n,
                 int((area[1:] < min_area).sum()), int((s_multi[1:] > max_multi).sum()))
    return out


def classify_points(xyz, ground, *, hag=None, return_number=None, number_of_returns=None,
                    rgb=None, intensity=None, config: ClassifyConfig | None = None,
                    **params) -> np.ndarray:
    """ASPRS classes for every point given a ground mask.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Coordinates in metres (local metric frame).
    ground : ndarray of bool, shape (N,)
        Ground points (e.g. from :func:`lidar2city.ground.ground_mask`).
    hag : ndarray, shape (N,), optional
        Height above ground (m); computed from ``ground`` with
        :func:`lidar2city.ground.dtm_from_ground` when omitted.
    return_number, number_of_returns : ndarray, shape (N,), optional
        Pulse return information, read by :func:`.cues.survey_cues`: a
        vegetation cue for multi-echo data; first/last-pulse pairs are
        recognised (a coincident first pulse is left out and takes its last
        pulse's class); constant, single or inconsistent fields are ignored.
    rgb : ndarray, shape (N, 3), optional
        Colour; greenness is a vegetation cue when given.
    intensity : ndarray, shape (N,), optional
        Inspected and logged only (absent, constant or informative).
    config : ClassifyConfig, optional
        Parameters; keyword arguments override single fields
        (``classify_points(xyz, g, min_height=2.5)``).

    Returns
    -------
    ndarray of uint8, shape (N,)
        2 ground, 6 building, 5 high / 4 medium / 3 low vegetation, 7 noise,
        1 other.

    Raises
    ------
    InputError
        On shape / dtype mismatches or non-finite coordinates.
    EmptyInputError
        If ``hag`` is omitted and there is no ground point.
    ConfigError
        On an unknown or invalid parameter.

    References
    ----------
    F. Rottensteiner, C. Briese, "A new method for building extraction in urban
    areas from high-resolution LIDAR data", IAPRS 34(3A), 2002.
    T. Rabbani, F. van den Heuvel, G. Vosselman, "Segmentation of point clouds
    using smoothness constraint", IAPRS 36(5), 2006.

    Examples
    --------
    >>> cls = classify_points(xyz, ground_mask)            # doctest: +SKIP
    >>> (cls == 6).mean()                                  # doctest: +SKIP
    """
    return _classify(xyz, ground, hag=hag, return_number=return_number,
                     number_of_returns=number_of_returns, rgb=rgb, intensity=intensity,
                     config=config, **params)["classes"]


def _classify(xyz, ground, *, hag=None, return_number=None, number_of_returns=None,
              rgb=None, intensity=None, config: ClassifyConfig | None = None, **params) -> dict:
    """:func:`classify_points` returning its intermediate arrays too (diagnostics, tests).

    With first/last-pulse pairs the intermediate arrays are those of the points
    kept (``kept``); duplicates take their partner's class.
    """
    import dataclasses

    if config is None:
        config = ClassifyConfig()
    if params:
        names = {f.name for f in dataclasses.fields(ClassifyConfig)}
        unknown = sorted(set(params) - names)
        if unknown:
            raise ConfigError(f"classify.{unknown[0]}: unknown option; known: {', '.join(sorted(names))}")
        config = dataclasses.replace(config, **params)
    c = config
    xyz, ground, hag, return_number, number_of_returns, rgb = _check(
        xyz, ground, hag, return_number, number_of_returns, rgb)
    if intensity is not None and np.shape(intensity) != (len(xyz),):
        raise InputError(f"intensity has shape {np.shape(intensity)}, expected ({len(xyz)},)")
    spacing = point_spacing(xyz[:, :2]) if len(xyz) else 1.0
    cues = survey_cues(xyz, return_number=return_number, number_of_returns=number_of_returns,
                       intensity=intensity, spacing=spacing)
    logger.info("survey: %d points, spacing %.2f m (%.1f pts/m2); %s; cues used: height above "
                "ground, planarity, region size and shape%s%s", len(xyz), spacing,
                1.0 / spacing ** 2, "; ".join(cues.notes),
                ", returns" if cues.has_returns else "", ", colour" if rgb is not None else "")
    if not cues.duplicate.any():
        out = _classify_kept(xyz, ground, hag, cues.multi, cues.not_last, cues.has_returns,
                             rgb, c)
        out["cues"] = cues
        return out
    kept = np.flatnonzero(~cues.duplicate)
    sub = lambda a: None if a is None else a[kept]  # noqa: E731
    out = _classify_kept(xyz[kept], ground[kept], sub(hag), cues.multi[kept],
                         cues.not_last[kept], cues.has_returns, sub(rgb), c)
    cls = np.empty(len(xyz), np.uint8)
    cls[kept] = out["classes"]
    dup = np.flatnonzero(cues.duplicate)
    cls[dup] = cls[cues.partner[dup]]
    out.update(classes=cls, kept=kept, cues=cues)
    return out


def _classify_kept(xyz, ground, hag, multi_all, not_last_all, has_returns, rgb, c) -> dict:
    """The classification proper, on points whose return cues are already read."""
    from scipy.spatial import cKDTree

    n = len(xyz)
    cls = np.full(n, ASPRS.UNCLASSIFIED, dtype=np.uint8)
    if n == 0:
        return {"classes": cls}
    cls[ground] = ASPRS.GROUND
    if hag is None:
        hag = height_above_ground(xyz, dtm_from_ground(xyz, ground, cell=c.dtm_cell))
    hag = np.asarray(hag, dtype=np.float64)
    spacing = point_spacing(xyz[:, :2])

    # --- noise: isolated points, far below / above the terrain -------------
    iso_r = max(c.isolation_radius, 4.0 * spacing)
    isolated = np.zeros(n, bool)
    cand = np.flatnonzero(~ground)
    if n > 2 and len(cand):
        dist, _ = cKDTree(xyz).query(xyz[cand], k=3, distance_upper_bound=iso_r, workers=-1)
        isolated[cand] = ~np.isfinite(dist[:, -1])
    # an isolated point on the terrain is sparse sampling (water, dark
    # surfaces), not noise: only isolated points off the surface are
    isolated &= np.abs(hag) > c.medium_height
    noise = ~ground & (isolated | (hag < -c.noise_below) | (hag > c.max_height))
    cls[noise] = ASPRS.NOISE

    # --- object points and their local shape --------------------------------
    obj = ~ground & ~noise
    obj_idx = np.flatnonzero(obj)
    if len(obj_idx) == 0:
        return {"classes": cls, "hag": hag}
    p = xyz[obj_idx]
    ph = hag[obj_idx]
    # dense clouds are thinned (one point per voxel) for the features so the
    # neighbourhoods keep a size in metres; every point then takes the
    # features of its nearest kept point
    obj_spacing = point_spacing(p[:, :2])
    # points in scan lines far closer along than across (8:1) have neighbourhoods on
    # one line, with no plane: they are thinned to a third of the gap between the
    # lines, so that the 8 nearest reach the lines beside (an 8:1 survey of the
    # synthetic town at 4 / 10 / 20 pts/m2: building F1 0.993 / 0.999 / 0.999; 0.000
    # unthinned; thinned to half the gap 0.821 at 4, to a quarter 0.861 at 20)
    gap = scan_line_gap(p[:, :2], obj_spacing) if len(p) > c.k else None
    if gap is not None:
        logger.info("object points in scan lines %.2f m apart (%.2f m spacing): thinned to "
                    "%.2f m for the local features", gap, obj_spacing, gap / 3.0)
    thin = max((gap or 0.0) / 3.0, c.feature_spacing if obj_spacing < c.feature_spacing
               else 0.0)
    if thin > 0:
        rep = _voxel_thin(p, thin)
        q = p[rep]
        nn = np.asarray(cKDTree(q).query(p, k=1, workers=-1)[1], dtype=np.int64)
    else:
        q, nn = p, np.arange(len(p))
    k = c.k
    shape = local_shape(q, k)
    cell = max(c.cell, 1.5 * spacing)
    # on sparse data a k-neighbourhood spans more roof detail and the seeds
    # cover a roof more loosely: thresholds grow with the feature spacing
    s_f = point_spacing(q[:, :2])
    max_residual = max(c.max_residual, _RESIDUAL_PER_SPACING * s_f)
    max_distance = max(c.max_distance, _DISTANCE_PER_SPACING * s_f)
    rough_residual = max(c.rough_residual, _ROUGH_PER_SPACING * s_f)
    closing_radius = max(c.closing_radius, _CLOSING_PER_SPACING * s_f)
    # a seed facet must hold enough points to be told from a smooth bit of canopy
    min_facet_area = max(c.min_facet_area, _FACET_POINTS * s_f * s_f)
    # the roughness limit follows the survey's noise, measured on the terrain
    # thinned as the object points are (a noisy survey's flat roofs are rougher)
    # (blocks of it on a large tile: sampled before the thinning, which costs)
    gxyz = xyz[ground]
    gxyz = gxyz[block_sample(gxyz[:, :2], 2 * _NOISE_POINTS)]
    if thin > 0 and len(gxyz):
        gxyz = gxyz[_voxel_thin(gxyz, thin)]
    noise_level = surface_noise(gxyz, k, max_points=2 * _NOISE_POINTS)
    roughness_limit = c.max_region_roughness
    if roughness_limit < 1:
        roughness_limit = max(roughness_limit, min(_ROUGHNESS_PER_NOISE * noise_level / max_residual,
                                                   _ROUGHNESS_MAX_FRACTION))
    if roughness_limit > c.max_region_roughness:
        logger.info("terrain noise %.3f m: region roughness limit raised to %.2f of max_residual",
                    noise_level, roughness_limit)
    if s_f > _ROUGHNESS_MAX_SPACING and c.max_region_roughness < 1:
        logger.info("feature spacing %.2f m: region roughness cue not used (over %.1f m a "
                    "neighbourhood spans roof detail)", s_f, _ROUGHNESS_MAX_SPACING)
    regions = planar_regions(q, shape, max_residual=max_residual, max_angle=c.max_angle,
                             max_distance=max_distance, area_cell=cell)
    lab = regions.labels[nn]
    residual = shape.residual[nn]
    # single-return data (every number_of_returns == 1) carries no return cue
    if has_returns:
        multi = multi_all[obj_idx]
        not_last = not_last_all[obj_idx]
    else:
        multi = np.zeros(len(p), bool)
        not_last = np.zeros(len(p), bool)
    green = greenness(rgb[obj_idx]) > c.green_threshold if rgb is not None else np.zeros(len(p), bool)

    # --- roof seeds ---------------------------------------------------------
    r = len(regions)
    inr = lab >= 0
    if r:
        size = np.maximum(np.bincount(lab[inr], minlength=r), 1)
        multi_frac = np.bincount(lab[inr], multi[inr], minlength=r) / size
        green_frac = np.bincount(lab[inr], green[inr], minlength=r) / size
        mean_h = np.bincount(lab[inr], ph[inr], minlength=r) / size
        # a plane running down to the terrain is a ramp, a bridge deck or
        # terrain; roof planes end at their eaves, high above the ground
        low_frac = np.bincount(lab[inr], ph[inr] < _CONTACT_HEIGHT, minlength=r) / size
        # parallel wires at one height form a "plane" of linear neighbourhoods
        mean_lin = np.bincount(lab[inr], shape.linearity[nn][inr], minlength=r) / size
        # a roof's points lie well inside the planarity threshold; a smooth
        # crown's region gathers the points that just pass it
        mean_res = np.bincount(lab[inr], residual[inr], minlength=r) / size / max_residual
        # one plane, or a large smooth surface (facets chained over ridges)
        fits = (regions.rms <= c.max_facet_rms) | (regions.area >= c.large_region_area)
        # how steep a region is: its plane's slope when it fits one; else its
        # surface's slope over its footprint (a steep roof face chained to the
        # facade below fits no plane, and the best-fit plane between the two
        # is steeper than the roof: it would pass for a wall)
        slope_nz = np.where(regions.rms <= c.max_facet_rms, regions.normal[:, 2],
                            _footprint_nz(p[inr], lab[inr], shape.normal[nn][inr, 2], r, cell))
        seed_region = ((regions.area >= min_facet_area) & fits
                       & (slope_nz >= np.cos(np.radians(c.max_facet_slope)))
                       & (multi_frac <= c.max_multi_return) & (green_frac <= 0.5)
                       & (mean_h >= c.min_height) & (low_frac <= c.max_ground_contact)
                       & (mean_lin <= c.max_linearity)
                       & ((mean_res <= roughness_limit)
                          | (s_f > _ROUGHNESS_MAX_SPACING)))
    else:
        seed_region = fits = np.zeros(0, bool)
    seed = np.zeros(len(p), bool)
    seed[inr] = seed_region[lab[inr]]
    seed &= ph >= c.min_height

    # --- building grid: seed cells, closing, holes, area filter ------------
    from scipy import ndimage

    # the grid is anchored on the local origin, not on the points' extent, so a
    # tile processed alone or with its neighbours puts cell edges in the same places
    x0, y0 = np.floor(p[:, 0].min() / cell) * cell, np.floor(p[:, 1].min() / cell) * cell
    ncol = int(np.floor((p[:, 0].max() - x0) / cell)) + 1
    nrow = int(np.floor((p[:, 1].max() - y0) / cell)) + 1
    if nrow * ncol > _MAX_CELLS:
        raise InputError(
            f"the object points span {nrow * cell:.0f} m x {ncol * cell:.0f} m, too large for "
            f"one building grid of {cell:g} m cells; split the input into tiles")
    pj = np.floor((p[:, 0] - x0) / cell).astype(np.int64)
    pi = np.floor((p[:, 1] - y0) / cell).astype(np.int64)
    # seed clusters: touching seed cells, before the closing joins a tree or a
    # stray patch to the building beside it
    seed = _drop_seed_clusters(seed, pi, pj, multi, (nrow, ncol), cell,
                               min_area=c.min_seed_cluster_area,
                               max_multi=c.max_cluster_multi_return if has_returns else 1.0)
    seed_grid = np.zeros((nrow, ncol), bool)
    seed_grid[pi[seed], pj[seed]] = True
    disk = _disk(closing_radius / cell)
    pad = disk.shape[0]
    padded = np.pad(seed_grid, pad)
    closed = ndimage.binary_closing(padded, structure=disk)[pad:-pad, pad:-pad] | seed_grid
    holes = ndimage.binary_fill_holes(closed) & ~closed
    hl, nh = ndimage.label(holes)
    if nh:
        hole_area = np.bincount(hl.ravel())[1:] * cell * cell
        small = np.concatenate([[False], hole_area <= c.max_hole_area])
        closed |= small[hl]
    bl, nb = ndimage.label(closed, structure=np.ones((3, 3), bool))
    if nb:
        # a roof is covered by its seeds; a tree gives scattered planar patches
        high_grid = np.zeros((nrow, ncol), bool)
        high = ph >= c.min_height
        high_grid[pi[high], pj[high]] = True
        lab_flat = bl.ravel()
        b_area = np.bincount(lab_flat, minlength=nb + 1)[1:] * cell * cell
        n_seed = np.bincount(lab_flat, seed_grid.ravel(), minlength=nb + 1)[1:]
        n_high = np.bincount(lab_flat, high_grid.ravel(), minlength=nb + 1)[1:]
        coverage = n_seed / np.maximum(n_high, 1)
        keep_b = (b_area >= c.min_building_area) & (coverage >= c.min_seed_coverage)
        if c.min_building_width > 0:
            # narrow structures (bridges, walls, fences, hedges on planar tops)
            # vanish under an erosion by half the width
            # (the tile border is no building edge: pad by replication)
            disk_w = _disk(0.5 * c.min_building_width / cell)
            pw = disk_w.shape[0]
            core = ndimage.binary_erosion(np.pad(closed, pw, mode="edge"),
                                          structure=disk_w)[pw:-pw, pw:-pw]
            wide = np.bincount(lab_flat, core.ravel(), minlength=nb + 1)[1:] > 0
            keep_b &= wide
        if c.max_linear_aspect > 0:
            keep_b &= ~_linear_structures(bl, nb, cell, c.max_linear_aspect,
                                          c.linear_max_width)
        big = np.concatenate([[False], keep_b])
        building_grid = big[bl]
    else:
        building_grid = closed
    # roof height per cell: highest seed point, spread to cells of the area without seeds
    roof = np.full((nrow, ncol), -np.inf)
    np.maximum.at(roof, (pi[seed], pj[seed]), p[seed, 2])
    # a wall or a taller part next to a lower roof stays under the highest roof nearby
    roof = ndimage.maximum_filter(roof, footprint=_disk(closing_radius / cell + 1),
                                  mode="nearest")
    has_roof = np.isfinite(roof)
    if has_roof.any():
        _, (ri, rj) = ndimage.distance_transform_edt(~has_roof, return_indices=True)
        roof = roof[ri, rj]
    # buildings reach one cell further for edges and walls
    building_zone = building_grid
    if c.edge_buffer > 0:
        building_zone = ndimage.binary_dilation(building_grid,
                                                structure=_disk(max(c.edge_buffer / cell, 1.0)))

    # --- point decisions ------------------------------------------------------
    rough = residual > rough_residual
    veg_cue = rough | multi | green
    in_zone = building_zone[pi, pj]
    in_building = building_grid[pi, pj]
    above_roof = p[:, 2] > roof[pi, pj] + c.roof_tolerance
    # elevated points on a sizeable plane that is no building (a shed, a
    # vehicle, a bridge deck) are "other", not vegetation
    planar = np.zeros(len(p), bool)
    if r:
        planar[inr] = ((regions.area >= min_facet_area) & fits)[lab[inr]]
    # vegetation inside a building area: above the roof and vegetation-like,
    # or rough multi-return points at the zone's edge (trees against walls)
    veg_over = above_roof & veg_cue & ~seed & (rough | not_last)
    if veg_over.any() and c.max_roof_object_area > 0:
        # chimneys, dormers, antennas: small single-return clusters on a roof
        # stay building; trees over roofs are larger or return several echoes
        over_grid = np.zeros((nrow, ncol), bool)
        over_grid[pi[veg_over], pj[veg_over]] = True
        ol, no = ndimage.label(over_grid, structure=np.ones((3, 3), bool))
        o_area = np.bincount(ol.ravel(), minlength=no + 1) * cell * cell
        o_lab = ol[pi, pj]
        o_multi = np.bincount(o_lab[veg_over], multi[veg_over], minlength=no + 1)
        o_count = np.maximum(np.bincount(o_lab[veg_over], minlength=no + 1), 1)
        small = (o_area <= c.max_roof_object_area) & (o_multi / o_count <= c.max_multi_return)
        small[0] = False
        veg_over &= ~small[o_lab]
    edge_veg = ~in_building & rough & (multi | green | (not has_returns)) & ~seed
    # walls and eaves join a building at its edge; nothing above its roof does
    edge_veg |= ~in_building & above_roof & ~seed
    is_building = (in_zone & (ph >= c.wall_min_height) & ~veg_over & ~edge_veg) | (seed & in_building)
    high = ph >= c.min_height
    is_veg = ~is_building & (veg_cue | ~planar)
    out = np.full(len(p), ASPRS.UNCLASSIFIED, dtype=np.uint8)
    out[is_veg & high] = ASPRS.HIGH_VEGETATION
    low_veg = ~is_building & ~high & (veg_cue | ~planar)
    out[low_veg & (ph >= c.medium_height)] = ASPRS.MEDIUM_VEGETATION
    out[low_veg & (ph < c.medium_height)] = ASPRS.LOW_VEGETATION
    out[is_building] = ASPRS.BUILDING
    cls[obj_idx] = out
    logger.info("classified %d points: spacing %.2f m, k=%d, %d planar regions, %d seeds, "
                "%d building cells", n, spacing, k, r, int(seed_region.sum()),
                int(building_grid.sum()))
    return {"classes": cls, "hag": hag, "obj_idx": obj_idx, "shape": shape, "regions": regions,
            "residual": residual, "max_residual": max_residual,
            "noise_level": noise_level, "roughness_limit": roughness_limit,
            "seed": seed, "labels": lab, "in_zone": in_zone, "in_building": in_building, "veg_over": veg_over,
            "edge_veg": edge_veg, "above_roof": above_roof, "linearity": shape.linearity[nn], "spacing": spacing, "k": k, "building_grid": building_grid,
            "grid_origin": (float(x0), float(y0)), "cell": cell}
