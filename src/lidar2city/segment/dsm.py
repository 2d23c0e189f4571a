"""Building regions from a gridded DSM: terrain, nDSM, vegetation and labels.

Pure functions on 2-D arrays plus the cell size in metres. NaN marks nodata
everywhere; no function reads files.

The pipeline follows the raster building-detection chain of the polygon
fitting paper (DTM by region growing on the DSM from seeds on open ground,
nDSM threshold, vegetation removal by colour or roughness, morphology,
connected components), each step usable on its own.

References
----------
Gerke, M., Heipke, C., Straub, B.-M. (2001). Building extraction from aerial
imagery using a generic scene model and invariant geometric moments.
IEEE/ISPRS Joint Workshop on Remote Sensing and Data Fusion over Urban Areas.
Rottensteiner, F., Briese, C. (2002). A new method for building extraction in
urban areas from high-resolution LIDAR data. IAPRS 34(3A).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..config import field
from ..errors import EmptyInputError, InputError

logger = logging.getLogger(__name__)

__all__ = [
    "DtmConfig",
    "BuildingMaskConfig",
    "dtm_from_dsm",
    "fill_nodata",
    "roughness",
    "slope_spread",
    "vegetation_from_roughness",
    "vegetation_from_colour",
    "building_mask",
    "RoofRegionsConfig",
    "roof_regions",
    "plane_share",
    "trim_to_edges",
    "split_at_saddles",
    "split_at_necks",
    "split_at_ridge_steps",
    "label_buildings",
    "grid_points",
]


def _check_grid(a, name) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2:
        raise InputError(f"{name} must be a 2-D array, got shape {a.shape}")
    if a.size == 0:
        raise EmptyInputError(f"{name} is empty")
    return a


def _check_cell(cell) -> float:
    cell = float(cell)
    if not np.isfinite(cell) or cell <= 0:
        raise InputError(f"cell must be a positive number of metres, got {cell}")
    return cell


# ----------------------------------------------------------------------------- DTM


@dataclass(frozen=True)
class DtmConfig:
    """Options of :func:`dtm_from_dsm` (stage ``dsm_dtm``)."""

    max_step: float = field(0.3, "largest height difference (m) between 4-neighbours inside "
                                 "one ground region, on top of what max_slope_deg allows")
    max_slope_deg: float = field(5.0, "steepest terrain slope (degrees) the region growing "
                                       "follows")
    seed_window: float = field(80.0, "side (m) of the moving window whose lowest pixels seed "
                                     "the region growing; larger than the biggest building")
    seed_tolerance: float = field(0.5, "pixels within this height (m) of their window's minimum "
                                       "are seeds")
    min_region_area: float = field(40.0, "ground regions smaller than this (m2) are dropped")


def _smooth_components(dsm, valid, threshold):
    """Connected components of the 4-neighbour graph whose edges differ less than ``threshold``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    h, w = dsm.shape
    idx = np.arange(h * w).reshape(h, w)
    rows, cols = [], []
    for a, b, za, zb, va, vb in (
        (idx[:, :-1], idx[:, 1:], dsm[:, :-1], dsm[:, 1:], valid[:, :-1], valid[:, 1:]),
        (idx[:-1, :], idx[1:, :], dsm[:-1, :], dsm[1:, :], valid[:-1, :], valid[1:, :]),
    ):
        ok = va & vb
        ok[ok] = np.abs(za[ok] - zb[ok]) <= threshold
        rows.append(a[ok])
        cols.append(b[ok])
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r), dtype=np.int8), (r, c)), shape=(h * w, h * w))
    _, labels = connected_components(graph, directed=False)
    return labels.reshape(h, w)


def _interpolate(values, known, valid):
    """Fill ``values`` outside ``known`` by linear interpolation (nearest outside the hull)."""
    from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator

    out = np.where(known, values, np.nan)
    todo = valid & ~known
    if not todo.any():
        return out
    # the fill inside a hole is decided by its rim: keep ground pixels next to
    # non-ground ones and a sparse lattice of the rest (bounded Delaunay size)
    rim = known & ~ndimage.binary_erosion(known, iterations=1, border_value=1)
    lattice = np.zeros_like(known)
    lattice[::8, ::8] = True
    use = rim | (known & lattice)
    rr, cc = np.nonzero(use)
    # a regular lattice is a degenerate (co-circular) Delaunay input that makes
    # Qhull slow; a tiny deterministic offset breaks the ties
    jitter = 1e-3 * np.sin(np.arange(2 * len(rr), dtype=np.float64) * 12.9898).reshape(-1, 2)
    pts = np.column_stack([rr, cc]).astype(np.float64) + jitter
    z = values[rr, cc]
    qr, qc = np.nonzero(todo)
    q = np.column_stack([qr, qc]).astype(np.float64)
    if len(pts) >= 3 and np.ptp(pts[:, 0]) > 0 and np.ptp(pts[:, 1]) > 0:
        filled = LinearNDInterpolator(pts, z)(q)
    else:
        filled = np.full(len(q), np.nan)
    bad = ~np.isfinite(filled)
    if bad.any():
        filled[bad] = NearestNDInterpolator(pts, z)(q[bad])
    out[qr, qc] = filled
    return out


def dtm_from_dsm(dsm, *, cell, max_step=0.3, max_slope_deg=5.0, seed_window=80.0,
                 seed_tolerance=0.5, min_region_area=40.0):
    """Terrain model from a DSM alone by region growing from seeds on open ground.

    Neighbouring pixels whose heights differ by less than
    ``max_step + cell * tan(max_slope_deg)`` are joined (region growing over the
    4-neighbour graph, all seeds at once: the union of the regions grown from
    each seed). Seeds are the pixels within ``seed_tolerance`` of the lowest
    height in a ``seed_window`` moving window — roads, squares, lawns — so every
    part of the scene gets seeds of its own and the regions of separate streets
    join. A smooth surface is interpolated through the ground regions (linear
    on the Delaunay triangulation of their rims, nearest outside the hull).
    The step threshold is deliberately small: DSMs are often smoothed, and a
    loose threshold lets the growing climb gradual tree crowns and pitched roofs.

    Parameters
    ----------
    dsm : ndarray, shape (H, W)
        Surface heights (m), NaN for nodata.
    cell : float
        Pixel size (m).

    Returns
    -------
    dtm : ndarray, shape (H, W)
        Terrain heights (m), NaN where the DSM has no data; never above the DSM.
    ground : ndarray of bool, shape (H, W)
        Pixels taken as ground (the regions grown from the seeds).

    Raises
    ------
    EmptyInputError
        The DSM has no valid pixel.

    Examples
    --------
    >>> z = np.zeros((40, 40)); z[10:20, 10:20] = 8.0
    >>> dtm, ground = dtm_from_dsm(z, cell=1.0, seed_window=30)
    >>> float(abs(dtm).max()), bool(ground[15, 15])
    (0.0, False)
    """
    dsm = _check_grid(dsm, "dsm")
    cell = _check_cell(cell)
    valid = np.isfinite(dsm)
    if not valid.any():
        raise EmptyInputError("the DSM holds no valid pixel")
    for name, v in (("max_step", max_step), ("seed_window", seed_window),
                    ("seed_tolerance", seed_tolerance)):
        if not v > 0:
            raise InputError(f"{name} must be positive, got {v}")
    if not 0 <= max_slope_deg < 90:
        raise InputError(f"max_slope_deg must be in [0, 90), got {max_slope_deg}")
    threshold = max_step + cell * np.tan(np.deg2rad(max_slope_deg))
    labels = _smooth_components(dsm, valid, threshold)

    big = np.where(valid, dsm, np.inf)
    size = max(3, int(round(seed_window / cell)) | 1)
    wmin = ndimage.minimum_filter(big, size=size, mode="nearest")
    seeds = valid & (dsm <= wmin + seed_tolerance)
    seed_labels = np.unique(labels[seeds])
    counts = np.bincount(labels.ravel(), minlength=labels.max() + 1)
    min_px = max(1, int(np.ceil(min_region_area / cell**2)))
    keep = seed_labels[counts[seed_labels] >= min_px]
    ground = valid & np.isin(labels, keep)
    if not ground.any():
        ground = seeds
    logger.debug("dtm: %d seeds, %d ground regions, %.1f %% ground", seeds.sum(), len(keep),
                 100.0 * ground.sum() / valid.sum())
    dtm = _interpolate(dsm, ground, valid)
    dtm = np.where(valid, np.minimum(dtm, dsm), np.nan)
    return dtm, ground


def fill_nodata(grid, where) -> np.ndarray:
    """Fill NaN cells of ``grid`` inside ``where`` by linear interpolation from the valid ones.

    Linear on the Delaunay triangulation of the valid cells bordering the gaps,
    nearest value outside their hull. Cells outside ``where`` stay NaN.
    """
    grid = _check_grid(grid, "grid")
    where = np.asarray(where, dtype=bool)
    known = np.isfinite(grid) & where
    if not known.any():
        raise EmptyInputError("no valid cell to interpolate from")
    return _interpolate(grid, known, where)


# ------------------------------------------------------------------------ vegetation


def roughness(ndsm, *, size=3) -> np.ndarray:
    """RMS residual (m) of a least-squares plane in a ``size`` x ``size`` window.

    Planar roofs (flat or pitched) give residuals near zero away from their
    ridges and eaves; tree crowns give large ones. Vectorised with box filters:
    for z = a + b x + c y on a symmetric window the residual variance is
    var(z) - b^2 var(x) - c^2 var(y).

    Parameters
    ----------
    ndsm : ndarray, shape (H, W)
        Heights (m), NaN for nodata (filled by the window mean).
    """
    z = _check_grid(ndsm, "ndsm")
    if size < 3 or size % 2 == 0:
        raise InputError(f"size must be an odd integer >= 3, got {size}")
    valid = np.isfinite(z)
    fill = np.where(valid, z, 0.0)
    nv = ndimage.uniform_filter(valid.astype(np.float64), size, mode="nearest")
    mean = ndimage.uniform_filter(fill, size, mode="nearest") / np.maximum(nv, 1e-9)
    zf = np.where(valid, z, mean)
    r = np.arange(size) - size // 2
    var_x = float((r**2).mean())
    ky = np.repeat(r[:, None], size, axis=1).astype(np.float64) / (size * size)
    kx = ky.T
    m = ndimage.uniform_filter(zf, size, mode="nearest")
    m2 = ndimage.uniform_filter(zf * zf, size, mode="nearest")
    # correlate with the coordinate kernels: sum(z * x) / n
    cx = ndimage.correlate(zf, kx, mode="nearest")
    cy = ndimage.correlate(zf, ky, mode="nearest")
    b = cx / var_x
    c = cy / var_x
    res = m2 - m * m - (b * b + c * c) * var_x
    out = np.sqrt(np.maximum(res, 0.0))
    return np.where(valid, out, np.nan)


def slope_spread(dsm, *, cell, window=1.5) -> np.ndarray:
    """Spread of the local plane slopes around each pixel (m/m); low on planar faces.

    The slope of a least-squares plane is taken in a ``window`` (m, rounded to
    an odd number of pixels, at least 3) around every pixel; its spread is the
    standard deviation of those slope vectors over the same window, and each
    pixel keeps the least spread of the windows two pixels around it, so a
    pixel next to a ridge or an eave still finds a window on one face.

    A roof face is planar over metres: its slopes agree even where a DSM
    keeping the highest point per cell makes the heights themselves noisy
    (a steep roof's residual to a plane reaches decimetres there, as much as
    a tree's), while a tree crown's slopes point every way.

    Parameters
    ----------
    dsm : ndarray, shape (H, W)
        Heights (m); NaN cells take their nearest valid height.
    cell : float
        Pixel size (m).
    window : float
        Side of the plane-fit window (m).

    Returns
    -------
    ndarray, shape (H, W)
        Spread of the slope vectors (dimensionless, m per m), NaN where the
        DSM is NaN.

    Examples
    --------
    >>> y, x = np.mgrid[0:12, 0:12] * 0.5
    >>> bool(np.allclose(slope_spread(0.8 * x + 0.3 * y, cell=0.5), 0.0))
    True
    """
    z = _check_grid(dsm, "dsm")
    cell = _check_cell(cell)
    if not window > 0:
        raise InputError(f"window must be a positive number of metres, got {window}")
    valid = np.isfinite(z)
    if not valid.any():
        raise EmptyInputError("the DSM holds no valid pixel")
    if not valid.all():
        idx = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
        z = z[tuple(idx)]
    size = max(3, int(round(window / cell)) | 1)
    r = np.arange(size) - size // 2
    var_x = float((r**2).mean())
    ky = np.repeat(r[:, None], size, axis=1).astype(np.float64) / (size * size * var_x * cell)
    # plane slopes along columns (x) and rows (y) in m per m
    b = ndimage.correlate(z, ky.T, mode="nearest")
    c = ndimage.correlate(z, ky, mode="nearest")
    mean2 = ndimage.uniform_filter(b * b + c * c, size, mode="nearest")
    mb = ndimage.uniform_filter(b, size, mode="nearest")
    mc = ndimage.uniform_filter(c, size, mode="nearest")
    spread = np.sqrt(np.maximum(mean2 - mb * mb - mc * mc, 0.0))
    spread = ndimage.minimum_filter(spread, size + 2, mode="nearest")
    return np.where(valid, spread, np.nan)


def vegetation_from_roughness(ndsm, elevated, *, cell, threshold=0.6, window=5.0):
    """Vegetation among ``elevated`` pixels: locally rough (non-planar) surfaces.

    The plane-fit residual (:func:`roughness`, 3 x 3) is taken only at interior
    pixels (whose whole window is elevated, so walls and eaves do not count),
    averaged over a ``window`` (m) and compared with ``threshold`` (m): tree
    crowns stay rough inside while roofs are planar, or rough only along
    ridges. Border pixels take the mean of the interior pixels around them;
    thin parts without interior pixels are left to the morphology.

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    cell = _check_cell(cell)
    elevated = np.asarray(elevated, dtype=bool)
    rough = roughness(ndsm)
    interior = ndimage.binary_erosion(elevated, structure=np.ones((3, 3), bool)) & np.isfinite(rough)
    size = max(3, int(round(window / cell)) | 1)
    w = interior.astype(np.float64)
    num = ndimage.uniform_filter(np.where(interior, rough, 0.0), size, mode="nearest")
    den = ndimage.uniform_filter(w, size, mode="nearest")
    mean_rough = np.where(den > 1e-9, num / np.maximum(den, 1e-9), 0.0)
    return elevated & (mean_rough > threshold)


def _mahalanobis2(x, mean, cov):
    inv = np.linalg.pinv(cov)
    d = x - mean
    return np.einsum("ij,jk,ik->i", d, inv, d)


def vegetation_from_colour(rgb, elevated, *, iterations=4, chi2=11.34, seed_exg=0.05):
    """Vegetation by Mahalanobis distance to single-Gaussian colour models.

    Two models are estimated from the data itself: vegetation in CIE L*u*v*
    (seeded with the elevated pixels whose excess-green index
    ``(2g - r - b) / (r + g + b)`` exceeds ``seed_exg``) and roofs in RGB (the
    other elevated pixels). A pixel is vegetation when its squared distance to
    the vegetation model is below ``chi2`` (the chi-square quantile, 3 degrees
    of freedom; 11.34 is 99 %) and it is closer to vegetation than to roofs (in
    units of each model's spread). Both models are re-estimated from the new
    classes ``iterations`` times.

    Parameters
    ----------
    rgb : ndarray, shape (3, H, W) or (H, W, 3)
        Colour, any numeric range (scaled by its maximum).
    elevated : ndarray of bool, shape (H, W)
        Pixels to classify (above the nDSM threshold).

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    from skimage.color import rgb2luv

    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.ndim != 3 or 3 not in (rgb.shape[0], rgb.shape[-1]):
        raise InputError(f"rgb must have shape (3, H, W) or (H, W, 3), got {rgb.shape}")
    if rgb.shape[0] == 3 and rgb.shape[-1] != 3:
        rgb = np.moveaxis(rgb, 0, -1)
    elevated = np.asarray(elevated, dtype=bool)
    if rgb.shape[:2] != elevated.shape:
        raise InputError(f"orthoimage {rgb.shape[:2]} and DSM {elevated.shape} differ in shape")
    finite = np.isfinite(rgb).all(axis=-1)
    top = np.nanmax(rgb[finite]) if finite.any() else 1.0
    scale = 255.0 if top > 1.0 and top <= 255.0 else (65535.0 if top > 255 else 1.0)
    rgb01 = np.clip(np.where(finite[..., None], rgb, 0.0) / scale, 0.0, 1.0)
    luv = rgb2luv(rgb01)
    sel = elevated & finite
    if sel.sum() < 10:
        return np.zeros_like(elevated)
    x_rgb = rgb01[sel]
    x_luv = luv[sel]
    s = x_rgb.sum(axis=1)
    exg = (2 * x_rgb[:, 1] - x_rgb[:, 0] - x_rgb[:, 2]) / np.maximum(s, 1e-6)
    veg = exg > seed_exg
    for _ in range(max(1, iterations)):
        if veg.sum() < 4 or (~veg).sum() < 4:
            break
        mv, cv = x_luv[veg].mean(axis=0), np.cov(x_luv[veg].T) + np.eye(3) * 1e-3
        mr, cr = x_rgb[~veg].mean(axis=0), np.cov(x_rgb[~veg].T) + np.eye(3) * 1e-6
        dv = _mahalanobis2(x_luv, mv, cv)
        dr = _mahalanobis2(x_rgb, mr, cr)
        new = (dv < chi2) & (dv < dr)
        if np.array_equal(new, veg):
            break
        veg = new
    out = np.zeros_like(elevated)
    out[sel] = veg
    return out


# ----------------------------------------------------------------------------- mask


@dataclass(frozen=True)
class BuildingMaskConfig:
    """Options of :func:`building_mask` (stage ``dsm_buildings``)."""

    min_height: float = field(2.5, "nDSM threshold (m): lower objects are not buildings")
    roughness_threshold: float = field(0.6, "mean plane-fit residual (m) above which an "
                                             "elevated surface is vegetation (no orthoimage)")
    roughness_window: float = field(5.0, "window (m) over which the roughness is averaged")
    opening: float = field(2.0, "morphological opening radius (m) removing thin parts "
                                "(overhanging branches, walls); 0 disables")
    min_area: float = field(20.0, "smallest building region (m2)")
    max_hole_area: float = field(12.0, "holes up to this area (m2) are filled; larger ones are "
                                       "kept as courtyards")


def _disk(radius_px):
    r = int(np.floor(radius_px))
    if r < 1:
        return None
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    return x * x + y * y <= radius_px * radius_px + 1e-9


def building_mask(ndsm, *, cell, vegetation=None, min_height=2.5, roughness_threshold=0.6,
                  roughness_window=5.0, opening=2.0, min_area=20.0, max_hole_area=12.0):
    """Building pixels: elevated, not vegetation, cleaned by morphology.

    Parameters
    ----------
    ndsm : ndarray, shape (H, W)
        Normalised heights (m), NaN for nodata.
    cell : float
        Pixel size (m).
    vegetation : ndarray of bool, shape (H, W), optional
        Vegetation pixels (e.g. from :func:`vegetation_from_colour`); default:
        :func:`vegetation_from_roughness`.

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    ndsm = _check_grid(ndsm, "ndsm")
    cell = _check_cell(cell)
    if min_height < 0 or min_area < 0 or max_hole_area < 0 or opening < 0:
        raise InputError("min_height, min_area, max_hole_area and opening must be >= 0")
    elevated = np.isfinite(ndsm) & (ndsm > min_height)
    if vegetation is None:
        vegetation = vegetation_from_roughness(ndsm, elevated, cell=cell,
                                               threshold=roughness_threshold,
                                               window=roughness_window)
    else:
        vegetation = np.asarray(vegetation, dtype=bool)
        if vegetation.shape != ndsm.shape:
            raise InputError(f"vegetation mask {vegetation.shape} and nDSM {ndsm.shape} differ")
    mask = elevated & ~vegetation
    se = _disk(opening / cell)
    if se is not None:
        mask = ndimage.binary_opening(mask, structure=se)
    mask = _remove_small(mask, max(1, int(np.ceil(min_area / cell**2))))
    holes = ndimage.binary_fill_holes(mask) & ~mask
    small_holes = _remove_small(holes, int(np.floor(max_hole_area / cell**2)) + 1) ^ holes
    return mask | small_holes


def _remove_small(mask, min_px):
    lab, n = ndimage.label(mask)
    if n == 0:
        return mask.copy()
    sizes = np.bincount(lab.ravel())
    keep = sizes >= min_px
    keep[0] = False
    return keep[lab]


@dataclass(frozen=True)
class RoofRegionsConfig:
    """Options of :func:`roof_regions` (stage ``dsm_roofs``)."""

    min_height: float = field(2.0, "nDSM threshold (m): lower objects are not buildings")
    max_step: float = field(0.5, "largest height difference (m) between 4-neighbours inside "
                                 "one roof region")
    min_area: float = field(10.0, "smallest roof region (m2)")
    min_pixels: int = field(8, "smallest roof region (pixels): on coarse rasters a few pixels "
                               "cannot hold a shape (8 pixels = 32 m2 at 2 m)")
    expand: float = field(2.0, "regions grow by this distance (m) into the remaining elevated "
                               "pixels (blurred eaves and walls)")
    max_hole_area: float = field(12.0, "holes up to this area (m2) are filled; larger ones are "
                                       "kept as courtyards")
    roughness_threshold: float = field(0.0, "without an orthoimage, regions whose interior "
                                            "mean plane-fit residual exceeds this (m) are "
                                            "vegetation; 0 disables the test")
    saddle_depth: float = field(1.0, "a grown region holding two summits (or plateaus) of at "
                                     "least min_area each, separated by a saddle at least this "
                                     "deep (m), is split at the saddle (a tree crown or a "
                                     "neighbour reached by the growing); 0 disables")
    edge_inset: float = field(0.5, "region pixels whose centre lies within this distance (m) of "
                                  "the regions' outer edge are dropped (the highest point per "
                                  "cell overstates a roof by half a cell on average, and eaves "
                                  "overhang the walls; 0: off)")
    edge_fraction: float = field(0.2, "after growing, a region keeps the pixels whose nDSM "
                                      "reaches this fraction of its roof height (the upper "
                                      "quartile of its nDSM): the edge of a blurred step lies "
                                      "at half its height; 0 disables the trimming")
    expand_roughness: float = field(0.2, "the growing by expand does not enter blobs "
                                         "wider than 2 m whose 3 x 3 plane-fit residual "
                                         "exceeds this (m): tree crowns touching a roof stay "
                                         "out, thin rough eaves are joined; 0 disables (off "
                                         "on rasters coarser than 1 m)")
    merge_area: float = field(5.0, "smooth fragments smaller than min_area but at least this "
                                   "large (m2) are merged into the region they share the "
                                   "longest edge with (dormers, roof steps, low annexes) "
                                   "if they also hold min_pixels; 0: they are dropped")
    min_planar_share: float = field(0.4, "regions with a smaller share of planar pixels (slope "
                                         "spread below planar_spread) are dropped: tree crowns "
                                         "slope every way, roofs are a few planar faces; 0: off "
                                         "(off on rasters coarser than 1 m, where 3 x 3 windows "
                                         "span whole roofs)")
    planar_spread: float = field(0.4, "a pixel is planar when the spread of the plane slopes "
                                      "around it (slope_spread, 1.5 m windows) is below this "
                                      "(m per m)")
    min_plane_share: float = field(0.5, "a region failing min_planar_share is kept when at "
                                        "least this share of its pixels lie within "
                                        "plane_tolerance of one plane fitted to it (a small flat "
                                        "roof, a roof under a little canopy; tree crowns are not "
                                        "planes); 0: off")
    plane_tolerance: float = field(0.2, "distance (m) from the region's plane within which a "
                                        "pixel counts as on it (the spread of a highest-point "
                                        "DSM on a roof face)")
    plane_contact: float = field(0.5, "the plane test (min_plane_share) keeps only regions "
                                      "with at least this share of the pixels around them in "
                                      "other regions: a roof between steps, whose slope "
                                      "windows straddle them; a free-standing region with no "
                                      "planar window is a hedge or a crown; 0: any region")
    ridge_step: float = field(0.5, "a region whose ridges break by at least this much (m) is "
                                   "split where its faces drain from each ridge piece (row "
                                   "houses of two heights whose eaves meet level, "
                                   ":func:`split_at_ridge_steps`); 0: off")
    neck_width: float = field(2.0, "a region made of parts of at least min_area joined only "
                                   "through necks narrower than this (m) is split into those "
                                   "parts (two sheds joined by a fence, a wing reached through "
                                   "a passage): each is fitted on its own; 0: off (off where "
                                   "half of it is less than a cell)")


def split_at_saddles(labels, ndsm, *, depth=1.0, min_pixels=1):
    """Split regions that hold several summits separated by saddles at least ``depth`` deep.

    Inside each region the summits are the regional maxima of the nDSM whose
    dynamic is at least ``depth`` (:func:`skimage.morphology.h_maxima`); with
    two or more, the region is divided by a marker-controlled watershed of the
    inverted nDSM, so the boundaries follow the valleys between the summits.
    Parts smaller than ``min_pixels`` are not kept as markers (they join a
    neighbour). A house and a tree crown, or two roofs, that region growing
    joined along a smooth slope are separated this way; a roof with one
    summit (a gable, a flat roof) stays whole.

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        0 background, 1..n regions.
    ndsm : ndarray, shape (H, W)
        Normalised heights (m), NaN for nodata.

    Returns
    -------
    labels : ndarray of int32, shape (H, W)
        Relabelled 1..m (m >= n).
    m : int

    Examples
    --------
    >>> z = np.zeros((5, 11)); z[1:4, 1:5] = 6.0; z[1:4, 6:10] = 7.0; z[1:4, 5] = 4.0
    >>> split_at_saddles((z > 2).astype(int), z, depth=1.0)[1]
    2
    """
    from skimage.morphology import h_maxima
    from skimage.segmentation import watershed

    labels = np.asarray(labels)
    ndsm = _check_grid(ndsm, "ndsm")
    if labels.shape != ndsm.shape:
        raise InputError(f"labels {labels.shape} and nDSM {ndsm.shape} differ in shape")
    if not depth > 0:
        raise InputError(f"depth must be positive, got {depth}")
    out = np.zeros(labels.shape, dtype=np.int32)
    nxt = 1
    eight = np.ones((3, 3), bool)
    for i, sl in enumerate(ndimage.find_objects(labels), start=1):
        if sl is None:
            continue
        m = labels[sl] == i
        z = np.where(m & np.isfinite(ndsm[sl]), ndsm[sl], 0.0)
        # the region well above its surroundings, so that only its own saddles count
        z = np.where(m, z - z[m].min() + 2.0 * depth + 1.0, 0.0)
        parts = m.astype(np.int32)
        markers, k = ndimage.label(h_maxima(z, depth) & m, structure=eight)
        if k > 1:
            ws = watershed(-z, markers, mask=m)
            sizes = np.bincount(ws.ravel(), minlength=k + 1)
            big = np.nonzero(sizes[1:] >= min_pixels)[0] + 1
            if len(big) > 1:
                parts = watershed(-z, np.where(np.isin(markers, big), markers, 0), mask=m)
        for j in np.unique(parts[parts > 0]):
            out[sl][parts == j] = nxt
            nxt += 1
    return out, nxt - 1


def _part_pairs(parts):
    """Unique 4-neighbour pairs (a, b), a < b, of different non-zero labels, with counts."""
    pairs = []
    for a, b in ((parts[:, :-1], parts[:, 1:]), (parts[:-1, :], parts[1:, :])):
        ok = (a > 0) & (b > 0) & (a != b)
        pairs.append(np.sort(np.column_stack([a[ok], b[ok]]), axis=1))
    pairs = np.concatenate(pairs)
    if len(pairs) == 0:
        return pairs, np.zeros(0, int)
    return np.unique(pairs, axis=0, return_counts=True)


def split_at_ridge_steps(labels, dsm, *, cell, step=0.5, radius=1.5, tolerance=0.25,
                         min_length=5.0, min_pixels=1):
    """Split regions whose ridges break by at least ``step`` metres (row houses of two heights).

    Region growing joins two row houses whose ridges differ by less than a
    wall's step where their eaves or faces meet level. Inside each region the
    ridge pixels are those within ``tolerance`` of the highest DSM height
    within ``radius`` metres in the region; they form ridge pieces where
    4-neighbours differ by at most ``tolerance`` (a ridge that steps up
    breaks into two pieces). Pieces at least ``min_length`` metres long
    (pixels x cell), run on along their own level, mark the parts: each pixel
    joins the piece it reaches with the least climb (the rises along a path
    of 4-neighbours; descending is free: a face goes to the ridge it drains
    from, not over a wall's step to the other), then parts
    whose ridges differ by less than ``step`` and that touch are joined again
    (one block where the DSM shows no step), and parts smaller than
    ``min_pixels`` join the neighbour they share most edges with.

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        0 background, 1..n regions.
    dsm : ndarray, shape (H, W)
        Heights (m), NaN for nodata.
    cell : float
        Pixel size (m).
    step : float
        Smallest ridge break (m) that splits; 0: no split.
    radius : float
        Window (m) within which a ridge pixel is (nearly) the highest.
    tolerance : float
        Height (m) within which pixels count as the highest, and as level along a ridge.
    min_length : float
        Shortest ridge piece (m, as pixels x cell) that marks a part.
    min_pixels : int
        Smallest part kept on its own.

    Notes
    -----
    A piece runs on along every pixel connected to it at its level; on a
    sloped face that is the face's contour at that height, so a flat dormer
    top takes the face below its level as its own part.

    Returns
    -------
    labels : ndarray of int32, shape (H, W)
        Relabelled 1..m (m >= n) in the order of the input regions.
    m : int

    Examples
    --------
    >>> y, x = np.mgrid[0:16, 0:40] * 0.5
    >>> z = 10.0 - np.abs(y - 3.75)            # a gable along x ...
    >>> z[:, 20:] += 1.0                       # ... whose second half is 1 m higher
    >>> split_at_ridge_steps(np.ones(z.shape, int), z, cell=0.5, step=0.5)[1]
    2
    """
    labels = np.asarray(labels)
    dsm = _check_grid(dsm, "dsm")
    cell = _check_cell(cell)
    if labels.shape != dsm.shape:
        raise InputError(f"labels {labels.shape} and DSM {dsm.shape} differ in shape")
    if not step >= 0 or not radius > 0 or not tolerance > 0 or not min_length >= 0:
        raise InputError("step and min_length must be >= 0 m, radius and tolerance > 0 m")
    disk = _disk(radius / cell)
    if disk is None:
        disk = np.ones((3, 3), bool)
    min_ridge = max(1, int(np.ceil(min_length / cell)))
    out = np.zeros(labels.shape, dtype=np.int32)
    nxt = 1
    for i, sl in enumerate(ndimage.find_objects(labels), start=1):
        if sl is None:
            continue
        m = (labels[sl] == i) & np.isfinite(dsm[sl])
        parts = (labels[sl] == i).astype(np.int32)
        if step > 0 and m.sum() >= 2 * max(1, int(min_pixels)):
            z = np.where(m, dsm[sl], -np.inf)
            ridge = m & (z >= ndimage.maximum_filter(z, footprint=disk) - tolerance)
            pieces = _smooth_components(np.where(ridge, z, np.nan), ridge, tolerance)
            pieces = np.where(ridge, pieces + 1, 0)
            ids, counts = np.unique(pieces[ridge], return_counts=True)
            big = ids[counts >= min_ridge]
            if len(big) > 1:
                heights = np.array([np.median(z[pieces == b]) for b in big])
                if np.ptp(heights) >= step:
                    # each piece runs on along its ridge's level (to the wall of a step,
                    # which the window of `radius` stopped short of)
                    markers = np.zeros(m.shape, np.int32)
                    for k, (b, hk) in enumerate(zip(big, heights, strict=True), start=1):
                        level, _ = ndimage.label(m & (np.abs(z - hk) <= tolerance))
                        on = np.unique(level[pieces == b])
                        markers[(markers == 0) & np.isin(level, on[on > 0])] = k
                    ws = _climb_to_markers(markers, np.where(m, z, 0.0), m, eps=1e-3 * cell)
                    ws = _join_parts(ws, np.concatenate([[0.0], heights]), step,
                                     max(1, int(min_pixels)))
                    parts = np.where(labels[sl] == i, np.maximum(ws, 1), 0)
        for j in np.unique(parts[parts > 0]):
            out[sl][parts == j] = nxt
            nxt += 1
    return out, nxt - 1


def _climb_to_markers(markers, z, mask, *, eps):
    """Each ``mask`` pixel joins the marker it reaches with the least climb: the sum of the
    rises between 4-neighbours along the path (descending is free) plus ``eps`` a step, so
    that faces go to the ridge they drain from, not over a wall's step to another."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    h, w = mask.shape
    idx = np.arange(h * w).reshape(h, w)
    rows, cols, wts = [], [], []
    for a, b, za, zb, ma, mb in ((idx[:, :-1], idx[:, 1:], z[:, :-1], z[:, 1:], mask[:, :-1],
                                  mask[:, 1:]),
                                 (idx[:-1, :], idx[1:, :], z[:-1, :], z[1:, :], mask[:-1, :],
                                  mask[1:, :])):
        ok = ma & mb
        rise = zb[ok] - za[ok]
        rows += [a[ok], b[ok]]
        cols += [b[ok], a[ok]]
        wts += [np.maximum(rise, 0.0) + eps, np.maximum(-rise, 0.0) + eps]
    graph = coo_matrix((np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(h * w, h * w)).tocsr()
    src = np.nonzero(markers.ravel() > 0)[0]
    _, _, origin = dijkstra(graph, directed=True, indices=src, min_only=True,
                            return_predecessors=True)
    out = np.where(origin >= 0, markers.ravel()[np.maximum(origin, 0)], 0).reshape(h, w)
    return np.where(mask, out, 0).astype(np.int32)


def _join_parts(parts, heights, step, min_pixels):
    """Touching parts whose ridge heights differ by less than ``step`` joined, then small
    parts into the neighbour sharing the most edges; labels stay those of the parts kept."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(heights)
    pairs, _ = _part_pairs(parts)
    level = pairs[np.abs(heights[pairs[:, 0]] - heights[pairs[:, 1]]) < step]
    graph = coo_matrix((np.ones(len(level)), (level[:, 0], level[:, 1])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    # each joined group keeps the label of its first part
    first = np.full(n, n)
    np.minimum.at(first, comp, np.arange(n))
    parts = first[comp][parts]
    for _ in range(n):
        sizes = np.bincount(parts.ravel(), minlength=n)
        small = [a for a in np.nonzero((sizes > 0) & (sizes < min_pixels))[0] if a > 0]
        if not small or len(np.unique(parts[parts > 0])) < 2:
            break
        pairs, counts = _part_pairs(parts)
        a = small[0]
        sel = (pairs == a).any(axis=1)
        if not sel.any():
            break
        other = pairs[sel][np.argmax(counts[sel])]
        parts[parts == a] = other[other != a][0]
    return parts


def split_at_necks(labels, *, cell, width=2.0, min_pixels=1):
    """Split regions whose parts are joined only through necks narrower than ``width``.

    Each region is opened (morphological opening, a disk of diameter
    ``width`` metres): what survives is its cores, the parts at least
    ``width`` wide. When two or more cores of at least ``min_pixels`` each
    remain, the region is split and every one of its pixels joins the core
    it reaches first inside the region (a geodesic flood from the cores), so
    the necks and thin appendages go to their nearest core. One outline
    drawn around two sheds joined by a fence or a narrow passage fits
    neither; their own outlines fit both. A region with one core stays whole,
    as do all regions when ``width / 2`` is less than one cell.

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        0 background, 1..n regions.
    cell : float
        Pixel size (m).
    width : float
        Narrowest part (m) that still holds a region together; 0: no split.
    min_pixels : int
        Smallest core that counts as a part.

    Returns
    -------
    labels : ndarray of int32, shape (H, W)
        Relabelled 1..m (m >= n) in the order of the input regions.
    m : int

    Examples
    --------
    >>> lab = np.zeros((8, 17), int); lab[1:7, 1:7] = 1; lab[1:7, 10:16] = 1; lab[3, 7:10] = 1
    >>> split_at_necks(lab, cell=0.5, width=2.0, min_pixels=10)[1]
    2
    """
    from skimage.segmentation import watershed

    labels = np.asarray(labels)
    cell = _check_cell(cell)
    if not width >= 0:
        raise InputError(f"width must be >= 0 m, got {width}")
    disk = _disk(0.5 * float(width) / cell)
    out = np.zeros(labels.shape, dtype=np.int32)
    nxt = 1
    pad = 0 if disk is None else disk.shape[0]
    for i, sl in enumerate(ndimage.find_objects(labels), start=1):
        if sl is None:
            continue
        r0, r1 = max(sl[0].start - pad, 0), min(sl[0].stop + pad, labels.shape[0])
        c0, c1 = max(sl[1].start - pad, 0), min(sl[1].stop + pad, labels.shape[1])
        m = labels[r0:r1, c0:c1] == i
        parts = m.astype(np.int32)
        if disk is not None:
            cores, k = ndimage.label(ndimage.binary_opening(m, structure=disk))
            if k > 1:
                big = np.nonzero(np.bincount(cores.ravel())[1:] >= max(1, int(min_pixels)))[0] + 1
                if len(big) > 1:
                    markers = np.where(np.isin(cores, big), cores, 0)
                    parts = watershed(np.zeros(m.shape), markers, mask=m)
        for j in np.unique(parts[parts > 0]):
            out[r0:r1, c0:c1][parts == j] = nxt
            nxt += 1
    return out, nxt - 1


def trim_to_edges(labels, ndsm, *, fraction=0.5, roof_quantile=75.0):
    """Cut every region back to the pixels above ``fraction`` of its roof height.

    In a smoothed or coarse DSM a wall becomes a ramp, and the outline of a
    building is best placed where the ramp crosses half the roof height (the
    edge of a blurred step). The roof height of a region is the
    ``roof_quantile`` percentile of its nDSM (robust to the ramp pixels); a
    region keeps its pixels at or above ``fraction`` of it and, of those, the
    largest 4-connected piece (lower appendages such as a tree crown or a
    garage reached by the growing are cut off at their necks).

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        0 background, 1..n regions.
    ndsm : ndarray, shape (H, W)
        Normalised heights (m), NaN for nodata (never kept).

    Returns
    -------
    ndarray of int32, shape (H, W)
        The trimmed labels (same ids; a region may vanish only if it has no
        valid pixel).

    Examples
    --------
    >>> z = np.zeros((7, 9)); z[1:6, 1:8] = 2.5; z[2:5, 2:7] = 6.0
    >>> lab = (z > 2).astype(int)
    >>> int((trim_to_edges(lab, z) == 1).sum())  # the 2.5 m skirt is below 0.5 x 6 m
    15
    """
    labels = np.asarray(labels)
    ndsm = _check_grid(ndsm, "ndsm")
    if labels.shape != ndsm.shape:
        raise InputError(f"labels {labels.shape} and nDSM {ndsm.shape} differ in shape")
    if not 0 <= fraction < 1:
        raise InputError(f"fraction must be in [0, 1), got {fraction}")
    if not 0 < roof_quantile <= 100:
        raise InputError(f"roof_quantile must be in (0, 100], got {roof_quantile}")
    z = np.where(np.isfinite(ndsm), ndsm, -np.inf)
    out = np.zeros(labels.shape, dtype=np.int32)
    for i, sl in enumerate(ndimage.find_objects(labels), start=1):
        if sl is None:
            continue
        m = (labels[sl] == i) & np.isfinite(z[sl])
        if not m.any():
            continue
        roof = np.percentile(z[sl][m], roof_quantile)
        keep = m & (z[sl] >= fraction * roof)
        pieces, n = ndimage.label(keep)
        if n > 1:
            keep = pieces == np.argmax(np.bincount(pieces.ravel())[1:]) + 1
        out[sl][keep] = i
    return out


def inset_regions(labels, *, cell, inset):
    """Drop the region pixels whose centre lies within ``inset`` metres of the regions' outer edge.

    A DSM that keeps the highest point of each cell marks a cell as roof as
    soon as one roof point falls in it, so its building regions reach on
    average half a cell beyond the walls (and eaves overhang the walls the
    footprints are drawn on). The pixel edge between a region and the
    background is the region's edge; a pixel ``k`` steps along rows and
    columns from the nearest background pixel lies ``(k - 1/2) cell`` inside
    it. Edges shared by two touching regions are not moved. With ``inset``
    below half a cell nothing changes: the default 0.5 m drops one ring of
    pixels from 0.5 m and 1 m grids, and nothing from coarser (blurred) ones.

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        0 background, > 0 regions.
    cell : float
        Pixel size (m).
    inset : float
        Distance (m), >= 0.

    Returns
    -------
    ndarray, shape (H, W)
        The labels with the inset pixels set to 0.
    """
    lab = np.asarray(labels)
    dist = ndimage.distance_transform_cdt(lab > 0, metric="taxicab")
    return np.where((dist - 0.5) * float(cell) > float(inset) + 1e-9, lab, 0)


def _merge_fragments(lab, keep, candidate, rounds=3):
    """Labels with the ``candidate`` components that touch a kept one merged into it.

    A fragment joins the kept (or already merged) region with which it shares
    the most 4-neighbour pixel edges; fragments touching none are dropped.
    """
    owner = np.where(keep, np.arange(len(keep)), 0)
    todo = candidate & ~keep
    todo[0] = False
    for _ in range(rounds):
        if not todo.any():
            break
        cur = owner[lab]
        pairs = []
        for a, b in ((lab[:, :-1], cur[:, 1:]), (lab[:, 1:], cur[:, :-1]),
                     (lab[:-1, :], cur[1:, :]), (lab[1:, :], cur[:-1, :])):
            ok = todo[a] & (b > 0)
            pairs.append(np.column_stack([a[ok], b[ok]]))
        pairs = np.concatenate(pairs)
        if len(pairs) == 0:
            break
        uniq, counts = np.unique(pairs, axis=0, return_counts=True)
        # per fragment the neighbour with the longest shared edge (ties: smallest id)
        order = np.lexsort((uniq[:, 1], -counts, uniq[:, 0]))
        uniq = uniq[order]
        first = np.ones(len(uniq), bool)
        first[1:] = uniq[1:, 0] != uniq[:-1, 0]
        owner[uniq[first, 0]] = uniq[first, 1]
        todo[uniq[first, 0]] = False
    return owner[lab]


def plane_share(heights, rows, cols, *, cell, tolerance=0.2, iterations=3, keep_share=0.7):
    """Share of pixels within ``tolerance`` metres of one plane fitted to them.

    The plane is fitted by least squares, then refitted ``iterations`` times to
    the ``keep_share`` of the pixels nearest to it (at least those within
    ``tolerance``), so chimneys, a neighbour's wall or an overhanging branch do
    not tilt it.

    Parameters
    ----------
    heights : ndarray, shape (n,)
        Heights (m).
    rows, cols : ndarray of int, shape (n,)
        Pixel positions.
    cell : float
        Pixel size (m).

    Returns
    -------
    float
        In [0, 1]; 0 for fewer than 3 pixels.

    Examples
    --------
    >>> r, c = np.mgrid[0:6, 0:6]
    >>> z = 0.3 * c + 0.1 * r; z[0, 0] = 5.0
    >>> round(plane_share(z.ravel(), r.ravel(), c.ravel(), cell=0.5), 3)
    0.972
    """
    z = np.asarray(heights, dtype=np.float64)
    if len(z) < 3:
        return 0.0
    a = np.column_stack([np.ones(len(z)), np.asarray(rows) * cell, np.asarray(cols) * cell])
    use = np.isfinite(z)
    res = np.full(len(z), np.inf)
    for _ in range(iterations + 1):
        if use.sum() < 3:
            break
        coef = np.linalg.lstsq(a[use], z[use], rcond=None)[0]
        res = np.abs(np.where(np.isfinite(z), z - a @ coef, np.inf))
        use = np.isfinite(res) & (res <= max(np.quantile(res[np.isfinite(res)], keep_share),
                                             tolerance))
    return float(np.mean(res <= tolerance))


def _contact_share(lab):
    """Per label: the share of the 4-neighbour pixels around the region in other regions."""
    n = int(lab.max()) + 1
    ring = np.zeros(n)
    other = np.zeros(n)
    for a, b in ((lab[:, :-1], lab[:, 1:]), (lab[:, 1:], lab[:, :-1]),
                 (lab[:-1, :], lab[1:, :]), (lab[1:, :], lab[:-1, :])):
        edge = (a > 0) & (a != b)
        ring += np.bincount(a[edge], minlength=n)
        other += np.bincount(a[edge & (b > 0)], minlength=n)
    return other / np.maximum(ring, 1)


def _on_one_plane(lab, dsm, todo, *, cell, tolerance, min_share):
    """Per label: True where a ``todo`` region has ``min_share`` of its pixels on one plane."""
    out = np.zeros(len(todo), dtype=bool)
    for i, sl in enumerate(ndimage.find_objects(lab), start=1):
        if sl is None or i >= len(todo) or not todo[i]:
            continue
        r, c = np.nonzero(lab[sl] == i)
        z = dsm[sl][r, c]
        out[i] = plane_share(z, r, c, cell=cell, tolerance=tolerance) >= min_share
    return out


def roof_regions(dsm, ndsm, *, cell, vegetation=None, min_height=2.0, max_step=0.5,
                 min_area=10.0, expand=2.0, max_hole_area=12.0, roughness_threshold=0.0,
                 saddle_depth=1.0, edge_fraction=0.2, edge_inset=0.5, min_pixels=8,
                 expand_roughness=0.2, merge_area=5.0, min_planar_share=0.4,
                 planar_spread=0.4, min_plane_share=0.5, plane_tolerance=0.2,
                 plane_contact=0.5, ridge_step=0.5, neck_width=2.0):
    """Building regions as smooth elevated surfaces grown on the DSM.

    The region growing of :func:`dtm_from_dsm` applied to the elevated pixels
    (nDSM > ``min_height``, minus ``vegetation``): 4-neighbours whose DSM
    heights differ by at most ``max_step`` join. Roofs are piecewise smooth,
    so each becomes one region, separated from neighbouring buildings of
    another height and from tree crowns, whose rough surfaces break into
    fragments smaller than ``min_area`` (and ``min_pixels``) and are dropped,
    except fragments of at least ``merge_area`` (and ``min_pixels``) that
    touch a kept region: they join the one they share the longest edge with
    (a dormer, a roof step, a low annex behind a step above ``max_step``).
    Regions then grow by
    ``expand`` into the remaining elevated pixels (the blurred eaves of a
    smoothed DSM) except rough blobs wider than 2 m (3 x 3 plane-fit residual
    above ``expand_roughness``: tree crowns touching a roof; only on rasters
    of 1 m or finer), are split where
    they hold several summits separated by
    saddles ``saddle_depth`` deep (:func:`split_at_saddles`), are cut back to
    a share of their roof height (:func:`trim_to_edges` with
    ``edge_fraction``), small holes are filled and large ones kept as
    courtyards, and their outer edges are moved in by ``edge_inset`` metres
    (:func:`inset_regions`: the highest point per cell overstates roofs),
    and regions whose parts are joined only through necks narrower than
    ``neck_width`` metres are split into those parts (:func:`split_at_necks`).
    Last, a region is dropped when less than ``min_planar_share`` of its
    pixels are planar (:func:`slope_spread` below ``planar_spread``): tree
    crowns and bushes whose heights grew into a smooth-enough region (only on
    rasters of 1 m or finer) -- unless at least ``min_plane_share`` of its
    pixels lie within ``plane_tolerance`` metres of one plane fitted to it
    (:func:`plane_share`): a small flat roof, or a roof under a little
    canopy, holds too few windows wholly on its face for the slope test --
    and at least ``plane_contact`` of the pixels around it belong to other
    regions (a roof between steps; a free-standing blob that fails the slope
    test is a hedge or a crown even when its heights lie near one plane).

    Parameters
    ----------
    dsm, ndsm : ndarray, shape (H, W)
        Surface and normalised heights (m), NaN for nodata.
    cell : float
        Pixel size (m).
    vegetation : ndarray of bool, optional
        Pixels excluded beforehand (e.g. :func:`vegetation_from_colour`).

    Returns
    -------
    labels : ndarray of int32, shape (H, W)
        0 background, 1..n regions.
    n : int
    """
    from skimage.segmentation import expand_labels

    dsm = _check_grid(dsm, "dsm")
    ndsm = _check_grid(ndsm, "ndsm")
    cell = _check_cell(cell)
    if dsm.shape != ndsm.shape:
        raise InputError(f"DSM {dsm.shape} and nDSM {ndsm.shape} differ in shape")
    if (max_step <= 0 or min_area < 0 or expand < 0 or max_hole_area < 0 or min_pixels < 0
            or merge_area < 0):
        raise InputError("max_step must be > 0; min_area, expand, max_hole_area, min_pixels, "
                         "merge_area >= 0")
    if not 0 <= edge_fraction < 1:
        raise InputError(f"edge_fraction must be in [0, 1), got {edge_fraction}")
    if saddle_depth < 0:
        raise InputError(f"saddle_depth must be >= 0, got {saddle_depth}")
    if edge_inset < 0:
        raise InputError(f"edge_inset must be >= 0, got {edge_inset}")
    if not neck_width >= 0:
        raise InputError(f"neck_width must be >= 0 m, got {neck_width}")
    if not 0 <= min_planar_share <= 1 or not planar_spread > 0:
        raise InputError(f"min_planar_share must be in [0, 1] and planar_spread > 0, got "
                         f"{min_planar_share} and {planar_spread}")
    if not 0 <= plane_contact <= 1:
        raise InputError(f"plane_contact must be in [0, 1], got {plane_contact}")
    if not 0 <= min_plane_share <= 1 or not plane_tolerance > 0:
        raise InputError(f"min_plane_share must be in [0, 1] and plane_tolerance > 0, got "
                         f"{min_plane_share} and {plane_tolerance}")
    elevated = np.isfinite(ndsm) & np.isfinite(dsm) & (ndsm > min_height)
    if vegetation is not None:
        vegetation = np.asarray(vegetation, dtype=bool)
        if vegetation.shape != dsm.shape:
            raise InputError(f"vegetation mask {vegetation.shape} and DSM {dsm.shape} differ")
        elevated &= ~vegetation
    lab = _smooth_components(np.where(elevated, dsm, np.nan), elevated, max_step) + 1
    lab[~elevated] = 0
    sizes = np.bincount(lab.ravel())
    min_px = max(1, int(min_pixels), int(np.ceil(min_area / cell**2)))
    keep = sizes >= min_px
    keep[0] = False
    if roughness_threshold > 0 and keep.any():
        rough = roughness(ndsm)
        interior = ndimage.binary_erosion(lab > 0, structure=np.ones((3, 3), bool))
        interior &= np.isfinite(rough)
        num = np.bincount(lab[interior], rough[interior], minlength=len(sizes))
        den = np.bincount(lab[interior], minlength=len(sizes))
        mean_rough = np.where(den > 0, num / np.maximum(den, 1), 0.0)
        keep &= mean_rough <= roughness_threshold
    if merge_area > 0:
        # a fragment needs min_pixels too: on coarse rasters a few pixels are trees and cars
        merge_px = max(1, int(min_pixels), int(np.ceil(merge_area / cell**2)))
        lab = _merge_fragments(lab, keep, sizes >= merge_px)
    else:
        lab = np.where(keep[lab], lab, 0)
    if expand > 0:
        grown = expand_labels(lab, distance=expand / cell)
        target = elevated
        disk = _disk(1.0 / cell)
        if expand_roughness > 0 and disk is not None:
            # rough blobs wider than 2 m (tree crowns) are not grown into; thin rough strips
            # (eaves, walls, roof furniture) are removed by the opening and still joined.
            # Coarser than 1 m a 3 x 3 window spans whole roofs: the test is off there.
            rough = elevated & (lab == 0) & (roughness(ndsm) > expand_roughness)
            rough = ndimage.binary_opening(rough, structure=disk)
            target = elevated & ~rough
        lab = np.where(target, grown, 0)
    if saddle_depth > 0:
        lab, _ = split_at_saddles(lab, ndsm, depth=saddle_depth,
                                  min_pixels=min_px)
    if ridge_step > 0:
        lab, _ = split_at_ridge_steps(lab, dsm, cell=cell, step=ridge_step, min_pixels=min_px)
    if edge_fraction > 0:
        lab = trim_to_edges(lab, ndsm, fraction=edge_fraction)
    # fill small holes region by region (courtyards stay)
    hole_px = int(np.floor(max_hole_area / cell**2))
    if hole_px > 0:
        holes = ndimage.binary_fill_holes(lab > 0) & (lab == 0)
        hl, nh = ndimage.label(holes)
        if nh:
            hs = np.bincount(hl.ravel())
            small = (hs <= hole_px)
            small[0] = False
            fill = small[hl]
            # a hole takes the label of its neighbouring region
            near = expand_labels(lab, distance=2.0)
            lab = np.where(fill, near, lab)
    if edge_inset > 0:
        lab = inset_regions(lab, cell=cell, inset=edge_inset)
    if neck_width > 0:
        # parts joined by a neck are fitted, and tested for planarity, on their own
        lab, _ = split_at_necks(lab, cell=cell, width=neck_width, min_pixels=min_px)
    if min_planar_share > 0 and cell <= 1.0 and lab.any():
        planar = (lab > 0) & (slope_spread(dsm, cell=cell) < planar_spread)
        n_all = np.bincount(lab.ravel())
        share = np.bincount(lab[planar], minlength=len(n_all)) / np.maximum(n_all, 1)
        keep = share >= min_planar_share
        if min_plane_share > 0:
            # a small flat roof, or one under a little canopy, has too few 1.5 m windows
            # wholly on it for the slope test; it still lies on one plane, a crown does not
            todo = ~keep
            if plane_contact > 0:
                # between steps, not free-standing: the pixels around it in other regions
                todo &= _contact_share(lab) >= plane_contact
            keep |= _on_one_plane(lab, dsm, todo, cell=cell, tolerance=plane_tolerance,
                                  min_share=min_plane_share)
        keep[0] = False
        lab = np.where(keep[lab], lab, 0)
    # touching regions stay apart (no re-labelling of connected components)
    ids = np.unique(lab[lab > 0])
    remap = np.zeros(lab.max() + 1, dtype=np.int32)
    remap[ids] = np.arange(1, len(ids) + 1, dtype=np.int32)
    return remap[lab], int(len(ids))


def label_buildings(mask, *, connectivity=1):
    """One label per building region (connected components).

    Returns
    -------
    labels : ndarray of int32, shape (H, W)
        0 for background, 1..n for the regions.
    n : int
    """
    mask = np.asarray(mask, dtype=bool)
    if mask.ndim != 2:
        raise InputError(f"mask must be 2-D, got shape {mask.shape}")
    if connectivity not in (1, 2):
        raise InputError(f"connectivity must be 1 or 2, got {connectivity}")
    structure = ndimage.generate_binary_structure(2, connectivity)
    labels, n = ndimage.label(mask, structure=structure)
    return labels.astype(np.int32), int(n)


# ---------------------------------------------------------------------------- points


def grid_points(xyz, values=None, *, cell, bounds=None, fill_gaps=1):
    """Grid points into a DSM (highest z per cell) and the values of those points.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    values : ndarray, shape (N,) or (N, K), optional
        Per-point values (e.g. RGB) sampled from the highest point of each
        cell, so an orthoimage matches the DSM surface.
    cell : float
        Pixel size (m).
    bounds : (xmin, ymin, xmax, ymax), optional
        Grid extent (m); default: the points' extent.
    fill_gaps : int
        Empty cells whose ``fill_gaps``-neighbourhood holds data get the
        nearest value; 0 keeps every empty cell NaN.

    Returns
    -------
    dict
        ``dsm`` (H, W) float64 with NaN for empty cells, ``values`` (K, H, W)
        or None, ``count`` (H, W) points per cell, ``x0``, ``y0`` (the top-left
        corner, m) and ``cell``. Row 0 is the northernmost row.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError(f"xyz must have shape (N, 3), got {xyz.shape}")
    if len(xyz) == 0:
        raise EmptyInputError("no points to grid")
    cell = _check_cell(cell)
    if bounds is None:
        lo = xyz[:, :2].min(axis=0)
        hi = xyz[:, :2].max(axis=0)
        x0 = np.floor(lo[0] / cell) * cell
        y_top = np.ceil((hi[1] + 1e-9) / cell) * cell
        w = int(np.floor((hi[0] - x0) / cell)) + 1
        h = int(np.floor((y_top - lo[1]) / cell)) + 1
    else:
        x0, ymin, xmax, y_top = (float(b) for b in bounds)
        w = max(1, int(np.ceil((xmax - x0) / cell)))
        h = max(1, int(np.ceil((y_top - ymin) / cell)))
    col = np.floor((xyz[:, 0] - x0) / cell).astype(np.int64)
    row = np.floor((y_top - xyz[:, 1]) / cell).astype(np.int64)
    inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    col, row = col[inside], row[inside]
    z = xyz[inside, 2]
    flat = row * w + col
    order = np.lexsort((-z, flat))  # per cell, highest first
    first = np.ones(len(order), dtype=bool)
    first[1:] = flat[order][1:] != flat[order][:-1]
    top = order[first]
    dsm = np.full(h * w, np.nan)
    dsm[flat[top]] = z[top]
    count = np.bincount(flat, minlength=h * w).reshape(h, w)
    vals = None
    if values is not None:
        v = np.asarray(values, dtype=np.float64)
        if len(v) != len(xyz):
            raise InputError(f"{len(v)} values for {len(xyz)} points")
        v = v[inside].reshape(len(z), -1)
        vals = np.full((v.shape[1], h * w), np.nan)
        vals[:, flat[top]] = v[top].T
        vals = vals.reshape(v.shape[1], h, w)
    dsm = dsm.reshape(h, w)
    if fill_gaps > 0:
        empty = ~np.isfinite(dsm)
        near = ndimage.binary_dilation(~empty, iterations=int(fill_gaps))
        todo = empty & near
        if todo.any():
            _, (ir, ic) = ndimage.distance_transform_edt(empty, return_indices=True)
            dsm[todo] = dsm[ir[todo], ic[todo]]
            if vals is not None:
                vals[:, todo] = vals[:, ir[todo], ic[todo]]
    return {"dsm": dsm, "values": vals, "count": count, "x0": float(x0), "y0": float(y_top),
            "cell": cell}
