"""LoD1.2 and LoD1.3 buildings from a footprint and the points around it.

:func:`reconstruct_building` is pure and independent per building (a batch
maps it over footprints in any order, on any worker): it sees only the
building points and ground points near its footprint, and never raises for a
bad building: the result's ``status`` is ``"failed"`` with a ``reason``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass

import numpy as np

from ..config import field
from ..datamodel import BuildingResult
from ..errors import ConfigError, InputError
from .coverage import reach_coverage
from .heights import ROOF_STATISTICS, ground_height, roof_height
from .lod13 import height_parts
from .prism import (_layout_distance, _layout_inside_distance, _layout_is_valid, _prism_solid,
                    _ring_contact, _separate_rings, clean_polygon)

logger = logging.getLogger(__name__)

__all__ = ["COVERAGE_REACH", "FEWEST_POINTS", "MIN_COVERAGE", "MIN_WALL_HEIGHT", "Lod1Config",
           "LOD13_MAX_CELLS", "LODS", "lod13_cell", "points_needed", "reconstruct_building"]

#: LoDs this module builds.
LODS = ("1.2", "1.3")


@dataclass(frozen=True)
class Lod1Config:
    """Configuration of the ``[lod1]`` stage (LoD1.2 / LoD1.3 prisms)."""

    lods: tuple = field(("1.2",), "LoDs to build: \"1.2\" (one prism) and/or \"1.3\" "
                        "(one prism per roof-height part).")
    roof_statistic: float | str = field(
        70.0, "Roof height: percentile (0-100) of the building points inside the footprint "
        "(3DBAG: 70), or \"mean\" (minimises the vertical RMSE), \"median\", \"max\".")
    ground_percentile: float = field(10.0, "Ground height: percentile of the ground points "
                                     "around the footprint.")
    ground_ring: float = field(3.0, "Width (m) of the ring around the footprint where ground "
                               "points are taken.")
    ground_wide_ring: float = field(10.0, "Wider ring (m) used when the first holds too few "
                                    "ground points.")
    min_ground_points: int = field(3, "Ground points needed in a ring to use it.")
    min_points: int = field(10, "Building points needed inside a footprint where the survey "
                            "is dense enough (see min_area).")
    min_area: float = field(2.0, "Roof area (m2) whose points a footprint needs at the survey's "
                            "measured density around it: on a sparse survey fewer than "
                            "min_points are enough (never fewer than 3).")
    min_height: float = field(0.5, "Smallest roof height above ground (m) for a model.")
    lod13_cell: float = field(0.5, "Raster cell (m) of the LoD1.3 height regions.")
    lod13_step: float = field(2.0, "Height difference (m) between the heights of neighbouring "
                              "roof surfaces at or above which they are separate LoD1.3 parts.")
    lod13_min_area: float = field(5.0, "LoD1.3 parts smaller than this (m2) join a neighbour.")
    coverage_cell: float = field(1.0, "Cell (m) for the share of the footprint without points.")
    precision: float = field(0.001, "Vertex grid (m): footprints are snapped to it so the "
                             "written (quantised) model is the validated one.")
    building_classes: tuple = field((6,), "Point classes that are building points.")
    ground_classes: tuple = field((2,), "Point classes that are ground points.")
    validate: bool = field(True, "Check every solid (closed, planar, oriented...) and record "
                           "the result per building.")

    def __post_init__(self):
        lods = tuple(str(v) for v in self.lods)
        bad = [v for v in lods if v not in LODS]
        if bad or not lods:
            raise ConfigError(f"lod1.lods: {bad or lods!r}; allowed: {', '.join(LODS)}")
        object.__setattr__(self, "lods", lods)
        s = self.roof_statistic
        if isinstance(s, str):
            if s not in ROOF_STATISTICS:
                raise ConfigError(f"lod1.roof_statistic: {s!r}; use a percentile 0-100 or one of "
                                  f"{', '.join(ROOF_STATISTICS)}")
        elif isinstance(s, bool) or not 0 <= float(s) <= 100:
            raise ConfigError(f"lod1.roof_statistic: {s!r} is not a percentile in [0, 100]")
        if not 0 <= self.ground_percentile <= 100:
            raise ConfigError(f"lod1.ground_percentile: {self.ground_percentile} not in [0, 100]")
        for name in ("lod13_cell", "coverage_cell", "lod13_step"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"lod1.{name}: must be > 0, got {getattr(self, name)}")
        for name in ("ground_ring", "ground_wide_ring", "lod13_min_area", "precision",
                     "min_height"):
            if getattr(self, name) < 0:
                raise ConfigError(f"lod1.{name}: must be >= 0, got {getattr(self, name)}")
        if self.min_points < 1:
            raise ConfigError(f"lod1.min_points: must be >= 1, got {self.min_points}")
        if not self.min_area >= 0:
            raise ConfigError(f"lod1.min_area: must be >= 0, got {self.min_area}")
        object.__setattr__(self, "building_classes", tuple(int(c) for c in self.building_classes))
        object.__setattr__(self, "ground_classes", tuple(int(c) for c in self.ground_classes))

    @property
    def search_radius(self) -> float:
        """How far (m) around a footprint points are needed."""
        return max(self.ground_ring, self.ground_wide_ring, self.lod13_cell)

    def replace(self, **changes) -> Lod1Config:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)


#: the fewest building points a model is made from on any survey: one or two returns
#: in a footprint are as likely a wire, a bird or a branch as a roof
FEWEST_POINTS = 3

#: share of a footprint's area within reach of its building points below which it gets its
#: LoD1.2 prism only (LoD1.3 and LoD2.2 stand in with that prism, saying why): a
#: footprint is the user's statement that a building is there, but its roof parts and
#: planes drawn from a corner of points would be invented for the rest. Module constants,
#: not config fields, so the configuration written into every output stays as it was.
MIN_COVERAGE = 0.25

#: the reach around each building point counted as covered, in point spacings measured
#: from those points: scan-line gaps of a 1-2 pts/m2 survey stay covered
COVERAGE_REACH = 3.0

#: the least height (m) of a wall: without ground around a footprint, its lowest building
#: point stands for the ground only when it lies at least this far under the roof
MIN_WALL_HEIGHT = 2.0

#: the most cells of a LoD1.3 height raster (512 x 512: at the 0.5 m cell, a footprint
#: whose bounding box is 256 m x 256 m); a larger footprint's cell grows to fit
LOD13_MAX_CELLS = 512 * 512


def points_needed(config: Lod1Config, density: float | None) -> int:
    """Building points a footprint needs for a model at a survey ``density`` (pts/m2).

    ``config.min_area`` m2 worth of points at that density, between
    :data:`FEWEST_POINTS` and ``config.min_points``: a fixed count would leave a
    small shed without a model on a sparse survey (a 5 m2 shed holds about 10
    points at 2 pts/m2) while a dense one keeps ``min_points``.

    Parameters
    ----------
    config : Lod1Config
    density : float or None
        Points per m2 around the building; None: unknown (``config.min_points``).

    Examples
    --------
    >>> points_needed(Lod1Config(), 2.0), points_needed(Lod1Config(), 10.0)
    (4, 10)
    """
    if density is None or not np.isfinite(density):
        return config.min_points
    need = int(np.ceil(config.min_area * max(float(density), 0.0) - 1e-9))
    return int(min(config.min_points, max(need, FEWEST_POINTS)))


def _failed(result, reason, t0):
    result.status = "failed"
    result.reason = reason
    result.solids.clear()
    result.parts.clear()
    result.attributes["valid"] = False
    result.attributes["reconstruction_time"] = round(time.perf_counter() - t0, 4)
    return result


def reconstruct_building(footprint, building_xyz, ground_xyz, *, config: Lod1Config | None = None,
                         id: str = "", fallback_ground_z=None,
                         point_density=None) -> BuildingResult:
    """LoD1.2 / LoD1.3 models of one building.

    Parameters
    ----------
    footprint : shapely Polygon or MultiPolygon
        Local metric coordinates (as the points).
    building_xyz : ndarray, shape (N, 3)
        Building points near the footprint (points outside it are ignored).
    ground_xyz : ndarray, shape (M, 3)
        Ground points near the footprint (within ``config.search_radius``).
    config : Lod1Config, optional
    id : str
        The footprint's identifier, kept as the ``footprint_id`` attribute.
    fallback_ground_z : float or callable, optional
        Ground height used when no ground point and no building point gives one
        (e.g. the area's ground level; a callable is evaluated only then);
        recorded as ``ground_source`` ``"fallback"``.
    point_density : float or callable, optional
        The survey's points per m2 around the footprint (a callable is evaluated
        only when fewer than ``config.min_points`` building points are inside):
        the points needed are then :func:`points_needed`; default
        ``config.min_points``.

    Returns
    -------
    BuildingResult
        ``solids["1.2"]``: a Solid (a list of Solids, i.e. a MultiSolid, for a
        multi-part footprint); ``parts["1.3"]``: one Solid per roof-height part.
        ``attributes``: ``footprint_id``, ``roof_height``, ``roof_height_min``,
        ``roof_height_max``, ``ground_height``, ``ground_source``,
        ``point_count``, ``point_density`` (pts/m2), ``no_data_fraction``,
        ``rmse_lod12`` / ``rmse_lod13`` (3-D point-to-model distance, m),
        ``lod13_parts``, ``valid``, ``validity_errors``,
        ``reconstruction_time`` (s). On failure ``status == "failed"`` and
        ``reason`` says why; this function does not raise for bad input.

    References
    ----------
    Peters R., Dukai B., Vitalis S., van Liempt J., Stoter J. (2022) Automated
    3D reconstruction of LoD2 and LoD1 models for all 10 million buildings of
    the Netherlands. PE&RS 88(3):165-170 (3DBAG: LoD1.2 at the 70th percentile,
    LoD1.3 height steps).
    """
    import shapely

    cfg = config or Lod1Config()
    t0 = time.perf_counter()
    result = BuildingResult(id=str(id), footprint=footprint)
    result.attributes["footprint_id"] = str(id)
    try:
        if footprint is None or getattr(footprint, "is_empty", True):
            return _failed(result, "invalid footprint: empty or missing geometry", t0)
        if footprint.geom_type not in ("Polygon", "MultiPolygon"):
            return _failed(result, f"invalid footprint: {footprint.geom_type} is not a polygon", t0)
        polys = clean_polygon(footprint, grid=cfg.precision)
        if not polys:
            reason = shapely.is_valid_reason(footprint) if not footprint.is_valid else "zero area"
            return _failed(result, f"invalid footprint: {reason}", t0)
        fp = polys[0] if len(polys) == 1 else shapely.MultiPolygon(polys)
        result.footprint = fp
        area = float(fp.area)
        bxyz = np.asarray(building_xyz, dtype=np.float64).reshape(-1, 3)
        gxyz = np.asarray(ground_xyz, dtype=np.float64).reshape(-1, 3)
        if len(bxyz):
            shapely.prepare(fp)
            x0, y0, x1, y1 = fp.bounds
            box = (bxyz[:, 0] >= x0) & (bxyz[:, 0] <= x1) & (bxyz[:, 1] >= y0) & (bxyz[:, 1] <= y1)
            idx = np.flatnonzero(box)
            idx = idx[shapely.contains_xy(fp, bxyz[idx, 0], bxyz[idx, 1])]
            inside = bxyz[idx]
        else:
            inside = bxyz
        n = len(inside)
        result.attributes["point_count"] = n
        result.attributes["point_density"] = round(n / area, 3) if area > 0 else 0.0
        from ..metrics.model import footprint_coverage

        result.attributes["no_data_fraction"] = round(
            1.0 - footprint_coverage(fp, inside[:, :2], cell=cfg.coverage_cell), 4)
        if n == 0:
            return _failed(result, "no points", t0)
        if n < cfg.min_points:
            density = point_density() if callable(point_density) else point_density
            need = points_needed(cfg, density)
            if n < need:
                why = "" if need == cfg.min_points else (
                    f": {cfg.min_area:g} m2 at the measured {density:.1f} pts/m2")
                return _failed(result, f"too few points ({n} < {need}{why})", t0)
        share, reach_m = reach_coverage(fp, inside[:, :2], reach=COVERAGE_REACH)
        low_coverage = ""
        if share < MIN_COVERAGE:
            low_coverage = (f"its {n} building points cover {100 * share:.1f} % of its "
                            f"{area:.0f} m2 (within {reach_m:.1f} m; less than "
                            f"{100 * MIN_COVERAGE:.0f} %)")
            result.attributes["point_coverage"] = round(share, 4)
            result.attributes["low_coverage"] = low_coverage
        elif len(polys) > 1:
            # a multi-part footprint may hold a part far from every point (a
            # mis-digitised or misplaced part): no height to give it, so it is
            # treated as a footprint its points do not cover
            empty = _empty_parts(polys, inside[:, :2], reach_m)
            if empty:
                low_coverage = "; ".join(
                    f"part {k + 1} of its {len(polys)} ({polys[k].area:.0f} m2) has no building "
                    f"point within {reach_m:.1f} m" for k in empty)
                result.attributes["low_coverage"] = low_coverage
        z = inside[:, 2]
        roof = roof_height(z, cfg.roof_statistic)
        ground, source = ground_height(
            fp, gxyz, percentile=cfg.ground_percentile, ring_width=cfg.ground_ring,
            wide_ring_width=cfg.ground_wide_ring, min_points=cfg.min_ground_points,
            building_z=z, fallback_z=fallback_ground_z)
        if source == "lowest building point" and roof - ground < MIN_WALL_HEIGHT:
            # no ground point near it, and its lowest point is too close under its roof to be
            # at the foot of a wall: it is on the roof. The area's ground level stands in when
            # known; else (a roof-only cloud: no ground anywhere) the floor stays at the lowest
            # point, as documented for roof-only clouds, and the model says so
            below = roof - ground
            fz = fallback_ground_z() if callable(fallback_ground_z) else fallback_ground_z
            if fz is not None and np.isfinite(fz) and roof - fz >= cfg.min_height:
                ground, source = float(fz), "fallback"
            else:
                where = "the floor is at that point, on the roof"
                if below < cfg.min_height:
                    # every point on the roof (a flat roof-only cloud): no wall to measure, so
                    # the floor goes 2 min_height under the roof, as LoD2.2 lowers the floor
                    # of a roof standing on it, rather than the building refused as too low
                    ground, source = roof - 2 * cfg.min_height, "below the roof"
                    where = f"the floor is {2 * cfg.min_height:g} m under its roof"
                result.attributes["ground_note"] = (
                    f"no ground point within {cfg.ground_wide_ring:g} m, and its lowest point "
                    f"is {below:.2f} m under its roof (less than a wall's {MIN_WALL_HEIGHT:g} m):"
                    f" {where}")
        result.attributes.update(
            roof_height=round(roof, 3), roof_height_min=round(float(z.min()), 3),
            roof_height_max=round(float(z.max()), 3),
            ground_height=round(ground, 3) if np.isfinite(ground) else None,
            ground_source=source)
        if not np.isfinite(ground):
            return _failed(result, "no ground height (no ground points, no fallback)", t0)
        if roof - ground < cfg.min_height:
            return _failed(result, f"roof {roof:.2f} m is less than {cfg.min_height} m above "
                                   f"ground {ground:.2f} m", t0)
        issues: list[int] = []
        solids, codes12 = None, []
        if "1.2" in cfg.lods:
            # each prism with its layout, as built: the RMSE and the checks need not find it
            solids, layouts = _prisms(polys, ground, roof, cfg.precision)
            result.solids["1.2"] = solids[0] if len(solids) == 1 else solids
            result.attributes["rmse_lod12"] = round(_rmse(inside, solids, layouts, True), 4)
            if cfg.validate:
                codes12 = _codes(solids, layouts)
                issues += codes12
        if "1.3" in cfg.lods and low_coverage:
            # the LoD1.2 prism stands in: no roof parts invented where there are no points
            if solids:
                prisms = solids
            else:
                prisms, layouts = _prisms(polys, ground, roof, cfg.precision)
            result.parts["1.3"] = list(prisms)
            result.attributes["lod13_parts"] = len(prisms)
            result.attributes["rmse_lod13"] = result.attributes["rmse_lod12"] if solids else round(
                _rmse(inside, prisms, layouts, True), 4)
            if cfg.validate:
                issues += codes12 if solids else _codes(prisms, layouts)
        elif "1.3" in cfg.lods:
            parts, layouts13 = _lod13(polys, inside, ground, cfg,
                                      lod12=None if solids is None else (roof, solids, layouts))
            result.parts["1.3"] = parts
            result.attributes["lod13_parts"] = len(parts)
            if solids is not None and _same_solids(parts, solids):
                # one part per polygon at the LoD1.2 height: the LoD1.2 prisms again
                result.attributes["rmse_lod13"] = result.attributes["rmse_lod12"]
                issues += codes12
            else:
                result.attributes["rmse_lod13"] = round(_rmse(inside, parts, layouts13), 4)
                if cfg.validate:
                    issues += _codes(parts, layouts13)
        if cfg.validate:
            result.attributes["valid"] = not issues
            result.attributes["validity_errors"] = " ".join(str(c) for c in sorted(set(issues)))
        result.attributes["reconstruction_time"] = round(time.perf_counter() - t0, 4)
        return result
    except Exception as exc:  # a batch never dies on one building
        logger.debug("building %s failed", id, exc_info=True)
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        kind = "invalid footprint" if isinstance(exc, InputError) else "error"
        return _failed(result, f"{kind}: {msg}", t0)


def _same_solids(a, b) -> bool:
    """Whether two lists of solids hold the same vertices and surfaces, in order."""
    if len(a) != len(b):
        return False
    for s, t in zip(a, b, strict=True):
        if s is t:
            continue
        if (s.vertices.shape != t.vertices.shape or not np.array_equal(s.vertices, t.vertices)
                or len(s.surfaces) != len(t.surfaces)):
            return False
        for f, g in zip(s.surfaces, t.surfaces, strict=True):
            if f.semantic != g.semantic or len(f.rings) != len(g.rings) or not all(
                    np.array_equal(r, q) for r, q in zip(f.rings, g.rings, strict=True)):
                return False
    return True


def _empty_parts(polys, xy, reach: float) -> list[int]:
    """Indices of the polygons with no point of ``xy`` inside or within ``reach`` (m)."""
    import shapely

    empty = []
    for k, p in enumerate(polys):
        x0, y0, x1, y1 = p.bounds
        near = ((xy[:, 0] >= x0 - reach) & (xy[:, 0] <= x1 + reach)
                & (xy[:, 1] >= y0 - reach) & (xy[:, 1] <= y1 + reach))
        if not near.any() or not shapely.dwithin(p, shapely.points(xy[near]), reach).any():
            empty.append(k)
    return empty


def _prisms(polys, ground, roof, grid):
    """The prisms of ``polys`` from ``ground`` to ``roof`` (:func:`prism_solid`), and their
    layouts (:func:`lidar2city.lod.prism._prism_layout`)."""
    built = [_prism_solid(p, ground, roof, grid) for p in polys]
    return [b[0] for b in built], [b[1] for b in built]


def _rmse(points, solids, layouts, inside=False) -> float:
    """RMSE of the 3-D distances of ``points`` to the prisms' faces (as
    :func:`lidar2city.metrics.model.model_rmse`, from the footprint rings:
    :func:`lidar2city.lod.prism.prism_distance` of the prisms laid out as ``layouts``).
    ``inside``: the points were selected inside the footprint the prisms were built on
    (the LoD1.2 prisms): one prism's distances are measured knowing it."""
    from ..metrics.model import rmse

    if inside and len(layouts) == 1:
        return rmse(_layout_inside_distance(points, layouts[0]))
    return rmse(_layout_distance(points, layouts))


def _codes(solids, layouts) -> list[int]:
    """val3dity codes of prisms: none for those valid by construction (their footprint
    proves it, :func:`lidar2city.lod.prism.prism_is_valid`), the full check for the others."""
    from ..validate.solid import solid_error_codes

    out: list[int] = []
    for s, layout in zip(solids, layouts, strict=True):
        if not _layout_is_valid(layout):
            out += solid_error_codes(s)
    return out


def lod13_cell(polygon, cell: float) -> float:
    """The LoD1.3 raster cell for ``polygon``: ``cell``, grown so the raster over its bounding
    box holds at most :data:`LOD13_MAX_CELLS` cells (a footprint of an industrial estate or a
    whole block must not stall its batch on a raster of millions of cells).

    Examples
    --------
    >>> from shapely.geometry import box
    >>> lod13_cell(box(0, 0, 30, 20), 0.5), lod13_cell(box(0, 0, 1000, 1000), 0.5)
    (0.5, 1.953125)
    """
    x0, y0, x1, y1 = polygon.bounds
    return max(cell, float(np.sqrt((x1 - x0) * (y1 - y0) / LOD13_MAX_CELLS)))


def _lod13(polys, inside, ground, cfg, lod12=None) -> tuple[list, list]:
    """Prisms of the roof-height parts of each footprint polygon, and their layouts.

    ``lod12``: ``(roof, prisms, layouts)`` of the LoD1.2 prisms of ``polys``: a polygon
    that is one part at that height keeps its LoD1.2 prism (the same one built again)."""
    import shapely
    from shapely.geometry.polygon import orient

    solids, layouts = [], []
    for i, poly in enumerate(polys):
        # one polygon: ``inside`` was selected by this very polygon, all of it is in it
        pts = inside if len(polys) == 1 else inside[
            shapely.contains_xy(poly, inside[:, 0], inside[:, 1])]
        parts = height_parts(poly, pts, cell=lod13_cell(poly, cfg.lod13_cell), step=cfg.lod13_step,
                             min_area=cfg.lod13_min_area, grid=cfg.precision)
        tol = 2.5 * max(cfg.precision, 0.001)
        # a part whose holes touch each other or its outline at a point (height regions
        # meeting corner to corner) is opened there as LoD1.2 footprints are: its prism
        # was non-manifold (val3dity 303) in the written file (only the contacts are cut:
        # no hole of it dropped, which would overlap the part inside)
        parts = [q for part in parts for q in (
            [orient(r, 1.0) for r in _separate_rings(part, cfg.precision, 2.0 * tol)]
            if part.interiors and _ring_contact(part, tol) is not None else [part])]
        for part in parts:
            if part is poly:  # the polygon whole (one height part): every one of its points
                zz = pts[:, 2]
            else:
                in_part = shapely.contains_xy(part, pts[:, 0], pts[:, 1])
                zz = pts[in_part, 2] if in_part.sum() >= 1 else pts[:, 2]
            if len(zz) == 0:
                zz = inside[:, 2]
            h = max(roof_height(zz, cfg.roof_statistic), ground + cfg.min_height)
            if part is poly and lod12 is not None and h == lod12[0]:
                solid, layout = lod12[1][i], lod12[2][i]
            else:
                solid, layout = _prism_solid(part, ground, h, cfg.precision)
            solids.append(solid)
            layouts.append(layout)
    return solids, layouts
