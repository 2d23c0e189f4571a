"""Roof type of a LoD2.2 roof from its final facet graph.

The type is read from the roof faces as built (2-D polygons, each with its
plane ``z = a x + b y + c``) and their adjacency, not from the count of
distinct planes: a gable split by noise into three faces, or carrying two
dormers and a chimney, is still a gable.

Every sloped face gets one of the four building axes as its down-slope
direction (``k = 0..3``, the building direction plus ``k * 90`` degrees) when
it is within ``axis_tol`` of one; the faces of one axis count together (a slope
split by noise is still one side of the roof). Then, in this order:

* ``flat``: flat faces cover all but ``minor`` of the roof area;
* ``shed``: one sloped roof plane covers all but ``minor``;
* ``mansard`` / ``gambrel``: in four / two axes a steep face lies below a
  face of the same axis at least ``break_angle`` shallower;
* ``gable``: two opposite roof planes meet in a ridge (they share an edge)
  and cover all but ``raised``, the rest being raised parts (dormers) that do
  not reach both main planes, or faces below ``tiny`` (chimneys);
* ``hip`` / ``half_hip`` / ``pyramid``: two opposite main planes with a ridge
  and, at each end, one face of a perpendicular axis touching both (a hip
  end); ``half_hip`` when those ends start more than ``eave_tol`` above the
  main eaves; ``pyramid`` when four planes of the four axes meet at one apex
  without a ridge;
* ``cross_gable``: ridges along both axes, the perpendicular gables covering
  more than ``raised`` (wings meeting the main roof in valleys: L, T, U shapes);
* ``complex`` otherwise (flat and sloped parts together, oblique faces...).

References
----------
The roof types of the CityGML ``roofType`` code list (flat, monopitch,
dualpitch, halfhipped, hipped, mansard, pavilion...) recognised from the
roof topology graph, as in Verma, V., Kumar, R., Hsu, S. (2006). 3D building
detection and modeling from aerial LIDAR data. CVPR (roof-topology-graph
patterns of simple roofs).
"""

from __future__ import annotations

import numpy as np

__all__ = ["ROOF_TYPES", "classify_roof"]

ROOF_TYPES = ("flat", "shed", "gable", "hip", "half_hip", "pyramid", "mansard", "gambrel",
              "cross_gable", "complex")


def _slope_deg(planes):
    return np.degrees(np.arctan(np.hypot(planes[:, 0], planes[:, 1])))


def _adjacency(faces, min_shared):
    """Boolean (F, F) matrix: faces sharing a boundary longer than ``min_shared``."""
    import shapely

    n = len(faces)
    adj = np.zeros((n, n), dtype=bool)
    if n < 2:
        return adj
    tree = shapely.STRtree(faces)
    a, b = tree.query(faces, predicate="intersects")
    keep = a < b
    for i, j in zip(a[keep], b[keep], strict=True):
        if faces[i].boundary.intersection(faces[j].boundary).length > min_shared:
            adj[i, j] = adj[j, i] = True
    return adj


def _face_heights(faces, planes):
    """Lowest and highest roof height (F,) of each face, at its vertices."""
    import shapely

    lo, hi, top = [], [], []
    for f, p in zip(faces, planes, strict=True):
        c = shapely.get_coordinates(f.exterior)
        z = c @ p[:2] + p[2]
        lo.append(z.min())
        hi.append(z.max())
        top.append(c[int(np.argmax(z))])
    return np.array(lo), np.array(hi), np.array(top)


def classify_roof(faces, planes, direction, *, flat_slope=5.0, axis_tol=25.0, minor=0.15,
                  raised=0.25, tiny=0.02, break_angle=20.0, eave_tol=0.5, min_shared=0.5) -> str:
    """The roof type of a roof's faces.

    Parameters
    ----------
    faces : sequence of shapely Polygon, length F
        Roof faces from above (local metres), a partition of the roof.
    planes : array_like, shape (F, 3)
        Each face's plane ``(a, b, c)``.
    direction : float
        Building direction (rad); the four axes are ``direction + k pi / 2``.
    flat_slope : float
        Faces flatter than this (deg) are flat.
    axis_tol : float
        Largest angle (deg) between a face's down-slope direction and its axis.
    minor : float
        Largest share of the roof area left to noise faces, clutter, oblique or
        flat faces beside the main planes of a sloped type (or sloped ones on a
        flat roof).
    raised : float
        Largest share of the roof area of the perpendicular faces raised on a
        gable or hip (dormers); a perpendicular gable larger than this is a wing
        (cross gable).
    tiny : float
        Faces below this share of the roof area are ignored (clutter).
    break_angle : float
        Smallest slope change (deg) between the steep and shallow faces of a mansard.
    eave_tol : float
        Height (m) by which hip ends must start above the main eaves to be half-hips.
    min_shared : float
        Shortest shared boundary (m) for two faces to meet (a ridge, a hip line).

    Returns
    -------
    str
        One of :data:`ROOF_TYPES`.
    """
    faces = list(faces)
    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 3)
    if len(faces) != len(planes):
        raise ValueError(f"planes: one per face, got {len(planes)} for {len(faces)} faces")
    if not faces:
        raise ValueError("faces: at least one roof face is needed")
    area = np.array([f.area for f in faces])
    share = area / max(area.sum(), 1e-12)
    slope = _slope_deg(planes)
    flat = slope < flat_slope
    if share[flat].sum() >= 1 - minor:
        return "flat"
    # down-slope direction relative to the building axes
    az = np.arctan2(-planes[:, 1], -planes[:, 0]) - direction
    k = np.round(az / (np.pi / 2))
    off = np.degrees(np.abs(az - k * np.pi / 2))
    axis = np.where(~flat & (off <= axis_tol), k.astype(np.int64) % 4, -1)
    keep = share >= tiny
    if share[keep & (axis < 0) & ~flat].sum() > minor or share[keep & flat].sum() > minor:
        return "complex"  # oblique faces or flat parts beside sloped ones
    lo, hi, top = _face_heights(faces, planes)
    # mansard / gambrel: a steep face below a shallower one of the same axis
    breaks = set()
    for ax in range(4):
        m = np.flatnonzero(keep & (axis == ax))
        if len(m) < 2:
            continue
        steep, shallow = m[np.argmax(slope[m])], m[np.argmin(slope[m])]
        if slope[steep] - slope[shallow] >= break_angle and lo[steep] < lo[shallow] - eave_tol:
            breaks.add(ax)
    if len(breaks) == 4:
        return "mansard"
    if len(breaks) == 2 and (min(breaks) + 2) in breaks:
        return "gambrel"
    if breaks:
        return "complex"
    ax_share = np.array([share[keep & (axis == a)].sum() for a in range(4)])
    if ax_share.max() >= 1 - minor:
        return "shed"
    adj = _adjacency(faces, min_shared)

    def ridge(a):
        """Faces of axes a and a+2 that meet (a ridge along the perpendicular axis)."""
        i = np.flatnonzero(keep & (axis == a))
        j = np.flatnonzero(keep & (axis == (a + 2) % 4))
        return bool(len(i) and len(j) and adj[np.ix_(i, j)].any())

    pair = [ax_share[a] + ax_share[a + 2] for a in (0, 1)]
    main = int(np.argmax(pair))
    ridges = [ridge(0), ridge(1)]
    if not ridges[main]:
        # no ridge along the main axis: a pyramid when four planes meet at one apex
        if np.all(ax_share > tiny) and not ridges[1 - main]:
            m = np.flatnonzero(keep & (axis >= 0))
            apex = top[m]
            spread = np.max(np.hypot(*(apex - apex.mean(axis=0)).T))
            if spread <= 2 * min_shared and np.ptp(hi[m]) <= eave_tol:
                return "pyramid"
        return "complex"
    mains = np.flatnonzero(keep & ((axis == main) | (axis == main + 2)))
    # hip ends can be small (half-hips): every perpendicular face counts here
    perp = np.flatnonzero((axis == main + 1) | (axis == (main + 3) % 4))
    sides = [np.flatnonzero(keep & (axis == main)), np.flatnonzero(keep & (axis == main + 2))]
    if not len(perp):
        return "gable" if pair[main] >= 1 - minor else "complex"
    # hip ends: perpendicular faces touching a main plane on both sides of the ridge
    ends = np.array([bool(adj[p, sides[0]].any() and adj[p, sides[1]].any()) for p in perp])
    end_axes = set(axis[perp[ends]].tolist())
    others = share[perp[~ends]].sum()
    if ridges[1 - main] and pair[1 - main] > raised:
        return "cross_gable"
    if len(end_axes) == 2 and others <= raised:
        eave = np.median(lo[mains])
        return "half_hip" if np.min(lo[perp[ends]]) > eave + eave_tol else "hip"
    if not ends.any() and pair[main] >= 1 - raised:
        return "gable"
    return "complex"
