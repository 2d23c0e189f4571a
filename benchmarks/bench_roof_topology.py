"""LoD2.2 roof topology (issue 12): cleanliness on Delft, wireframe F1 on synthetic roofs, speed.

Usage: python benchmarks/bench_roof_topology.py [DATA_DIR] [delft|synthetic|city3d]
       [--figure docs/roof_topology_delft.png] [--topology grid] [--no-step-snake] [--no-restore]
       [--select] [--raised] [--outline] [--band]
       python benchmarks/bench_roof_topology.py [DATA_DIR] --pareto
(default data $LIDAR2CITY_DATA or ../shared/data; one section name runs only that
section; --figure also draws a Delft block from above, the points beside our
roofs; --topology grid measures the label-grid + snake partition, the one
before the line arrangement; --no-step-snake sets ``[lod22] step_snake = false``:
step edges as angle-snapped straight pieces instead of the exact 2-D snake's;
--no-restore sets ``[lod22] restore = false``: facets the partition lost stay lost;
--select sets ``[lod22] select = true`` (each roof three ways, the least BIC kept);
--raised sets ``[lod22] raised_parts = true`` (chimneys as level rectangles);
--outline sets ``[lod22] outline_tolerance = 1`` (outline jogs within a point spacing
straightened);
--band also prints the median band of the Delft RMSE (:func:`median_band`: the buildings
that decide the median, their squared error by where the points lie, and the median
each error source at zero would give);
--pareto prints only the Delft Pareto table of the ``[lod22]`` variants and the
per-building choice among them, :func:`pareto`)

1. Delft shared tile, 132 BGT footprints, AHN3 class 6 building points (as
   bench_lod22.py): median roof corners per building (distinct vertices where a
   roof-face outline turns by > 10 deg, :mod:`lidar2city.metrics.wireframe`),
   the share of roof-face edge length in edges shorter than 0.5 m, the
   median point-to-mesh RMSE (same scoring code as bench_lod22.py), validity,
   roof faces and time per building. Then where the squared error comes from
   (a diagnostic, the score above is unchanged): points more than 0.3 m from the
   model that lie (a) within 0.3 m of a footprint edge shared with another
   footprint and above our roof (the neighbour's wall or roof edge), (b) more than
   0.3 m below our roof (facades and recessed parts inside the footprint), (c)
   more than 0.3 m above it elsewhere (chimneys, dormers, clutter); with the
   median RMSE that each class alone keeps from the ideal.
2. Synthetic roofs with exact wireframes (:mod:`lidar2city.synthetic_roofs`):
   corner and edge precision / recall / F1 at 0.5 m (3-D), pooled over all
   roofs, at 8 and 25 points/m2 with 3-5 cm noise, per roof kind too; and the
   roof type attribute against the kind's type (:data:`ROOF_TYPE_OF_KIND`),
   right / total per density and the kinds typed wrong.
3. City3D dense roof-only clouds: footprint traced from the points, floor at
   the lowest point; time per building of LoD2.2 (roof code) and with the
   footprint tracing; roof types found (counts).

Sections 1 and 3 also print the count of each roof type found.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

# the roof type a modeller gives each synthetic kind (dormers do not change a gable,
# gables meeting in valleys are a cross gable, a flat roof with a parapet is flat)
ROOF_TYPE_OF_KIND = {"gable": "gable", "hip": "hip", "half_hip": "half_hip", "mansard": "mansard",
                     "L": "cross_gable", "T": "cross_gable", "U": "cross_gable", "dormer": "gable",
                     "stepped": "complex", "parapet": "flat"}


def type_counts(types):
    """``'gable 9, hip 5, ...'``: counts of each roof type, most frequent first."""
    kinds, counts = np.unique(np.asarray(types, dtype=str), return_counts=True)
    order = np.lexsort((kinds, -counts))
    return ", ".join(f"{kinds[i]} {counts[i]}" for i in order)


def option(name):
    """The value after ``--name`` on the command line, or None."""
    argv = sys.argv[1:]
    return argv[argv.index(name) + 1] if name in argv and argv.index(name) + 1 < len(argv) else None


def config():
    from lidar2city.roof.building import Lod22Config

    return Lod22Config(topology=option("--topology") or "arrangement",
                       step_snake="--no-step-snake" not in sys.argv[1:],
                       restore="--no-restore" not in sys.argv[1:],
                       select="--select" in sys.argv[1:],
                       raised_parts="--raised" in sys.argv[1:],
                       outline_tolerance=1.0 if "--outline" in sys.argv[1:] else 0.0)


def data_dir() -> Path:
    values = {option("--figure"), option("--topology")}
    args = [a for a in sys.argv[1:] if not a.startswith("--") and a not in ("delft", "synthetic", "city3d")
            and a not in values]
    if args:
        return Path(args[0])
    if os.environ.get("LIDAR2CITY_DATA"):
        return Path(os.environ["LIDAR2CITY_DATA"])
    return ROOT.parent / "shared" / "data"


def roof_height(solids, xy):
    """Height (N,) of the highest roof face above each point (x, y); NaN outside every face."""
    import shapely

    z = np.full(len(xy), np.nan)
    for s in solids:
        for surf in s.surfaces:
            if surf.semantic != "RoofSurface":
                continue
            v = s.vertices[surf.rings[0]]
            # Newell normal of the (planar) ring
            w = np.roll(v, -1, axis=0)
            n = np.array([np.sum((v[:, 1] - w[:, 1]) * (v[:, 2] + w[:, 2])),
                          np.sum((v[:, 2] - w[:, 2]) * (v[:, 0] + w[:, 0])),
                          np.sum((v[:, 0] - w[:, 0]) * (v[:, 1] + w[:, 1]))])
            if abs(n[2]) < 1e-9:
                continue
            inside = shapely.contains_xy(shapely.Polygon(v[:, :2]).buffer(1e-6), xy[:, 0], xy[:, 1])
            h = v[0, 2] - ((xy[inside, 0] - v[0, 0]) * n[0] + (xy[inside, 1] - v[0, 1]) * n[1]) / n[2]
            z[inside] = np.fmax(z[inside], h)
    return z


def error_sources(parts):
    """Share of the squared point-to-mesh error and median RMSE without each error class.

    ``parts``: per building ``(distances, points, roof height at the points, distance to the
    footprint outline, distance to another footprint)``."""
    classes = {"neighbour edge above our roof": [], "below our roof": [], "above our roof elsewhere": []}
    sq_total, sq_class = 0.0, dict.fromkeys(classes, 0.0)
    for dist, pts, zr, d_edge, d_other in parts:
        dz = pts[:, 2] - zr
        far = dist > 0.3
        nb = far & (d_edge < 0.3) & (d_other < 0.5) & (dz > 0.3)
        masks = {"neighbour edge above our roof": nb, "below our roof": far & (dz < -0.3),
                 "above our roof elsewhere": far & (dz > 0.3) & ~nb}
        sq_total += float(np.sum(dist ** 2))
        for k, m in masks.items():
            sq_class[k] += float(np.sum(dist[m] ** 2))
            classes[k].append(np.sqrt(np.mean(np.where(m, 0.0, dist) ** 2)))
    return {k: (sq_class[k] / max(sq_total, 1e-12), float(np.median(v))) for k, v in classes.items()}


def ceilings(parts, *, near=0.3, link=1.0, min_points=4, inner=1.0):
    """Median RMSE if a kind of error were modelled away exactly: what each way of improving
    the roof could reach at best (a diagnostic; the score is unchanged).

    Of the points more than ``near`` m from the model and not in the neighbour-edge class
    (:func:`error_sources`), clusters (linked within ``link`` m, at least ``min_points``)
    above the roof are chimneys, dormers and other roof parts; below it and more than
    ``inner`` m inside the outline, lower roof parts; the rest (single points, facade
    points within ``inner`` m of the outline, the neighbours' edges) no roof face can take.
    Points within ``near`` m of the model are what plane placement (refits, shifted
    step lines) can improve. Returns ``{ceiling: median RMSE}``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    keys = ("points near the model (plane placement, refits, step shifts)",
            "clusters above the roof (chimneys, dormers)",
            "clusters above + below the roof > 1 m inside the outline (roof parts)",
            "all three")
    out = {k: [] for k in keys}
    for dist, pts, zr, d_edge, d_other in parts:
        dz = pts[:, 2] - zr
        far = dist > near
        nb = far & (d_edge < 0.3) & (d_other < 0.5) & (dz > 0.3)
        idx = np.flatnonzero(far & ~nb)
        up, low = np.zeros(len(dist), bool), np.zeros(len(dist), bool)
        if len(idx) >= min_points:
            pairs = cKDTree(pts[idx]).query_pairs(link, output_type="ndarray")
            graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(idx),) * 2)
            n, lab = connected_components(graph, directed=False)
            big = np.bincount(lab, minlength=n)[lab] >= min_points
            med_dz = np.array([np.median(dz[idx[lab == c]]) for c in range(n)])
            med_edge = np.array([np.median(d_edge[idx[lab == c]]) for c in range(n)])
            up[idx[big & (med_dz[lab] > 0)]] = True
            low[idx[big & (med_dz[lab] <= 0) & (med_edge[lab] > inner)]] = True
        zero = {keys[0]: ~far, keys[1]: up, keys[2]: up | low, keys[3]: ~far | up | low}
        for k, m in zero.items():
            out[k].append(np.sqrt(np.mean(np.where(m, 0.0, dist) ** 2)))
    return {k: float(np.median(v)) for k, v in out.items()}


def delft_data(d):
    """The Delft tile's points, its BGT footprints (local metres) and the point classes."""
    from lidar2city.io.las import read_points
    from lidar2city.io.vector import read_footprints

    cloud = read_points(d / "ahn3_cropped_1.laz", crs="EPSG:7415")
    fps, _ = read_footprints(d / "footprints_bgt.gpkg", origin=cloud.origin[:2], target_crs=cloud.crs)
    return cloud, fps, cloud.get("classification")


def delft_models(cloud, fps, cfg):
    """LoD1.2 + LoD2.2 of every footprint with the ``[lod22]`` configuration ``cfg``."""
    from lidar2city.lod.lod1 import Lod1Config
    from lidar2city.tools.reconstruct import reconstruct_buildings

    return reconstruct_buildings(cloud, fps, config=Lod1Config(lods=("1.2",)), lod22=cfg)


def building_score(g, r, bxyz):
    """``(points, solids, point-to-mesh distances, (corners, short length, total length))`` of
    one building's LoD2.2 model: its class 6 points inside the footprint ``g`` against the
    solids of its result ``r``."""
    import shapely

    from lidar2city.lod.mesh import solid_triangles
    from lidar2city.metrics.model import point_mesh_distance
    from lidar2city.metrics.wireframe import roof_cleanliness, roof_wireframe

    pts = bxyz[shapely.contains_xy(g, bxyz[:, 0], bxyz[:, 1])]
    s22 = r.solids["2.2"]
    s22 = s22 if isinstance(s22, list) else [s22]
    dist = point_mesh_distance(pts, solid_triangles(s22))
    return pts, s22, dist, roof_cleanliness(roof_wireframe(s22))


def delft(d):
    import shapely

    from lidar2city.metrics.model import rmse
    from lidar2city.validate.solid import check_solid

    cloud, fps, cls = delft_data(d)
    results = delft_models(cloud, fps, config())
    bxyz = cloud.xyz[cls == 6]
    rms, corners, short, total, valid, faces, times, fallback = [], [], 0.0, 0.0, 0, 0, [], 0
    types, parts, solids = [], [], []
    tree = shapely.STRtree(fps.geometries)
    for g, r in zip(fps.geometries, results, strict=True):
        pts, s22, dist, (c, sh, tot) = building_score(g, r, bxyz)
        rms.append(rmse(dist))
        xy = shapely.points(pts[:, :2])
        others = [h for h in tree.query(g.buffer(1.0)) if fps.geometries[h] is not g]
        near = shapely.union_all([fps.geometries[h] for h in others]) if others else None
        parts.append((dist, pts, roof_height(s22, pts[:, :2]), shapely.distance(g.boundary, xy),
                      shapely.distance(near, xy) if near is not None else np.full(len(pts), np.inf)))
        solids.append(s22)
        fell = "lod22_fallback" in r.attributes
        valid += all(not check_solid(s) for s in s22) and not fell
        fallback += fell
        corners.append(c)
        short += sh
        total += tot
        faces += sum(surf.semantic == "RoofSurface" for s in s22 for surf in s.surfaces)
        times.append(r.attributes.get("lod22_time", 0.0))
        types.append(r.attributes.get("roof_type", "-"))
    n = len(results)
    print(f"Delft shared tile, {n} BGT footprints (AHN3 class 6 points inside each)")
    print(f"  median roof corners per building (turn > 10 deg): {np.median(corners):.1f}  (target <= 14)")
    print(f"  short-edge share (roof-face edge length in edges < 0.5 m): {100 * short / max(total, 1e-9):.2f} %"
          f"  (target <= 1.8 %)")
    print(f"  LoD2.2 RMSE point to mesh: median {np.median(rms):.3f} m  (target <= 0.15 m)")
    print("  where the squared error comes from (points > 0.3 m from the model; share of the squared "
          "error, median RMSE with that class at zero error):")
    for k, (share, med) in error_sources(parts).items():
        print(f"    {k}: {100 * share:.1f} %, median {med:.3f} m")
    print("  the best each kind of roof improvement could reach (median RMSE with that error at zero):")
    for k, med in ceilings(parts).items():
        print(f"    {k}: {med:.3f} m")
    print(f"  valid LoD2.2 solids {valid}/{n} (LoD1.2 fallbacks with a stated reason: {fallback}), "
          f"roof faces {faces}")
    print(f"  LoD2.2 time per building: median {1000 * np.median(times):.1f} ms, mean {1000 * np.mean(times):.1f} ms")
    print(f"  roof types: {type_counts(types)}")
    models = [r.attributes["roof_model"] for r in results if "roof_model" in r.attributes]
    if models:
        print(f"  models kept by [lod22] select: {type_counts(models)}")
    if "--band" in sys.argv[1:]:
        median_band(np.array(rms), np.array(corners), types, parts, solids, fps.geometries, bxyz)
    if option("--figure"):
        figure(Path(option("--figure")), cloud.xyz[cls == 6], fps.geometries, results)


#: the error sources of :func:`median_band`, in the order a point is given to the first that holds
BAND_SOURCES = ("neighbour edge above", "cluster above", "cluster below > 1 m in", "below near outline",
                "outline < 0.5 m", "step edge < 0.5 m", "intersection < 0.5 m", "other far", "near (< 0.3 m)")


def _interior_edges(solids, footprint, *, probe=0.05, level=0.1):
    """The roof-face edges of ``solids`` off the footprint outline, as ``(step, intersection)``
    lists of 2-D segments: a step edge has faces more than ``level`` m apart in height on
    its two sides (``probe`` m off its middle), an intersection edge does not."""
    import shapely

    step, inter = [], []
    for s in solids:
        for surf in s.surfaces:
            if surf.semantic != "RoofSurface":
                continue
            v = s.vertices[surf.rings[0]][:, :2]
            for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
                length = float(np.hypot(*(b - a)))
                m = (a + b) / 2
                if length < 1e-6 or footprint.boundary.distance(shapely.Point(m)) < probe:
                    continue
                nrm = np.array([a[1] - b[1], b[0] - a[0]]) / length
                z = roof_height(solids, np.array([m + probe * nrm, m - probe * nrm]))
                (step if not np.all(np.isfinite(z)) or abs(z[0] - z[1]) > level else inter).append((a, b))
    return step, inter


def _segment_distance(xy, segments):
    import shapely

    if not segments:
        return np.full(len(xy), np.inf)
    lines = shapely.multilinestrings([[tuple(a), tuple(b)] for a, b in segments])
    return shapely.distance(lines, shapely.points(xy))


def point_sources(dist, pts, zr, d_edge, d_other, solids, footprint, *, near=0.3, link=1.0, min_points=4,
                  inner=1.0, band=0.5):
    """The error source of each point of a building (index into :data:`BAND_SOURCES`).

    Points within ``near`` m of the model are ``near``; of the others, in this order: a
    neighbour's edge above our roof (as :func:`error_sources`), clusters (linked within
    ``link`` m, ``min_points`` or more, as :func:`ceilings`) above the roof, clusters below
    it with their median more than ``inner`` m inside the outline, clusters below it nearer
    the outline (facades set back, porches), then single points within ``band`` m of the
    outline, of a step edge, of an intersection edge, and the rest.

    Returns ``(source, cluster)``: the source of each point and its cluster's number
    (-1 for a point in no cluster of sources 2-4)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    dz = pts[:, 2] - zr
    far = dist > near
    nb = far & (d_edge < 0.3) & (d_other < 0.5) & (dz > 0.3)
    idx = np.flatnonzero(far & ~nb)
    up, low_in, low_out = (np.zeros(len(dist), bool) for _ in range(3))
    cluster = np.full(len(dist), -1)
    if len(idx) >= min_points:
        pairs = cKDTree(pts[idx]).query_pairs(link, output_type="ndarray")
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(idx),) * 2)
        n, lab = connected_components(graph, directed=False)
        big = np.bincount(lab, minlength=n)[lab] >= min_points
        # a point under no roof face (NaN) counts as below it
        med_dz = np.array([np.median(np.nan_to_num(dz[idx[lab == c]], nan=-1.0)) for c in range(n)])
        med_edge = np.array([np.median(d_edge[idx[lab == c]]) for c in range(n)])
        up[idx[big & (med_dz[lab] > 0)]] = True
        low_in[idx[big & (med_dz[lab] <= 0) & (med_edge[lab] > inner)]] = True
        low_out[idx[big & (med_dz[lab] <= 0) & (med_edge[lab] <= inner)]] = True
        cluster[idx[big]] = lab[big]
    step, inter = _interior_edges(solids, footprint)
    masks = (nb, up, low_in, low_out, d_edge < band, _segment_distance(pts[:, :2], step) < band,
             _segment_distance(pts[:, :2], inter) < band, np.ones(len(dist), bool))
    source = np.full(len(dist), len(BAND_SOURCES) - 1)
    rest = far.copy()
    for k, m in enumerate(masks):
        source[rest & m] = k
        rest &= ~m
    return source, np.where(np.isin(source, (1, 2, 3)), cluster, -1)


def _ideal_parts(dist, groups, corners, *, penalty=None, part_corners=2):
    """``(RMSE, corners)`` of a building whose point groups (``groups``: boolean masks over
    ``dist``) are modelled exactly, each at the cost of ``part_corners`` roof corners,
    taken largest gain first while ``n log(SSE / n) + penalty log(n) corners`` drops
    (``penalty`` None: the BIC of :func:`lidar2city.roof.building.bic`)."""
    from lidar2city.roof.building import CORNER_PARAMETERS

    p = CORNER_PARAMETERS if penalty is None else penalty
    n, sq = len(dist), dist ** 2
    sse = float(sq.sum())
    for g in sorted((float(sq[m].sum()) for m in groups), reverse=True):
        if g <= 0 or g >= sse or n * np.log((sse - g) / sse) + p * np.log(n) * part_corners >= 0:
            break
        sse, corners = sse - g, corners + part_corners
    return np.sqrt(sse / n), corners


def median_band(rms, corners, types, parts, solids, geoms, bxyz, *, target=0.15, upto=0.185, reach=0.8,
                level=0.3):
    """The buildings that decide the median RMSE and where their squared error is (a
    diagnostic; the score is unchanged).

    Prints how many buildings must fall to ``target`` or below for the median to get
    there, one row per building with ``target`` < RMSE <= ``upto`` (id, RMSE, corners,
    points, footprint area, roof type, share of its squared error per source of
    :func:`point_sources`), and per source over all buildings: the median RMSE with that
    source at zero error, and how many buildings then reach ``target``. Then how much of
    the largest source's squared error (a neighbour's edge above our roof) is in points
    with a building point (of ``bxyz``) outside the footprint within ``reach`` m across
    and ``level`` m in height (the neighbour's roof or wall going on over the line), and
    how far inside the line they lie. Last, ideal models (:func:`_ideal_parts`): the
    clusters above / below the roof, a strip at the neighbour's height along the shared
    edges, or both, modelled exactly at 2 corners a group, for several corner penalties:
    what the median RMSE and corners could be at best."""
    import shapely
    from scipy.spatial import cKDTree


    n = len(rms)
    need = n // 2 + 1  # the middle value (both, for an even n) at or below the target
    done = int(np.sum(rms <= target))
    print(f"  median band: {done}/{n} buildings at or below {target:.3f} m; the median needs "
          f"{need}: {max(need - done, 0)} more must drop")
    found = [point_sources(*p, s, g) for p, s, g in zip(parts, solids, geoms, strict=True)]
    src = [f[0] for f in found]
    print("    id   RMSE  corners points  area m2  roof type    % of its squared error: "
          + ", ".join(f"({k + 1}) {name}" for k, name in enumerate(BAND_SOURCES)))
    print("    " + " " * 57 + " ".join(f"{f'({k + 1})':>4}" for k in range(len(BAND_SOURCES))))
    for i in np.argsort(rms, kind="stable"):
        if not target < rms[i] <= upto:
            continue
        sq = parts[i][0] ** 2
        share = np.bincount(src[i], weights=sq, minlength=len(BAND_SOURCES)) / max(sq.sum(), 1e-12)
        print(f"    {i:3d}  {rms[i]:.3f}  {corners[i]:4d}  {len(sq):6d}  {geoms[i].area:7.0f}  {types[i]:11s} "
              + " ".join(f"{100 * v:4.0f}" for v in share))
    print(f"  per source, all {n} buildings: share of the squared error, median RMSE with it at zero, "
          f"buildings at or below {target:.3f} m then")
    sse = np.array([np.sum(p[0] ** 2) for p in parts])
    for k, name in enumerate(BAND_SOURCES):
        zeroed = np.array([np.sqrt(np.mean(np.where(s == k, 0.0, p[0]) ** 2)) for s, p in zip(src, parts)])
        share = sum(np.sum(p[0][s == k] ** 2) for s, p in zip(src, parts)) / sse.sum()
        print(f"    ({k + 1}) {name:24s} {100 * share:5.1f} %  {np.median(zeroed):.4f} m  {np.sum(zeroed <= target)}")
    tree = cKDTree(bxyz[:, :2])
    sq_nb, sq_on, depth = 0.0, 0.0, []
    for p, s, g in zip(parts, src, geoms, strict=True):
        for k in np.flatnonzero(s == 0):
            q = bxyz[tree.query_ball_point(p[1][k, :2], reach)]
            out = q[~shapely.contains_xy(g, q[:, 0], q[:, 1])]
            sq_nb += p[0][k] ** 2
            sq_on += p[0][k] ** 2 * bool(np.any(np.abs(out[:, 2] - p[1][k, 2]) <= level))
            depth.append(p[3][k])
    if depth:
        print(f"  of (1), {100 * sq_on / sq_nb:.0f} % of its squared error in points with a building point outside "
              f"the footprint within {reach} m across and {level} m in height; {len(depth)} points, "
              f"{np.median(depth):.2f} m inside the footprint line in the median (90 % within "
              f"{np.percentile(depth, 90):.2f} m)")
    kinds = {"clusters (2)-(4)": lambda s, c: [c == k for k in np.unique(c[c >= 0])],
             "neighbour strip (1)": lambda s, c: [s == 0],
             "both": lambda s, c: [c == k for k in np.unique(c[c >= 0])] + [s == 0]}
    print("  ideal models: each group modelled exactly at 2 corners (the least: a part clipped at the outline), "
          "taken while n log(SSE/n) + p log(n) corners drops (p 3 = BIC); median RMSE / median corners")
    for p in (3, 10, 20, 35, 50):
        cells = []
        for make in kinds.values():
            ideal = np.array([_ideal_parts(q[0], make(*f), c, penalty=p)
                              for q, f, c in zip(parts, found, corners, strict=True)])
            cells.append(f"{np.median(ideal[:, 0]):.4f} m / {np.median(ideal[:, 1]):.1f}")
        print(f"    p {p:2d}: " + ", ".join(f"{k} {v}" for k, v in zip(kinds, cells, strict=True)))


#: the [lod22] variants the Pareto table compares (name, Lod22Config keywords): every roof
#: model this code can produce by its options, each a candidate for the per-building choice
PARETO_VARIANTS = (("default", {}), ("grid partition", {"topology": "grid"}),
                   ("no restored facets", {"restore": False}), ("steps by angle", {"step_snake": False}),
                   ("short edges kept", {"min_edge": 0.0}), ("min facet 0.5 m2", {"min_facet_area": 0.5}),
                   ("min facet 2 m2", {"min_facet_area": 2.0}), ("dist_tol 0.15 m", {"dist_tol": 0.15}),
                   ("merge angle 5 deg", {"merge_angle": 5.0}), ("raised parts", {"raised_parts": True}),
                   ("outline straightened", {"outline_tolerance": 1.0}),
                   ("raised + outline", {"raised_parts": True, "outline_tolerance": 1.0}))


def pareto(d, ks=(0, 1, 2, 4, 8, 16, 32, 64, 128)):
    """Median corners against median RMSE of every variant in :data:`PARETO_VARIANTS` on Delft,
    the per-building best of them (the most any choice among them can reach), and the choice
    per building by one criterion, ``n log(SSE / n) + k corners`` (a BIC-like trade of fit for
    corners): ``k`` picked on the even-numbered footprints (the lowest median RMSE whose median
    corners stay <= 14 there), then scored on the odd ones and the whole tile."""
    from lidar2city.roof.building import Lod22Config

    cloud, fps, cls = delft_data(d)
    bxyz = cloud.xyz[cls == 6]
    rms, corners, npts = [], [], None
    print(f"Delft Pareto table ({len(fps.geometries)} footprints): variant, median corners, short-edge share, "
          "median RMSE, valid")
    for name, kw in PARETO_VARIANTS:
        results = delft_models(cloud, fps, Lod22Config(**kw))
        scored = [building_score(g, r, bxyz) for g, r in zip(fps.geometries, results, strict=True)]
        rms.append([np.sqrt(np.mean(x[2] ** 2)) for x in scored])
        corners.append([x[3][0] for x in scored])
        npts = np.array([len(x[0]) for x in scored])
        short = sum(x[3][1] for x in scored) / max(sum(x[3][2] for x in scored), 1e-9)
        fell = sum("lod22_fallback" in r.attributes for r in results)
        print(f"  {name:20s} {np.median(corners[-1]):5.1f}  {100 * short:5.2f} %  {np.median(rms[-1]):.4f} m"
              f"  {len(results) - fell}/{len(results)}")
    R, C = np.array(rms), np.array(corners, dtype=float)
    cols = np.arange(R.shape[1])
    best = np.argmin(R, axis=0)
    print(f"  per-building best of the {len(R)} (lowest RMSE): median corners {np.median(C[best, cols]):.1f}, "
          f"median RMSE {np.median(R[best, cols]):.4f} m")
    halves = {"tuning (even)": cols[0::2], "test (odd)": cols[1::2], "whole tile": cols}

    def choose(k, idx):
        cost = npts[idx] * np.log(R[:, idx] ** 2 + 1e-9) + k * C[:, idx]
        pick = np.argmin(cost, axis=0)
        return R[pick, idx], C[pick, idx]

    print("  choice per building by n log(SSE/n) + k corners: k, then median corners / RMSE on "
          + ", ".join(halves))
    for k in ks:
        meds = [[np.median(v) for v in choose(k, i)] for i in halves.values()]
        print(f"    k {k:4g}: " + ", ".join(f"{c:.1f} / {r:.4f}" for r, c in meds))
    names = [name for name, _ in PARETO_VARIANTS]
    sets = {"all": np.arange(len(R)),
            "[lod22] select's three": np.array([names.index(n) for n in ("default", "steps by angle",
                                                                          "min facet 2 m2")])}
    print("  choice per building by BIC, n log(SSE/n) + p log(n) corners (no constant fitted; "
          "[lod22] select uses p = 3): p, then median corners / RMSE on " + ", ".join(halves))
    for label, rows in sets.items():
        for p in (2, 3, 4):
            cost = npts * np.log(R[rows] ** 2 + 1e-9) + p * np.log(npts) * C[rows]
            pick = rows[np.argmin(cost, axis=0)]
            meds = [(np.median(R[pick[i], i]), np.median(C[pick[i], i])) for i in halves.values()]
            print(f"    {label}, p {p}: " + ", ".join(f"{c:.1f} / {r:.4f}" for r, c in meds))
    ok = [k for k in ks if np.median(choose(k, halves["tuning (even)"])[1]) <= 14]
    if ok:
        k = min(ok, key=lambda k: np.median(choose(k, halves["tuning (even)"])[0]))
        r_t, c_t = choose(k, halves["test (odd)"])
        r_a, c_a = choose(k, cols)
        print(f"  k chosen on the tuning half: {k:g}; test half: {np.median(c_t):.1f} corners, "
              f"{np.median(r_t):.4f} m (default there: {np.median(C[0, halves['test (odd)']]):.1f}, "
              f"{np.median(R[0, halves['test (odd)']]):.4f} m); whole tile {np.median(c_a):.1f} corners, "
              f"{np.median(r_a):.4f} m")


def figure(path, bxyz, geoms, results, size=70.0):
    """The densest ``size`` m square of the tile from above: building points by height beside
    our LoD2.2 roof faces (shaded by their facing) with their edges."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import shapely
    from matplotlib.collections import PolyCollection

    cent = np.array([g.centroid.coords[0] for g in geoms])
    counts = [np.sum(np.all(np.abs(cent - c) < size / 2, axis=1)) for c in cent]
    c0 = cent[int(np.argmax(counts))]
    lo, hi = c0 - size / 2, c0 + size / 2
    box = shapely.box(*lo, *hi)
    pts = bxyz[np.all((bxyz[:, :2] >= lo) & (bxyz[:, :2] <= hi), axis=1)]
    inside = shapely.contains_xy(shapely.union_all([g for g in geoms if g.intersects(box)]), pts[:, 0], pts[:, 1])
    pts = pts[inside]
    fig, ax = plt.subplots(1, 2, figsize=(10, 5.2))
    ax[0].scatter(pts[:, 0], pts[:, 1], c=pts[:, 2], s=1.2, cmap="viridis", linewidths=0)
    ax[0].set_title("AHN3 building points (height)", fontsize=10)
    polys, colours = [], []
    light = np.array([-1.0, 1.0, 1.5]) / np.linalg.norm([-1.0, 1.0, 1.5])
    for g, r in zip(geoms, results, strict=True):
        if not g.intersects(box):
            continue
        s22 = r.solids["2.2"]
        for s in (s22 if isinstance(s22, list) else [s22]):
            for surf in s.surfaces:
                if surf.semantic != "RoofSurface":
                    continue
                v = s.vertices[surf.rings[0]]
                n = np.cross(v[1] - v[0], v[2] - v[0])
                n = n / (np.linalg.norm(n) or 1.0)
                shade = 0.35 + 0.6 * max(float(n @ light), 0.0)
                polys.append(v[:, :2])
                colours.append((shade, shade * 0.8, shade * 0.7))
    ax[1].add_collection(PolyCollection(polys, facecolors=colours, edgecolors="k", linewidths=0.5))
    ax[1].set_title("lidar2city LoD2.2 roof faces", fontsize=10)
    for a in ax:
        a.set_xlim(lo[0], hi[0])
        a.set_ylim(lo[1], hi[1])
        a.set_aspect("equal")
        a.set_xticks([])
        a.set_yticks([])
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=72)
    plt.close(fig)
    print(f"  figure: {path} ({path.stat().st_size // 1024} kB)")


def synthetic():
    from lidar2city.metrics.wireframe import pooled_scores, roof_wireframe, wireframe_scores
    from lidar2city.roof.building import reconstruct_lod22
    from lidar2city.synthetic_roofs import ROOF_KINDS, roof_sample

    keys = ("corners_matched", "corners_pred", "corners_ref", "edges_matched", "edges_pred", "edges_ref")
    for density in (8.0, 25.0):
        total = dict.fromkeys(keys, 0)
        per_kind = {}
        n_fail, typed, wrong = 0, 0, []
        for kind in ROOF_KINDS:
            acc = dict.fromkeys(keys, 0)
            for seed in range(4):
                s = roof_sample(kind, density=density, seed=seed)
                try:
                    res = reconstruct_lod22(s.footprint, s.xyz, s.ground_z, config=config())
                except Exception:  # noqa: BLE001 - a failed roof scores zero matches
                    n_fail += 1
                    sc = {k: 0 for k in keys}
                    sc["corners_ref"], sc["edges_ref"] = len(s.wireframe.corners), len(s.wireframe.edges)
                else:
                    sc = wireframe_scores(roof_wireframe(res.solids), s.wireframe, tolerance=0.5)
                    found = res.attributes["roof_type"]
                    typed += found == ROOF_TYPE_OF_KIND[kind]
                    if found != ROOF_TYPE_OF_KIND[kind]:
                        wrong.append(f"{kind}#{seed} as {found}")
                for k in keys:
                    acc[k] += sc[k]
                    total[k] += sc[k]
            per_kind[kind] = pooled_scores(acc)
        p = pooled_scores(total)
        print(f"Synthetic roofs, {density:g} pts/m2, 3-5 cm noise, {len(ROOF_KINDS)} kinds x 4 seeds "
              f"({n_fail} failed): corner F1 {p['corner_f1']:.3f} (P {p['corner_precision']:.3f} "
              f"R {p['corner_recall']:.3f}), edge F1 {p['edge_f1']:.3f} (P {p['edge_precision']:.3f} "
              f"R {p['edge_recall']:.3f})  (targets >= 0.90 / >= 0.80)")
        print("    " + ", ".join(f"{k} {v['corner_f1']:.2f}/{v['edge_f1']:.2f}" for k, v in per_kind.items()))
        print(f"  roof type right {typed}/{4 * len(ROOF_KINDS)}" + (f" (wrong: {', '.join(wrong)})" if wrong else ""))


def city3d(folder):
    import shapely

    from lidar2city.footprints import extract_footprints
    from lidar2city.io.ply import read_ply
    from lidar2city.metrics.model import model_rmse
    from lidar2city.metrics.wireframe import roof_cleanliness, roof_wireframe
    from lidar2city.roof.building import reconstruct_lod22
    from lidar2city.validate.solid import check_solid

    files = sorted(folder.glob("*.ply"), key=lambda p: int(p.stem))
    clouds = [read_ply(f).xyz for f in files]
    t_roof, t_all, t_cpu, rms, valid, corners, types = [], [], [], [], 0, [], []
    for xyz in clouds:
        t0 = time.perf_counter()
        fps = extract_footprints(xyz, np.full(len(xyz), 6), regularize="snake")
        fp = shapely.union_all([x.polygon for x in fps])
        t1, c1 = time.perf_counter(), time.process_time()
        res = reconstruct_lod22(fp, xyz, float(xyz[:, 2].min()), config=config())
        t2 = time.perf_counter()
        t_cpu.append(time.process_time() - c1)
        t_roof.append(t2 - t1)
        t_all.append(t2 - t0)
        valid += all(not check_solid(s) for s in res.solids)
        inside = shapely.contains_xy(fp, xyz[:, 0], xyz[:, 1])
        rms.append(model_rmse(xyz[inside], res.solids))
        corners.append(roof_cleanliness(roof_wireframe(res.solids))[0])
        types.append(res.attributes["roof_type"])
    n = len(files)
    print(f"City3D roof-only clouds ({n}; footprint traced, floor = lowest point): valid {valid}/{n}, "
          f"RMSE median {np.median(rms):.3f} m, corners median {np.median(corners):.0f}")
    print(f"  time per building: LoD2.2 roof code mean {np.mean(t_roof):.3f} s (median {np.median(t_roof):.3f}, "
          f"max {np.max(t_roof):.3f}); with footprint tracing mean {np.mean(t_all):.3f} s  (target <= 0.3 s)")
    print(f"  roof code CPU time per building (what load does not inflate): mean {np.mean(t_cpu):.3f} s")
    print(f"  roof types: {type_counts(types)}")


def main():
    sys.path.insert(0, str(ROOT / "src"))
    if "--pareto" in sys.argv[1:]:
        pareto(data_dir() / "delft")
        return
    only = next((a for a in sys.argv[1:] if a in ("delft", "synthetic", "city3d")), None)
    if only in (None, "delft"):
        delft(data_dir() / "delft")
    if only in (None, "synthetic"):
        synthetic()
    if only in (None, "city3d"):
        city3d(data_dir() / "city3d" / "building_instances")


if __name__ == "__main__":
    main()
