"""``reconstruct``: point cloud tiles (+ footprints) to LoD1 / LoD2.2 buildings in a file.

The job, for any number of tiles and buildings, in four parts:

1. plan (:func:`plan_reconstruct`, :mod:`lidar2city.tools.blocks`): index the
   tiles by their headers (:func:`lidar2city.io.las.scan_tiles`), decide once
   whether the input is classified or raw, scan the footprint file in chunks
   for their ids and bounds (:func:`index_footprints`) and group them by the
   cell of a CRS-aligned grid of ``block_size`` metres holding the centre of their bounding box (or,
   without footprints, one cell per grid cell to trace them in): an ordered
   list of picklable block specs;
2. one task per block (:func:`lidar2city.tools.task.run_block`, what runs on a
   worker): read its footprints by feature id and the points of its
   buildings plus a margin from the tiles that meet it, classify them if the input is raw (:func:`point_roles`), and give
   each building exactly the points within its footprint's bounding box plus
   ``search_radius`` metres, so a result does not depend on tiling, blocks,
   workers or order;
3. an executor (:mod:`lidar2city.tools.engine`) runs the tasks;
4. the results are put back in the footprint file's order (:func:`assemble`)
   and written as CityJSON, CityJSONSeq, OBJ or GeoPackage (:data:`FORMATS`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import CRSError, EmptyInputError, InputError

logger = logging.getLogger(__name__)

__all__ = ["FORMATS", "ReconstructSummary", "ReconstructPlan", "PointGrid", "format_from_name",
           "lod1_config", "point_roles", "load_footprints", "reconstruct_buildings",
           "index_footprints", "write_buildings", "plan_reconstruct", "run_blocks", "InOrder",
           "reconstruct"]

#: output format name -> file name endings that select it.
FORMATS = {
    "cityjson": (".city.json", ".json"),
    "cityjsonseq": (".city.jsonl", ".jsonl"),
    "obj": (".obj",),
    "gpkg": (".gpkg",),
}


def format_from_name(path, fmt=None) -> str:
    """The output format: ``fmt`` if given, else from the file name's ending."""
    if fmt is not None:
        fmt = fmt.lower()
        if fmt not in FORMATS:
            raise InputError(f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")
        return fmt
    name = str(path).lower()
    for f, endings in FORMATS.items():
        if any(name.endswith(e) for e in endings):
            if f == "cityjson" and name.endswith(".jsonl"):
                continue
            return f
    raise InputError(f"cannot tell the format of {str(path)!r} from its name; use --format "
                     f"({', '.join(FORMATS)}) or a name ending in .city.json, .city.jsonl, "
                     ".obj or .gpkg")


@dataclass
class ReconstructSummary:
    """What a reconstruct run did."""

    output: str
    total: int = 0
    done: int = 0
    failed: int = 0
    invalid: int = 0
    reasons: Counter = field(default_factory=Counter)
    seconds: float = 0.0
    lods: tuple = ()
    format: str = ""
    lod22: dict = field(default_factory=dict)
    blocks: int = 0
    resumed: int = 0
    worker_peak_mb: float = 0.0
    worker_cpu: dict = field(default_factory=dict)
    process_cpu: dict = field(default_factory=dict)
    startup_seconds: float = 0.0

    def lines(self) -> list[str]:
        out = [f"{self.done} of {self.total} buildings reconstructed (LoD {', '.join(self.lods)}), "
               f"{self.failed} failed, {self.invalid} invalid, in {self.seconds:.2f} s -> "
               f"{self.output} ({self.format})"]
        if self.resumed:
            out.append(f"  resumed: {self.resumed} of {self.blocks} blocks taken from the journal")
        for reason, n in self.reasons.most_common():
            out.append(f"  failed: {n} x {reason}")
        if self.lod22:
            d = self.lod22
            out.append(f"  LoD2.2: {d['modelled']} roofs, {d['fallbacks']} LoD1.2 fallbacks, "
                       f"{d['type_iv']} building(s) needed type IV reductions, "
                       f"{1000 * d['time_per_building']:.0f} ms per building")
        return out


class PointGrid:
    """A uniform 2-D grid index over points: which points fall in a bounding box.

    Parameters
    ----------
    xy : ndarray, shape (N, 2)
    cell : float
        Cell size (metres).
    """

    def __init__(self, xy, cell: float = 10.0):
        self.xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        self.cell = float(cell)
        if len(self.xy) == 0:
            self.lo = np.zeros(2)
            self.shape = (1, 1)
            self.order = np.zeros(0, dtype=np.int64)
            self.starts = np.zeros(2, dtype=np.int64)
            self._sorted = self.xy
            return
        self.lo = self.xy.min(axis=0)
        # cell of each point, a column at a time: floor((xy - lo) / cell)
        ij = []
        for d in range(2):
            t = np.subtract(self.xy[:, d], self.lo[d])
            np.divide(t, self.cell, out=t)
            ij.append(np.floor(t, out=t).astype(np.int64))
            del t
        self.shape = (int(ij[0].max()) + 1, int(ij[1].max()) + 1)
        key = ij[0]
        key *= self.shape[1]
        key += ij[1]
        del ij
        # the order inside a cell does not matter (a query returns its indices sorted):
        # the default sort, several times faster than a stable one
        self.order = np.argsort(key)
        counts = np.bincount(key, minlength=self.shape[0] * self.shape[1])
        self.starts = np.concatenate([[0], np.cumsum(counts)])
        # the coordinates in cell order: a query reads runs of neighbouring memory
        # instead of gathering points from all over the cloud
        self._sorted = self.xy[self.order]

    def query(self, xmin, ymin, xmax, ymax) -> np.ndarray:
        """Indices of the points inside the box (bounds included), sorted."""
        if len(self.order) == 0:
            return np.zeros(0, dtype=np.int64)
        i0, j0 = np.floor((np.array([xmin, ymin]) - self.lo) / self.cell).astype(np.int64)
        i1, j1 = np.floor((np.array([xmax, ymax]) - self.lo) / self.cell).astype(np.int64)
        i0, j0 = max(i0, 0), max(j0, 0)
        i1, j1 = min(i1, self.shape[0] - 1), min(j1, self.shape[1] - 1)
        if i0 > i1 or j0 > j1:
            return np.zeros(0, dtype=np.int64)
        rows = np.arange(i0, i1 + 1)
        a = self.starts[rows * self.shape[1] + j0]
        b = self.starts[rows * self.shape[1] + j1 + 1]
        cnt = b - a
        pos = np.repeat(a, cnt) + (np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt))
        p = self._sorted[pos]
        keep = (p[:, 0] >= xmin) & (p[:, 0] <= xmax) & (p[:, 1] >= ymin) & (p[:, 1] <= ymax)
        return np.sort(self.order[pos[keep]])


def lod1_config(config=None, *, lods=None, stages=()):
    """``(Lod1Config, resolved configuration dict, {stage: config})`` for a reconstruct run.

    ``config`` is None, a dict of sections, a TOML path or a :class:`Lod1Config`.
    ``lods`` (e.g. from ``--lod``) overrides the file's ``lod1.lods``; "2.2" is built by
    the ``lod22`` (or ``primitives``) stage on top of LoD1.2, which gives its ground height
    and its fallback. Only ``lod1``, the ``stages`` named and the sections the file holds
    are resolved (and imported): a LoD1 run does not load the LoD2 machinery.
    """
    from ..config import read_config, resolved_dict, stage_config
    from ..lod.lod1 import Lod1Config

    if isinstance(config, Lod1Config):
        data, cfg = {}, config
    else:
        data = read_config(config)
        cfg = stage_config("lod1", data)
    others = {name: stage_config(name, data) for name in sorted({*data, *stages} - {"lod1"})}
    if lods:
        lod1_lods = tuple(v for v in lods if v != "2.2") or ("1.2",)
        cfg = cfg.replace(lods=lod1_lods)
    resolved = resolved_dict({**others, "lod1": cfg})
    return cfg, resolved, others


def point_roles(cloud, config, *, classified=None, ground_filter: bool = False):
    """Boolean masks ``(building, ground)`` of the cloud's points, and the classes.

    Uses the classification the input carries (ASPRS 6 building, 2 ground by
    default; ``config.building_classes`` / ``ground_classes``); a raw tile
    without building points is ground-filtered and classified first
    (:func:`lidar2city.tools.classify.classify_cloud`). ``classified`` makes
    that choice for the caller (a run over many blocks decides it once for
    all of them): True keeps the input's classes, False classifies.
    ``ground_filter`` (classified input without any ground class): the ground
    is filtered from the points that are not building points, the building
    points kept as they are.

    Raises
    ------
    EmptyInputError
        When no building point is found even after classification.
    """
    cls = cloud.get("classification")
    if classified is None:
        classified = cls is not None and np.isin(cls, config.building_classes).any()
    if classified and cls is not None:
        if not np.isin(cls, config.building_classes).any():
            raise EmptyInputError("no building point in the input's classes")
        if ground_filter:
            from ..ground import ground_mask

            other = np.flatnonzero(~np.isin(cls, config.building_classes))
            if len(other) >= 3:
                cls = np.array(cls, copy=True)
                cls[other[np.asarray(ground_mask(cloud.xyz[other]), dtype=bool)]] = \
                    config.ground_classes[0]
    else:
        from .classify import classify_cloud

        logger.info("no building class in the input: filtering ground and classifying")
        cls = classify_cloud(cloud)
        if not np.isin(cls, config.building_classes).any():
            raise EmptyInputError("no building point found in the input, even after classification")
    return np.isin(cls, config.building_classes), np.isin(cls, config.ground_classes), cls


def footprints_from_points(cloud, classes, *, config=None, within=None):
    """Footprints traced from the building points and regularised by the 2-D snake.

    What ``reconstruct`` uses when no footprint file is given: one footprint per
    building block (:func:`lidar2city.footprints.extract_footprints`), ids
    ``b1``, ``b2``... in a deterministic order. ``config`` (a run file's
    ``[footprints]`` section) replaces the default, which is the snake regulariser
    (:func:`footprints_config`). ``within`` (a local box): only the footprints
    that may be centred in it are wanted (others may be left out; see
    ``extract_footprints``).

    Raises
    ------
    EmptyInputError
        When no building region is found.
    """
    import dataclasses

    from ..footprints import extract_footprints

    cfg = footprints_config(config)
    found = extract_footprints(cloud.xyz, classes, within=within, **dataclasses.asdict(cfg))
    if not found:
        raise EmptyInputError("no building footprint found in the points")
    return as_footprints(found)


def footprints_config(config=None):
    """The ``[footprints]`` stage traced footprints are made with: ``config``, or by
    default the stage's defaults with the snake regulariser."""
    from ..config import stage_config

    return config if config is not None else stage_config("footprints", None, regularize="snake")


def as_footprints(found):
    """Traced footprints (a list of :class:`lidar2city.footprints.Footprint`) as the
    :class:`~lidar2city.datamodel.Footprints` of a run: ids ``b1``, ``b2``... in their
    order, their area, direction, vertex count and mean deviation, and their
    reasons (``_note``)."""
    from ..datamodel import Footprints

    keys = ("area", "direction", "n_vertices", "mean_deviation")
    return Footprints([f.polygon for f in found], [f"b{i + 1}" for i in range(len(found))],
                      {k: [f.attributes.get(k) for f in found] for k in keys}
                      | {"_note": [f.reason for f in found]})


def load_footprints(path, cloud, *, id_field=None, layer=None, extent=None):
    """Footprints in the cloud's local frame, restricted to those meeting the points' extent.

    ``cloud`` gives the frame (origin, units, CRS); ``extent`` (local
    ``(xmin, ymin, xmax, ymax)``) replaces the extent of its points.
    ``path=None`` is handled by the caller (:func:`footprints_from_points`).
    """
    import shapely

    from ..io.vector import read_footprints

    fps, _ = read_footprints(path, layer=layer, id_field=id_field, origin=cloud.origin[:2],
                             xy_unit=cloud.xy_unit, target_crs=cloud.crs)
    if extent is None:
        extent = (*cloud.xyz[:, :2].min(axis=0), *cloud.xyz[:, :2].max(axis=0))
    area = shapely.box(*extent)
    keep = [i for i, g in enumerate(fps.geometries) if g is None or g.intersects(area)]
    if not keep:
        raise EmptyInputError(f"none of the {len(fps)} footprints of {str(path)!r} meets the "
                              "point cloud's extent (check both CRSs)")
    if len(keep) < len(fps):
        logger.warning("%d of %d footprint(s) outside the point cloud's extent: no model",
                       len(fps) - len(keep), len(fps))
    return _subset(fps, keep)


#: footprints read at a time by the planner's scan of the footprint file
FOOTPRINT_CHUNK = 50_000


def index_footprints(path, frame, *, id_field=None, layer=None, extent=None, chunk=None):
    """Feature ids, building ids and local bounds of the footprints meeting ``extent``.

    The planner's view of a footprint file of any size: it is scanned
    ``chunk`` features at a time (default :data:`FOOTPRINT_CHUNK`) and only
    these three are kept; each block's
    footprints are read again by their feature ids on the worker
    (:func:`lidar2city.tools.task.block_footprints`). The footprints kept and
    their ids are those of :func:`load_footprints` (ids made unique over the
    whole file, in its order).

    Returns
    -------
    fids : list of int
    ids : list of str
    bounds : ndarray, shape (M, 4)
        NaN for an empty footprint.
    """
    import shapely

    from ..io.vector import no_usable_footprint, overlapping, read_footprints, unique

    chunk = int(chunk or FOOTPRINT_CHUNK)
    area = shapely.box(*extent)
    all_ids, fids, keep, bounds, geoms, notes = [], [], [], [], [], []
    outlines, repeated = set(), 0  # a footprint repeated exactly: two overlapping models
    overlaps, largest = 0, 0.0  # footprints overlapping others (in one chunk of the file)
    while True:
        part, src_crs = read_footprints(path, layer=layer, id_field=id_field,
                                        origin=frame.origin[:2], xy_unit=frame.xy_unit,
                                        target_crs=frame.crs, skip_features=len(all_ids),
                                        max_features=chunk, unique_ids=False, with_fids=True)
        if not all_ids and len(part) and src_crs is None and frame.crs is not None:
            logger.warning("the footprints of %r have no CRS: taken to be in the input's (%s)",
                           str(path), frame.crs.name)
        # the geometries only as far as "is there one": for the error when none is usable
        geoms += [None if g is None else True for g in part.geometries]
        notes += part.attributes.get("_note", [""] * len(part))
        for g, f in zip(part.geometries, part.attributes.get("_fid", []), strict=True):
            if g is None or g.intersects(area):
                keep.append(True)
                fids.append(f)
                if g is not None:  # 64-bit hashes: the planner stays small on any file
                    key = hash(g.wkb)
                    repeated += key in outlines
                    outlines.add(key)
                bounds.append([np.nan] * 4 if g is None or g.is_empty else g.bounds)
            else:
                keep.append(False)
        pairs, most = overlapping(part.geometries)
        overlaps, largest = overlaps + pairs, max(largest, most)
        all_ids += part.ids
        if len(part) < chunk:
            break
    if not all_ids:
        raise EmptyInputError(f"{str(path)!r} holds no footprints")
    no_usable_footprint(path, geoms, notes)  # say why, once, before any block runs
    ids = unique(all_ids)
    kept = [i for i, k in enumerate(keep) if k]
    if not kept:
        raise EmptyInputError(f"none of the {len(all_ids)} footprints of {str(path)!r} meets the "
                              "point cloud's extent (check both CRSs)")
    if len(kept) < len(all_ids):
        logger.warning("%d of %d footprint(s) outside the point cloud's extent: no model",
                       len(all_ids) - len(kept), len(all_ids))
    if repeated:
        logger.warning("%d footprint(s) of %r repeat an earlier one's outline exactly: each "
                       "gets its own (overlapping) model; remove the duplicates", repeated,
                       str(path))
    if overlaps:
        logger.warning("%d pair(s) of footprints of %r overlap (by up to %.1f m2): each takes "
                       "the points of the overlap, so their models overlap and mix the two "
                       "roofs' heights", overlaps, str(path), largest)
    return fids, [ids[i] for i in kept], np.array(bounds, dtype=np.float64).reshape(-1, 4)


def _chunk_order(geometries, chunk):
    """Building indices grouped by square chunks of ``chunk`` metres (row by row)."""
    import shapely

    cent = np.array([[np.nan, np.nan] if g is None or g.is_empty else
                     shapely.get_coordinates(g.envelope).mean(axis=0) for g in geometries],
                    dtype=np.float64).reshape(-1, 2)
    cent = np.nan_to_num(cent, nan=0.0)
    key = np.floor(cent / chunk).astype(np.int64)
    return np.lexsort((key[:, 0], key[:, 1]))


def reconstruct_buildings(cloud, footprints, *, config=None, building=None, ground=None,
                          chunk: float = 250.0, progress=None, lod22=None,
                          area_ground=None) -> list:
    """LoD1 models of every footprint (results in footprint order).

    Parameters
    ----------
    cloud : PointCloud
    footprints : Footprints
        Same local frame as ``cloud``.
    config : Lod1Config, optional
    building, ground : ndarray of bool, shape (N,), optional
        Point roles; default from the classification (:func:`point_roles`).
    chunk : float
        Side (m) of the spatial chunks buildings are visited in.
    progress : callable, optional
        ``progress(done, total, result)`` after each building.
    lod22 : Lod22Config, optional
        Also build LoD2.2 roofs (:func:`lidar2city.roof.building.reconstruct_lod22`).
    area_ground : callable, optional
        ``area_ground(xmin, ymin, xmax, ymax)``: the heights of the ground points in
        that local box (bounds included), for the area's ground level of a
        building without ground around it (50 m around its footprint); default
        those of ``cloud``. For a cloud cut to the buildings' surroundings
        (:func:`lidar2city.tools.task.run_block`) that keeps the wider area elsewhere.
    """
    from ..lod.lod1 import Lod1Config, reconstruct_building
    from ..metrics import model as _model  # noqa: F401  (imported once, not in the first building's time)
    from ..validate import solid as _solid  # noqa: F401
    from .info import point_density

    cfg = config or Lod1Config()
    if building is None or ground is None:
        building, ground, _ = point_roles(cloud, cfg)
    bxyz = cloud.xyz[building]
    gxyz = cloud.xyz[ground]
    bgrid = PointGrid(bxyz[:, :2], cell=10.0)
    ggrid = PointGrid(gxyz[:, :2], cell=10.0)
    radius = cfg.search_radius
    area_radius = 50.0
    grids = []  # every point's grid, for the density around a footprint with few points
    total = len(footprints)
    results = [None] * total
    notes = footprints.attributes.get("_note", [""] * total)
    for done, i in enumerate(_chunk_order(footprints.geometries, chunk), start=1):
        g = footprints.geometries[i]
        fid = footprints.ids[i]
        if g is None or g.is_empty:
            res = reconstruct_building(None, np.zeros((0, 3)), np.zeros((0, 3)), config=cfg, id=fid)
            res.reason = f"invalid footprint: {notes[i] or 'empty geometry'}"
        else:
            x0, y0, x1, y1 = g.bounds
            if lod22 is not None:  # the roof's points (overhang included) hold the prism's
                m = lod22.overhang
                near = bgrid.query(x0 - m, y0 - m, x1 + m, y1 + m)
                p = bxyz[near]
                bi = near[(p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)]
            else:
                bi = bgrid.query(x0, y0, x1, y1)
            gi = ggrid.query(x0 - radius, y0 - radius, x1 + radius, y1 + radius)
            def fallback(x0=x0, y0=y0, x1=x1, y1=y1):
                # the area's ground level: ground points within 50 m
                box = (x0 - area_radius, y0 - area_radius, x1 + area_radius, y1 + area_radius)
                z = gxyz[ggrid.query(*box), 2] if area_ground is None else area_ground(*box)
                return float(np.percentile(z, cfg.ground_percentile)) if len(z) else None

            def density(x0=x0, y0=y0, x1=x1, y1=y1):
                # the survey's density around the footprint, every point counted (built
                # only for a footprint holding fewer than min_points building points)
                if not grids:
                    grids.append(PointGrid(cloud.xyz[:, :2], cell=10.0))
                near = grids[0].query(x0 - radius, y0 - radius, x1 + radius, y1 + radius)
                # averaged over 5 m cells with points: gaps between scan lines count,
                # water and the space beyond the tile's edge do not
                return point_density(cloud.xyz[near, :2], cell=5.0)

            res = reconstruct_building(g, bxyz[bi], gxyz[gi], config=cfg, id=fid,
                                       fallback_ground_z=fallback, point_density=density)
            if lod22 is not None and res.ok:
                add_lod22(res, g, bxyz[near], lod22, precision=cfg.precision,
                          anchor=building_anchor(cloud, x0, y0))
        if notes[i]:
            res.attributes["footprint_note"] = notes[i]
        results[i] = res
        if progress is not None:
            progress(done, total, res)
    return results


#: how many point spacings a LoD2.2 roof corner may rise above its highest point (a ridge
#: between points, the steepest facet rising 3 m per metre) before the prism stands in
SPIKE_SPACINGS = 3.0


def building_anchor(cloud, x, y) -> np.ndarray:
    """The local ``(x, y)`` of the whole CRS unit at or below the world position of the
    local point ``(x, y)``: where a building's LoD2.2 is computed from, whatever the
    run's origin (the lower corner of all its tiles).

    A roof's arithmetic (plane offsets, the vertex grids it snaps to) in coordinates
    measured from the run's origin would make a building's model depend on which other
    tiles are in the run. Measured from this anchor, its points and footprint are the
    same numbers in every run (both origins whole units: the differences are exact),
    so is its model.
    """
    o = np.asarray(cloud.origin[:2], dtype=np.float64)
    unit = float(cloud.xy_unit)
    return (np.floor(o + np.array([x, y]) / unit) - o) * unit


def add_lod22(result, footprint, building_xyz, config, *, precision=0.001,
              anchor=None) -> None:
    """Add the LoD2.2 solid(s) and roof attributes to a LoD1 result (in place).

    The LoD1.2 ground height is the floor. When no roof can be fitted, or the
    roof fits its points worse than the LoD1.2 prism's by more than a step
    (``2 * elevation_error``, :func:`lidar2city.lod.roofcheck.worse_than_prism`),
    the LoD1.2 prism stands in for LoD2.2 and ``lod22_fallback`` says why: every
    footprint keeps a valid solid, the better founded of the two. So it does when a
    roof corner rises more than ``2 * elevation_error`` plus :data:`SPIKE_SPACINGS`
    point spacings above the highest of the roof's points
    (:func:`lidar2city.lod.roofcheck.rises_above_points`).

    ``anchor``: the local ``(x, y)`` the roof is computed from (:func:`building_anchor`);
    the solids stored are in the footprint's frame.
    """
    from ..errors import AlgorithmError
    from ..lod.roofcheck import rises_above_points, worse_than_prism
    from ..roof.building import reconstruct_lod22

    if result.attributes.get("low_coverage"):  # no roof planes drawn from a corner of points
        set_lod22(result, None, {}, result.attributes["low_coverage"])
        return
    ground_z = result.attributes.get("ground_height")
    a = np.zeros(2) if anchor is None else np.asarray(anchor, dtype=np.float64)
    if a.any():
        import shapely

        footprint = shapely.transform(footprint, lambda c: c - a)
        building_xyz = building_xyz - np.append(a, 0.0)
    try:
        out = reconstruct_lod22(footprint, building_xyz, float(ground_z), config=config,
                                precision=precision)
    except AlgorithmError as exc:
        set_lod22(result, None, {}, str(exc))
        return
    lod12 = result.solids.get("1.2")
    worse = "" if lod12 is None else worse_than_prism(
        out.solids, _moved(lod12, -a), building_xyz, margin=2.0 * config.elevation_error)
    if not worse:  # a corner farther above the roof's points than a steep facet over 3 spacings
        import shapely

        grown = footprint.buffer(config.overhang)
        own = building_xyz[shapely.contains_xy(grown, building_xyz[:, 0], building_xyz[:, 1])]
        spacing = float(np.sqrt(grown.area / max(len(own), 1)))
        worse = rises_above_points(out.solids, own, tolerance=2.0 * config.elevation_error
                                   + SPIKE_SPACINGS * spacing)
    if worse:
        set_lod22(result, None, {}, worse)
        return
    set_lod22(result, [_moved(s, a) for s in out.solids], out.attributes, precision=precision,
              checked=out.issues)


def _moved(solids, d):
    """A solid, or a list of solids (a multi-part footprint's), moved by ``d`` = (dx, dy)
    (themselves when ``d`` is zero)."""
    if not np.any(d):
        return solids
    if isinstance(solids, (list, tuple)):
        return [_moved(s, d) for s in solids]
    return type(solids)(solids.vertices + np.append(d, 0.0), solids.surfaces)


def set_lod22(result, solids, attributes, reason="", *, precision=0.001, checked=None) -> None:
    """Store LoD2.2 ``solids`` in ``result`` once they validate; else the LoD1.2 prism, with why.

    The vertices are first put on the output's ``precision`` grid (the CityJSON
    quantisation), so the solid validated is the one written. ``checked``: the
    :func:`~lidar2city.validate.solid.check_solid` issues of each solid when the
    caller already validated them on that grid (they are then stored as they are).
    """
    from ..roof.solid import on_grid
    from ..validate.solid import check_solid

    if solids and checked is not None and all(c is not None for c in checked):
        issues = [i for c in checked for i in c]
    elif solids:
        solids = [on_grid(s, precision) for s in solids]
        issues = [i for s in solids for i in check_solid(s)]
    if solids:
        if not issues:
            result.solids["2.2"] = solids[0] if len(solids) == 1 else list(solids)
            result.attributes.update(attributes)
            return
        reason = f"LoD2.2 solid invalid ({issues[0].code} {issues[0].detail})"
    lod12 = result.solids.get("1.2")
    if lod12 is not None:
        result.solids["2.2"] = lod12
        reason = f"LoD1.2 prism: {reason}"
    result.attributes["lod22_fallback"] = reason


def add_primitives(results, cloud, footprints, *, config=None, user_primitives=None,
                   progress=None) -> list:
    """LoD2.2 as fitted primitives (floating models) for every LoD1 result (in place).

    Returns the primitive fits (one result per footprint, for check images).
    """
    from .primitives import reconstruct_primitives

    prims = reconstruct_primitives(cloud, footprints, config=config,
                                   user_primitives=user_primitives, progress=progress)
    for r, p in zip(results, prims, strict=True):
        if not r.ok:
            continue
        solid = p.solids.get("2.2") if p.ok else None
        solids = None if solid is None else (solid if isinstance(solid, list) else [solid])
        set_lod22(r, solids, p.attributes, p.reason or "no primitive fitted")
    return prims


def _fields_for_output(footprints):
    return {k: v for k, v in footprints.attributes.items() if not k.startswith("_")}


#: attributes that measure a run (wall times) rather than describe a building: kept on the
#: results for summaries and benchmarks, never written, so that outputs are deterministic
RUN_ATTRIBUTES = ("reconstruction_time", "lod22_time")


def _title(lods) -> str:
    return f"lidar2city LoD{'+'.join(lods)} buildings"


def _without_run_attributes(result):
    import dataclasses

    return dataclasses.replace(result, attributes={k: v for k, v in result.attributes.items()
                                                   if k not in RUN_ATTRIBUTES})


def write_buildings(path, results, cloud, *, fmt=None, configuration=None, attributes=None,
                    lods=("1.2",)) -> str:
    """Write results in the format chosen by ``fmt`` or the file name; returns the format.

    The same results give the same file: :data:`RUN_ATTRIBUTES` are left out.
    """
    fmt = format_from_name(path, fmt)
    results = [_without_run_attributes(r) for r in results]
    title = _title(lods)
    common = dict(origin=cloud.origin, crs=cloud.crs, xy_unit=cloud.xy_unit, z_unit=cloud.z_unit,
                  configuration=configuration, attributes=attributes, title=title)
    if fmt == "cityjson":
        from ..io.cityjson import write_cityjson

        write_cityjson(path, results, **common)
    elif fmt == "cityjsonseq":
        from ..io.cityjson import write_cityjsonseq

        write_cityjsonseq(path, results, **common)
    elif fmt == "obj":
        from ..io.obj import write_obj

        write_obj(path, results, origin=cloud.origin, crs=cloud.crs, xy_unit=cloud.xy_unit,
                  z_unit=cloud.z_unit, lod=lods)
    elif fmt == "gpkg":
        _write_gpkg(path, results, cloud, attributes=attributes, configuration=configuration,
                    lods=lods)
    return fmt


def _face_multipolygon(solids):
    """Every face of ``solids`` as one 3-D MultiPolygon (local metres)."""
    import shapely

    from ..datamodel import Solid

    if isinstance(solids, Solid):
        solids = [solids]
    polys = []
    for s in solids:
        v = np.asarray(s.vertices)
        for surf in s.surfaces:
            rings = [v[np.asarray(r)] for r in surf.rings]
            polys.append(shapely.Polygon(rings[0], rings[1:]))
    return shapely.MultiPolygon(polys) if polys else None


def _write_gpkg(path, results, cloud, *, attributes=None, configuration=None, lods=("1.2",)):
    import json

    from ..io.vector import VectorLayer, write_layers

    keys = []
    for r in results:
        for k in r.attributes:
            if k not in keys:
                keys.append(k)
    fields = {"id": [str(r.id) for r in results], "status": [r.status for r in results],
              "reason": [r.reason for r in results]}
    for k, v in (attributes or {}).items():
        if k not in fields:
            fields[k] = list(v)
    for k in keys:
        vals = [r.attributes.get(k) for r in results]
        if all(v is None or isinstance(v, (bool, np.bool_)) for v in vals):
            vals = [None if v is None else int(v) for v in vals]
        elif all(v is None or isinstance(v, (int, float, np.number)) for v in vals):
            vals = np.array([np.nan if v is None else float(v) for v in vals])
        else:
            vals = [None if v is None else str(v) for v in vals]
        fields[k] = vals
    import shapely

    foot = [shapely.MultiPolygon(shapely.get_parts(r.footprint)) if r.footprint is not None
            and not r.footprint.is_empty else None for r in results]
    layers = [VectorLayer("footprints", foot, fields, "MultiPolygon")]
    for lod in lods:
        rows = [r for r in results if (lod in r.solids or lod in r.parts)]
        geoms = [_face_multipolygon(r.solids[lod] if lod in r.solids else r.parts[lod])
                 for r in rows]
        layers.append(VectorLayer(f"lod{lod.replace('.', '')}", geoms,
                                  {"id": [str(r.id) for r in rows]}, "MultiPolygon Z"))
    meta = {"lidar2city_configuration": json.dumps(configuration or {})}
    with fixed_gpkg_date():
        write_layers(path, layers, origin=cloud.origin, crs=cloud.crs, xy_unit=cloud.xy_unit,
                     z_unit=cloud.z_unit, metadata=meta, driver="GPKG")  # whatever its name


#: the time stamp written in GeoPackage outputs (``gpkg_contents.last_change``)
GPKG_DATE = "2000-01-01T00:00:00.000Z"


@contextlib.contextmanager
def fixed_gpkg_date():
    """GDAL stamps every GeoPackage table with the time of writing: inside this
    context the stamp is :data:`GPKG_DATE`, so the same results are the same bytes."""
    import pyogrio

    before = pyogrio.get_gdal_config_option("OGR_CURRENT_DATE")
    pyogrio.set_gdal_config_options({"OGR_CURRENT_DATE": GPKG_DATE})
    try:
        yield
    finally:
        pyogrio.set_gdal_config_options({"OGR_CURRENT_DATE": before})


#: the side (m) of the processing blocks by default (with footprints, the largest:
#: :func:`lidar2city.tools.blocks.footprint_block_size` halves it for dense areas)
BLOCK_SIZE = 1000.0

#: how LoD2.2 roofs are made: the roof-topology framework or fitted primitives
LOD22_METHODS = ("roof", "primitives")


def reconstruct(inputs, output, *, footprints=None, lods=None, crs=None, config=None, fmt=None,
                id_field=None, layer=None, progress=None, method="roof",
                primitives=None, check_images=None, block_size=None, workers=1,
                scheduler=None, resume=False, block_progress=None,
                edits=None) -> ReconstructSummary:
    """Read tiles and footprints, reconstruct every building, write ``output``.

    The area is processed block by block: blocks are the cells of a square
    grid of ``block_size`` metres aligned on the CRS's origin (not on the
    tiles), a building belongs to the block holding the centre of its
    footprint's bounding box, and each block reads only the points of its
    buildings plus a margin (their ground ring, the area's ground level within
    50 m, the roof overhang) from the tiles that meet it. Memory is bounded by
    a few tiles, and a building gets the same points, hence the same model,
    however the area is cut into files and in whichever order they are given.
    Without footprints, a block traces the footprints in its cell plus a
    buffer (``margin`` + 100 m) and keeps those centred in its cell.

    The run is a plan (:mod:`lidar2city.tools.blocks`: the ordered block
    specs), one task per block (:func:`lidar2city.tools.task.run_block`), an
    executor (:mod:`lidar2city.tools.engine`) and a writer fed in a fixed order.

    Parameters
    ----------
    inputs : path or sequence of paths
        LAS/LAZ tiles of one area (one CRS): files, folders of tiles or glob
        patterns (:func:`lidar2city.io.tiles.tile_paths`).
    output : path
        ``.city.json``, ``.city.jsonl``, ``.obj`` or ``.gpkg`` (or ``fmt``).
    footprints : path, optional
        Any OGR vector source with building polygons; without it footprints are
        traced from the building points and regularised by the 2-D snake.
    lods : sequence of {"1.2", "1.3", "2.2"}, optional
        LoDs to write; overrides ``[lod1] lods`` of the configuration.
    crs : str, optional
        CRS of the tiles when they carry none (or to override theirs).
    config : path, dict or Lod1Config, optional
        Run configuration (TOML).
    progress : callable, optional
        ``progress(done, total, result)`` for every building as its block
        finishes; ``total`` is None when footprints are traced.
    method : {"roof", "primitives"}
        LoD2.2 from the roof topology (facets, snake, intersection edges) or
        from floating primitives fitted by least squares.
    primitives : path, optional
        With ``method="primitives"``: a CSV / TOML / vector file naming a
        primitive and approximate parameters per footprint id (semi-automatic).
    check_images : path, optional
        With ``method="primitives"``: a folder for one PNG per building, the fitted
        wire frame over its points, for checking by eye.
    block_size : float, optional
        Side (m) of the processing blocks. None (default): with ``footprints``
        on classified points, :data:`BLOCK_SIZE` halved while a block would read
        more than :data:`lidar2city.tools.blocks.BLOCK_POINTS` tile points (the
        output is the same at any size; only what a block holds changes);
        else :data:`BLOCK_SIZE` (traced blocks shape the footprints, a raw
        block is classified on its own).
    workers : int or "auto"
        1 (default): blocks run in this process; N > 1: in this process and
        N - 1 processes forked from it once the run is planned and the tiles the
        workers share are decoded (:class:`lidar2city.tools.forked.ForkExecutor`;
        a Dask ``LocalCluster`` of N worker processes where the system does not
        fork, or with ``LIDAR2CITY_LOCAL_EXECUTOR=dask``). The output is the same bytes.
        ``"auto"`` (the command line's default): one per ~1.5 CPU seconds of
        the run's expected work, at most the usable cores, 1 for a small run or
        where this process cannot safely fork (:func:`auto_workers`). The
        default here stays 1: a library call runs in the caller's process,
        whose threads and children are the caller's; the command line is a
        process of its own.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``) to run the
        blocks on instead; its workers read the tiles and footprints by path.
    resume : bool
        Keep the blocks an interrupted run of the same inputs and options
        recorded in its journal (``OUT.journal``) and run only the others.
    block_progress : callable, optional
        ``block_progress(done, total)`` after every block.
    edits : path, optional
        An ``EDITS.json`` written by ``lidar2city edit`` or the viewer: every
        edit is re-applied to its building inside its block
        (:func:`lidar2city.tools.edit.apply_block_edits`); an edit naming no
        footprint is an error before any block runs. Needs ``footprints``.

    Returns
    -------
    ReconstructSummary

    Raises
    ------
    InputError
        Bad options, a journal of another run beside ``output``, a scheduler
        that does not answer.
    """
    from .engine import make_executor
    from .task import worker_modules

    t0 = time.perf_counter()
    if workers == "auto":
        workers = 1 if scheduler is not None else auto_workers(
            inputs, footprints=footprints, lods=lods, method=method)
    # a cluster starts (its workers import the task modules) while the area is planned;
    # the scratch files of the run (tiles decoded for the workers) go with it
    with make_executor(workers, scheduler, preload=worker_modules(lods, method),
                       client_computes=CLIENT_COMPUTES) as executor, \
            contextlib.ExitStack() as scratch:
        return _reconstruct(executor, t0, inputs, output, footprints=footprints, lods=lods,
                            crs=crs, config=config, fmt=fmt, id_field=id_field, layer=layer,
                            progress=progress, method=method, primitives=primitives,
                            check_images=check_images, block_size=block_size, resume=resume,
                            block_progress=block_progress, edits=edits, scratch=scratch)


#: with ``workers`` N > 1 on a local cluster, this process computes too, beside
#: N - 1 worker processes (:meth:`lidar2city.tools.engine.DaskExecutor._map_shared`):
#: after its planning it would otherwise wait, idle, for the cluster to start
CLIENT_COMPUTES = True


#: expected CPU seconds of one process per input point (tile headers), by what the
#: run builds; measured on the Delft tile (640,510 points, 132 footprints, 1
#: process, session 9): LoD1.2 0.45 s, LoD1.2 + 1.3 1.0 s, LoD2.2 3.6 s
#: (imports excluded), without footprints 11.7 s. The units of :data:`AUTO_LEAST_SECONDS`
#: (on session 15's machine a run takes ~1.4x these, imports excluded: the threshold
#: below was measured in these units)
AUTO_SECONDS_PER_POINT = {"lod1": 1.6e-6, "lod22": 5.5e-6, "traced": 18e-6}

#: the least expected work (CPU seconds of one process, :data:`AUTO_SECONDS_PER_POINT`)
#: per worker for ``workers="auto"`` to run one more, by local executor
#: (:func:`lidar2city.tools.engine.local_executor`). ``"fork"``: the children are
#: forked in ~6 ms (3 CPU ms) from the planned run, but a run on 2 workers costs
#: 12-28 % more CPU (its block cut into parts, each reading and levelling its own
#: points; pages copied on write): at load 5-7 Delft clips of 10 and 30 buildings
#: (expected 1.1 and 1.9 s) end 1.31x and 1.23x later on 2 workers, the whole tile
#: (3.5 s) about as soon and sooner on a quiet machine
#: (``benchmarks/bench_workers_auto.py``); 1.5 s a worker takes 2 workers from 3 s,
#: and never 1 worker per core for a run that would leave each a second or less.
#: ``"dask"`` (no fork on this system, or ``LIDAR2CITY_LOCAL_EXECUTOR=dask``): a
#: ``LocalCluster`` costs ~0.9 s of wall time and ~1.1 CPU-second to start, its 2
#: workers end a run of W seconds in about 0.9 + 0.55 W: a worker must get 3 s
AUTO_LEAST_SECONDS = {"fork": 1.5, "dask": 3.0}


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where known)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


def fork_hazard() -> str | None:
    """Why forking this process now is not safe, or None.

    A forked child has only the thread that forked; a lock another thread held
    at that moment (a library's, a logging handler's) stays held in the child
    for ever. The fork executor knows the native pools of the run's own
    libraries (lazrs, OpenBLAS: :mod:`lidar2city.tools.forked`), not the Python
    threads of whoever called it: a call from another thread than the main one
    (whose signal handlers a run installs and whose Ctrl-C it handles), or while
    any other Python thread is alive (a test runner's, a notebook's, a Dask
    client's left by an earlier run), is not forked by ``workers="auto"``."""
    import threading

    here = threading.current_thread()
    if here is not threading.main_thread():
        return f"called from the thread {here.name!r}, not the main one"
    others = sorted(t.name for t in threading.enumerate() if t is not here and t.is_alive())
    if others:
        return (f"{len(others)} other thread(s) alive ({', '.join(others[:3])}"
                f"{', ...' if len(others) > 3 else ''})")
    return None


def observer() -> str | None:
    """What watches this process from inside (a profiler, a tracer: cProfile, a
    debugger, coverage), or None: its figures would miss the work of other worker
    processes, so ``workers="auto"`` then runs in one."""
    import sys

    if sys.getprofile() is not None:
        return "a profiler is attached"
    if sys.gettrace() is not None:
        return "a tracer (debugger, coverage) is attached"
    return None


def auto_workers(inputs, *, footprints=None, lods=None, method="roof", cores=None,
                 executor=None) -> int:
    """The worker processes of ``workers="auto"``.

    One per :data:`AUTO_LEAST_SECONDS` of the run's expected work in one
    process (the points the tiles' headers declare x :data:`AUTO_SECONDS_PER_POINT`),
    at most the usable cores (``cores``, default :func:`usable_cores`), at least 1.
    ``executor``: the local executor the workers would run on (default
    :func:`lidar2city.tools.engine.local_executor`): for ``"fork"``, 1 when
    forking here is not safe (:func:`fork_hazard`). 1 as well under a profiler
    or tracer (:func:`observer`: ``python -m cProfile``'s figures would miss the
    workers). Only the headers needed to reach the most workers the cores allow
    are opened.

    The machine's load is not looked at. With no cluster to start, 2 forked
    workers cost 12-17 % more CPU on Delft and end it in 0.68-0.99x the wall
    time of one process beside 0, 1, 2 or 4 busy loops of the same session
    (``benchmarks/bench_workers_auto.py --busy``), but in 0.71-1.28x (speed-ups
    0.78-1.41) when other sessions load the machine (the scheduler shares the
    cores between sessions first: a second worker gets little more). A load
    rule would have to tell those apart; and without one the same command
    always runs on the same number of workers, so that ``--resume`` finds the
    plan (the blocks cut for that many) its journal was made with. A 1-minute
    load average, as before, also counted the command's own previous run when
    commands run back to back."""
    from ..io.las import count_points
    from ..io.tiles import tile_paths

    cores = usable_cores() if cores is None else int(cores)
    if cores < 2:
        logger.info("--workers auto: 1 (1 usable core)")
        return 1
    watched = observer()
    if watched is not None:
        logger.info("--workers auto: 1 (%s)", watched)
        return 1
    if executor is None:
        from .engine import local_executor

        executor = local_executor()
    if executor == "fork":
        hazard = fork_hazard()
        if hazard is not None:
            logger.info("--workers auto: 1 (no fork: %s)", hazard)
            return 1
    kind = ("traced" if footprints is None
            else "lod22" if "2.2" in (lods or ()) else "lod1")
    rate = AUTO_SECONDS_PER_POINT[kind]
    least = AUTO_LEAST_SECONDS[executor]
    per_worker = int(np.ceil(least / rate))
    points = count_points(tile_paths(inputs), at_least=per_worker * cores)
    workers = max(1, min(cores, points // per_worker))
    logger.info("--workers auto: %d (%d points, ~%.1f CPU s expected in one process, %.1f s "
                "a worker at least; %d cores, %s)", workers, points, points * rate, least,
                cores, executor)
    return workers


def _reconstruct(executor, t0, inputs, output, *, footprints, lods, crs, config, fmt, id_field,
                 layer, progress, method, primitives, check_images, block_size, resume,
                 block_progress, edits, scratch=None) -> ReconstructSummary:
    """:func:`reconstruct` on a started ``executor``; ``scratch``: an ExitStack
    that removes the run's scratch files (None: the run makes none)."""
    from ..io.journal import Journal, file_stamp, run_key
    from ..io.tiles import tile_paths

    paths = tile_paths(inputs)
    inputs = paths
    # an external cluster's workers are counted once it answers
    workers = executor.workers or executor.ready().workers
    plan = plan_reconstruct(inputs, output, footprints=footprints, lods=lods, crs=crs,
                            config=config, fmt=fmt, id_field=id_field, layer=layer, method=method,
                            primitives=primitives, check_images=check_images,
                            block_size=block_size, edits=edits, workers=workers)
    from .task import give_back_memory

    give_back_memory()  # what the planning freed (it reads every header), before the blocks
    if executor.local_workers and scratch is not None:
        # the tiles every worker would decode first: decoded once, here, while the
        # cluster starts (the decoding leaves the interpreter lock to its start)
        shared = shared_tiles(plan)
        if shared:
            from .task import predecode

            plan = dataclasses.replace(plan, options=dataclasses.replace(
                plan.options, decoded=predecode(shared, scratch)))
            give_back_memory()  # the decoding's arrays: the client holds no point
    elif getattr(executor, "inherits", False) and scratch is not None:
        # the workers will be forked from this process: the tiles they share are
        # decoded once, here, and inherited (:class:`~lidar2city.tools.forked.ForkExecutor`)
        shared = shared_tiles(plan)
        if shared:
            from .task import hold_tiles

            hold_tiles(shared, scratch)
    first = {}
    if plan.trace_first:  # traced blocks too few for the workers: traced first, built in parts
        plan = trace_then_split(executor, plan, first)
    key = run_key({
        "version": _version(), "inputs": [file_stamp(p) for p in paths],
        "footprints": None if footprints is None else file_stamp(footprints),
        "primitives": None if primitives is None else file_stamp(primitives),
        # the edits' content: a run resumed with other edits is refused
        "edits": [e.to_dict() for e in plan.options.edits],
        "options": [plan.fmt, plan.lods, plan.resolved, crs, id_field, layer, method,
                    plan.options.block_size,
                    None if check_images is None else str(check_images)],
        # blocks cut into parts for several workers: the journal's blocks are those parts
        **({} if plan.split is None else {"split": plan.split}),
        **({"traced_parts": True} if plan.parts else {})})
    journal = Journal.open(output, key, len(plan.specs), resume=resume)
    n_blocks = len(plan.specs)
    state, cpu = {"blocks": 0, "buildings": 0, "mb": first.get("mb", 0.0)}, first.get("cpu", {})
    ordered, sink = InOrder(plan), _sink(output, plan)
    tally = _Tally(output, plan)

    def take(out):
        state["blocks"] += 1
        state["mb"] = max(state["mb"], out.worker_mb)
        if out.worker:  # not a block failed twice, nor one taken from the journal
            cpu[out.worker] = cpu.get(out.worker, 0.0) + out.cpu
        for r in out.results:
            state["buildings"] += 1
            if progress is not None:
                progress(state["buildings"], plan.total, r)
        if block_progress is not None:
            block_progress(state["blocks"], n_blocks)
        for r, fields, encoded in ordered.add(out):
            tally.add(r)
            sink.add(r, fields, encoded)

    try:
        done = set()
        for i in journal.done():
            out = journal.load(i) if i < n_blocks else None
            if out is not None:
                done.add(i)
                out.worker = ""  # its CPU belongs to the run that made it
                take(out)
        if done:
            logger.info("resuming: %d of %d blocks already done", len(done), n_blocks)
        pending = [s for s in plan.specs if s.index not in done]
        if pending:
            logger.info("%d blocks on %s", len(pending), executor.describe())
            for k, out in enumerate(run_blocks(executor, plan, pending), start=1):
                # a failed block is tried again by --resume; the last one to finish
                # is not saved (nothing runs after it: no block would be spared)
                if not out.failed and k < len(pending):
                    journal.save(out.index, out)
                take(out)
            state["startup"], state["process_cpu"] = (executor.startup_seconds,
                                                      executor.process_cpu())
        try:
            ordered.check()
        except InputError:  # every block ran: a --resume could only fail the same way
            journal.remove()
            raise
        sink.close()
    except BaseException:
        sink.abort()
        if not journal.done():  # nothing to resume: leave nothing behind
            journal.remove()
        raise
    finally:
        ordered.close()
    journal.remove()
    summary = tally.summary
    summary.blocks, summary.resumed = n_blocks, n_blocks - len(pending)
    summary.worker_peak_mb = state["mb"]
    summary.worker_cpu = dict(sorted(cpu.items()))
    summary.startup_seconds = state.get("startup", 0.0)
    summary.process_cpu = state.get("process_cpu", {})
    summary.seconds = time.perf_counter() - t0
    return summary


class InOrder:
    """Block outputs in (any order), ``(result, footprint fields, encoded or None)`` out in
    the output's order (``encoded``: the block's text of the result, see
    :func:`lidar2city.tools.task.encode_block`).

    With footprints the order is the footprint file's (each footprint carries
    its position in ``_index``); traced footprints come block by block and are
    numbered ``b1``, ``b2``... (traced by a first pass and built in parts,
    :attr:`ReconstructPlan.parts`, they carry their positions in ``_index``
    too). Results are released as soon as all those before them are known,
    so a run whose footprints are in spatial order holds few of them.
    """

    def __init__(self, plan):
        self.plan = plan
        self.pending = {}
        self.next = 0
        self.numbered = 0
        self.points = plan.points
        # outputs in blocks (traced in the block), or footprint by footprint
        self.by_block = plan.traced and not plan.parts
        # encoded results waiting for those before them: on disk (their number grows
        # with the area when the footprint file is not in spatial order)
        self.spilled = None

    def add(self, out) -> list:
        """The results that ``out`` makes ready, in order."""
        self.points |= out.points
        fps = out.footprints
        keys = sorted(k for k in fps.attributes if not k.startswith("_"))
        encoded = out.encoded or [None] * len(out.results)
        items = [(r, {k: fps.attributes[k][j] for k in keys}, encoded[j])
                 for j, r in enumerate(out.results)]
        if self.by_block:
            self.pending[out.index] = items
        else:
            self.pending.update(zip(fps.attributes["_index"], items, strict=True))
        ready = []
        spilled = self.spilled
        while True:
            if self.next in self.pending:
                got = self.pending.pop(self.next)
            elif spilled is not None and self.next in spilled:
                got = spilled.pop(self.next)
            else:
                break
            ready += got if self.by_block else [got]
            self.next += 1
        if out.encoded is not None and self.pending and not self.by_block:
            # this block's results that wait: their text (and light results) to disk
            if spilled is None:
                from ..io.spill import SpillFile

                spilled = self.spilled = SpillFile()
            for key in list(self.pending):
                spilled.put(key, self.pending.pop(key))
        for r, _, _ in ready:
            if self.plan.traced:
                self.numbered += 1
                r.id = f"b{self.numbered}"
                if "footprint_id" in r.attributes:
                    r.attributes["footprint_id"] = r.id
            for lod in [k for k in r.solids if k not in self.plan.lods]:
                del r.solids[lod]  # LoD1 built only as the base of LoD2.2 is not written
        return ready

    def check(self) -> None:
        """Raise when the run found no building point at all (traced: no footprint)."""
        if not self.points or (self.plan.traced and not self.numbered):
            from ..io.las import check_header_bounds

            # blocks are planned on the headers' bounds: a wrong one hides its points
            check_header_bounds({t.path: t for s in self.plan.specs for t in s.tiles}.values())
            raise EmptyInputError("no building point found in the input, even after "
                                  "classification" if not self.plan.traced
                                  else "no building footprint found in the points")
        left = len(self.pending) + (len(self.spilled) if self.spilled is not None else 0)
        if left:  # pragma: no cover - every block is given once
            raise RuntimeError(f"{left} results left out of order")

    def close(self) -> None:
        """Remove the scratch file of the results that waited, if any."""
        if self.spilled is not None:
            self.spilled.close()


class _Collect:
    """A sink keeping every result, written at the end by :func:`write_buildings`."""

    def __init__(self, output, plan):
        self.output, self.plan = output, plan
        self.results, self.fields = [], []

    def add(self, result, fields, encoded=None):
        self.results.append(result)
        self.fields.append(fields)

    def close(self):
        keys = sorted(set().union(*self.fields)) if self.fields else []
        attributes = {k: [f.get(k) for f in self.fields] for k in keys}
        write_buildings(self.output, self.results, self.plan.frame, fmt=self.plan.fmt,
                        configuration=self.plan.resolved, attributes=attributes,
                        lods=self.plan.lods)

    def abort(self):
        self.results, self.fields = [], []


class _Stream:
    """A sink writing CityJSONSeq features as they come (nothing kept)."""

    def __init__(self, output, plan):
        from ..io.cityjsonseq import CityJSONSeqWriter

        f = plan.frame
        self.writer = CityJSONSeqWriter(output, origin=f.origin, crs=f.crs, xy_unit=f.xy_unit,
                                        z_unit=f.z_unit, scale=SEQ_SCALE,
                                        configuration=plan.resolved, title=_title(plan.lods))

    def add(self, result, fields, encoded=None):
        if encoded is not None:  # made in the block, with this writer's scale and units
            self.writer.add_encoded(*encoded)
        else:
            self.writer.add(_without_run_attributes(result), fields)

    def close(self):
        self.writer.close()

    def abort(self):
        self.writer.abort()


#: the quantisation step of a streamed CityJSONSeq output (CRS units)
SEQ_SCALE = 0.001


def _sink(output, plan):
    return (_Stream if plan.fmt == "cityjsonseq" else _Collect)(output, plan)


class _Tally:
    """The run's :class:`ReconstructSummary`, counted result by result."""

    def __init__(self, output, plan):
        self.summary = ReconstructSummary(str(output), lods=plan.lods, format=plan.fmt)
        self.lod22 = "2.2" in plan.lods
        self.times, self.modelled, self.fallbacks, self.type_iv = [], 0, 0, 0
        if self.lod22:
            self.summary.lod22 = {"modelled": 0, "fallbacks": 0, "type_iv": 0,
                                  "time_per_building": 0.0}

    def add(self, r):
        s = self.summary
        s.total += 1
        if r.attributes.get("low_coverage"):
            logger.warning("footprint %r: %s: LoD1.2 prism only", r.id,
                           r.attributes["low_coverage"])
        if r.ok:
            s.done += 1
            if r.attributes.get("valid") is False:
                s.invalid += 1
        else:
            s.failed += 1
            s.reasons[_reason_kind(r.reason)] += 1
        if self.lod22 and r.ok and "2.2" in r.solids:
            fallback = "lod22_fallback" in r.attributes
            self.modelled += not fallback
            self.fallbacks += fallback
            self.type_iv += r.attributes.get("type_iv", 0) > 0
            if "lod22_time" in r.attributes:
                self.times.append(r.attributes["lod22_time"])
            s.lod22 = {"modelled": self.modelled, "fallbacks": self.fallbacks,
                       "type_iv": self.type_iv,
                       "time_per_building": float(np.mean(self.times)) if self.times else 0.0}


def _version():
    from .. import __version__

    return __version__


def _check_area(reader) -> None:
    """Raise :class:`EmptyInputError` when the tiles' points cover no area.

    One point, or points on a line, hold no building: say so before any
    footprint is matched against the extent (which would blame the CRSs).
    """
    wb = reader.world_bounds()
    size = (wb[2:] - wb[:2]) * reader.xy_unit
    if not (size > 0).all():
        raise EmptyInputError(f"the input's {reader.count} point(s) cover {size[0]:.1f} m x "
                              f"{size[1]:.1f} m: no area to reconstruct buildings in")


@dataclass(eq=False)
class ReconstructPlan:
    """A planned run: the ordered block specs, the options every block gets, the output's frame."""

    specs: list
    options: object
    frame: object
    fmt: str
    lods: tuple
    resolved: dict
    traced: bool
    total: int | None
    #: the most footprints of a block part (blocks cut for several workers), or None;
    #: ``(split, workers)`` when blocks where the workers' shares meet were cut too
    #: (:func:`lidar2city.tools.blocks.meet_blocks`)
    split: int | tuple | None = None
    #: traced blocks are too few for the workers: trace them first, then build
    #: their buildings in parts (:func:`trace_then_split`)
    trace_first: bool = False
    #: the specs are parts of traced blocks, their footprints carried inline
    parts: bool = False
    #: a first pass found building points
    points: bool = False
    #: what a building reads around its footprint's box (m)
    margin: float = 0.0


def plan_reconstruct(inputs, output, *, footprints=None, lods=None, crs=None, config=None,
                     fmt=None, id_field=None, layer=None, method="roof", primitives=None,
                     check_images=None, block_size=None, edits=None,
                     workers: int = 1) -> ReconstructPlan:
    """Check the options, index the tiles and cut the area into block specs (no point read).

    Keywords as :func:`reconstruct`; ``workers``: the processes that will run
    the blocks. With several, a block holding more footprints than an even
    share of the executor's runs (:func:`lidar2city.tools.blocks.split_size`)
    is cut into parts of its footprints when its buildings allow it
    (:func:`lidar2city.tools.task.splittable`): a single large tile is then
    shared by the workers, with the same results. So is a whole block where
    the workers' contiguous shares of blocks meet (:func:`lidar2city.tools.blocks.meet_blocks`),
    into small parts: the side that ends its share first takes those, not a
    whole block, from the other's.
    """
    from ..io.las import TileReader, check_header_bounds, scan_tiles
    from .blocks import (BLOCK_POINTS, FootprintRef, Frame, footprint_block_size,
                         footprint_blocks, split_size, traced_blocks)
    from .engine import RUNS_PER_WORKER
    from .task import BlockOptions, splittable

    fmt = format_from_name(output, fmt)
    if method not in LOD22_METHODS:
        raise InputError(f"method must be one of {', '.join(LOD22_METHODS)}, got {method!r}")
    if primitives is not None or check_images is not None:
        if not ("2.2" in (lods or ()) and method == "primitives"):
            raise InputError("--primitives and --check-images go with --method primitives --lod 2.2")
    if block_size is not None and not block_size > 0:
        raise InputError(f"block_size must be positive, got {block_size}")
    if edits is not None and footprints is None:
        # traced footprints are numbered when the run is assembled, after the
        # blocks ran: an edit's building id cannot be found inside a block
        raise InputError("--edits needs --footprints (the footprints the edited model was "
                         "made from)")
    want22 = "2.2" in (lods or ())
    cfg, resolved, others = lod1_config(
        config, lods=lods, stages=(("lod22" if method == "roof" else "primitives"),) if want22 else ())
    want = tuple(lods) if lods else cfg.lods
    lod22 = others.get("lod22") if want22 and method == "roof" else None
    tiles = scan_tiles(inputs, crs=crs)
    if crs is None and footprints is not None and tiles[0].crs is None:
        # tiles without a CRS (AHN): the footprints' CRS is the best guess, so that
        # the output still carries one (a wrong guess shows as footprints off the tile)
        from ..io.vector import vector_crs

        fp_crs = vector_crs(footprints, layer=layer)
        if fp_crs is not None and (fp_crs.is_geographic or fp_crs.is_compound
                                   and fp_crs.sub_crs_list[0].is_geographic):
            # points in degrees cannot be modelled: the tiles' CRS is another one
            raise CRSError(f"the input has no CRS and its footprints' ({fp_crs.name}) is "
                           "geographic: pass --crs EPSG:xxxx, the tiles' CRS (the footprints "
                           "are reprojected onto it)")
        if fp_crs is not None:
            logger.warning("the input has no CRS: taking the footprints' (%s; pass --crs "
                           "EPSG:xxxx to choose one)", fp_crs.name)
            # the counts were checked by the first scan: not decoded again
            tiles = scan_tiles(inputs, crs=fp_crs, check_count=False)
    reader = TileReader(tiles)
    _check_area(reader)
    # classified input (some building points anywhere) or raw: decided once for
    # the run, so that every block is treated alike whatever it holds
    classified, grounded = reader.classes_found([cfg.building_classes, cfg.ground_classes])
    if not classified:
        logger.info("no building class in the input: every block is ground-filtered and classified")
    no_ground = classified and not grounded
    if no_ground:
        logger.warning("the input has building points but no ground class (%s): the ground is "
                       "filtered from the other points, if any",
                       ", ".join(str(c) for c in cfg.ground_classes))
    if reader.crs is None:
        logger.warning("the input has no CRS: the output will have no reference system "
                       "(pass --crs EPSG:xxxx)")
    frame = Frame.of(reader)
    user_prims = None
    if want22 and method == "primitives" and primitives is not None:
        from ..io.primitives import read_primitives

        user_prims = read_primitives(primitives)
        from ..fit.primitives import PRIMITIVES

        for fid, spec in user_prims.items():  # checked before any block runs
            if spec.get("primitive") not in PRIMITIVES:
                raise InputError(f"{primitives}: footprint {fid}: unknown primitive "
                                 f"{spec.get('primitive')!r}; known: {', '.join(PRIMITIVES)}")
    options = BlockOptions(cfg, classified, float(block_size or BLOCK_SIZE), lod22=lod22,
                           primitives=others.get("primitives") if want22 and method == "primitives"
                           else None,
                           user_primitives=user_prims,
                           check_images=None if check_images is None else str(check_images),
                           footprints_config=others.get("footprints"), ground_filter=no_ground,
                           # given footprints streamed: each block encodes its buildings
                           encode=({"lods": want, "scale": SEQ_SCALE, "xy_unit": frame.xy_unit,
                                    "z_unit": frame.z_unit}
                                   if fmt == "cityjsonseq" and footprints is not None else None),
                           **_edit_options(edits, cfg, lod22, others, want, method))
    # what a building needs around its footprint: its ground ring, the area's
    # ground level (50 m) and the roof's overhang
    margin = max(cfg.search_radius, 50.0) + (lod22.overhang if lod22 is not None else 0.0)
    split, first = None, False
    if footprints is None:
        logger.info("no footprints given: tracing them from the building points")
        specs = traced_blocks(tiles, frame, reader.world_bounds(), options.block_size,
                              margin + 100.0)
        # fewer blocks than the executor's runs: each is traced first, and its
        # buildings built in parts by all the workers (the same results)
        first = (int(workers or 1) > 1 and splittable(options)
                 and len(specs) < RUNS_PER_WORKER * int(workers))
    else:
        wb = reader.world_bounds()
        lo = (wb[:2] - reader.origin[:2]) * reader.xy_unit
        hi = (wb[2:] - reader.origin[:2]) * reader.xy_unit
        try:
            fids, ids, bounds = index_footprints(footprints, frame, id_field=id_field,
                                                 layer=layer, extent=(*lo, *hi))
        except EmptyInputError:
            check_header_bounds(tiles)  # the extent is the headers': are they right?
            raise

        def ref(idx):
            return FootprintRef(str(footprints), layer, id_field, tuple(fids[i] for i in idx),
                                tuple(ids[i] for i in idx), tuple(idx))

        # one process runs the blocks whole: the same plan as ever
        split = (split_size(len(fids), RUNS_PER_WORKER * int(workers))
                 if int(workers or 1) > 1 and splittable(options) else None)
        if block_size is None and splittable(options):
            # as large as the points a block should hold allow; only where a building's
            # model does not depend on its block (classified points: no block classifies
            # or filters its ground on its own), so the output is the same bytes
            size = footprint_block_size(tiles, frame, bounds, margin, BLOCK_SIZE)
            if size != BLOCK_SIZE:
                logger.info("blocks of %g m (%d points by the tile headers; at most ~%d a "
                            "block)", size, reader.count, BLOCK_POINTS)
            options = dataclasses.replace(options, block_size=size)
        # blocks where the workers' shares meet cut too (small parts at the end)
        meet = int(workers or 1) if split is not None else None
        specs = footprint_blocks(tiles, frame, bounds, options.block_size, margin, ref,
                                 split=split, meet=meet)
        if len({spec.cell for spec in specs}) == len(specs):
            split = None  # no block was cut: the plan of one process
        else:
            held = Counter()
            for spec in specs:
                held[spec.cell] += spec.size
            parts = Counter(spec.cell for spec in specs)
            if any(parts[c] > 1 and n <= split for c, n in held.items()):
                # a block cut where shares meet: the blocks cut depend on both
                split = (split, meet)  # (the journal's key)
        if options.edits:  # an unknown building id: an error before any block runs
            from .edit import check_edit_ids

            check_edit_ids(options.edits, ids, source=str(edits))
    return ReconstructPlan(specs, options, frame, fmt, want, resolved, footprints is None,
                           None if footprints is None else sum(s.size for s in specs), split,
                           trace_first=first, margin=margin)


#: parts of a traced block per executor run (:func:`trace_then_split`): parts of
#: about equal expected work (a building's work taken to grow with its area),
#: handed heaviest first to the free worker. On Delft (2 workers, 3 rounds at
#: load ~2) 1 gave 8 parts and 8.5-10.2 s, 2 gave 10 parts and 8.7-10.8 s, 3
#: 8.9-9.4 s: each part reads and sorts its box again, the dynamic hand-out
#: already evens the workers out
PARTS_PER_RUN = 1


def trace_then_split(executor, plan, first=None) -> ReconstructPlan:
    """The plan of a traced run whose blocks are traced first on ``executor``
    (:func:`lidar2city.tools.task.trace_outlines`: a block of many outlines has
    them regularised in pieces by all the workers, :func:`_regularise_staged`,
    the same footprints as :func:`lidar2city.tools.task.trace_footprints`
    gives in one pass), then cut into parts of
    their footprints of about equal expected work (the footprints' areas,
    :data:`PARTS_PER_RUN` parts per executor run,
    :func:`lidar2city.tools.blocks.traced_parts`) that the workers share,
    heaviest first, each handed to whichever worker is free (``balance``).

    A part builds its footprints from the points of their boxes plus the
    margin inside the block's box, with the block's classes (the input's: the
    plan is :func:`~lidar2city.tools.task.splittable`), nothing claimed, ids
    and fields as the block gives them: the same results, in the same order,
    as the block building them itself. ``first`` (a dict) gets the first
    pass's ``cpu`` per worker and peak ``mb``.
    """
    import dataclasses

    from .blocks import SPLIT_LEAST, split_size, traced_parts
    from .engine import RUNS_PER_WORKER
    from .task import tile_keeper, trace_outlines

    traced, points = [None] * len(plan.specs), False
    cpu, mb, staged = {}, [0.0], {}

    def note(out):
        mb[0] = max(mb[0], out.worker_mb)
        cpu[out.worker] = cpu.get(out.worker, 0.0) + out.cpu

    # the blocks' outlines; a block with many has them regularised by all the workers
    for i, out in executor.map(trace_outlines, plan.specs, plan.options, run_hook=tile_keeper):
        if isinstance(out, BaseException):
            _failed_block(plan.specs[i], out)  # logged: no footprint traced there
            continue
        points = points or out.points
        note(out)
        if out.staged is not None:
            staged[i] = out.staged
        else:
            traced[i] = out.footprints
    for i, fps in _regularise_staged(executor, plan, staged, note):
        traced[i] = fps
    if first is not None:
        first.update(cpu=cpu, mb=mb[0])
    total = sum(len(f) for f in traced if f is not None)
    # a building's work grows with its points, hence its area: parts of equal
    # areas, their work counted in buildings (the executor's runs of equal work)
    areas = [np.array([g.area for g in f.geometries], dtype=np.float64) if f else None
             for f in traced]
    whole = sum(float(a.sum()) for a in areas if a is not None)
    scale = total / whole if whole > 0 else 0.0
    runs = RUNS_PER_WORKER * int(executor.workers or 1)
    split = split_size(total, runs)
    specs, position = [], 0
    for spec, fps, area in zip(plan.specs, traced, areas, strict=True):
        if not fps:
            continue
        bounds = np.array([g.bounds for g in fps.geometries], dtype=np.float64).reshape(-1, 4)

        def inline(idx, fps=fps, at=position):
            part = _subset(fps, idx)
            part.attributes["_index"] = [at + i for i in idx]
            return part

        # + 1 m: every box a building queries lies a metre inside its part's box
        specs += traced_parts(spec, bounds, plan.margin + 1.0, area * scale,
                              max(total / (PARTS_PER_RUN * runs), float(SPLIT_LEAST)), inline, len(specs))
        position += len(fps)
    # heaviest first: handed out one by one to the free worker, they end about together
    heavy = sorted(specs, key=lambda s: (-s.work, s.index))
    specs = [dataclasses.replace(s, index=k) for k, s in enumerate(heavy)]
    logger.info("%d traced footprints in %d parts", total, len(specs))
    return dataclasses.replace(plan, specs=specs, trace_first=False, parts=True, points=points,
                               split=split)


#: pieces of the traced blocks' outlines per executor run (:func:`_regularise_staged`):
#: the pieces are of about equal expected work, handed out heaviest outlines first
#: to whichever worker is free; more, smaller pieces end the workers closer together
OUTLINE_PIECES = 2


def _regularise_staged(executor, plan, staged, note):
    """``(block position, its footprints or None)`` of the traced blocks ``staged``
    (position -> :class:`~lidar2city.tools.task.TracedStage`), their outlines
    regularised in pieces by all the workers of ``executor``
    (:func:`lidar2city.tools.task.regularise_parts`), then made disjoint, kept
    and numbered as one pass makes them (:func:`lidar2city.tools.task.staged_footprints`):
    the same footprints. A block with a piece that failed twice gets no footprint,
    the failure logged (as a block whose tracing failed). ``note(out)`` is called
    with each piece's output (its process's CPU and memory)."""
    if not staged:
        return
    from .engine import RUNS_PER_WORKER
    from .task import outline_parts, regularise_parts, staged_footprints

    items = outline_parts(staged, OUTLINE_PIECES * RUNS_PER_WORKER * int(executor.workers or 1))
    logger.info("%d traced outlines of %d block(s) regularised in %d pieces",
                sum(len(st.outlines) for st in staged.values()), len(staged), len(items))
    found = {b: [None] * len(st.outlines) for b, st in staged.items()}
    failed = {}
    for j, out in executor.map(regularise_parts, items, costs=[it.work for it in items],
                               balance=True):
        item = items[j]
        if isinstance(out, BaseException):
            failed.setdefault(item.block, out)
            continue
        note(out)
        for k, f in zip(item.parts, out.footprints, strict=True):
            found[item.block][k] = f
    for b, st in sorted(staged.items()):
        fps = None
        if b not in failed:
            try:
                fps = staged_footprints(plan.specs[b], plan.options, st, found[b])
            except Exception as exc:  # noqa: BLE001 - as a block whose tracing failed
                failed[b] = exc
        if b in failed:
            _failed_block(plan.specs[b], failed[b])  # logged: no footprint traced there
        yield b, fps


def shared_tiles(plan) -> list:
    """The tiles the first tasks of several workers read, worth decoding once for all
    (:func:`lidar2city.tools.task.predecode`): those of the blocks cut into parts
    (:attr:`ReconstructPlan.split`; the parts of a block are dealt to all the
    workers, and a tile under the block is read by each of them) or traced first
    (:attr:`ReconstructPlan.trace_first`: the block traced by one worker, then
    built in parts by all); none for a plan of whole blocks, whose workers read
    tiles of their own."""
    if plan.trace_first:
        specs = plan.specs
    elif plan.split is not None:
        cells = Counter(s.cell for s in plan.specs)
        specs = [s for s in plan.specs if cells[s.cell] > 1]
        if len(specs) < len(plan.specs):
            # also whole blocks: the parts are those of blocks where the workers'
            # shares meet (:func:`lidar2city.tools.blocks.meet_blocks`), reached by
            # each side late in the run; decoding them here would hold the fork back
            return []
    else:
        return []
    return [t for s in specs for t in s.tiles]


def _edit_options(edits, cfg, lod22, others, lods, method) -> dict:
    """The :class:`~lidar2city.tools.task.BlockOptions` fields of an ``EDITS.json``
    (its parsed edits travel to the blocks, not its path)."""
    if edits is None:
        return {}
    from .edit import EditContext, load_edits

    return {"edits": tuple(load_edits(edits)),
            "edit_context": EditContext(cfg, lod22, others.get("primitives"), lods, method)}


def run_blocks(executor, plan, specs=None):
    """Run ``specs`` (default all of the plan's) on ``executor``; yield each
    :class:`~lidar2city.tools.task.BlockOutput` as it finishes (any order).

    A block that failed twice gives each of its footprints a stated reason.
    """
    from . import task

    specs = plan.specs if specs is None else specs
    # runs of equal numbers of buildings (traced blocks: of equal numbers of blocks)
    costs = [s.work for s in specs]
    for i, out in executor.map(task.run_block, specs, plan.options, run_hook=task.tile_keeper,
                               costs=costs, **({"balance": True} if dealt_one_by_one(plan, specs)
                                               else {})):
        yield _failed_block(specs[i], out) if isinstance(out, BaseException) else out


def dealt_one_by_one(plan, specs) -> bool:
    """Whether the blocks ``specs`` of ``plan`` are handed out one by one, in order, to
    whichever worker is free (the executors' ``balance``), rather than in runs of
    neighbouring blocks dealt in shares: when every one is a part of a block cut
    for the workers (traced parts, :attr:`ReconstructPlan.parts`, or parts of given
    footprints, :attr:`ReconstructPlan.split`), whose tiles every worker holds
    already (:func:`shared_tiles`), so that no run has tiles of its own to pass on.
    Parts of given footprints come largest first (:data:`lidar2city.tools.blocks.RAMP`):
    the last ones, the smallest, even out the workers' ends; traced parts are
    handed out heaviest first (:func:`trace_then_split`)."""
    if plan.parts:
        return True
    if plan.split is None or not specs:
        return False
    cells = Counter(s.cell for s in plan.specs)
    return all(cells[s.cell] > 1 for s in specs)


def _failed_block(spec, exc):
    from ..datamodel import Footprints
    from .task import BlockOutput

    fps = Footprints([], [])
    if spec.footprints is not None:
        from .task import block_footprints

        try:  # the block's fields for its stated reasons
            fps = block_footprints(spec)
        except Exception:  # noqa: BLE001 - the reason is stated without them
            ref = spec.footprints
            fps = Footprints([None] * len(ref), list(ref.ids), {"_index": list(ref.positions)})
    msg = str(exc).splitlines()[0] if str(exc) else ""
    reason = f"block failed twice: {type(exc).__name__}{': ' + msg if msg else ''}"
    if spec.footprints is None:
        logger.error("block %d (cell %s): %s; no footprint traced there", spec.index,
                     spec.cell, reason)
    return BlockOutput(spec.index, [_unmodelled(fid, reason) for fid in fps.ids], fps, True,
                       failed=True)


def _unmodelled(fid, reason):
    from ..datamodel import BuildingResult

    return BuildingResult(str(fid), status="failed", reason=reason)


def _concat_footprints(parts):
    from ..datamodel import Footprints

    geoms = [g for p in parts for g in p.geometries]
    ids = [i for p in parts for i in p.ids]
    keys = sorted(set().union(*(p.attributes for p in parts))) if parts else []
    attrs = {k: [v for p in parts for v in p.attributes.get(k, [None] * len(p))] for k in keys}
    return Footprints(geoms, ids, attrs)


def _subset(fps, idx):
    from ..datamodel import Footprints

    return Footprints([fps.geometries[i] for i in idx], [fps.ids[i] for i in idx],
                      {k: [v[i] for i in idx] for k, v in fps.attributes.items()})


def _reason_kind(reason: str) -> str:
    """A reason without its numbers, to count failures by kind."""
    import re

    return re.sub(r"-?\d+(\.\d+)?", "N", reason)

