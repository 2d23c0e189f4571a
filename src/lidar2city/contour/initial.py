"""Initial building contours from a DSM: height mask, roughness filter, Canny edges.

One closed contour per building region, in pixel coordinates ``(row, col)``
where pixel centres are at integer positions.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy import ndimage as ndi

from ..errors import EmptyInputError, InputError

logger = logging.getLogger(__name__)

__all__ = ["roughness_index", "aspect_coherence", "linked_edges", "building_regions", "initial_contours"]


def _filled(a):
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2:
        raise InputError(f"expected a 2-D raster, got shape {a.shape}")
    ok = np.isfinite(a)
    if not ok.any():
        raise EmptyInputError("raster holds no finite value")
    if ok.all():
        return a.copy()
    # nearest valid value: keeps edges sharp and gradients finite
    idx = ndi.distance_transform_edt(~ok, return_distances=False, return_indices=True)
    return a[tuple(idx)]


def roughness_index(dsm, *, cell=1.0) -> np.ndarray:
    """Terrain ruggedness index of a DSM, as a slope (dimensionless).

    The mean absolute height difference of each pixel to its 8 neighbours
    (Riley et al. 1999), divided by the cell size so thresholds do not depend
    on the resolution. NaN pixels are filled by their nearest valid value.

    Parameters
    ----------
    dsm : ndarray, shape (H, W)
    cell : float
        Pixel size in metres.

    Returns
    -------
    ndarray, shape (H, W)

    References
    ----------
    Riley, S. J., DeGloria, S. D., Elliot, R. (1999). A terrain ruggedness index
    that quantifies topographic heterogeneity. Intermountain J. Sciences 5(1-4).
    """
    z = np.pad(_filled(dsm), 1, mode="edge")
    h, w = z.shape[0] - 2, z.shape[1] - 2
    centre = z[1:-1, 1:-1]
    acc = np.zeros((h, w))
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                acc += np.abs(centre - z[1 + dr:1 + dr + h, 1 + dc:1 + dc + w])
    return acc / 8.0 / float(cell)


def aspect_coherence(dsm, labels, *, cell=1.0, sigma=0.7) -> np.ndarray:
    """Four-fold coherence of the slope directions (aspects) of each labelled region.

    ``|sum_p s_p exp(4 i theta_p)| / sum_p s_p`` over the region's pixels, with
    ``theta`` the aspect and ``s`` the slope of the Gaussian-smoothed DSM. A
    building's walls and roof planes face a few directions 90 degrees apart
    (a rectangle's four sides, a gable's two or a hip roof's four planes), all
    equal modulo 90 degrees: the four-fold mean resultant length is high. A
    tree crown slopes away from its top in every direction: it is near 0.

    Parameters
    ----------
    dsm : ndarray, shape (H, W)
    labels : ndarray of int, shape (H, W)
        0 background, 1..n regions.
    cell : float
        Pixel size (m).
    sigma : float
        Gaussian smoothing of the DSM before the gradient (pixels).

    Returns
    -------
    ndarray, shape (n,)
        Coherence in [0, 1] of regions 1..n (0 for empty or flat ones).
    """
    z = _filled(dsm)
    lab = np.asarray(labels)
    if lab.shape != z.shape:
        raise InputError(f"dsm {z.shape} and labels {lab.shape} differ in shape")
    n = int(lab.max()) if lab.size else 0
    if n == 0:
        return np.zeros(0)
    if sigma > 0:
        z = ndi.gaussian_filter(z, sigma)
    gr, gc = np.gradient(z, float(cell))
    slope = np.hypot(gr, gc)
    four = 4.0 * np.arctan2(gr, gc)
    idx = np.arange(1, n + 1)
    re = ndi.sum_labels(slope * np.cos(four), lab, idx)
    im = ndi.sum_labels(slope * np.sin(four), lab, idx)
    tot = ndi.sum_labels(slope, lab, idx)
    return np.where(tot > 0, np.hypot(re, im) / np.maximum(tot, 1e-12), 0.0)


def linked_edges(dsm, *, sigma=1.0, low_threshold=None, high_threshold=None,
                 max_gap=1, min_length=4) -> np.ndarray:
    """Canny edges of a DSM with small gaps closed and short segments dropped.

    Parameters
    ----------
    dsm : ndarray, shape (H, W)
    sigma : float
        Gaussian smoothing of the Canny detector, in pixels.
    low_threshold, high_threshold : float, optional
        Hysteresis thresholds on the gradient magnitude of the smoothed DSM
        (metres of height per pixel); default 0.5 and 1.0.
    max_gap : int
        Gaps of up to this many pixels between edge pixels are bridged by a
        morphological closing (0: none).
    min_length : int
        Edge chains (8-connected) with fewer pixels are dropped.

    Returns
    -------
    ndarray of bool, shape (H, W)

    References
    ----------
    Canny, J. (1986). A computational approach to edge detection. IEEE PAMI 8(6).
    """
    from skimage.feature import canny
    from skimage.morphology import skeletonize

    z = _filled(dsm)
    lo = 0.5 if low_threshold is None else float(low_threshold)
    hi = 1.0 if high_threshold is None else float(high_threshold)
    if hi < lo:
        raise InputError(f"high_threshold ({hi}) must be >= low_threshold ({lo})")
    edges = canny(z, sigma=sigma, low_threshold=lo, high_threshold=hi)
    if max_gap > 0:
        size = 2 * int(np.ceil(max_gap / 2.0)) + 1
        closed = ndi.binary_closing(edges, structure=np.ones((size, size), bool), border_value=0)
        edges = skeletonize(closed | edges)
    if min_length > 1:
        lab, n = ndi.label(edges, structure=np.ones((3, 3), bool))
        if n:
            sizes = np.bincount(lab.ravel(), minlength=n + 1)
            keep = sizes >= min_length
            keep[0] = False
            edges = keep[lab]
    return edges


def building_regions(dsm, ndsm, *, cell=1.0, min_height=3.0, max_roughness=1.0,
                     canny_sigma=1.0, max_gap=1, min_edge_length=4, min_area=20.0,
                     split_distance=3, relative_height=0.5, min_aspect_coherence=0.1,
                     edges=None) -> np.ndarray:
    """Label image of candidate building regions.

    1. Pixels higher than ``min_height`` above the terrain form the candidate
       mask; linked Canny edges of the DSM cut it where buildings touch trees
       or each other.
    2. What is still joined is cut at its necks: watershed of the distance
       transform, one piece per distance maximum at least ``split_distance``
       pixels from the others (:func:`~.raster.object_segments`).
    3. Each piece keeps only its pixels higher than ``relative_height`` times
       its 90th height percentile: a DSM blurs a wall of height ``h`` into a
       ramp whose mid-point (``h / 2``) is the wall, and the lower crowns or
       sheds leaning on a building fall below it.
    4. Regions whose median roughness index exceeds ``max_roughness``
       (vegetation: rough, irregular canopy), whose slope directions are not
       coherent (:func:`aspect_coherence` below ``min_aspect_coherence``: tree
       crowns slope every way) or smaller than ``min_area`` are dropped; the cut pixels (edges) are given back to their neighbouring
       region, within the candidate mask and the region's height cut.

    Parameters
    ----------
    split_distance : int
        Smallest distance between two pieces' centres (pixels); 0: no split.
    relative_height : float
        Share of a piece's 90th height percentile (above terrain) its pixels
        must exceed, in [0, 1); 0: no cut.
    min_aspect_coherence : float
        Smallest four-fold aspect coherence of a building region, in [0, 1];
        0: no test.

    Returns
    -------
    ndarray of int32, shape (H, W)
        0 for background, 1..n for regions.
    """
    from skimage.measure import label as cc_label
    from skimage.segmentation import expand_labels

    from .raster import object_segments

    z = _filled(dsm)
    nd = np.asarray(ndsm, dtype=np.float64)
    if nd.shape != z.shape:
        raise InputError(f"dsm and ndsm differ in shape: {z.shape} vs {nd.shape}")
    if not 0 <= relative_height < 1:
        raise InputError(f"relative_height must be in [0, 1), got {relative_height}")
    nd = np.nan_to_num(nd, nan=0.0)
    cand = nd > min_height
    if edges is None:
        edges = linked_edges(z, sigma=canny_sigma, max_gap=max_gap, min_length=min_edge_length)
    core = cand & ~edges
    if split_distance > 0:
        lab = object_segments(core, min_distance=split_distance)
    else:
        lab, _ = ndi.label(core)
    if relative_height > 0 and lab.max() > 0:
        lab = np.where(nd > _label_threshold(nd, lab, relative_height)[lab], lab, 0)
    lab = cc_label(lab, background=0, connectivity=1)
    n = int(lab.max())
    if n == 0:
        return lab.astype(np.int32)
    rough = roughness_index(z, cell=cell)
    idx = np.arange(1, n + 1)
    area = ndi.sum_labels(np.ones_like(lab), lab, idx) * cell * cell
    med = ndi.labeled_comprehension(rough, lab, idx, np.median, np.float64, 0.0)
    keep = np.zeros(n + 1, bool)
    coh = aspect_coherence(z, lab, cell=cell) if min_aspect_coherence > 0 else np.ones(n)
    keep[1:] = (area >= min_area) & (med <= max_roughness) & (coh >= min_aspect_coherence)
    logger.debug("%d regions, %d kept (%d too small, %d too rough, %d incoherent aspects)", n,
                 int(keep.sum()), int((area < min_area).sum()), int((med > max_roughness).sum()),
                 int((coh < min_aspect_coherence).sum()))
    thr = _label_threshold(nd, lab, relative_height) if relative_height > 0 else np.zeros(n + 1)
    lab = np.where(keep[lab], lab, 0)
    lab = expand_labels(lab, 1.5) * cand  # 1.5: diagonal neighbours (corners) too
    lab = np.where(nd > thr[lab], lab, 0)
    lab, _, _ = _relabel(lab)
    return lab.astype(np.int32)


def _label_threshold(nd, lab, share):
    """``share`` x the 90th height percentile of every label; index 0 (background) is +inf."""
    n = int(lab.max())
    idx = np.arange(1, n + 1)
    top = ndi.labeled_comprehension(nd, lab, idx, lambda v: np.percentile(v, 90), np.float64, 0.0)
    return np.concatenate([[np.inf], share * np.asarray(top)])


def _relabel(lab):
    from skimage.segmentation import relabel_sequential

    return relabel_sequential(lab)


def initial_contours(labels, *, min_vertices=8) -> list[np.ndarray]:
    """One closed contour per labelled region: its outer boundary.

    The contour runs half-way between the region's boundary pixel centres and
    their outside neighbours (iso-line 0.5 of the region mask), so the pixels
    whose centres it encloses are exactly the (hole-filled) region.

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        0 background, 1..n regions (see :func:`building_regions`).

    Returns
    -------
    list of ndarray, shape (M, 2)
        ``(row, col)`` vertices, not repeated at the end, one per region in
        label order; regions whose outline has fewer than ``min_vertices``
        vertices are skipped.
    """
    from skimage.measure import find_contours

    labels = np.asarray(labels)
    out = []
    for k, sl in enumerate(ndi.find_objects(labels), start=1):
        if sl is None:
            continue
        r0, c0 = sl[0].start - 1, sl[1].start - 1
        sub = labels[sl] == k
        sub = np.pad(ndi.binary_fill_holes(sub), 1)
        rings = find_contours(sub.astype(np.float64), 0.5)
        if not rings:
            continue
        ring = max(rings, key=len)[:-1]
        if len(ring) < min_vertices:
            continue
        out.append(ring + np.array([r0, c0], dtype=np.float64))
    return out
