"""Building / vegetation separation on the shared real data.

Prints per file the building and vegetation precision / recall / F1 and the
time of :func:`lidar2city.classify.classify_points`, twice: with the file's
own ground class as the ground mask, and with a simple stand-in ground filter
(lowest point per 1 m cell, grey opening of 25 m, points within 0.5 m of the
opened surface and 1 m of the cell minimum) so the dependence on the ground
mask is known (the stand-in needs a tile much wider than its 25 m window: on
the 18 m x 12 m Nebraska sample it is not meaningful). Then the Delft tile
thinned at random to 1/2, 1/4 and 1/8 of its density, with and without
return numbers, for the dependence on density and on the return cue.

Then surveys of other kinds, from raw tiles (ground from
:func:`lidar2city.ground.ground_mask`, the default filter): the ISPRS Stuttgart
sites (first and last pulse as separate points, no reference classes: the
share of first-pulse points called building, and how the return fields were
read), and the synthetic town re-written as other surveys would record it
(:mod:`lidar2city.synthetic_surveys`: first/last-pulse pairs in file order and
shuffled, single returns, no return fields, feet through a LAS file, 1.5, 25,
35 and 50 pts/m2, scan lines 8 x closer along than across at 4, 10 and 20 pts/m2) with
building precision / recall / F1 against its truth.
``--png PATH`` also draws CSite4's classes (docs/classify_csite4.png);
``--nebraska-png PATH`` draws where the Nebraska sample's building points are
missed, which are as dark as the leaves, and the reference's building share per
0.3 m column against our outline (docs/classify_nebraska_misses.png; the
breakdown by cause, with see-through and intensity tests, and the test of a
2-D labelling are always printed). How Delft's and Nebraska's references label
the canopy over and beside roofs, and what labelling every point of our outline
building would score on each, is printed after the Nebraska breakdown;
``--reconstruct`` also runs ``lidar2city reconstruct`` on CSite4 without
footprints (LoD2.2) and validates the result (~10 min on 2 busy cores);
``--scan-lines`` also reconstructs the synthetic town recorded in scan lines 8:1
(10 pts/m2) without footprints, LoD1.2 + 1.3 + 2.2: models, truth buildings
matched at IoU >= 0.5 by a LoD1.2 footprint, validity.

Reference mappings: AHN (Delft) class 6 building, class 1 "unclassified
(vegetation and other)" counted as vegetation, 9 water and 26 civil
structures ignored; ASPRS files 3/4/5 vegetation, 6 building, 7 noise ignored.

Run: ``PYTHONPATH=src python benchmarks/bench_classify.py [DATA_DIR] [--png PATH]
[--nebraska-png PATH] [--reconstruct]``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

from lidar2city.classify import classify_points, point_spacing
from lidar2city.io.las import read_points
from lidar2city.metrics.classification import ASPRS_MAPPING, classification_scores

AHN = {6: "building", 1: "vegetation", 2: "ground"}

FILES = [
    # path, crs, reference mapping, ignored reference codes
    ("delft/ahn3_cropped_1.laz", "EPSG:7415", AHN, (9, 26)),
    ("misc/file_with_both_wkt_and_geotiff_vlrs.las", None, ASPRS_MAPPING, (7,)),
    ("misc/autzen_trim.laz", None, None, ()),
]


def stand_in_ground(xyz, *, cell=1.0, window=25.0, tol=0.5):
    """A crude one-window morphological ground filter (not the project's ground filter)."""
    from scipy import ndimage

    ij = np.floor((xyz[:, :2] - xyz[:, :2].min(axis=0)) / cell).astype(np.int64)
    shape = ij.max(axis=0) + 1
    zmin = np.full(shape, np.inf)
    np.minimum.at(zmin, (ij[:, 0], ij[:, 1]), xyz[:, 2])
    empty = ~np.isfinite(zmin)
    _, (a, b) = ndimage.distance_transform_edt(empty, return_indices=True)
    zmin = zmin[a, b]
    w = int(window / cell) | 1
    opened = ndimage.grey_opening(zmin, size=(w, w))
    surf = opened[ij[:, 0], ij[:, 1]]
    cellmin = zmin[ij[:, 0], ij[:, 1]]
    return (xyz[:, 2] - surf < tol) & (xyz[:, 2] - cellmin < 1.0)


def main(data: Path):
    print(f"{'file':<44} {'ground':<9} {'class':<10} {'P':>6} {'R':>6} {'F1':>6} {'time s':>7}")
    for rel, crs, mapping, ignore in FILES:
        path = data / rel
        if not path.exists():
            print(f"{rel}: missing, skipped")
            continue
        cloud = read_points(path, crs=crs)
        a = cloud.attributes
        ref = a["classification"]
        rgb = None
        if all(k in a for k in ("red", "green", "blue")):
            rgb = np.column_stack([a["red"], a["green"], a["blue"]])
        for gname, ground in (("file", ref == 2), ("stand-in", stand_in_ground(cloud.xyz))):
            t0 = time.perf_counter()
            cls = classify_points(cloud.xyz, ground, return_number=a.get("return_number"),
                                  number_of_returns=a.get("number_of_returns"), rgb=rgb)
            dt = time.perf_counter() - t0
            if mapping is None:
                counts = dict(zip(*np.unique(cls, return_counts=True), strict=True))
                print(f"{rel:<44} {gname:<9} (no building/vegetation reference) classes "
                      + ", ".join(f"{int(k)}: {int(v)}" for k, v in counts.items())
                      + f"  {dt:7.2f}")
                continue
            s = classification_scores(ref, cls, mapping=mapping, predicted_mapping=ASPRS_MAPPING,
                                      ignore=ignore)
            for k in ("building", "vegetation"):
                print(f"{rel:<44} {gname:<9} {k:<10} {s.precision[k]:6.3f} {s.recall[k]:6.3f} "
                      f"{s.f1[k]:6.3f} {dt:7.2f}")
            print(f"{'':<44} {gname:<9} overall accuracy {s.overall_accuracy:.3f}, "
                  f"kappa {s.kappa:.3f}")


NEBRASKA = "misc/file_with_both_wkt_and_geotiff_vlrs.las"


def _prf(pred, bld, valid, *, text=True):
    """Building precision, recall and F1 of the mask ``pred`` against the reference mask ``bld``."""
    tp = int((pred & bld).sum())
    fp = int((pred & ~bld & valid).sum())
    p, r = tp / max(tp + fp, 1), tp / max(int(bld.sum()), 1)
    f1 = 2 * p * r / max(p + r, 1e-12)
    return f"precision {p:.3f}, recall {r:.3f}, F1 {f1:.3f}" if text else f1


def _in_outline(xyz, out, *, dilate=0.0, shift=(0.0, 0.0)):
    """Whether each point lies in the classifier's building outline (its building grid),
    dilated by ``dilate`` metres and shifted by ``shift`` (dx, dy) metres."""
    from scipy import ndimage

    grid, cell = out["building_grid"], out["cell"]
    x0, y0 = out["grid_origin"]
    if dilate > 0:
        grid = ndimage.distance_transform_edt(~grid) * cell <= dilate
    j = np.floor((xyz[:, 0] - x0 - shift[0]) / cell).astype(np.int64)
    i = np.floor((xyz[:, 1] - y0 - shift[1]) / cell).astype(np.int64)
    ok = (i >= 0) & (i < grid.shape[0]) & (j >= 0) & (j < grid.shape[1])
    inside = np.zeros(len(xyz), bool)
    inside[ok] = grid[i[ok], j[ok]]
    return inside


def canopy_over_roofs(data: Path):
    """How each reference labels the canopy over and beside roofs, and what labelling
    every point of our outline building (at every height) would score on both.

    Per file (Delft: AHN classes, ground = class 2; Nebraska: ASPRS classes): the
    object points inside our building outline more than ``roof_tolerance`` above
    the roof (not on a roof plane), and those in the 0.5 m ring round it above
    the roof, split by reference class; then the building F1 of our classes, and
    of our classes plus every object point from 0.5 m up in the outline dilated
    by 0, 0.5 and 1 m.
    """
    from lidar2city.classify.core import _classify

    print("\nCanopy over and beside roofs: how the references label it (points of our outline "
          "more than 1 m above the roof, off the roof planes; reference building / vegetation)")
    for rel, crs, veg_codes, ignore in (("delft/ahn3_cropped_1.laz", "EPSG:7415", (1,), (9, 26)),
                                        (NEBRASKA, None, (3, 4, 5), (7,))):
        path = data / rel
        if not path.exists():
            continue
        cloud = read_points(path, crs=crs)
        a = cloud.attributes
        ref = a["classification"]
        out = _classify(cloud.xyz, ref == 2, return_number=a["return_number"],
                        number_of_returns=a["number_of_returns"])
        cls, hag, oi = out["classes"], out["hag"], out["obj_idx"]
        flags = {}
        for key in ("seed", "in_building", "in_zone", "above_roof"):
            flags[key] = np.zeros(len(ref), bool)
            flags[key][oi] = out[key]
        bld, veg, valid = ref == 6, np.isin(ref, veg_codes), ~np.isin(ref, ignore)
        over = flags["above_roof"] & ~flags["seed"]
        inside, ring = over & flags["in_building"], over & flags["in_zone"] & ~flags["in_building"]
        obj = valid & (ref != 2) & (hag >= 0.5)
        f1 = [_prf((cls == 6) | (obj & _in_outline(cloud.xyz, out, dilate=d)), bld, valid,
                   text=False) for d in (0.0, 0.5, 1.0)]
        rules = ", ".join(f"dilated {d:g} m {f:.3f}" for d, f in zip((0.0, 0.5, 1.0), f1,
                                                                      strict=True))
        print(f"  {rel:<44} over the roof {int((inside & bld).sum())} / "
              f"{int((inside & veg).sum())}, "
              f"in the ring above it {int((ring & bld).sum())} / {int((ring & veg).sum())}; "
              f"building F1 ours {_prf(cls == 6, bld, valid, text=False):.3f}, every object point "
              f"of the outline: {rules}")


def nebraska_misses(data: Path, png=None):
    """Where the Nebraska sample's reference building points are missed, and why.

    Every missed building point (reference 6, called something else; ground =
    the file's class 2) goes to the first of: under ``min_height`` (2 m) above
    the terrain; more than 1 m above the roof (the highest smooth building
    point called building within 1 m horizontally); rough (local residual above
    3 times the median of the building points found: canopy-like); the rest
    (smooth at roof level: roof edges, small buildings, our misses). Also the local residual of hits,
    misses and reference high vegetation, and the share with a reference
    vegetation point within 0.3 m. ``png``: top view and two vertical slices.
    """
    from scipy.spatial import cKDTree

    from lidar2city.classify.core import _classify

    path = data / NEBRASKA
    if not path.exists():
        return
    cloud = read_points(path)
    a = cloud.attributes
    ref = a["classification"]
    xyz = cloud.xyz
    out = _classify(xyz, ref == 2, return_number=a["return_number"],
                    number_of_returns=a["number_of_returns"])
    cls, hag = out["classes"], out["hag"]
    res = np.full(len(xyz), np.nan)
    res[out["obj_idx"]] = out["residual"]
    bld = ref == 6
    hit, miss = bld & (cls == 6), bld & (cls != 6)
    # rough: a local residual 3 times that of the typical building point found
    smooth_res = 3.0 * np.nanmedian(res[hit])
    rough = ~(res <= smooth_res)
    false = (cls == 6) & ~bld & (ref != 7)
    smooth_roof = hit & ~rough
    tree = cKDTree(xyz[smooth_roof, :2])
    roof_z = np.full(len(xyz), -np.inf)
    for i, nb in zip(np.flatnonzero(miss), tree.query_ball_point(xyz[miss, :2], 1.0), strict=True):
        if nb:
            roof_z[i] = xyz[smooth_roof][nb, 2].max()
    low = miss & (hag < 2.0)
    above = miss & ~low & (xyz[:, 2] > roof_z + 1.0)
    rough_m = miss & ~low & ~above & rough
    rest = miss & ~low & ~above & ~rough_m
    veg = np.isin(ref, (3, 4, 5))
    d_veg, _ = cKDTree(xyz[veg]).query(xyz, k=1)
    print(f"\nNebraska sample ({len(xyz)} points, single returns, ground = file class 2): "
          f"{int(bld.sum())} building points, {int(hit.sum())} found, {int(miss.sum())} missed, "
          f"{int(false.sum())} false")
    print(f"  missed: {int(low.sum())} under 2 m above the terrain, {int(above.sum())} more than "
          f"1 m above the roof beside them, {int(rough_m.sum())} rough at roof level, "
          f"{int(rest.sum())} smooth at roof level")
    best = hit.sum() + rest.sum()
    print(f"  upper bound with every smooth miss found and no false building: precision 1, "
          f"recall {best / bld.sum():.3f}, F1 {2 * best / (best + bld.sum()):.3f}")
    high_veg = ref == 5
    for name, m in (("found", hit), ("missed", miss), ("false", false),
                    ("ref. high vegetation", high_veg)):
        print(f"  {name:<21} local residual median {np.nanmedian(res[m]):.3f} m "
              f"(rough above {smooth_res:.3f}): rough {np.mean(rough[m]):.2f}, "
              f"ref. vegetation within 0.3 m {np.mean(d_veg[m] < 0.3):.2f}")
    seed, dark = _nebraska_causes(xyz, ref, a["intensity"], out, res)
    columns, best_shift = _nebraska_columns(xyz, ref, hag, out)
    if png is None:
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    other = ~(hit | miss | false)
    fig, axes = plt.subplots(3, 3, figsize=(16, 13.8), gridspec_kw={"width_ratios": [1.4, 1, 1]})
    lower, third = axes[1], axes[2]
    axes = axes[0]
    groups = ((other & (ref == 2), "ground", "tan", 0.5),
              (other & veg, "ref. vegetation", "yellowgreen", 0.8),
              (hit, "building found", "red", 1.5), (miss, "building missed", "blue", 2.5),
              (false, "vegetation called building", "orange", 2.5))
    z0 = xyz[:, 2].min()

    def draw(row, groups, slices, title, *, top=True):
        """Top view (highest on top) and two vertical slices of the point groups."""
        for m, label, colour, size in groups if top else ():
            order = np.flatnonzero(m)[np.argsort(xyz[m, 2])]
            row[0].scatter(xyz[order, 0], xyz[order, 1], s=size, c=colour, label=label, lw=0)
        row[0].set_title(title, fontsize=9)
        for ax, (axis, lo, hi) in zip(row[1:], slices, strict=True):
            sl = (xyz[:, axis] >= lo) & (xyz[:, axis] < hi)
            u = 1 - axis
            for m, label, colour, size in groups:
                mm = m & sl
                ax.scatter(xyz[mm, u], xyz[mm, 2] - z0, s=size + 1, c=colour, lw=0, label=label)
            ax.set_title(f"vertical slice {'xy'[axis]} {lo:g}-{hi:g} m", fontsize=9)
            ax.set_xlabel(f"{'xy'[u]} (m)")
            ax.set_ylabel("height (m)")

    draw(axes, groups, ((0, 0.5, 1.5), (1, 5.0, 6.0)), "top view (highest on top)")
    # what the reference building points are: bright roof planes vs points as
    # dark as the leaves (intensity under the 5th percentile of the roof planes')
    kinds = ((other & veg, "ref. vegetation", "yellowgreen", 0.8),
             (bld & seed, "ref. building on a roof plane found", "red", 1.5),
             (bld & ~seed & dark, "ref. building off the roof planes, dark", "purple", 2.5),
             (bld & ~seed & ~dark, "ref. building off the roof planes, bright", "black", 2.5))
    draw(lower, kinds, ((1, 1.0, 2.0), (0, 14.0, 15.0)),
         "reference building points: roof planes and dark points")
    # the reference labels by 2-D position: share of building per column, our outline
    inside = _in_outline(xyz, out)
    sides = ((ref == 2, "ground", "tan", 0.5),
             (veg & ~inside, "ref. vegetation", "yellowgreen", 0.8),
             (veg & inside, "ref. vegetation in our outline", "darkgreen", 1.5),
             (bld & inside, "ref. building in our outline", "red", 1.5),
             (bld & ~inside, "ref. building outside it", "blue", 2.5))
    draw(third, sides, ((0, 2.0, 3.0), (1, 6.5, 7.5)),
         f"reference building share per {_COLUMN:g} m column (points from 0.5 m up)\n"
         f"black: our outline; dashed: shifted by {best_shift} m (best)", top=False)
    nrow, ncol = columns.shape
    im = third[0].imshow(columns, origin="lower", extent=(0, ncol * _COLUMN, 0, nrow * _COLUMN),
                         cmap="coolwarm_r", vmin=0, vmax=1, interpolation="nearest")
    fig.colorbar(im, ax=third[0], fraction=0.03)
    grid, cell = out["building_grid"], out["cell"]
    gx = out["grid_origin"][0] + (np.arange(grid.shape[1]) + 0.5) * cell
    gy = out["grid_origin"][1] + (np.arange(grid.shape[0]) + 0.5) * cell
    third[0].contour(gx, gy, grid.astype(float), levels=[0.5], colors="k")
    third[0].contour(gx + best_shift[0], gy + best_shift[1], grid.astype(float), levels=[0.5],
                     colors="k", linestyles="dashed")
    third[0].set_xlim(0, ncol * _COLUMN)
    third[0].set_ylim(0, nrow * _COLUMN)
    for ax in (*axes, *lower, *third):
        ax.set_aspect("equal")
    for ax in (axes[0], lower[0], third[1]):
        ax.legend(fontsize=7, markerscale=4, loc="upper right" if ax is third[1] else "upper left")
    fig.suptitle("Nebraska sample: reference building points missed (blue) and where they are "
                 "(top); which are roof planes and which are as dark as the leaves (middle);\n"
                 "the reference labels by 2-D position, its building columns reaching over open "
                 "ground beside the roofs (bottom)", fontsize=10)
    fig.tight_layout()
    fig.savefig(png, dpi=80)
    plt.close(fig)
    print(f"  figure written to {png}")


def _nebraska_causes(xyz, ref, intensity, out, res):
    """Per-cause breakdown of the Nebraska sample's reference building points.

    Every point goes to the first of: under 2 m above the terrain; on a roof
    plane found (a seed region); inside the building outline (the grid of
    closed roof seeds) at most 1 m above the roof; inside it more than 1 m
    above the roof; in the edge ring (0.5 m) around the outline; beyond. Per
    cause: the reference building points found / missed, the reference
    vegetation called building there, and two physical tests of what the
    points are: "see-through" (a non-ground point at least 2 m lower lies
    within 0.3 m horizontally: the pulses went on through them, so they are
    no opaque roof) and the intensity (median; the roof planes' points are
    bright, leaves and twigs dark). Then the scores of the two consistent
    ways to treat the see-through, dark points near roofs.
    """
    from scipy.spatial import cKDTree

    cls, hag, oi = out["classes"], out["hag"], out["obj_idx"]

    def on_all(key):
        v = np.zeros(len(xyz), bool)
        v[oi] = out[key]
        return v

    seed, in_bld, in_zone, above = (on_all(k) for k in ("seed", "in_building", "in_zone",
                                                          "above_roof"))
    valid = ref != 7
    bld, pb = ref == 6, cls == 6
    veg = np.isin(ref, (3, 4, 5))
    obj = valid & (ref != 2)
    tree = cKDTree(xyz[obj, :2])
    z_obj = xyz[obj, 2]
    see_through = np.zeros(len(xyz), bool)
    for i in np.flatnonzero((bld | pb | veg) & valid & (hag >= 2.0)):
        nb = tree.query_ball_point(xyz[i, :2], 0.3)
        see_through[i] = bool(np.any(z_obj[nb] < xyz[i, 2] - 2.0))
    intensity = np.asarray(intensity, dtype=np.float64)
    # "dark": below the 5th percentile of the intensity of the roof planes found
    dark = intensity < np.percentile(intensity[seed], 5)
    low = hag < 2.0
    causes = (("under 2 m above the terrain", low),
              ("on a roof plane found (seed)", ~low & seed),
              ("in the outline, <= 1 m above the roof", ~low & ~seed & in_bld & ~above),
              ("in the outline, > 1 m above the roof", ~low & ~seed & in_bld & above),
              ("in the 0.5 m ring round the outline", ~low & ~seed & in_zone & ~in_bld),
              ("beyond the outline", ~low & ~seed & ~in_zone))
    print("  reference building points by cause (first that applies; see-through: a non-ground "
          "point >= 2 m lower within 0.3 m):")
    print(f"    {'cause':<40} {'ref bld':>7} {'found':>6} {'missed':>6} {'false':>6} "
          f"{'see-through':>11} {'dark':>5} {'intensity':>9} {'residual':>8}")
    for name, m in causes:
        mb = m & bld
        print(f"    {name:<40} {int(mb.sum()):7d} {int((mb & pb).sum()):6d} "
              f"{int((mb & ~pb).sum()):6d} {int((m & pb & ~bld & valid).sum()):6d} "
              f"{np.mean(see_through[mb]) if mb.any() else 0:11.2f} "
              f"{np.mean(dark[mb]) if mb.any() else 0:5.2f} "
              f"{np.median(intensity[mb]) if mb.any() else 0:9.0f} "
              f"{np.nanmedian(res[mb]) if mb.any() else 0:8.3f}")
    hv = (ref == 5) & (hag >= 2.0)
    print(f"    {'(reference high vegetation)':<40} {int(hv.sum()):7d} {'':>6} {'':>6} "
          f"{int((hv & pb).sum()):6d} {np.mean(see_through[hv]):11.2f} {np.mean(dark[hv]):5.2f} "
          f"{np.median(intensity[hv]):9.0f} {np.nanmedian(res[hv]):8.3f}")

    def score(pred):
        return _prf(pred, bld, valid)

    canopy = ~seed & see_through & dark
    print(f"  ours: {score(pb)}; see-through and dark (intensity under the 5th percentile of "
          f"the roof planes', {int(np.percentile(intensity[seed], 5))}): {int((canopy & bld).sum())} "
          f"reference building points, {int((canopy & veg).sum())} reference vegetation")
    print(f"  the same classes but see-through dark points never building: {score(pb & ~canopy)}; "
          f"every point of the outline and its ring from {0.5:g} m up building: "
          f"{score(pb | (in_zone & (hag >= 0.5) & valid))}")
    # does any simple distance rule tell the reference's building canopy from its vegetation?
    d, _ = cKDTree(xyz[seed, :2]).query(xyz[:, :2])
    rest = ~seed & (hag >= 2.0) & valid
    bands = (0.0, 0.25, 0.5, 1.0, 1.5, 2.0, np.inf)
    print("  points above 2 m off the roof planes, by horizontal distance to the nearest "
          "roof-plane point (reference building / vegetation): " + ", ".join(
              f"{lo:g}-{hi:g} m {int((rest & bld & (d >= lo) & (d < hi)).sum())}"
              f"/{int((rest & veg & (d >= lo) & (d < hi)).sum())}"
              for lo, hi in zip(bands[:-1], bands[1:], strict=True)))
    return seed, dark


#: Column size (m) of the test of a 2-D labelling (point spacing 0.09 m: ~10 points a column).
_COLUMN = 0.3


def _nebraska_columns(xyz, ref, hag, out):
    """Does the Nebraska reference label by 2-D position (a footprint polygon) or in 3-D?

    Object points from 0.5 m up are binned into ``_COLUMN`` (m) columns: the share
    lying in a column of one reference class (building or vegetation), and the
    building F1 of the best possible 2-D labelling (each column its majority
    class). Then the F1 of labelling every object point in our outline building,
    with the outline shifted by up to 2 m (0.25 m steps): the best shift, and
    where the reference's building columns lie that our outline plus 0.5 m does
    not reach (ground seen below them: no roof under the canopy there).

    Returns the building share per column (NaN where empty) and the best shift.
    """
    from scipy.spatial import cKDTree

    bld, veg, valid = ref == 6, np.isin(ref, (3, 4, 5)), ref != 7
    obj = valid & (ref != 2) & (hag >= 0.5)
    ij = np.floor(xyz[:, :2] / _COLUMN).astype(np.int64)
    ncol, nrow = ij.max(axis=0) + 1
    key = ij[:, 1] * ncol + ij[:, 0]
    nb = np.bincount(key[obj & bld], minlength=nrow * ncol)
    nv = np.bincount(key[obj & veg], minlength=nrow * ncol)
    pure = np.where((nb > 0) & (nv > 0), 0, nb + nv).sum() / max((nb + nv).sum(), 1)
    majority = np.maximum(nb, nv).sum() / max((nb + nv).sum(), 1)
    column_bld = (nb > nv)[key]
    share = np.where(nb + nv > 0, nb / np.maximum(nb + nv, 1), np.nan).reshape(nrow, ncol)
    print(f"  2-D or 3-D labelling? {pure:.3f} of the object points from 0.5 m up lie in "
          f"{_COLUMN:g} m columns holding one reference class ({majority:.3f} share their "
          f"column's majority class); the best 2-D labelling (each "
          f"column its majority class): {_prf(obj & column_bld, bld, valid)}")
    seed = np.zeros(len(xyz), bool)
    seed[out["obj_idx"]] = out["seed"]
    steps = np.arange(-2.0, 2.0001, 0.25)
    f1 = np.array([[_prf(seed | (obj & _in_outline(xyz, out, shift=(dx, dy))), bld, valid,
                         text=False) for dx in steps] for dy in steps])
    iy, ix = np.unravel_index(np.argmax(f1), f1.shape)
    zero = int(np.argmin(np.abs(steps)))
    best = (float(steps[ix]), float(steps[iy]))
    print(f"  every object point from 0.5 m up in our outline building: F1 {f1[zero, zero]:.3f}; "
          f"with the outline shifted by ({best[0]:+g}, {best[1]:+g}) m, the best shift: "
          f"{f1[iy, ix]:.3f}")
    beyond = obj & column_bld & ~_in_outline(xyz, out, dilate=0.5)
    cols = np.unique(key[beyond])
    # a roof hidden under the canopy would show through its gaps as the terrain does
    _, near = cKDTree(xyz[seed, :2]).query(xyz[:, :2])
    at_roof = obj & (np.abs(xyz[:, 2] - xyz[seed, 2][near]) < 0.75)
    print(f"  reference building columns beyond our outline + 0.5 m: "
          f"{len(cols) * _COLUMN ** 2:.1f} m2, {int((beyond & bld).sum())} reference building / "
          f"{int((beyond & veg).sum())} vegetation "
          f"points; terrain points seen in {np.isin(cols, key[ref == 2]).mean():.0%} of those "
          f"columns, a point at roof height (within 0.75 m of the nearest roof plane point's) in "
          f"{np.isin(cols, key[at_roof]).mean():.0%}: canopy over open ground, no hidden roof")
    return share, best


def density_sweep(data: Path):
    """Delft thinned at random to lower densities, with and without return numbers."""
    path = data / "delft" / "ahn3_cropped_1.laz"
    if not path.exists():
        return
    cloud = read_points(path, crs="EPSG:7415")
    a = cloud.attributes
    rng = np.random.default_rng(0)
    u = rng.random(len(cloud))
    print("\nDelft thinned at random (ground = AHN class 2):")
    print(f"{'keep':>5} {'pts/m2':>7} {'returns':<8} {'bld P':>6} {'bld R':>6} {'bld F1':>6} "
          f"{'veg P':>6} {'veg R':>6} {'veg F1':>6} {'time s':>7}")
    for keep in (1.0, 0.5, 0.25, 0.12):
        sel = u < keep
        ref = a["classification"][sel]
        for returns in (True, False):
            t0 = time.perf_counter()
            cls = classify_points(
                cloud.xyz[sel], ref == 2,
                return_number=a["return_number"][sel] if returns else None,
                number_of_returns=a["number_of_returns"][sel] if returns else None)
            dt = time.perf_counter() - t0
            s = classification_scores(ref, cls, mapping=AHN, predicted_mapping=ASPRS_MAPPING,
                                      ignore=(9, 26))
            print(f"{keep:5.2f} {16.1 * keep:7.1f} {'yes' if returns else 'no':<8} "
                  f"{s.precision['building']:6.3f} {s.recall['building']:6.3f} "
                  f"{s.f1['building']:6.3f} {s.precision['vegetation']:6.3f} "
                  f"{s.recall['vegetation']:6.3f} {s.f1['vegetation']:6.3f} {dt:7.2f}")


ISPRS_SITES = ("CSite1_red2-utm.laz", "CSite2_orig-utm.laz", "CSite3_orig-utm.laz",
               "CSite4_orig-utm.laz", "FSite5_orig-utm.laz")

#: colours of the class image (ASPRS code -> RGB)
COLOURS = {1: (150, 150, 230), 2: (220, 205, 165), 3: (160, 225, 130), 4: (80, 185, 80),
           5: (25, 120, 25), 6: (210, 40, 25), 7: (0, 0, 0)}


def _raw_classes(cloud):
    """Ground filter, then classification with the cloud's own fields (a raw tile)."""
    from lidar2city.classify.core import _classify
    from lidar2city.ground import ground_mask

    a = cloud.attributes
    ground = ground_mask(cloud.xyz)
    return _classify(cloud.xyz, ground, return_number=a.get("return_number"),
                     number_of_returns=a.get("number_of_returns"), intensity=a.get("intensity"))


def class_image(xyz, classes, path, *, cell=1.0, title=""):
    """PNG of the class of the highest point per ``cell`` (m) grid cell, with a legend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    ij = np.floor((xyz[:, :2] - xyz[:, :2].min(axis=0)) / cell).astype(np.int64)
    ncol, nrow = ij.max(axis=0) + 1
    order = np.lexsort((xyz[:, 2],))  # lowest first: the highest point of a cell wins
    img = np.full((nrow, ncol, 3), 255, np.uint8)
    lut = np.full((256, 3), 255, np.uint8)
    for k, rgb in COLOURS.items():
        lut[k] = rgb
    code = np.zeros((nrow, ncol), np.uint8)
    code[ij[order, 1], ij[order, 0]] = classes[order]
    # scan-line gaps: empty cells take the nearest cell's class up to 2 cells away
    from scipy import ndimage

    dist, (a, b) = ndimage.distance_transform_edt(code == 0, return_indices=True)
    code = np.where(dist <= 2, code[a, b], 0)
    img[code > 0] = lut[code[code > 0]]
    names = {1: "other", 2: "ground", 3: "low veg.", 4: "medium veg.", 5: "high veg.",
             6: "building", 7: "noise"}
    fig, ax = plt.subplots(figsize=(7, 7 * nrow / ncol + 0.6))
    ax.imshow(img, origin="lower", extent=(0, ncol * cell, 0, nrow * cell), interpolation="nearest")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=9)
    present = sorted(set(np.unique(classes).tolist()) & set(COLOURS))
    ax.legend(handles=[Patch(color=np.array(COLOURS[k]) / 255, label=names[k]) for k in present],
              loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def isprs_sites(data: Path, png=None):
    """First/last-pulse sites: share of first-pulse points called building."""
    folder = data / "isprs" / "sites"
    print("\nISPRS Stuttgart sites, raw (ground = ground_mask default; no reference classes):")
    print(f"{'site':<22} {'points':>7} {'pulses/m2':>9} {'returns read as':<15} "
          f"{'one-echo pulses':>15} {'first-pulse building':>20} {'time s':>7}")
    for name in ISPRS_SITES:
        path = folder / name
        if not path.exists():
            print(f"{name}: missing, skipped")
            continue
        cloud = read_points(path)
        t0 = time.perf_counter()
        out = _raw_classes(cloud)
        dt = time.perf_counter() - t0
        cls, cues = out["classes"], out["cues"]
        first = cloud.attributes["return_number"] == 1
        one_echo = cues.duplicate.sum() / max(first.sum(), 1) if cues.returns == "pairs" else np.nan
        density = 1 / point_spacing(cloud.xyz[first, :2]) ** 2
        print(f"{name:<22} {len(cloud):>7} {density:9.1f} {cues.returns:<15} "
              f"{one_echo:15.3f} {(cls[first] == 6).mean():20.3f} {dt:7.2f}")
        if png is not None and name.startswith("CSite4"):
            class_image(cloud.xyz[first], cls[first], png,
                        title=f"ISPRS CSite4, first pulse, classes from the raw tile "
                              f"(building {(cls[first] == 6).mean():.1%} of first-pulse points)")
            print(f"{'':<22} class image written to {png}")


def synthetic_surveys():
    """The synthetic town as other surveys record it: building P / R / F1 from raw points."""
    import tempfile

    from lidar2city.synthetic_surveys import make_survey

    print("\nSynthetic town (200 m x 150 m, seed 0) as other surveys, raw "
          "(ground = ground_mask default):")
    print(f"{'survey':<28} {'points':>7} {'bld P':>6} {'bld R':>6} {'bld F1':>6} {'time s':>7}")
    cases = [("multi-echo, 10 pts/m2", "multi", 10.0, False, False),
             ("first/last pairs", "pairs", 10.0, False, False),
             ("first/last pairs shuffled", "pairs", 10.0, True, False),
             ("single returns", "single", 10.0, False, False),
             ("no return fields", "no_returns", 10.0, False, False),
             ("feet (LAS file)", "feet", 10.0, False, False),
             ("1.5 pts/m2", "multi", 1.5, False, False),
             ("1.5 pts/m2 pairs", "pairs", 1.5, False, False),
             ("1.5 pts/m2 single returns", "single", 1.5, False, False),
             ("25 pts/m2", "multi", 25.0, False, False),
             # dense surveys (LiDAR HD, AHN4/5, drone): the region roughness limit
             # follows the terrain's noise (5 cm here)
             ("35 pts/m2", "multi", 35.0, False, False),
             ("50 pts/m2", "multi", 50.0, False, False),
             # with add_canopy: stands of crowns, up to 5 echoes, crowns over roofs
             ("canopy, 5 echoes, 10 pts/m2", "multi", 10.0, False, True),
             ("canopy, 5 echoes, 25 pts/m2", "multi", 25.0, False, True),
             ("canopy, 5 echoes, 50 pts/m2", "multi", 50.0, False, True),
             ("canopy, single, 50 pts/m2", "single", 50.0, False, True),
             ("canopy, pairs, 10 pts/m2", "pairs", 10.0, False, True),
             ("canopy, single, 10 pts/m2", "single", 10.0, False, True),
             ("canopy, single, 25 pts/m2", "single", 25.0, False, True),
             ("canopy, no returns, 10", "no_returns", 10.0, False, True),
             ("canopy, 5 echoes, 1.5", "multi", 1.5, False, True),
             ("canopy, pairs, 1.5", "pairs", 1.5, False, True),
             ("canopy, single, 1.5", "single", 1.5, False, True),
             # scan lines 8 x closer along than across (make_survey anisotropy=8)
             ("scan lines 8:1, 4 pts/m2", "multi", 4.0, False, False, 8.0),
             ("scan lines 8:1, 10 pts/m2", "multi", 10.0, False, False, 8.0),
             ("scan lines 8:1, 20 pts/m2", "multi", 20.0, False, False, 8.0)]
    for label, kind, density, shuffle, canopy, *aniso in cases:
        cloud = make_survey(kind, density=density, shuffle=shuffle, canopy=canopy,
                            anisotropy=aniso[0] if aniso else 1.0)
        if kind == "feet":
            from lidar2city.io.las import write_points

            with tempfile.TemporaryDirectory() as tmp:
                write_points(Path(tmp) / "feet.laz", cloud)
                cloud = read_points(Path(tmp) / "feet.laz")
        t0 = time.perf_counter()
        cls = _raw_classes(cloud)["classes"]
        dt = time.perf_counter() - t0
        s = classification_scores(cloud.attributes["classification"], cls, mapping=ASPRS_MAPPING,
                                  predicted_mapping=ASPRS_MAPPING, ignore=(7,))
        print(f"{label:<28} {len(cloud):>7} {s.precision['building']:6.3f} "
              f"{s.recall['building']:6.3f} {s.f1['building']:6.3f} {dt:7.2f}")


def reconstruct_csite4(data: Path):
    """``lidar2city reconstruct CSite4 --lod 2.2`` without footprints, then validation.

    Prints the buildings with a true LoD2.2 roof, those given an LoD1.2 prism
    instead (with the reason), the failed ones, and the validity of the file.
    """
    import collections
    import json
    import subprocess
    import tempfile

    from lidar2city.tools.validate import validate_file

    src = data / "isprs" / "sites" / "CSite4_orig-utm.laz"
    if not src.exists():
        return
    print("\nreconstruct CSite4 (raw, no footprints) --lod 2.2, then validate:")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "c4.city.json"
        t0 = time.perf_counter()
        subprocess.run(["lidar2city", "reconstruct", str(src), "--lod", "2.2", "-o", str(out)],
                       check=True, capture_output=True)
        dt = time.perf_counter() - t0
        report = validate_file(out)
        summary = report.summary()
        doc = json.loads(out.read_text())
    counts = collections.Counter()
    large = []
    for oid, obj in doc["CityObjects"].items():
        a = obj.get("attributes", {})
        kind = ("failed" if a.get("status") != "ok" else
                "LoD1.2 prism" if a.get("lod22_fallback") else "LoD2.2 roof")
        counts[kind] += 1
        if a.get("status") == "ok" and a.get("area", 0) >= 1000:
            large.append((a["area"], oid, kind, (a.get("lod22_fallback") or "")[:60]))
    print(f"{len(doc['CityObjects'])} footprints traced: " + ", ".join(
        f"{counts[k]} {k}" for k in ("LoD2.2 roof", "LoD1.2 prism", "failed"))
        + f"; file {'VALID' if report.valid else 'INVALID'} ({summary['invalid']} invalid "
          f"object(s), schema {summary['schema']}); {dt:.0f} s")
    for area, oid, kind, why in sorted(large, reverse=True):
        print(f"  {oid:<5} {area:8.0f} m2  {kind:<13} {why}")


def scan_lines_reconstruct():
    """``--scan-lines``: reconstruct without footprints on the town in scan lines 8:1."""
    import json
    import tempfile

    import shapely

    from lidar2city.datamodel import PointCloud
    from lidar2city.io.las import write_points
    from lidar2city.synthetic import make_town
    from lidar2city.synthetic_surveys import scan_lines, survey_variant
    from lidar2city.tools.reconstruct import reconstruct
    from lidar2city.tools.validate import validate_file

    town = make_town(size=(200, 150), density=120.0, seed=0)
    c = scan_lines(survey_variant(town, "multi"), 10.0, 8.0)
    raw = PointCloud(c.xyz, c.origin, c.crs, c.xy_unit, c.z_unit,
                     {k: v for k, v in c.attributes.items() if k != "classification"})
    with tempfile.TemporaryDirectory() as tmp:
        src, out = Path(tmp) / "lines.laz", Path(tmp) / "lines.city.json"
        write_points(src, raw)
        s = reconstruct([src], out, lods=("1.2", "1.3", "2.2"))
        valid = validate_file(out).valid
        doc = json.loads(out.read_text())
    t = doc["transform"]
    v = np.array(doc["vertices"]) * t["scale"] + t["translate"] - np.asarray(town.cloud.origin)
    polys = []
    for o in doc["CityObjects"].values():
        g = [g for g in o.get("geometry", []) if g["lod"] == "1.2"]
        if o["type"] != "Building" or not g:
            continue
        solids = [g[0]["boundaries"]] if g[0]["type"] == "Solid" else g[0]["boundaries"]
        polys.append(shapely.union_all([shapely.Polygon(v[sol[0][0][0], :2],
                                                        [v[r, :2] for r in sol[0][0][1:]])
                                        for sol in solids]))
    hit = sum(any(tp.intersection(p).area / tp.union(p).area >= 0.5 for p in polys)
              for tp in town.footprints.geometries)
    print(f"\nscan lines 8:1, 10 pts/m2, no footprints: {s.done}/{s.total} modelled, "
          f"{hit}/{len(town.footprints.geometries)} truth buildings matched (IoU >= 0.5); "
          f"{'valid' if valid else 'INVALID'}")


if __name__ == "__main__":
    args = sys.argv[1:]
    lines = "--scan-lines" in args
    if lines:
        args.remove("--scan-lines")
    png = None
    neb_png = None
    rebuild = "--reconstruct" in args
    if rebuild:
        args.remove("--reconstruct")
    if "--png" in args:
        i = args.index("--png")
        png = Path(args[i + 1])
        del args[i:i + 2]
    if "--nebraska-png" in args:
        i = args.index("--nebraska-png")
        neb_png = Path(args[i + 1])
        del args[i:i + 2]
    default = os.environ.get("LIDAR2CITY_DATA", Path(__file__).resolve().parents[1].parent
                             / "shared" / "data")
    folder = Path(args[0] if args else default)
    main(folder)
    nebraska_misses(folder, neb_png)
    canopy_over_roofs(folder)
    density_sweep(folder)
    isprs_sites(folder, png)
    synthetic_surveys()
    if rebuild:
        reconstruct_csite4(folder)
    if lines:
        scan_lines_reconstruct()
