"""LoD2.2 of one building: the seed framework's steps chained, pure and per building."""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass

import numpy as np

from ..config import field
from ..errors import AlgorithmError, ConfigError, FitError
from ..validate.solid import check_solid
from .arrangement import (arrangement_partition, collapse_short_edges, raised_parts, restore_facets,
                          roof_lines)
from .facets import segment_planes
from .refine import refine_partition
from .rooftype import classify_roof
from .solid import nudge_on_grid, on_grid, partition_edges, partition_solid, split_saddles
from .topology import roof_partition

logger = logging.getLogger(__name__)

__all__ = ["Lod22Config", "Lod22Result", "reconstruct_lod22", "regularize_planes", "select_variants",
           "model_cost", "CORNER_PARAMETERS"]


TOPOLOGY_METHODS = ("arrangement", "grid")


@dataclass(frozen=True)
class Lod22Config:
    """Configuration of the ``[lod22]`` stage (LoD2.2 roofs)."""

    cell: float | None = field(None, "Label grid cell (m); default the point spacing, "
                               "clipped to 0.25-1.0 m.")
    dist_tol: float = field(0.2, "Largest point-to-plane distance (m) within a facet "
                            "(about 2-3x the elevation noise).")
    angle_tol: float = field(20.0, "Largest angle (deg) between a point's normal and its facet.")
    min_facet_area: float = field(1.0, "Smallest roof facet (m2).")
    merge_angle: float = field(10.0, "Adjacent facets closer than this (deg) merge when one plane fits both.")
    overhang: float = field(0.5, "Points up to this far (m) outside the footprint help fit planes.")
    simplify: float | None = field(None, "Douglas-Peucker tolerance (m) of inner roof edges; default one cell.")
    elevation_error: float = field(0.15, "Elevation error dh_T of the data (m); T_step = 2 dh_T.")
    max_shift: float = field(1.0, "Largest move (m) of a vertex onto a plane intersection.")
    snap_angle: float = field(10.0, "Facet orientations within this (deg) of the building's axes "
                              "are made exactly parallel / perpendicular.")
    flat_slope: float = field(3.0, "Facets flatter than this (deg) become horizontal.")
    min_height: float = field(0.5, "Smallest roof height above the floor (m).")
    snake: bool = field(True, "Adjust the roof topology with the 2-D snake (E_Dir + E_Dis).")
    snake_cell: float = field(0.5, "Snake grid step as a fraction of the label grid cell.")
    snake_window: int = field(3, "Snake half-window w: (2w+1)^2 candidate positions per vertex.")
    min_edge: float = field(1.5, "Roof edges shorter than this many label cells are collapsed "
                            "(their ends merge) where the partition stays valid; 0 keeps them.")
    topology: str = field("arrangement", "Roof partition method: 'arrangement' (straight exact "
                          "intersection lines and direction-snapped step lines, noded and labelled) "
                          "or 'grid' (label-grid chains simplified, then the snake).")
    restore: bool = field(True, "With topology 'arrangement': cut the facets the partition lost "
                          "back in as rectangles when the solid then fits the points better.")
    step_snake: bool = field(True, "With topology 'arrangement': step edges (walls between faces "
                             "at different heights) from the exact 2-D snake over all step "
                             "chains at once; false: straight pieces snapped to the axes by angle.")
    raised_parts: bool = field(False, "With topology 'arrangement': clusters of points standing "
                               "T_step above the roof (chimneys, small dormers) cut in as level "
                               "rectangles when the model's BIC (see select) drops (Delft: median "
                               "RMSE 0.165 -> 0.161 m for ~11 % more reconstruct CPU).")
    outline_tolerance: float = field(0.0, "Outline vertices within this many point spacings of "
                                     "the line through their neighbours (jogs the points cannot "
                                     "resolve) are dropped from the roof outline (Douglas-Peucker, "
                                     "topology kept) when that leaves at most 1 % of the part's "
                                     "points outside it; 0 (the default) keeps the footprint as given.")
    select: bool = field(False, "Build each building's roof three ways (as configured, with step "
                         "edges snapped by angle, with twice min_facet_area) and keep the one of "
                         "least BIC, n log(SSE / n) + 3 log(n) corners (n points inside the "
                         "footprint, SSE their squared distances to the model, 3 coordinates per "
                         "roof corner seen from above); about 2.5x the CPU of one.")

    def __post_init__(self):
        for name in ("dist_tol", "angle_tol", "min_facet_area", "elevation_error", "max_shift"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"lod22.{name}: must be > 0, got {getattr(self, name)}")
        if self.topology not in TOPOLOGY_METHODS:
            raise ConfigError(f"lod22.topology: must be one of {sorted(TOPOLOGY_METHODS)}, "
                              f"got {self.topology!r}")
        if self.cell is not None and self.cell <= 0:
            raise ConfigError(f"lod22.cell: must be > 0, got {self.cell}")


@dataclass(eq=False)
class Lod22Result:
    """Solids (one per footprint part) and per-building attributes.

    ``issues``: when the solids were validated as they are (on the output grid), the
    :func:`~lidar2city.validate.solid.check_solid` issues of each one; None when not.
    """

    solids: list
    attributes: dict
    issues: list | None = None


def _spacing(xy, area):
    return float(np.sqrt(max(area, 1e-6) / max(len(xy), 1)))


def regularize_planes(planes, labels, xyz, direction, *, snap_angle=10.0, flat_slope=3.0):
    """Make facet orientations parallel / perpendicular to the building direction (seed step 4).

    A facet whose down-slope direction is within ``snap_angle`` of one of the
    four axes ``direction + k * 90 deg`` is refitted with that direction fixed
    (slope and offset by least squares on its points); facets flatter than
    ``flat_slope`` become horizontal at their points' mean height.

    Returns a new (K, 3) array.
    """
    out = np.array(planes, dtype=np.float64, copy=True)
    for k in range(len(out)):
        pts = xyz[labels == k]
        if len(pts) < 3:
            continue
        a, b, _ = out[k]
        slope = np.degrees(np.arctan(np.hypot(a, b)))
        if slope < flat_slope:
            out[k] = (0.0, 0.0, float(pts[:, 2].mean()))
            continue
        psi = np.arctan2(b, a)
        rel = np.degrees((psi - direction) % (np.pi / 2))
        off = min(rel, 90.0 - rel)
        if off > snap_angle:
            continue
        axis = direction + np.round((psi - direction) / (np.pi / 2)) * (np.pi / 2)
        u = pts[:, 0] * np.cos(axis) + pts[:, 1] * np.sin(axis)
        A = np.column_stack([u, np.ones_like(u)])
        (s, c), *_ = np.linalg.lstsq(A, pts[:, 2], rcond=None)
        out[k] = (s * np.cos(axis), s * np.sin(axis), c)
    return out


#: the largest share of a part's points a straightened outline may leave outside its roof
_OUTLINE_LEFT_OUT = 0.01


def straighten_outline(poly, tolerance):
    """``poly`` with the outline vertices within ``tolerance`` (m) of the line through the
    vertices kept beside them dropped (Douglas-Peucker, topology kept): jogs and kinks
    smaller than the points can resolve. Every point of the result's boundary lies within
    ``tolerance`` of the footprint's; ``poly`` itself when the result is not one valid
    polygon with as many rings."""
    import shapely

    out = shapely.simplify(poly, tolerance, preserve_topology=True)
    if (out.geom_type != "Polygon" or not out.is_valid or out.is_empty
            or len(out.interiors) != len(poly.interiors)):
        return poly
    return out


def _direction(footprint):
    """Dominant direction (rad, in [0, pi/2)) of the footprint's edges."""
    from ..regularize.direction import dominant_direction

    return float(dominant_direction(footprint))


def part_floor(poly, xyz, labels, planes, ground_z, *, min_height, spacing, flat_slope=3.0,
               share=1 / 3, building_points=None):
    """The floor of one footprint part: ``ground_z``, or lower when the roof stands on it.

    The sloped facets whose plane, at their own points and at the outline
    vertices within ``2 spacing`` of them (where their faces meet the outline),
    comes down to within ``min_height`` of the floor: when they hold at least
    ``share`` of the part's points, the roof itself stands on the floor (a cloud
    of roof points only whose floor was taken at its lowest point, the eaves; a
    ground estimate too high under a low roof). Those planes are roof the data
    fits, not faces to flatten: the floor goes ``2 min_height`` below their
    lowest height. Fewer points (a low clutter facet, sloped ground inside the
    outline) leave the floor as given and their faces are flattened as before.

    Flat facets on the floor count too when, with the sloped ones, they hold at
    least ``share`` of the part's points and of the building's
    (``building_points``, default the part's): a flat roof of roof points only,
    its floor taken at its lowest point, on the roof. Lifting it to ``2
    min_height`` over the floor would put the roof a metre above every point; a
    part of a larger building that is mostly ground (a traced patch behind the
    house) holds too few of the building's points to move its floor.

    Returns the floor (m), at most ``ground_z``.
    """
    from scipy.spatial import cKDTree

    corners = np.asarray(poly.exterior.coords)[:, :2]
    lows, held, flat_lows, flat_held = [], 0, [], 0
    planes = np.asarray(planes)
    # each plane's lowest height over its points and every corner: no lower than over its
    # points and the corners near them, so a plane whose bound stays above the floor's
    # reach (by more than rounding) is passed without its points' tree
    bound = np.full(len(planes), np.inf)
    if len(planes):
        lab = np.asarray(labels)
        mine = np.flatnonzero((lab >= 0) & (lab < len(planes)))
        pl = planes[lab[mine]]
        np.minimum.at(bound, lab[mine], xyz[mine, 0] * pl[:, 0] + xyz[mine, 1] * pl[:, 1] + pl[:, 2])
        bound = np.minimum(bound, (corners @ planes[:, :2].T + planes[:, 2]).min(axis=0))
    for k, (a, b, c) in enumerate(planes):
        if bound[k] >= ground_z + min_height + 1e-6:
            continue
        flat = np.degrees(np.arctan(np.hypot(a, b))) < flat_slope
        own = xyz[labels == k]
        if not len(own):
            continue
        near = cKDTree(own[:, :2]).query(corners, distance_upper_bound=2 * spacing)[0] < np.inf
        low = float(np.min(np.vstack([own[:, :2], corners[near]]) @ (a, b) + c))
        if low >= ground_z + min_height:
            continue
        if flat:
            flat_lows.append(low)
            flat_held += len(own)
        else:
            lows.append(low)
            held += len(own)
    if lows and held >= share * len(xyz):
        return min(ground_z, min(lows) - 2 * min_height)
    total = len(xyz) if building_points is None else max(int(building_points), len(xyz))
    if flat_lows and held + flat_held >= share * total:
        return min(ground_z, min(lows + flat_lows) - 2 * min_height)
    return ground_z


def _fix_low_faces(faces, face_labels, planes, ground_z, min_height, xyz):
    """Faces whose plane dips below the floor get a horizontal plane at their points' median."""
    planes = list(map(np.asarray, planes))
    face_labels = np.array(face_labels, copy=True)
    import shapely

    for fi, f in enumerate(faces):
        pl = planes[face_labels[fi]]
        c = np.asarray(f.exterior.coords)
        if np.min(pl[0] * c[:, 0] + pl[1] * c[:, 1] + pl[2]) >= ground_z + min_height:
            continue
        inside = shapely.contains_xy(f, xyz[:, 0], xyz[:, 1])
        z = np.median(xyz[inside, 2]) if inside.any() else ground_z + 3.0
        planes.append(np.array([0.0, 0.0, max(float(z), ground_z + 2 * min_height)]))
        face_labels[fi] = len(planes) - 1
    return face_labels, np.asarray(planes)


def _face_top(face, plane):
    """The height of ``face``'s highest corner on ``plane`` ``(a, b, c)``."""
    c = np.asarray(face.exterior.coords)
    return float(np.max(c[:, 0] * plane[0] + c[:, 1] * plane[1] + plane[2]))


def _top(faces, face_labels, planes):
    """The highest corner of a roof partition, each face on its plane."""
    return max(_face_top(f, planes[k]) for f, k in zip(faces, face_labels, strict=True))


def _fix_high_faces(faces, face_labels, planes, xyz, *, spacing, t_step, cap=True):
    """Faces whose plane rises above every point near them are capped or levelled.

    A plane fitted to one part of the roof and given to a face reaching where its
    points never did (a steep facet extrapolated over a patch without points) can
    put the face's corners metres above every point of the building: a spike. A
    face is supported when its highest corner stays within ``t_step + min(tan(slope) *
    spacing, max(spacing / 2, 2 t_step))`` of the highest point within two point
    spacings of it: the plane's rise over one spacing (a ridge corner between points
    one spacing apart), but no more than half a spacing (a 45 deg ridge half a spacing
    from its nearest points; on a sparse survey a steep plane rises metres over one
    spacing: ISPRS CSite1's 50-60 deg faces at 2.8 m put corners 2-4 m above every
    point) nor less than a step (a dense survey's steep face a spacing beyond its
    points, 0.5-0.6 m on Delft's mansards). An unsupported face with at least 3 points
    keeps its plane up to ``t_step`` above that highest point and gets a horizontal
    cap at that height beyond (the face cut along the plane's contour line); any
    other unsupported face (or one the contour does not cut cleanly) takes a
    horizontal plane at the median of its points (of the points near it when it
    holds none), as :func:`_fix_low_faces` does for faces below the floor; so does
    every unsupported face when ``cap`` is False.

    Returns ``(faces, face_labels, planes)``: the inputs themselves when every face is
    supported; else new lists, the caps and levels as planes appended to ``planes``.
    """
    out, changed, caps = [[], [], list(map(np.asarray, planes))], False, []
    x, y = xyz[:, 0], xyz[:, 1]
    zmin = float(xyz[:, 2].min()) if len(xyz) else 0.0
    by_x = np.argsort(x, kind="stable")  # each face's box of points by two binary searches
    xs = x[by_x]
    held = _held_faces(faces, face_labels, planes, xyz, (by_x, xs), zmin, spacing=spacing,
                       t_step=t_step)
    for fi, f in enumerate(faces):
        fixed = None if held[fi] else _fixed_face(
            f, planes[face_labels[fi]], xyz, (by_x, xs), zmin, spacing=spacing, t_step=t_step, cap=cap)
        if fixed is None:
            out[0].append(f)
            out[1].append(face_labels[fi])
            continue
        changed = True
        parts, z = fixed
        out[2].append(np.array([0.0, 0.0, z]))
        for k, g in enumerate(parts):
            if parts[0]:
                caps += range(len(out[0]), len(out[0]) + len(g)) if k else []
            out[0] += g
            out[1] += [face_labels[fi] if k == 0 else len(out[2]) - 1] * len(g)
    if not changed:
        return faces, face_labels, planes
    faces, labels, planes = out[0], np.asarray(out[1], dtype=np.int64), np.asarray(out[2])
    return _merge_thin_caps(faces, labels, planes, caps, spacing=spacing)


def _merge_thin_caps(faces, labels, planes, caps, *, spacing):
    """Caps narrower than a point spacing on average (the tip of a face no point reached)
    join the neighbour they share most boundary with when its plane stays at or below the
    cap over them: the roof gets no new corners for a part no point can place."""
    import shapely

    drop = set()
    for i in caps:
        f = faces[i]
        if f.area >= spacing * f.length / 2:
            continue
        shared = [(f.boundary.intersection(g.boundary).length, j) for j, g in enumerate(faces)
                  if j != i and j not in drop]
        length, j = max(shared, default=(0.0, -1))
        if length <= 0:
            continue
        c = np.asarray(f.exterior.coords)
        pl = planes[labels[j]]
        if np.max(pl[0] * c[:, 0] + pl[1] * c[:, 1] + pl[2]) > planes[labels[i]][2] + 1e-9:
            continue
        merged = shapely.union(shapely.set_precision(faces[j], 0.0), shapely.set_precision(f, 0.0))
        if merged.geom_type != "Polygon":
            continue
        faces[j] = shapely.geometry.polygon.orient(merged, 1.0)
        drop.add(i)
    keep = [k for k in range(len(faces)) if k not in drop]
    return [faces[k] for k in keep], labels[keep], planes


#: the most (face, point) pairs :func:`_held_faces` tests in one call
_HELD_PAIRS = 1 << 21


def _held_faces(faces, face_labels, planes, xyz, sorted_x, zmin, *, spacing, t_step):
    """Per face, True when :func:`_fixed_face` finds it supported by its first two tests
    (its highest corner no higher than the lowest point, or than its own points, plus its
    tolerance), the tests of all faces in vectorised calls: the same doubles, compared the
    same way. False says nothing (the face goes through :func:`_fixed_face`)."""
    import shapely

    n = len(faces)
    if not n or not len(xyz):
        return np.zeros(n, dtype=bool)
    arr = np.asarray(faces, dtype=object)
    pl = np.array([np.asarray(planes[k], dtype=np.float64) for k in face_labels]).reshape(n, 3)
    c, which = shapely.get_coordinates(shapely.get_exterior_ring(arr), return_index=True)
    if len(np.unique(which)) != n:
        return np.zeros(n, dtype=bool)
    p = pl[which]
    z = p[:, 0] * c[:, 0] + p[:, 1] * c[:, 1] + p[:, 2]
    top = np.maximum.reduceat(z, np.flatnonzero(np.r_[True, which[1:] != which[:-1]]))
    tol = t_step + np.minimum(np.minimum(np.hypot(pl[:, 0], pl[:, 1]), _SPIKE_MAX_TAN) * spacing,
                              max(spacing / 2, 2 * t_step))
    held = top <= zmin + tol
    rest = np.flatnonzero(~held)
    if not len(rest):
        return held
    # the highest of each face's own points (in its box, then inside it)
    x, y = xyz[:, 0], xyz[:, 1]
    by_x, xs = sorted_x
    box = shapely.bounds(arr[rest])
    lo, hi = np.searchsorted(xs, box[:, 0], "left"), np.searchsorted(xs, box[:, 2], "right")
    span = hi - lo
    if int(span.sum()) > _HELD_PAIRS:
        return held
    js = np.repeat(np.arange(len(rest)), span)
    cand = by_x[lo[js] + np.arange(len(js)) - np.repeat(np.cumsum(span) - span, span)]
    # only points high enough to hold the face are tested for being in it (rounding is
    # monotonic: top <= max(z) + tol exactly when top <= z + tol for one of the z)
    t_r, tol_r = top[rest], tol[rest]
    inbox = (y[cand] >= box[js, 1]) & (y[cand] <= box[js, 3]) & (t_r[js] <= xyz[cand, 2] + tol_r[js])
    js, cand = js[inbox], cand[inbox]
    # each face prepared once for its many points (the same answers, an index per face
    # instead of a pass over its ring per point); released after
    tested = arr[rest]
    fresh = tested[~shapely.is_prepared(tested)]
    shapely.prepare(fresh)
    try:
        inside = shapely.contains_xy(tested[js], x[cand], y[cand])
    finally:
        shapely.destroy_prepared(fresh)
    held[rest[np.unique(js[inside])]] = True
    return held


def _fixed_face(f, pl, xyz, sorted_x, zmin, *, spacing, t_step, cap=True):
    """None when face ``f`` on plane ``pl`` is supported (:func:`_fix_high_faces`); else
    ``(parts, z)``: ``[[below...], [above...]]`` the polygons keeping ``pl`` and those
    taking the horizontal plane at ``z``."""
    import shapely

    reach = 2.0 * spacing
    c = np.asarray(f.exterior.coords)
    top = float(np.max(pl[0] * c[:, 0] + pl[1] * c[:, 1] + pl[2]))
    tol = t_step + min(min(float(np.hypot(pl[0], pl[1])), _SPIKE_MAX_TAN) * spacing,
                       max(spacing / 2, 2 * t_step))
    if not len(xyz) or top <= zmin + tol:
        return None  # no higher than the lowest point: supported whatever lies near
    x, y = xyz[:, 0], xyz[:, 1]
    x0, y0, x1, y1 = f.bounds
    by_x, xs = sorted_x  # the points' order by x and their sorted x
    lo, hi = np.searchsorted(xs, x0 - reach, "left"), np.searchsorted(xs, x1 + reach, "right")
    cand = np.sort(by_x[lo:hi])
    cand = cand[(y[cand] >= y0 - reach) & (y[cand] <= y1 + reach)]
    # most faces are held by their own points: those inside it already reach its top
    # (they are among the points near it), so the buffer is not needed to say so
    own = cand[(x[cand] >= x0) & (x[cand] <= x1) & (y[cand] >= y0) & (y[cand] <= y1)]
    own = own[shapely.contains_xy(f, x[own], y[own])]
    if len(own) and top <= float(xyz[own, 2].max()) + tol:
        return None
    near = cand[shapely.contains_xy(f.buffer(reach), x[cand], y[cand])]
    if not len(near):
        return None  # nothing near to say how high it is: add_lod22's whole-roof check decides
    high = float(xyz[near, 2].max())
    if top <= high + tol:
        return None
    inside = near[shapely.contains_xy(f, x[near], y[near])]
    logger.debug("a face of %.2f m2 rises %.2f m above its %d nearest points", f.area, top - high, len(near))
    if cap and len(inside) >= 3:
        # the cap a step above the highest point: the face keeps its plane where its points
        # are, even a plane that fits them loosely (levelling such a face at its points'
        # median, as before session 11, moved the whole face; of the roofs the session 11
        # spike fixes changed, 14 of 18 on ISPRS CSite1 and 12 of 14 on FSite5 fit their
        # points better with caps only, RMSE point to mesh)
        parts = _below_contour(f, pl, high + t_step)
        if parts:
            return parts, high + t_step
    return [[], [f]], float(np.median(xyz[inside if len(inside) else near, 2]))


def _below_contour(face, plane, z, min_area=1e-4):
    """``[below, above]``: the polygons of ``face`` where ``plane`` lies below and above the
    height ``z``, or None when the cut leaves a part smaller than ``min_area`` (m2) or
    loses area (more than the face's precision grid can explain)."""
    import shapely

    from shapely.geometry.polygon import orient

    g = float(np.hypot(plane[0], plane[1]))
    if g < 1e-9:
        return None
    n = np.array([plane[0], plane[1]]) / g  # uphill
    t = np.array([-n[1], n[0]])
    cx, cy = face.centroid.x, face.centroid.y
    p = np.array([cx, cy]) - n * ((plane[0] * cx + plane[1] * cy + plane[2] - z) / g)
    x0, y0, x1, y1 = face.bounds
    r = 2.0 * (x1 - x0 + y1 - y0) + np.hypot(*(p - [cx, cy])) + 1.0
    half = shapely.Polygon([p + t * r, p - t * r, p - t * r - n * r, p + t * r - n * r])
    # cut in full precision: a face's precision grid would move the cut's ends off its edges
    exact = shapely.set_precision(face, 0.0)
    cut = [shapely.get_parts(exact.intersection(half)), shapely.get_parts(exact.difference(half))]
    # counter-clockwise exteriors, as the partition's faces (overlays return them clockwise)
    parts = [[orient(q, 1.0) for q in c if isinstance(q, shapely.Polygon)] for c in cut]
    slack = min_area
    if not all(parts) or any(q.area < min_area for c in parts for q in c) \
            or abs(sum(q.area for c in parts for q in c) - face.area) > slack:
        return None
    return parts


#: the steepest slope (tangent, ~72 deg) whose rise over one point spacing a supported
#: roof corner may have above its nearest points
_SPIKE_MAX_TAN = 3.0


def _clean_faces(faces, labels, precision=5e-3):
    """Repair faces whose rings touch themselves (a hole pinched into the shell)."""
    import shapely

    # a 5 mm grid for all faces (coarser than the 1 mm CityJSON quantisation and validator
    # snapping, so distinct vertices stay distinct after them): shared vertices
    # snap alike, and near-zero-width spikes collapse and vanish on both sides
    snapped = shapely.set_precision(np.asarray(faces, dtype=object), precision)
    # emptiness, kind, validity and repeated vertices of all faces in vectorised calls
    empty = shapely.is_empty(snapped)
    polygon = (shapely.get_type_id(snapped) == 3) & ~empty
    valid = shapely.is_valid(snapped)
    pinched = _repeat_vertices(snapped, polygon)
    out_f, out_l = [], []
    for i, (f, lab) in enumerate(zip(snapped, labels, strict=True)):
        if empty[i]:
            continue
        if not polygon[i]:
            parts = [g for g in shapely.get_parts(f) if g.geom_type == "Polygon" and g.area > 1e-9]
            out_f += parts
            out_l += [lab] * len(parts)
            continue
        if valid[i] and not pinched[i]:
            out_f.append(f)
            out_l.append(lab)
            continue
        fixed = shapely.make_valid(shapely.buffer(f, 0) if not f.is_valid else f)
        for g in shapely.get_parts(fixed):
            if g.geom_type == "Polygon" and g.area > 1e-9:
                out_f.append(g)
                out_l.append(lab)
    return _absorb_slivers(out_f, np.asarray(out_l, dtype=np.int64))


def _repeat_vertices(faces, which):
    """Per face, whether one of its rings passes twice through one vertex (to 0.1 mm), its
    closing vertex aside (:func:`_repeats_a_vertex` of every ring); only the polygons
    ``which`` (a mask) are looked at, the rings of all of them at once."""
    from .arrangement import _flat_rings

    out = np.zeros(len(faces), dtype=bool)
    idx = np.flatnonzero(which)
    if not len(idx):
        return out
    xy, owner, sizes = _flat_rings(faces[idx])
    r = np.round(xy, 4)
    ring = np.repeat(np.arange(len(sizes)), sizes)
    order = np.lexsort((r[:, 1], r[:, 0], ring))
    rs, gs = r[order], ring[order]
    dup = (gs[1:] == gs[:-1]) & (rs[1:, 0] == rs[:-1, 0]) & (rs[1:, 1] == rs[:-1, 1])
    out[idx[owner[gs[1:][dup]]]] = True
    return out


def _repeats_a_vertex(ring) -> bool:
    """Whether a ring passes twice through one vertex (to 0.1 mm), its closing vertex aside."""
    c = np.round(np.asarray(ring.coords)[:-1], 4).tolist()  # one rounding for the whole ring
    return len(set(map(tuple, c))) != len(c)


def _absorb_slivers(faces, labels, *, min_width=0.01):
    """Slivers (narrower than ``min_width`` on average) join the neighbour they share most with."""
    import shapely

    faces, labels = list(faces), list(labels)
    i = 0
    while i < len(faces):
        f = faces[i]
        if f.area >= min_width * f.length / 2 or len(faces) == 1:
            i += 1
            continue
        shared = [(f.boundary.intersection(g.boundary).length, j) for j, g in enumerate(faces) if j != i]
        length, j = max(shared)
        merged = shapely.set_precision(shapely.union(faces[j], f), 5e-3) if length > 0 else None
        if merged is None or merged.geom_type != "Polygon":
            i += 1
            continue
        faces[j] = merged
        del faces[i], labels[i]
        i = 0
    return faces, np.asarray(labels, dtype=np.int64)


def _ring_edges(solid):
    """``(a, b)``: every edge a -> b of every ring of the solid's surfaces (vertex ids)."""
    rings = [r for s in solid.surfaces for r in s.rings if len(r)]
    if not rings:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    sizes = np.fromiter(map(len, rings), dtype=np.int64, count=len(rings))
    a = np.concatenate(rings).astype(np.int64, copy=False)
    ends = np.cumsum(sizes)
    nxt = np.arange(1, len(a) + 1)
    nxt[ends - 1] = ends - sizes  # a ring's last vertex -> its first
    return a, a[nxt]


def _nonmanifold_points(solid):
    """2-D positions of vertical edges shared by more than two surfaces (saddle vertices)."""
    a, b = _ring_edges(solid)
    if not len(a):
        return np.zeros((0, 2))
    n = max(len(solid.vertices), int(a.max()) + 1)
    edges, count = np.unique(np.minimum(a, b) * n + np.maximum(a, b), return_counts=True)
    shared = edges[count > 2]
    if not len(shared):  # the usual case: no row-wise unique to set up
        return np.zeros((0, 2))
    return np.unique(np.round(solid.vertices[shared // n, :2], 6), axis=0)


def _manifold_solid(faces, face_labels, planes, ground_z, min_height, max_rounds=8,
                    repair=True, first=None):
    """The partition's solid; at a saddle vertex (alternating heights around it, where four
    walls would share a vertical edge) the face at the intermediate height takes its
    longest-shared neighbour's plane, until the shell is 2-manifold. When that does not
    converge within ``max_rounds``, every face keeps its plane and the saddle vertices
    are cut out of the partition instead (:func:`lidar2city.roof.solid.split_saddles`).

    Returns ``(solid, relabelled)``, the number of faces that took another plane. With
    ``repair=False`` a shell with a saddle is returned at once with ``relabelled = 1``
    (the caller has another partition to try: each repair round rebuilds the solid).

    ``first``: a dict holding the faces' edges and first solid from an earlier call on the
    same partition (filled here when empty), so that repairing it later rebuilds nothing."""
    import shapely

    labels0 = face_labels
    face_labels = np.array(face_labels, copy=True)
    face_array = np.asarray(faces, dtype=object)
    boundaries = None  # taken at the first saddle (most partitions have none)
    # the relabelling is a function of the labels: once a labelling comes back, the
    # rounds left repeat that cycle, and the labelling after max_rounds is known
    seen: dict = {}  # labels -> round
    solids: list = []  # the solid of each round's labels
    for r in range(max_rounds + 1):
        key = face_labels.tobytes()
        if key in seen:
            i = seen[key]
            solid = solids[i + (max_rounds - i) % (r - i)]
            break
        if r == 0 and first:
            edges, solid = first["edges"], first["solid"]
        else:
            if r == 0:
                edges = partition_edges(faces)  # the faces stay: each round only relabels
            solid = partition_solid(faces, planes[face_labels], ground_z, min_height=min_height,
                                    edges=edges)
            if r == 0 and first is not None:
                first.update(edges=edges, solid=solid)
        if r == max_rounds:
            break
        seen[key] = r
        solids.append(solid)
        bad = _nonmanifold_points(solid)
        if not len(bad):
            return solid, r
        if not repair:
            return solid, 1
        p = bad[0]
        at = np.flatnonzero(shapely.distance(face_array, shapely.Point(p)) < 1e-6).tolist()
        z = np.array([planes[face_labels[i]] @ (p[0], p[1], 1.0) for i in at])
        mid = [i for i, zz in zip(at, z, strict=True) if z.min() + 1e-3 < zz < z.max() - 1e-3]
        victim = min(mid or at, key=lambda i: faces[i].area)
        others = np.flatnonzero((np.arange(len(faces)) != victim)
                                & (face_labels != face_labels[victim]))
        if boundaries is None:
            boundaries = shapely.boundary(face_array)
        shared = shapely.length(shapely.intersection(boundaries[victim], boundaries[others]))
        neigh = [(float(L), int(j)) for L, j in zip(shared, others, strict=True) if L > 0]
        if not neigh:
            return solid, r
        face_labels[victim] = face_labels[_plane_donor(faces, face_labels, planes, victim, neigh,
                                                       min_height)]
    if len(_nonmanifold_points(solid)):
        # taking planes did not converge (one face's new plane makes the next saddle): keep
        # every plane and cut the saddle vertices out of the partition instead
        cut = _saddle_cut(faces, planes[np.asarray(labels0)], ground_z, min_height,
                          solids[0] if solids else None)
        if cut is not None:
            return cut, 0
    return solid, max_rounds


def _plane_donor(faces, face_labels, planes, victim, neigh, tolerance):
    """The neighbour whose plane face ``victim`` takes at a saddle: the longest-shared of
    ``neigh`` (``[(shared length, face)]``) whose plane, over the victim, stays within
    ``tolerance`` of the higher of the victim's own top and that neighbour's; the one
    rising least when none does. A plane carried over a large face (a flat part beside a
    small sloped one) would else put the victim's far corner metres above every point:
    CSite1's b250, +1.97 m, CSite2's b19, +4.3 m over the partition's highest corner."""
    v = faces[victim]
    own = _face_top(v, planes[face_labels[victim]])
    rises = []
    for _, j in sorted(neigh, reverse=True):
        pl = planes[face_labels[j]]
        rise = _face_top(v, pl) - max(own, _face_top(faces[j], pl))
        if rise <= tolerance:
            return j
        rises.append((rise, j))
    return min(rises)[1]


def _same_partition(a, b) -> bool:
    """Two ``(faces, face_labels, planes)`` equal to the bit (the same solid is built of them)."""
    import shapely

    if a[0] is b[0] and a[1] is b[1] and a[2] is b[2]:
        return True
    if len(a[0]) != len(b[0]) or not np.array_equal(a[1], b[1]) or not np.array_equal(a[2], b[2]):
        return False
    wkb = [shapely.to_wkb(np.asarray(f, dtype=object)) for f in (a[0], b[0])]
    return bool(np.array_equal(wkb[0], wkb[1]))


def _saddle_cut(faces, own, ground_z, min_height, solid=None):
    """The solid of the partition with every face on its own plane (``own``, per face;
    ``solid`` when already built) and its saddle vertices cut out
    (:func:`lidar2city.roof.solid.split_saddles`, up to three rounds), or None when a
    saddle stays or the cut solid does not validate."""
    cut = solid if solid is not None else partition_solid(faces, own, ground_z, min_height=min_height)
    for _ in range(3):
        bad = _nonmanifold_points(cut)
        if not len(bad):
            break
        split = split_saddles(faces, bad)
        if all(a is b for a, b in zip(split, faces, strict=True)):
            break  # no saddle could be cut: every further round would rebuild this solid
        faces = split
        cut = partition_solid(faces, own, ground_z, min_height=min_height)
    if not len(_nonmanifold_points(cut)) and _valid_cut(cut):
        return cut
    return None


def _valid_cut(solid, precision=1e-3) -> bool:
    """The solid valid as computed and with its vertices on the output grid (a notch or
    patch is a few centimetres: it must not make faces intersect once rounded)."""
    from ..datamodel import Solid

    rounded = Solid(np.round(solid.vertices / precision) * precision, solid.surfaces)
    return not check_solid(solid) and not check_solid(rounded)


def _parts(footprint):
    return list(getattr(footprint, "geoms", [footprint]))


def reconstruct_lod22(footprint, building_xyz, ground_z, *, config: Lod22Config | None = None,
                      direction=None, precision: float | None = None) -> Lod22Result:
    """LoD2.2 solids of one building from its footprint and building points.

    Parameters
    ----------
    footprint : shapely Polygon or MultiPolygon
        Local metres; it is the outer boundary of the roof topology.
    building_xyz : ndarray, shape (N, 3)
        Building points near the footprint (those farther than ``overhang``
        outside are ignored).
    ground_z : float
        Floor height (m). A part whose main sloped planes come down to it (the
        roof standing on the floor, :func:`part_floor`) gets its floor lower, by
        ``floor_lowered`` m (an attribute), rather than its roof flattened.
    config : Lod22Config
    direction : float, optional
        Building direction (rad); default estimated from the footprint.
    precision : float, optional
        Output vertex grid (m), e.g. 0.001 for CityJSON's millimetres. When given,
        the solids returned have their vertices on it, and each was validated as
        returned (``Lod22Result.issues``), which also decides whether the
        arrangement partition's solid is kept or the label grid's tried: the solid
        validated is the one written, once. None validates the solids as computed
        and leaves ``issues`` None.

    Returns
    -------
    Lod22Result
        One closed solid per footprint polygon and the attributes: number of
        roof planes, roof type, ridge height, slope and azimuth of the main
        facet, intersection / step edge counts, type IV count, time.

    Raises
    ------
    FitError
        When a footprint part has fewer than 3 points within ``overhang``, or a
        roof plane stays below the floor (the caller records the reason). A part
        without any planar facet gets one horizontal roof at its median height.

    References
    ----------
    Main seed framework, Fig. 1 steps 2-8; eqs. 1-6.
    """
    import shapely

    cfg = config or Lod22Config()
    if cfg.select:
        return _select_model(footprint, building_xyz, ground_z, cfg=cfg, direction=direction,
                             precision=precision)
    t0 = time.perf_counter()
    xyz = np.asarray(building_xyz, dtype=np.float64)
    solids, attrs, issues = [], {}, []
    n_planes, type4, n_int, n_step, moved, snake_fallbacks = 0, 0, 0, 0, 0, 0
    roof_areas, roof_planes, roof_faces, directions = [], [], [], []
    parts = _parts(footprint)
    # the building's points, for a part's floor (part_floor): one part holds them all
    n_building = None if len(parts) == 1 else int(np.count_nonzero(shapely.contains_xy(
        footprint.buffer(cfg.overhang), xyz[:, 0], xyz[:, 1])))
    skipped, lowered = 0, 0.0
    for poly in parts:
        grown = poly.buffer(cfg.overhang)
        near = shapely.contains_xy(grown, xyz[:, 0], xyz[:, 1])
        pts = xyz[near]
        if len(pts) < 3:
            raise FitError(f"too few points on the roof ({len(pts)})")
        centred = pts[:, :2] - pts[:, :2].mean(axis=0)
        if np.linalg.svd(centred, compute_uv=False)[1] / np.sqrt(len(pts)) < 0.01:
            raise FitError(f"the {len(pts)} roof points lie on one line: no roof surface between them")
        spacing = _spacing(pts[:, :2], grown.area)
        cell = cfg.cell or float(np.clip(spacing, 0.25, 1.0))
        if poly.area < cell * cell:
            if len(parts) > 1:
                skipped += 1  # a sliver beside the building's other parts
                continue
            raise FitError(f"footprint smaller than one label cell ({poly.area:.3f} m2 < "
                           f"{cell:.2f} m x {cell:.2f} m)")
        d = _direction(poly) if direction is None else direction
        labels, planes = segment_planes(pts, dist_tol=cfg.dist_tol, angle_tol=cfg.angle_tol,
                                        min_area=cfg.min_facet_area, merge_angle=cfg.merge_angle)
        if len(planes) == 0:
            # no planar facet: one horizontal roof at the median height
            labels = np.zeros(len(pts), dtype=np.int64)
            planes = np.array([[0.0, 0.0, float(np.median(pts[:, 2]))]])
        planes = regularize_planes(planes, labels, pts, d, snap_angle=cfg.snap_angle,
                                   flat_slope=cfg.flat_slope)
        floor = part_floor(poly, pts, labels, planes, ground_z, min_height=cfg.min_height,
                           spacing=spacing, flat_slope=cfg.flat_slope, building_points=n_building)
        lowered = max(lowered, ground_z - floor)
        # the arrangement with raised rims along the outline, without them, then the grid;
        # with the outline straightened first, then the footprint as given
        outlines = [poly]
        if cfg.outline_tolerance > 0 and cfg.topology == "arrangement":
            straight = straighten_outline(poly, cfg.outline_tolerance * spacing)
            # kept where it leaves few of the part's points outside the roof (a jog cut off
            # with the points on it is a part of the building, not noise of the outline)
            inside = shapely.contains_xy(poly, pts[:, 0], pts[:, 1])
            left = np.count_nonzero(inside & ~shapely.contains_xy(straight, pts[:, 0], pts[:, 1]))
            if straight is not poly and left <= _OUTLINE_LEFT_OUT * np.count_nonzero(inside):
                outlines = [straight, poly]
        tries = [(m, o) for o in outlines for m in ("rims", "arrangement")] + [("grid", poly)] \
            if cfg.topology == "arrangement" else [("grid", poly)]
        info, shared, last = {}, {}, None
        for k, (method, outline) in enumerate(tries):
            if method == "arrangement" and not info.get("rims", 1) and last is outline:
                continue  # no rim was found: the same partition as the try before
            if last is not outline:
                info, shared, last = {}, {}, outline
            final = k == len(tries) - 1
            try:
                solid, faces, face_labels, planes_k, info = _part_solid(
                    method, outline, pts, labels, planes, floor, cell=cell, direction=d, cfg=cfg,
                    shared=shared)
                if cfg.raised_parts and method != "grid":
                    solid, faces, face_labels, planes_k, info = _with_raised_parts(
                        (solid, faces, face_labels, planes_k, info), method, outline, pts, floor,
                        cell=cell, direction=d, spacing=spacing, cfg=cfg)
            except (FitError, ValueError, shapely.errors.GEOSException) as exc:
                if final:
                    raise
                logger.debug("%s roof topology failed (%s); trying the next", method, exc)
                continue
            written = on_grid(solid, precision)
            if final:
                found = check_solid(written) if precision else None
                if found:
                    solid, found = _nudged(solid, written, found, precision)
                break
            if _closed_shell(solid):
                found = check_solid(written)
                if found:
                    # a crossing vertex rounded off its edge: moved by a grid step rather
                    # than the roof redone without rims or by the coarser grid partition
                    solid, found = _nudged(solid, written, found, precision)
                if not found:
                    break
            logger.debug("%s roof topology gave an invalid solid; trying the next", method)
        solids.append(solid)
        issues.append(found)
        n_int += info["intersection"]
        n_step += info["step"]
        moved += info["moved"]
        type4 += info.get("IV", 0)
        snake_fallbacks += bool(info.get("snake_fallback"))
        n_planes += len(np.unique(face_labels))
        roof_areas += [f.area for f in faces]
        roof_planes += [planes_k[k] for k in face_labels]
        roof_faces += list(faces)
        directions.append((poly.area, d))
    if not solids:
        raise FitError(f"every footprint part is smaller than one label cell ({skipped} parts)")
    if skipped:
        attrs["skipped_parts"] = skipped
    if lowered > 0:
        attrs["floor_lowered"] = round(lowered, 3)  # the roof stood on the floor given
    main = roof_planes[int(np.argmax(roof_areas))]
    zmax = max(float(s.vertices[:, 2].max()) for s in solids)
    attrs.update(
        roof_planes=n_planes,
        roof_type=classify_roof(roof_faces, np.asarray(roof_planes), max(directions)[1],
                                flat_slope=max(cfg.flat_slope, 5.0)),
        ridge_height=round(zmax, 3),
        main_slope=round(float(np.degrees(np.arctan(np.hypot(main[0], main[1])))), 2),
        main_azimuth=round(float(np.degrees(np.arctan2(-main[0], -main[1])) % 360), 2),
        intersection_edges=n_int,
        step_edges=n_step,
        type_iv=type4,
        snake_fallback=snake_fallbacks,
        lod22_time=round(time.perf_counter() - t0, 4),
    )
    if precision:
        return Lod22Result([on_grid(s, precision) for s in solids], attrs, issues)
    return Lod22Result(solids, attrs)


def select_variants(cfg):
    """``(name, config)`` of the roof models :func:`reconstruct_lod22` chooses between when
    ``cfg.select``: ``cfg`` itself, step edges snapped by angle, and facets of at least
    twice ``cfg.min_facet_area`` (a simpler roof)."""
    base = dataclasses.replace(cfg, select=False)
    return (("default", base), ("steps by angle", dataclasses.replace(base, step_snake=False)),
            ("larger facets", dataclasses.replace(base, min_facet_area=2 * cfg.min_facet_area)))


#: free parameters of one roof corner in the model selection: its three coordinates
CORNER_PARAMETERS = 3


def model_cost(xyz, solids):
    """The Bayesian information criterion of a building's model, ``n log(SSE / n) + p log(n)``,
    with ``p`` = :data:`CORNER_PARAMETERS` per roof corner seen from above
    (:func:`lidar2city.metrics.wireframe.roof_cleanliness`): ``xyz`` (n, 3) its points, SSE
    their squared point-to-mesh distances (:func:`lidar2city.metrics.model.point_mesh_distance`).
    Lower is better: a corner must buy its keep in fit.

    References
    ----------
    Schwarz, G. (1978). Estimating the dimension of a model. Annals of Statistics 6(2), 461-464.
    """
    return bic(len(xyz), *fit_terms(xyz, solids))


def fit_terms(xyz, solids):
    """``(sse, corners)`` of :func:`model_cost`: the points' sum of squared point-to-mesh
    distances to ``solids`` and the roof corners seen from above."""
    from ..lod.mesh import solid_triangles
    from ..metrics.model import point_mesh_distance
    from ..metrics.wireframe import roof_cleanliness, roof_wireframe

    sse = float(np.sum(point_mesh_distance(xyz, solid_triangles(solids)) ** 2))
    return sse, roof_cleanliness(roof_wireframe(solids))[0]


def bic(n, sse, corners):
    """:func:`model_cost` of a model with ``corners`` roof corners whose ``n`` points have
    the sum of squared distances ``sse``."""
    # a floor of 1 mm RMS: below it the fit is exact for every purpose
    return n * np.log(max(sse / n, 1e-6)) + CORNER_PARAMETERS * np.log(n) * corners


def _select_model(footprint, building_xyz, ground_z, *, cfg, direction, precision):
    """The model of :func:`select_variants` with the least :func:`model_cost` over the points
    inside the footprint; models with validation issues only when no other is left. The
    first model's error (FitError) is raised; another model that fails is left out."""
    import shapely

    t0 = time.perf_counter()
    xyz = np.asarray(building_xyz, dtype=np.float64)
    own = xyz[shapely.contains_xy(footprint, xyz[:, 0], xyz[:, 1])]
    best = None
    for i, (name, c) in enumerate(select_variants(cfg)):
        try:
            res = reconstruct_lod22(footprint, xyz, ground_z, config=c, direction=direction,
                                    precision=precision)
        except AlgorithmError:
            if i == 0:
                raise
            continue
        if len(own) < 3:
            return res  # too few points to compare models on
        bad = res.issues is not None and any(res.issues)
        key = (bad, model_cost(own, res.solids))
        if best is None or key < best[0]:
            best = (key, name, res)
    _, name, res = best
    res.attributes.update(roof_model=name, lod22_time=round(time.perf_counter() - t0, 4))
    return res


def _nudged(solid, written, found, precision):
    """``(solid, issues)``: the solid on the grid with a crossing vertex moved by one grid
    step when that validates it (:func:`.solid.nudge_on_grid`), else as it was."""
    moved, left = nudge_on_grid(written, found, precision)
    return (solid, found) if left else (moved, left)


def _closed_shell(solid) -> bool:
    """Every edge of the solid used exactly twice, in opposite directions (a closed,
    2-manifold, consistently oriented shell: the cheap part of a val3dity check)."""
    a, b = _ring_edges(solid)
    keep = a != b
    a, b = np.asarray(a[keep], dtype=np.int64), np.asarray(b[keep], dtype=np.int64)
    if not len(a):
        return True
    # edge counts from one integer key per edge (a row-wise unique is several times slower)
    lo = min(int(a.min()), int(b.min()))
    a, b = a - lo, b - lo
    n = int(max(a.max(), b.max())) + 1
    directed = np.unique(a * n + b, return_counts=True)[1]
    und = np.unique(np.minimum(a, b) * n + np.maximum(a, b), return_counts=True)[1]
    return bool(np.all(directed == 1) and np.all(und == 2))


def _part_solid(method, poly, pts, labels, planes, ground_z, *, cell, direction, cfg, shared=None):
    """The solid of one footprint polygon by one roof partition method.

    With ``cfg.restore`` and the arrangement, the roof parts the partition lost
    (:func:`lidar2city.roof.arrangement.restore_facets`) are cut back in when the
    solid with them is a closed valid shell and fits the part's points better:
    the sum of squared point-to-mesh distances drops by at least that of the
    smallest facet (``min_facet_area`` of points) lying ``T_step`` off.

    ``shared``: a dict kept across the methods tried on the same polygon; the
    arrangement's boundary lines (:func:`.arrangement.roof_lines`, most of its
    cost) are computed once in it for the tries with and without rims.

    Returns ``(solid, faces, face_labels, planes, info)``; raises FitError when
    a roof stays below the floor.
    """
    info = {}
    restored = None
    spacing = _spacing(pts[:, :2], poly.buffer(cfg.overhang).area)
    if method in ("rims", "arrangement"):
        kw = dict(cell=cell, direction=direction, t_step=2 * cfg.elevation_error,
                  max_shift=cfg.max_shift, snap_angle=cfg.snap_angle, step_snake=cfg.step_snake,
                  snake_window=cfg.snake_window, snake_cell=cfg.snake_cell)
        shared = {} if shared is None else shared
        if "lines" not in shared:
            shared["lines"] = roof_lines(poly, pts, labels, planes, **kw)
        faces, face_labels, kinds, planes = arrangement_partition(
            poly, pts, labels, planes, rims=method == "rims", lines=shared["lines"], **kw)
        info["rims"] = kinds.count("rim")
        if cfg.restore:
            restored = restore_facets(faces, face_labels, poly, pts, labels, planes, direction=direction,
                                      spacing=spacing, t_step=2 * cfg.elevation_error,
                                      min_area=cfg.min_facet_area)
    else:
        part = roof_partition(poly, pts[:, :2], labels, planes, cell=cell, simplify=cfg.simplify)
        faces, face_labels = part.faces, part.face_labels
        if cfg.snake:
            faces, info = _snake_adjust(faces, poly, part.raw_chains, cell=cell * cfg.snake_cell,
                                        direction=direction, window=cfg.snake_window)
    out = _finish_solid(method, poly, pts, faces, face_labels, planes, ground_z, cell=cell, cfg=cfg, info=info,
                        spacing=spacing)
    if restored is None or not restored[2]:
        return out
    import shapely

    try:
        alt = _finish_solid(method, poly, pts, *restored[:2], planes, ground_z, cell=cell, cfg=cfg, info=info,
                            spacing=spacing)
    except (FitError, ValueError, shapely.errors.GEOSException):
        return out
    if not _closed_shell(alt[0]) or check_solid(alt[0]):
        return out
    from ..lod.mesh import solid_triangles
    from ..metrics.model import point_mesh_distance

    own = pts[shapely.contains_xy(poly, pts[:, 0], pts[:, 1])]
    if not len(own):
        return out
    sq = [float(np.sum(point_mesh_distance(own, solid_triangles(r[0])) ** 2)) for r in (out, alt)]
    if sq[0] - sq[1] < cfg.min_facet_area / spacing ** 2 * (2 * cfg.elevation_error) ** 2:
        return out
    alt[4]["restored"] = restored[2]
    return alt


def _with_raised_parts(part, method, poly, pts, ground_z, *, cell, direction, spacing, cfg):
    """``part`` (:func:`_part_solid`'s answer) with the clusters standing above its roof
    cut in as level rectangles (:func:`lidar2city.roof.arrangement.raised_parts`) when
    the solid stays a closed valid shell and its :func:`model_cost` over the part's
    points drops (each rectangle's corners must buy their keep); else ``part``."""
    import shapely

    solid, faces, face_labels, planes, info = part
    faces2, labels2, planes2, added, (lifted, level) = raised_parts(
        faces, face_labels, poly, pts, planes, direction=direction, spacing=spacing,
        t_step=2 * cfg.elevation_error, fit=True)
    own = pts[shapely.contains_xy(poly, pts[:, 0], pts[:, 1])]
    if not added or len(own) < 3:
        return part
    from ..lod.mesh import solid_triangles
    from ..metrics.model import point_mesh_distance
    from ..metrics.wireframe import roof_cleanliness, roof_wireframe

    # the most the rectangles can win, before their solid is built: their points as far
    # from the roof as they are now and on their levels in the new solid, each rectangle
    # with at least two new corners (one clipped at the outline), the other points as they are
    tri = solid_triangles([solid])
    gain = float(np.sum(point_mesh_distance(pts[lifted], tri) ** 2 - (pts[lifted, 2] - level) ** 2))
    if gain <= 0:
        return part
    n = len(own)
    sse = float(np.sum(point_mesh_distance(own, tri) ** 2))
    corners = roof_cleanliness(roof_wireframe([solid]))[0]
    cost = bic(n, sse, corners)
    if bic(n, sse - gain, corners + _RAISED_MIN_CORNERS * added) >= cost:
        return part
    try:
        alt = _finish_solid(method, poly, pts, faces2, labels2, planes2, ground_z, cell=cell, cfg=cfg,
                            info=info)
    except (FitError, ValueError, shapely.errors.GEOSException):
        return part
    if not _closed_shell(alt[0]) or check_solid(alt[0]) or model_cost(own, [alt[0]]) >= cost:
        return part
    alt[4]["raised"] = added
    return alt


#: the fewest corners a raised part's rectangle adds to a roof: two where it is clipped at the outline
_RAISED_MIN_CORNERS = 2


def _finish_solid(method, poly, pts, faces, face_labels, planes, ground_z, *, cell, cfg, info, spacing=None):
    """Refine a roof partition (intersection lines, short edges) and build its solid.

    ``spacing``: the points' spacing over the footprint grown by ``cfg.overhang``
    (:func:`_spacing`), computed here when not given."""
    faces, refined = refine_partition(faces, face_labels, planes, t_step=2 * cfg.elevation_error,
                                      max_shift=cfg.max_shift)
    info = {**info, **refined}
    if spacing is None:
        spacing = _spacing(pts[:, :2], poly.buffer(cfg.overhang).area)
    variants = [(faces, face_labels)]
    if method in ("rims", "arrangement") and cfg.min_edge > 0:
        collapsed, kept = collapse_short_edges(faces, poly, min_length=cfg.min_edge * cell)
        if len(collapsed) != len(faces) or any(a is not b and not a.equals_exact(b, 0) for a, b in zip(collapsed, faces)):
            variants.insert(0, (collapsed, face_labels[kept]))
    kw = dict(ground_z=ground_z, pts=pts, spacing=spacing, cfg=cfg, memo={})
    solid, faces, face_labels, planes_f = _variant_solid(variants, planes, **kw)
    if len(variants) > 1 and not _closed_shell(solid):
        # the last variant's shell stays open (its saddle repair did not converge, or a floor
        # sliver): the first variant's saddles repaired instead (from its fixes and solids
        # already built), kept when that closes and validates, rather than the caller
        # building another partition: traced Delft's 1049 and 1293 m2 blocks built theirs twice
        alt = _variant_solid(variants[:1], planes, **kw)
        if _closed_shell(alt[0]) and not check_solid(alt[0]) and float(
                alt[0].vertices[:, 2].max()) <= _top(*alt[1:]) + 2 * cfg.elevation_error:
            solid, faces, face_labels, planes_f = alt
    return solid, faces, face_labels, planes_f, info


def _variant_solid(variants, planes, *, ground_z, pts, spacing, cfg, memo):
    """``(solid, faces, face_labels, planes)`` of the first of ``variants`` (``(faces,
    face_labels)`` of one refined partition each, preferred first) whose solid closes
    without a face taking a neighbour's plane; the last one's saddles repaired.

    ``memo``: a dict kept across calls on the same variants (a call on the first of them
    alone repairs it): each variant's cleaned faces, fixes and first solids, keyed by its
    faces list (alive as long as ``variants``)."""
    pinched = None  # the first variant's solid with its spike left, when the fix pinched a saddle
    for i, (faces, face_labels) in enumerate(variants):
        # collapsing short edges can pinch faces at different heights into a saddle; the
        # uncollapsed partition is used then rather than a face taking a neighbour's plane
        # (so only the last variant's saddles are repaired)
        last = i == len(variants) - 1
        k = id(faces)
        if (k, "clean") not in memo:
            faces, face_labels = _clean_faces(faces, face_labels)
            face_labels, planes_f = _fix_low_faces(faces, face_labels, planes, ground_z, cfg.min_height, pts)
            memo[k, "clean"] = faces, face_labels, planes_f
        faces, face_labels, planes_f = memo[k, "clean"]
        # spikes capped, else levelled, else the roof as partitioned (a spike left is refused
        # with the whole roof by add_lod22's check)
        tried = None  # the capped roof's partition
        for cap in (True, False):
            if (k, cap) not in memo:
                memo[k, cap] = _fix_high_faces(faces, face_labels, planes_f, pts, spacing=spacing,
                                               t_step=2 * cfg.elevation_error, cap=cap)
            fixed = memo[k, cap]
            if tried is not None and fixed[0] is not faces and _same_partition(tried, fixed):
                # levelling gave the very partition capping gave: the same solid, refused again
                continue
            solid, relabelled = _manifold_solid(*fixed, ground_z, cfg.min_height / 2, repair=last,
                                                first=memo.setdefault((k, cap, "solid"), {}))
            tried = fixed
            # a fix is kept when its solid is valid and its saddle repair did not raise a new
            # spike (faces taking their neighbours' planes: ISPRS samp11 b54, +3.4 m)
            if fixed[0] is faces or (_closed_shell(solid) and not check_solid(solid) and float(
                    solid.vertices[:, 2].max()) <= _top(*fixed) + 2 * cfg.elevation_error):
                faces, face_labels, planes_f = fixed
                break
        else:
            solid, relabelled = _manifold_solid(faces, face_labels, planes_f, ground_z, cfg.min_height / 2,
                                                repair=last, first=memo.setdefault((k, "solid"), {}))
            if pinched is not None:  # no variant takes the fix: the first one's solid, as before
                solid, faces, face_labels, planes_f = pinched
                break
            if not relabelled and not last:
                # the fixed faces pinch a saddle only the last variant repairs (FSite5 b9:
                # a levelled face beside a collapsed edge, its roof left 1.2 m over its points)
                pinched = solid, faces, face_labels, planes_f
                continue
        if not relabelled:
            break
    return solid, faces, face_labels, planes_f


#: the largest exact roof snake solve (table elements, about 1 CPU second per 1e8): the
#: roof graph of a block of many houses is too wide for it and keeps its simplified faces
SNAKE_MAX_WORK = 1e8


def _snake_adjust(faces, footprint, raw_chains, *, cell, direction, window=2,
                  max_work=SNAKE_MAX_WORK):
    """The 2-D snake over the whole roof topology graph at once (seed step 5).

    The inner vertices of the partition move to the global minimum of
    E = C_Dir E_Dir + C_Dis E_Dis (:func:`lidar2city.regularize.snake.adjust_planar_graph`);
    the footprint outline stays fixed (it is the given boundary). The deviation
    energy is measured against the raw label-grid boundaries. When the moved
    graph is no longer a partition of the footprint, or when the exact solve
    would touch more than ``max_work`` table elements
    (:func:`lidar2city.snake.solver.reduction_work`, checked before any energy
    table is built: a large block's roof graph is too wide for it), the faces
    are kept as they were (``snake_fallback``).

    Returns ``(faces, info)`` with the solver's reduction counts in ``info``.
    """
    import shapely
    from shapely.geometry import Polygon

    from ..regularize.snake import adjust_planar_graph
    from ..snake.solver import reduction_work
    from .refine import _remove_spikes
    from .solid import _key

    keys, xy, edges = {}, [], set()
    for f in faces:
        for ring in [f.exterior, *f.interiors]:
            c = np.asarray(ring.coords)[:-1]
            ids = []
            for p in c:
                k = _key(p)
                if k not in keys:
                    keys[k] = len(xy)
                    xy.append(p)
                ids.append(keys[k])
            for a, b in zip(ids, ids[1:] + ids[:1], strict=True):
                if a != b:
                    edges.add((min(a, b), max(a, b)))
    xy = np.asarray(xy, dtype=np.float64)
    outline = footprint.boundary
    fixed = shapely.distance(outline, shapely.points(xy)) < 1e-6
    if fixed.all() or not raw_chains:
        return faces, {}
    e = np.array(sorted(edges), dtype=np.int64)
    e = e[~(fixed[e[:, 0]] & fixed[e[:, 1]])]
    segs = np.concatenate([np.stack([c[:-1], c[1:]], axis=1) for c in raw_chains if len(c) > 1])
    # the exact solve grows with the graph's width (tables over several vertices of
    # (2w+1)^2 states): a roof graph too wide for it keeps its simplified faces
    work = reduction_work(np.where(fixed, 1, (2 * window + 1) ** 2), e)
    if work > max_work:
        logger.debug("roof snake skipped: ~%.3g table elements (limit %.3g)", work, max_work)
        return faces, {"snake_fallback": True}
    new, info = adjust_planar_graph(xy, e, original_segments=segs, cell=cell, window=window,
                                    direction=direction, fixed=fixed)
    face_ids = [[keys[_key(p)] for ring in [f.exterior, *f.interiors]
                 for p in np.asarray(ring.coords)[:-1]] for f in faces]

    def rebuild():
        out = []
        for f in faces:
            rings = []
            for ring in [f.exterior, *f.interiors]:
                pts = [new[keys[_key(p)]] for p in np.asarray(ring.coords)[:-1]]
                dedup = [q for i, q in enumerate(pts) if i == 0 or np.hypot(*(q - pts[i - 1])) > 1e-9]
                if len(dedup) > 1 and np.hypot(*(dedup[0] - dedup[-1])) < 1e-9:
                    dedup.pop()
                rings.append(_remove_spikes(dedup))
            out.append(Polygon(rings[0], [r for r in rings[1:] if len(r) >= 3])
                       if len(rings[0]) >= 3 else None)
        return out

    total = footprint.area
    red = dict(info.get("reductions", {}))
    # the snake's grid can push a vertex across a neighbour's edge; the moves of the faces
    # that broke are undone (a few rounds), the rest of the global minimum is kept
    for _ in range(4):
        out = rebuild()
        bad = {i for i, f in enumerate(out) if f is None or not f.is_valid or f.area <= 1e-6
               or f.difference(footprint).area > 1e-6}
        good = [i for i in range(len(out)) if i not in bad]
        if good:
            tree = shapely.STRtree([out[i] for i in good])
            for a, b in zip(*tree.query([out[i] for i in good], predicate="overlaps"), strict=True):
                if a != b and out[good[a]].intersection(out[good[b]]).area > 1e-6:
                    bad.update((good[a], good[b]))
        if not bad:
            break
        for i in bad:
            new[face_ids[i]] = xy[face_ids[i]]
    ok = (all(f is not None and f.is_valid and f.area > 1e-6 for f in out)
          and abs(sum(f.area for f in out) - total) < 1e-6 * max(total, 1)
          and abs(shapely.union_all(out).area - total) < 1e-6 * max(total, 1))
    if not ok:
        logger.debug("snake adjustment broke the roof partition; keeping the simplified one")
        return faces, {**red, "snake_fallback": True}
    return out, red

