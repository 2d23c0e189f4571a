"""Polygon fitting on the Delft 0.5 m DSM against the 132 BGT footprints (issue 16).

Usage: ``PYTHONPATH=src python benchmarks/bench_dsm_fit_delft.py [DATA_DIR] [--dsm-from-laz]
[--set stage.field=value ...] [--per-building] [--quick]`` (``--set`` overrides a DSM stage
option, e.g. ``--set dsm_roofs.min_area=5``, to compare settings; ``--per-building`` prints
each reference's false positive / negative area and the outlines it got, largest losses
first; ``--quick`` stops after the scores and halves, skipping the oracle and the studies).

Inputs: ``delft/dsm_50cm.tif`` and ``dtm_50cm.tif`` (or, with
``--dsm-from-laz``, the DSM and DTM made by ``lidar2city rasterize`` from
``ahn3_cropped_1.laz``), scored against ``footprints_bgt.gpkg``.

Protocol (the BGT footprints cover only the two central blocks of the tile):

* restricted: the predictions that touch a reference footprint, clipped to
  the references' convex hull grown by 2 m, scored per area against all
  references (completeness, correctness, quality) and by one-to-one
  IoU >= 0.5 matching;
* aligned: the share of the outline length of those predictions within 3
  degrees of each polygon's own main axes;
* halves: quality on the north and south halves of the references' rows (the
  split of ``bench_active_contour.py``: options are chosen on the north half)
  and the signed edge offset (false positives minus false negatives within
  1.5 m of the references' outer edges, per metre of edge: > 0 outward), and
  the area where outlines overlap each other;
* pixel kappa of the fitted outlines on the reference-neighbourhood domain
  of ``bench_active_contour.py`` (10 m around the references, minus
  above-ground pieces holding no reference pixel);
* sub-pixel edges: on outline edges against low ground, the mean distance
  to the reference edge now and with each edge moved to the DSM's own
  half-height roof edge (minus the best single inset), how well the
  DSM's edge predicts the reference's, and the mean offset on eave edges
  (the roof rising inwards) and flat ones (:func:`edge_study`);
* oracle: the reference footprints rasterised on the DSM grid, fitted as if
  they were the segmented regions: what the fitting alone loses;
* segmentation alone: the same regions' pixel outlines, not fitted
  (``--regularize none``), and the pixel error budget of the fitted outlines
  on the reference neighbourhood: false positives / negatives within one
  cell of a reference edge (edge placement) and farther than two cells
  (whole objects: trees, sheds and annexes without a footprint, missed low
  annexes);
* area budget by cause, per half: false positives / negatives within 0.5 m
  of a reference edge and deeper, by the roof region they fall in (or none),
  its height and roughness (:func:`cause_budget`);
* object-level ceiling: the same outlines keeping only those with at least
  30 % of their area on a reference footprint - what a perfect tree / shed
  test on whole regions could reach (it uses the reference: a bound, not a
  method).

Row houses are separate BGT footprints; a block fitted as one outline costs
nothing in the per-area scores, but is not matched one-to-one.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def score(pred, ref, hull, tree):
    """Restricted per-area scores, matching and alignment of outlines ``pred``."""
    from lidar2city.metrics.footprints import area_metrics, axis_alignment, match_objects

    hits = np.unique(tree.query(pred, predicate="intersects")[0]) if pred else []
    touching = [pred[i] for i in hits]
    clipped = [g.intersection(hull) for g in touching]
    clipped = [g for g in clipped if not g.is_empty]
    am = area_metrics(clipped, ref)
    mo = match_objects(clipped, ref, min_iou=0.5)
    al = axis_alignment(touching, tolerance_deg=3.0)
    return (f"quality {am['quality']:.4f} (completeness {am['completeness']:.3f}, correctness "
            f"{am['correctness']:.3f}), matched IoU>=0.5 {mo['matched']}/{len(ref)}, aligned "
            f"{100 * al['aligned_share']:.1f} % ({len(touching)} predictions touching a reference)")


def halves(pred, ref, hull, tree, y_split):
    """Quality, aligned share and signed edge offset on the north and south halves.

    The halves split the references' rows as ``bench_active_contour.py`` does
    (world y of the split row). The signed edge offset is the area of false
    positives minus false negatives within 1.5 m of the references' outer
    edges, per metre of those edges (m, > 0: the outlines sit outward).
    """
    import shapely

    ru = shapely.union_all(ref)
    out = []
    for name, box in (("north", shapely.box(-1e12, y_split, 1e12, 1e12)),
                      ("south", shapely.box(-1e12, -1e12, 1e12, y_split))):
        clip = hull.intersection(box)
        r = [g.intersection(box) for g in ref if g.intersects(box)]
        r = [g for g in r if g.area > 0]
        hits = np.unique(tree.query(pred, predicate="intersects")[0]) if pred else []
        p = [pred[i].intersection(clip) for i in hits]
        p = [g for g in p if not g.is_empty]
        from lidar2city.metrics.footprints import area_metrics

        q = area_metrics(p, r)["quality"]
        pu, rb = shapely.union_all(p), ru.intersection(box)
        edge = rb.boundary.intersection(clip)
        band = edge.buffer(1.5)
        off = (pu.difference(rb).intersection(band).area
               - rb.difference(pu).intersection(band).area) / max(edge.length, 1e-9)
        out.append(f"{name} quality {q:.4f}, signed edge offset {off:+.3f} m")
    return "; ".join(out)


def overlap(pred):
    """Area (m2) covered by more than one outline: sum of the areas minus their union's."""
    import shapely

    return sum(g.area for g in pred) - shapely.union_all(pred).area


def on_reference(pred, ref_union, share=0.3):
    """The outlines with at least ``share`` of their area on the references (an oracle)."""
    return [g for g in pred if g.area > 0 and g.intersection(ref_union).area >= share * g.area]


def error_budget(pred, ref, dom):
    """Pixel errors on ``dom`` split by their distance to the reference's edge."""
    from scipy import ndimage

    fp, fn = pred & ~ref & dom, ref & ~pred & dom
    d_out = ndimage.distance_transform_edt(~ref)  # outside: cells to the nearest reference pixel
    d_in = ndimage.distance_transform_edt(ref)  # inside: cells to the nearest non-reference pixel
    return (f"FP {int(fp.sum())} px ({int((fp & (d_out <= 1)).sum())} within one cell of a "
            f"reference edge, {int((fp & (d_out > 2)).sum())} farther than two cells), "
            f"FN {int(fn.sum())} px ({int((fn & (d_in <= 1)).sum())} within one cell, "
            f"{int((fn & (d_in > 2)).sum())} deeper than two cells)")


def edge_study(pred, ref_union, hull, nd, transform, cell, y_split, band=1.5):
    """Lead 1, sub-pixel edges: can the DSM place the fitted edges closer to the references?

    For each outline edge of at least 2 m against low ground (median nDSM of
    the cells 0.5-1.5 m outside below 1 m) whose reference edge lies within
    0.8 m: the reference's offset from the edge (area of the reference in a
    +-1.5 m strip over its length, m; > 0: the reference reaches further out)
    and the DSM's own half-height estimate of the roof edge in the same strip
    (the roof share of each cell, nDSM / roof height clipped to [0, 1]). Prints
    the mean |offset| now, with the edges moved to the DSM's estimate minus
    the best single inset, and the correlation of the two, per half.
    """
    import shapely

    h, w = nd.shape
    rows = []
    for p in pred:
        if not p.intersects(ref_union):
            continue
        xy = np.asarray(shapely.geometry.polygon.orient(p, 1.0).exterior.coords)
        for a, b in zip(xy[:-1], xy[1:], strict=True):
            length = float(np.hypot(*(b - a)))
            if length < 2.0:
                continue
            t = (b - a) / length
            n = np.array([t[1], -t[0]])
            a0, b0 = a + 0.5 * t, b - 0.5 * t
            rect = shapely.Polygon([a0 - band * n, b0 - band * n, b0 + band * n, a0 + band * n])
            if not rect.within(hull):
                continue
            s_ref = -band + 2 * band * rect.intersection(ref_union).area / rect.area
            if abs(s_ref) >= 0.8:
                continue
            x0, y0, x1, y1 = rect.bounds
            c0 = max(int(np.floor((x0 - transform.c) / cell)), 0)
            c1 = min(int(np.ceil((x1 - transform.c) / cell)), w)
            r0 = max(int(np.floor((transform.f - y1) / cell)), 0)
            r1 = min(int(np.ceil((transform.f - y0) / cell)), h)
            rr, cc = np.mgrid[r0:r1, c0:c1]
            px, py = transform.c + (cc + 0.5) * cell, transform.f - (rr + 0.5) * cell
            u = (px - a[0]) * t[0] + (py - a[1]) * t[1]
            v = (px - a[0]) * n[0] + (py - a[1]) * n[1]
            ins = (u >= 0.5) & (u <= length - 0.5) & (np.abs(v) <= band)
            z, v = nd[rr[ins], cc[ins]], v[ins]
            inner, outer = z[v < -0.5], z[v > 0.5]
            if len(inner) < 3 or len(outer) < 3 or np.median(outer) >= 1.0:
                continue
            roof = max(float(np.median(inner)), 1e-6)
            s_dsm = -band + 2 * band * float(np.clip(z / roof, 0, 1).mean())
            # the roof's rise inwards (m/m) from 0.75 to 2.75 m inside: > 0 on an eave edge
            us = np.arange(0.5, length - 0.5, cell)
            rise = []
            for depth in (0.75, 2.75):
                q = a[None, :] + us[:, None] * t[None, :] - depth * n[None, :]
                qc = np.floor((q[:, 0] - transform.c) / cell).astype(int)
                qr = np.floor((transform.f - q[:, 1]) / cell).astype(int)
                ok = (qr >= 0) & (qr < h) & (qc >= 0) & (qc < w)
                rise.append(float(np.median(nd[qr[ok], qc[ok]])) if ok.any() else np.nan)
            rows.append((length, s_ref, s_dsm, (a[1] + b[1]) / 2 >= y_split,
                         (rise[1] - rise[0]) / 2.0))
    if not rows:
        return "no edge"
    o = np.array(rows)
    out = []
    for name, sel in (("north", o[:, 3] > 0), ("south", o[:, 3] == 0)):
        L, sr, sd = o[sel, 0], o[sel, 1], o[sel, 2]
        # the single inset that centres the DSM estimate on the references, chosen per half
        d0 = float(np.average(sd - sr, weights=L))
        out.append(f"{name} {sel.sum()} edges, {L.sum():.0f} m: mean |offset| now "
                   f"{np.average(np.abs(sr), weights=L):.3f} m "
                   f"(mean {np.average(sr, weights=L):+.3f}),"
                   f" at the DSM half-height edge minus {d0:.2f} m "
                   f"{np.average(np.abs(sr - (sd - d0)), weights=L):.3f} m, correlation "
                   f"{np.corrcoef(sr, sd)[0, 1]:+.2f}; mean offset by the roof's rise inwards: "
                   + ", ".join(
                       f"{lab} {L[k].sum():.0f} m {np.average(sr[k], weights=L[k]):+.3f} m"
                       for lab, k in (("eaves (> 0.3 m/m)", o[sel, 4] > 0.3),
                                      ("flat (within 0.1 m/m)", np.abs(o[sel, 4]) < 0.1))
                       if k.any()))
    return "; ".join(out)


def cause_budget(pred, ref, hull, dsm, dtm, transform, cell, split_row, *, roofs=None, sup=4):
    """False positive / negative area of the scored outlines by cause, per half (m2).

    The scored outlines (touching a reference, clipped to the hull) and the
    references are rasterised at ``cell / sup``. An error within 0.5 m of a
    reference edge is edge placement; deeper, a false positive lies in a roof
    region (:func:`~lidar2city.tools.dsm.segment_dsm`, the run's ``roofs`` options) with
    at least 30 % of its pixels on a reference -- at 0.6 of its roof height
    (75th nDSM percentile) or more, or lower -- or in one mostly off the
    references (sheds, annexes, crowns touching a reference), or on no region
    (the fit reaching past its pixels); a false negative is on a region (lost
    by the fit) or on none: nDSM below 2 m, rough (slope spread 0.4 or more:
    crowns over roofs), or smooth.
    """
    from affine import Affine
    from rasterio import features
    from scipy import ndimage

    from lidar2city.segment.dsm import slope_spread
    from lidar2city.tools.dsm import segment_dsm

    seg = segment_dsm(dsm, cell=cell, dtm=dtm, segment_config=roofs)
    lab, nd = seg["labels"], np.nan_to_num(seg["ndsm"])
    ts = transform * Affine.scale(1 / sup)
    shp = (lab.shape[0] * sup, lab.shape[1] * sup)

    def raster(gs):
        gs = [g for g in gs if not g.is_empty]
        return features.rasterize([(g, 1) for g in gs], out_shape=shp, transform=ts, fill=0,
                                  dtype="uint8").astype(bool)

    P, R = raster([g.intersection(hull) for g in pred]), raster(ref)
    n = lab.max() + 1
    centre = R[sup // 2::sup, sup // 2::sup]
    on = np.bincount(lab.ravel(), centre.ravel().astype(float), minlength=n) / np.maximum(
        np.bincount(lab.ravel(), minlength=n), 1)
    roof = np.zeros(n)
    for i, sl in enumerate(ndimage.find_objects(lab), start=1):
        if sl is not None:
            roof[i] = np.percentile(nd[sl][lab[sl] == i], 75)
    up = lambda a: np.kron(a, np.ones((sup, sup), dtype=a.dtype))  # noqa: E731
    L, Z = up(lab), up(nd)
    low = Z < 0.6 * roof[L]
    rough = up(slope_spread(dsm, cell=cell)) >= 0.4
    d_out = ndimage.distance_transform_edt(~R) * cell / sup
    d_in = ndimage.distance_transform_edt(R) * cell / sup
    a = (cell / sup) ** 2
    north = np.zeros(shp, bool)
    north[:split_row * sup] = True
    out = []
    for name, h in (("north", north), ("south", ~north)):
        fp, fn = P & ~R & h, R & ~P & h
        dfp, dfn = fp & (d_out > 0.5), fn & (d_in > 0.5)
        seg_on = (L > 0) & (on[L] >= 0.3)
        m2 = lambda m: f"{m.sum() * a:.0f}"  # noqa: E731
        out.append(
            f"{name}: FP {m2(fp)} m2 = {m2(fp & (d_out <= 0.5))} within 0.5 m of a reference "
            f"edge + deeper {m2(dfp & seg_on & ~low)} in regions mostly on a reference at "
            f"roof height, {m2(dfp & seg_on & low)} in their parts below 0.6 x roof, "
            f"{m2(dfp & (L > 0) & ~seg_on)} in regions mostly off the references, "
            f"{m2(dfp & (L == 0))} on no region; FN {m2(fn)} m2 = {m2(fn & (d_in <= 0.5))} "
            f"within 0.5 m + deeper {m2(dfn & (L > 0))} on a region (lost by the fit), "
            f"{m2(dfn & (L == 0) & (Z < 2.0))} on none below 2 m, "
            f"{m2(dfn & (L == 0) & (Z >= 2.0) & rough)} rough (crowns), "
            f"{m2(dfn & (L == 0) & (Z >= 2.0) & ~rough)} smooth")
    return "; ".join(out)


def per_building(pred, kinds, ref, hull, tree, y_split, top=25):
    """Each reference's false positive / negative area and the outlines it got, by loss.

    A reference's false negatives are its area outside every scored outline
    (touching a reference, clipped to the hull); an outline's false positives
    (its clipped area on no reference) are shared among the references it
    covers in proportion to the area it covers of each. Prints the ``top``
    largest losses: half, FP and FN (m2), then the outlines touching the
    reference (index, shape type, vertex count, main axis in degrees modulo
    90, the share of its area on this reference).
    """
    import shapely

    from lidar2city.fit.polygon import _main_axis

    ru = shapely.union_all(ref)
    hits = np.unique(tree.query(pred, predicate="intersects")[0]) if pred else []
    clip = {int(i): pred[i].intersection(hull) for i in hits}
    pu = shapely.union_all(list(clip.values()))
    fp = np.zeros(len(ref))
    touch = [[] for _ in ref]
    for i, g in clip.items():
        cover = {int(j): g.intersection(ref[j]).area for j in tree.query(g, predicate="intersects")}
        tot = sum(cover.values())
        extra = g.difference(ru).area
        for j, a in cover.items():
            if a <= 0:
                continue
            fp[j] += extra * a / tot
            touch[j].append((i, a / g.area))
    fn = np.array([r.difference(pu).area for r in ref])
    order = np.argsort(-(fp + fn), kind="stable")
    lines = [f"per reference building (the {top} largest FP + FN of {len(ref)}; the totals "
             f"over all references on the last line):"]
    tot = {"north": 0.0, "south": 0.0}
    for j in range(len(ref)):
        tot["north" if ref[j].centroid.y >= y_split else "south"] += fp[j] + fn[j]
    for j in order[:top]:
        half = "north" if ref[j].centroid.y >= y_split else "south"
        desc = ", ".join(
            f"#{i} {kinds[i]} {len(pred[i].exterior.coords) - 1}v "
            f"{np.degrees(_main_axis(pred[i])):.1f}deg {100 * s:.0f}%"
            for i, s in sorted(touch[j], key=lambda t: -t[1]))
        lines.append(f"    ref {j:3d} {half} area {ref[j].area:6.1f} m2 FP {fp[j]:5.1f} "
                     f"FN {fn[j]:5.1f} | {desc or 'no outline'}")
    lines.append(f"    all references: FP + FN north {tot['north']:.0f} m2, "
                 f"south {tot['south']:.0f} m2")
    return "\n".join(lines)


def main(argv):
    import pyogrio
    import shapely
    import shapely.affinity
    from rasterio import features

    from lidar2city.io.raster import read_raster
    from lidar2city.metrics.footprints import pixel_metrics
    from lidar2city.tools.active_contour import reference_mask, scoring_domain
    from lidar2city.tools.dsm import footprints_from_dsm, outlines_from_labels

    from lidar2city.tools.dsm import load_dsm_config

    overrides, rest = {}, []
    it = iter(argv)
    for a in it:
        if a == "--set":
            k, v = next(it).split("=", 1)
            overrides[k] = float(v)
        else:
            rest.append(a)
    argv = rest
    config = load_dsm_config(None, **overrides) if overrides else None
    if overrides:
        print(f"options: {overrides}")
    args = [a for a in argv if not a.startswith("--")]
    root = Path(args[0]) if args else Path(__file__).resolve().parents[2] / "shared" / "data"
    if not (root / "delft").exists():
        root = Path("/work/shared/data")
    dd = root / "delft"
    _, _, wkb, _ = pyogrio.raw.read(str(dd / "footprints_bgt.gpkg"))
    ref = [max(shapely.get_parts(g), key=lambda p: p.area) for g in shapely.from_wkb(wkb)]
    hull = shapely.union_all(ref).convex_hull.buffer(2.0)
    tree = shapely.STRtree(ref)
    with tempfile.TemporaryDirectory() as tmp:
        dsm, dtm = dd / "dsm_50cm.tif", dd / "dtm_50cm.tif"
        if "--dsm-from-laz" in argv:
            from lidar2city.tools.rasterize import rasterize_files

            dsm, dtm = Path(tmp) / "dsm.tif", Path(tmp) / "dtm.tif"
            for p, prod in ((dsm, "dsm"), (dtm, "dtm")):
                rasterize_files(dd / "ahn3_cropped_1.laz", p, product=prod, cell=0.5,
                                crs="EPSG:28992")
            print("DSM and DTM rasterised from ahn3_cropped_1.laz by lidar2city rasterize")
        d = read_raster(dsm)
        t = read_raster(dtm)
        refm = reference_mask(dd / "footprints_bgt.gpkg", d)
        nd = np.nan_to_num(d.array - t.array)
        dom = scoring_domain(refm, nd > 3.0, "reference", cell=d.cell_size)

        # the fitting alone, on the rasterised references
        if "--quick" not in argv:
            lab = features.rasterize([(g, i + 1) for i, g in enumerate(ref)], out_shape=d.shape,
                                     transform=d.transform, fill=0, dtype="int32")
            oracle = outlines_from_labels(lab, nd, cell=d.cell_size)
            ox, oy = d.transform.c, d.transform.f
            opred = [shapely.affinity.translate(r.footprint, ox, oy) for r in oracle if r.ok]
            print(f"oracle (references rasterised at {d.cell_size:g} m, then fitted): "
                  f"{score(opred, ref, hull, tree)}")

        out = Path(tmp) / "fp.gpkg"
        t0 = time.perf_counter()
        summary = footprints_from_dsm(dsm, dtm=dtm, output=out, config=config)
        el = time.perf_counter() - t0
        _, _, w2, f2 = pyogrio.raw.read(str(out))
        geoms = shapely.from_wkb(w2)
        good = ~shapely.is_empty(geoms) & ~shapely.is_missing(geoms)
        pred = [max(shapely.get_parts(g), key=lambda p: p.area) for g in geoms[good]]
        kinds = [str(k) for k in np.asarray(f2[1])[good]]
        print(f"footprints --dsm: {summary['buildings']} outlines in {el:.1f} s "
              f"({summary['failed']} failed), shape types {summary['shape_types']}")
        print(f"  restricted: {score(pred, ref, hull, tree)}")
        rows = np.nonzero(refm.any(axis=1))[0]
        y_split = d.transform.f - int((rows.min() + rows.max() + 1) // 2) * d.cell_size
        print(f"  halves: {halves(pred, ref, hull, tree, y_split)}")
        if "--per-building" in argv:
            print(per_building(pred, kinds, ref, hull, tree, y_split))
        if "--quick" in argv:
            return
        near = [pred[i] for i in np.unique(tree.query(pred, predicate="intersects")[0])]
        ref_all = shapely.union_all(ref)
        graze = [g for g in near if g.intersection(ref_all).area < 1.0]
        print(f"  predictions touching a reference over less than 1 m2 (scored whole): "
              f"{len(graze)}, {sum(g.intersection(hull).area for g in graze):.0f} m2")
        print(f"  outlines touching a reference overlap each other on {overlap(near):.0f} m2 "
              f"(of {sum(g.area for g in near):.0f} m2)")
        pm = features.rasterize([(g, 1) for g in pred], out_shape=d.shape, transform=d.transform,
                                fill=0, dtype="uint8").astype(bool)
        m = pixel_metrics(pm[dom], refm[dom])
        print(f"  pixels on the reference neighbourhood: kappa {m['kappa']:.4f}, OA "
              f"{m['overall_accuracy']:.4f}, PA {m['producers_accuracy']:.3f}, "
              f"UA {m['users_accuracy']:.3f}")
        print(f"  error budget: {error_budget(pm, refm, dom)}")
        study = edge_study(pred, ref_all, hull, nd, d.transform, d.cell_size, y_split)
        print(f"  sub-pixel edges (outline edges against low ground within 0.8 m of a "
              f"reference edge): {study}")
        split_row = int((rows.min() + rows.max() + 1) // 2)
        roofs = config["dsm_roofs"] if config else None
        budget = cause_budget(near, ref, hull, d.array, t.array, d.transform, d.cell_size,
                              split_row, roofs=roofs)
        print(f"  area budget by cause: {budget}")
        ref_union = ref_all
        print(f"  object-level ceiling (outlines with >= 30 % of their area on a reference): "
              f"{score(on_reference(pred, ref_union), ref, hull, tree)}")

        raw = Path(tmp) / "raw.gpkg"
        footprints_from_dsm(dsm, dtm=dtm, output=raw, regularize="none", config=config)
        _, _, w3, _ = pyogrio.raw.read(str(raw))
        g3 = shapely.from_wkb(w3)
        g3 = g3[~shapely.is_empty(g3) & ~shapely.is_missing(g3)]
        rpred = [max(shapely.get_parts(g), key=lambda p: p.area) for g in g3]
        print(f"segmentation alone (the same regions' pixel outlines, not fitted): "
              f"{score(rpred, ref, hull, tree)}")
        print(f"  halves: {halves(rpred, ref, hull, tree, y_split)}")
        print(f"  object-level ceiling (outlines with >= 30 % of their area on a reference): "
              f"{score(on_reference(rpred, ref_union), ref, hull, tree)}")


if __name__ == "__main__":
    main(sys.argv[1:])
