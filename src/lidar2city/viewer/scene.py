"""What the viewer draws, as arrays: building meshes, colours by attribute, a legend, and
the subsampled point cloud. Pure functions (no server, no file).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["COLOUR_BY", "building_meshes", "merge_meshes", "group_by_colour", "ray_pick",
           "attribute_values", "colours_for", "legend_markdown", "subsample", "class_colours",
           "worst_buildings", "attributes_markdown"]

#: "Colour by" choices -> how a building's value is found (see :func:`attribute_values`)
COLOUR_BY = ("RMSE", "roof type", "status", "validity", "height", "edited")

_PALETTE = np.array([[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40],
                     [148, 103, 189], [140, 86, 75], [227, 119, 194], [127, 127, 127],
                     [188, 189, 34], [23, 190, 207]], dtype=np.uint8)
# a perceptual ramp (viridis at 6 stops) for numeric attributes
_RAMP = np.array([[68, 1, 84], [65, 68, 135], [42, 120, 142], [34, 168, 132],
                  [122, 209, 81], [253, 231, 37]], dtype=np.float64)
_GREY = (170, 170, 170)


def building_meshes(solids_by_building: dict, origin) -> dict:
    """``{building id: (vertices (V, 3) float32, triangles (T, 3) int32)}`` in a display frame.

    ``solids_by_building`` maps an id to a list of
    :class:`~lidar2city.datamodel.Solid` in world coordinates; ``origin`` (3,) is
    subtracted so that float32 keeps millimetres.
    """
    from ..lod.mesh import triangulate_surfaces

    o = np.asarray(origin, dtype=np.float64)
    out = {}
    for bid, solids in solids_by_building.items():
        verts, tris, n = [], [], 0
        for s in solids:
            t, _ = triangulate_surfaces(s.vertices, s.surfaces)
            if len(t) == 0:
                continue
            verts.append(s.vertices - o)
            tris.append(np.asarray(t, dtype=np.int64) + n)
            n += len(s.vertices)
        if verts:
            out[bid] = (np.concatenate(verts).astype(np.float32),
                        np.concatenate(tris).astype(np.int32))
    return out


def merge_meshes(meshes: dict, ids) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One mesh of several buildings' meshes: ``(vertices (V, 3), triangles (T, 3), owner (T,))``.

    ``meshes`` maps an id to ``(vertices, triangles)`` as from :func:`building_meshes`;
    ``ids`` lists the ids to merge, in order (ids without a mesh are skipped);
    ``owner[k]`` is the position in ``ids`` of the building triangle ``k`` belongs to.

    Examples
    --------
    >>> tri = (np.zeros((3, 3), np.float32), np.array([[0, 1, 2]], np.int32))
    >>> v, t, owner = merge_meshes({"a": tri, "b": tri}, ["a", "b"])
    >>> t.tolist(), owner.tolist()
    ([[0, 1, 2], [3, 4, 5]], [0, 1])
    """
    parts = [(i, meshes[b]) for i, b in enumerate(ids) if b in meshes]
    if not parts:
        return (np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32),
                np.zeros(0, np.int64))
    sizes = np.array([len(v) for _, (v, _) in parts])
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    verts = np.concatenate([v for _, (v, _) in parts]).astype(np.float32)
    tris = np.concatenate([np.asarray(t, np.int64) + o for (_, (_, t)), o in zip(parts, offsets)])
    owner = np.repeat([i for i, _ in parts], [len(t) for _, (_, t) in parts])
    return verts, tris.astype(np.int32), owner.astype(np.int64)


def group_by_colour(colours: dict) -> dict:
    """``{(r, g, b): [ids, sorted]}``: the buildings drawn as one mesh per colour."""
    groups: dict = {}
    for bid, c in colours.items():
        groups.setdefault(tuple(int(x) for x in c), []).append(bid)
    return {c: sorted(ids) for c, ids in sorted(groups.items())}


def ray_pick(vertices, triangles, origin, direction, *, eps: float = 1e-9):
    """Index of the nearest triangle a ray hits, or None (Möller–Trumbore, vectorised).

    Parameters
    ----------
    vertices : (V, 3) array
    triangles : (T, 3) int array
    origin, direction : (3,) arrays
        The ray, in the vertices' frame (``direction`` need not be unit length).

    References
    ----------
    T. Möller, B. Trumbore (1997), Fast, minimum storage ray-triangle intersection,
    Journal of Graphics Tools 2(1): 21-28.

    Examples
    --------
    >>> v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    >>> ray_pick(v, np.array([[0, 1, 2]]), (0.2, 0.2, 5.0), (0, 0, -1.0))
    0
    >>> ray_pick(v, np.array([[0, 1, 2]]), (2.0, 2.0, 5.0), (0, 0, -1.0)) is None
    True
    """
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    if len(t) == 0:
        return None
    o = np.asarray(origin, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    a = v[t[:, 0]]
    e1, e2 = v[t[:, 1]] - a, v[t[:, 2]] - a
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > eps
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    w = (q @ d) * inv
    dist = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (w >= 0) & (u + w <= 1) & (dist > 0)
    if not hit.any():
        return None
    idx = np.flatnonzero(hit)
    return int(idx[np.argmin(dist[idx])])


def _rmse(a: dict):
    for k in ("viewer_rmse", "rmse_lod22", "primitive_residual_rmse", "rmse_lod13", "rmse_lod12"):
        v = a.get(k)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
            return float(v)
    return None


def attribute_values(attributes: dict, by: str) -> dict:
    """``{building id: value}`` of the chosen :data:`COLOUR_BY` attribute (None when absent)."""
    if by not in COLOUR_BY:
        raise ValueError(f"by must be one of {', '.join(COLOUR_BY)}, got {by!r}")
    out = {}
    for bid, a in attributes.items():
        if by == "RMSE":
            v = _rmse(a)
        elif by == "roof type":
            v = a.get("roof_type") or a.get("primitive")
        elif by == "status":
            v = ("failed: " + str(a.get("reason", ""))[:40] if a.get("status") == "failed"
                 else "LoD1.2 fallback" if a.get("lod22_fallback") else a.get("status", "ok"))
        elif by == "validity":
            v = "valid" if a.get("valid", True) is not False else "invalid"
        elif by == "height":
            rh, gh = a.get("roof_height"), a.get("ground_height")
            v = (float(rh) - float(gh)) if isinstance(rh, (int, float)) and \
                isinstance(gh, (int, float)) else None
        else:
            v = "edited" if a.get("edit") else "as reconstructed"
        out[bid] = v
    return out


def colours_for(values: dict, *, levels: int = 16) -> tuple[dict, list]:
    """Colours per building and the legend entries ``[(label, (r, g, b))]``.

    Numbers get a ramp between their 2nd and 98th percentiles, in ``levels``
    steps (so that the buildings are drawn as a few meshes, one per colour; 5
    legend stops), text a palette in sorted order; None is grey.
    """
    if levels < 2:
        raise ValueError(f"levels must be at least 2, got {levels}")
    nums = [v for v in values.values() if isinstance(v, (int, float)) and not isinstance(v, bool)]
    colours, legend = {}, []
    if nums and len(nums) == sum(v is not None for v in values.values()):
        lo, hi = np.percentile(nums, [2, 98]) if len(nums) > 1 else (nums[0], nums[0] + 1)
        hi = hi if hi > lo else lo + 1e-9

        def ramp(v):
            t = round(float(np.clip((v - lo) / (hi - lo), 0, 1)) * (levels - 1)) / (levels - 1)
            t *= len(_RAMP) - 1
            i = min(int(t), len(_RAMP) - 2)
            c = _RAMP[i] + (t - i) * (_RAMP[i + 1] - _RAMP[i])
            return tuple(int(round(x)) for x in c)

        for bid, v in values.items():
            colours[bid] = _GREY if v is None else ramp(v)
        for q in np.linspace(lo, hi, 5):
            legend.append((f"{q:.2f}", ramp(q)))
    else:
        cats = sorted({str(v) for v in values.values() if v is not None})
        lut = {c: tuple(int(x) for x in _PALETTE[i % len(_PALETTE)]) for i, c in enumerate(cats)}
        for bid, v in values.items():
            colours[bid] = _GREY if v is None else lut[str(v)]
        legend = list(lut.items())
    if any(v is None for v in values.values()):
        legend.append(("no value", _GREY))
    return colours, legend


def legend_markdown(title: str, legend: list) -> str:
    """The legend as markdown (a coloured square per entry)."""
    rows = [f"**{title}**", ""]
    for label, (r, g, b) in legend:
        rows.append(f"<span style='color:rgb({r},{g},{b})'>&#9632;</span> {label}  ")
    return "\n".join(rows)


def subsample(n: int, max_points: int) -> np.ndarray:
    """Indices of at most ``max_points`` of ``n`` points, evenly strided (deterministic)."""
    if max_points <= 0:
        return np.zeros(0, dtype=np.int64)
    if n <= max_points:
        return np.arange(n)
    return np.arange(0, n, int(math.ceil(n / max_points)))


#: ASPRS class -> display colour
_CLASS_COLOURS = {2: (160, 120, 70), 3: (120, 200, 90), 4: (80, 170, 70), 5: (40, 130, 50),
                  6: (230, 90, 70), 9: (70, 130, 230), 7: (255, 0, 255)}


def class_colours(classes) -> np.ndarray:
    """(N, 3) uint8 colours of ASPRS classes (others light grey)."""
    c = np.asarray(classes)
    out = np.full((len(c), 3), 200, dtype=np.uint8)
    for k, col in _CLASS_COLOURS.items():
        out[c == k] = col
    return out


def worst_buildings(attributes: dict, n: int = 20) -> list[tuple[str, float | None]]:
    """The ``n`` worst buildings: failed first, then invalid, then by decreasing RMSE."""
    def key(item):
        bid, a = item
        r = _rmse(a)
        return (a.get("status") != "failed", a.get("valid", True) is not False,
                -(r if r is not None else -1.0), bid)

    return [(bid, _rmse(a)) for bid, a in sorted(attributes.items(), key=key)[:n]]


def attributes_markdown(bid: str, a: dict) -> str:
    """A building's attributes and quality figures as a markdown table."""
    first = ("status", "reason", "edit", "viewer_rmse", "rmse_lod12", "rmse_lod13",
             "primitive_residual_rmse", "valid", "validity_errors", "lod22_fallback", "roof_type",
             "primitive", "roof_height", "ground_height", "point_count", "point_density")
    keys = [k for k in first if k in a] + sorted(k for k in a if k not in first)
    rows = [f"**Building {bid}**", "", "| attribute | value |", "|---|---|"]
    whole = ("status", "reason", "edit", "validity_errors", "lod22_fallback")
    for k in keys:
        v = a[k]
        if isinstance(v, float):
            v = f"{v:.3f}" if abs(v) < 1e5 else f"{v:.1f}"
        v = str(v)
        if k not in whole and len(v) > 60:  # the reasons are read whole
            v = v[:60] + "..."
        rows.append(f"| {k} | {v.replace('|', chr(92) + '|')} |")
    return "\n".join(rows)
