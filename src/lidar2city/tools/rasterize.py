"""``lidar2city rasterize``: DSM, DTM, nDSM, intensity or colour rasters from LAS/LAZ tiles.

The peer is PDAL's ``writers.gdal``: one grid for all the input tiles, its
edges on multiples of the cell (so rasters of neighbouring areas line up), the
CRS of the tiles, a nodata value. The products are the inputs of the DSM
methods (``footprints --dsm``, ``reconstruct --dsm``, ``tune``).
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ..datamodel import ASPRS
from ..errors import CRSError, EmptyInputError, InputError

logger = logging.getLogger(__name__)

__all__ = ["PRODUCTS", "GROUND_SOURCES", "rasterize_points", "rasterize_files"]

#: products and what each holds
PRODUCTS = {
    "dsm": "highest return per cell (noise classes left out), empty cells from the nearest filled one",
    "dtm": "terrain at each cell centre from the ground points, gaps interpolated",
    "ndsm": "dsm - dtm",
    "intensity": "mean intensity of the points per cell",
    "rgb": "mean red, green, blue of the points per cell (3 bands, uint16 as in LAS)",
}
#: where the ground points of the DTM come from
GROUND_SOURCES = ("auto", "classified", "filter")
#: ASPRS low (7) and high (18) noise
NOISE_CLASSES = (7, 18)


def _ground(cloud, ground):
    """Ground mask of the cloud: class 2, or the ground filter on an unclassified cloud."""
    cls = cloud.attributes.get("classification")
    has = cls is not None and bool((cls == ASPRS.GROUND).any())
    if ground == "classified" or (ground == "auto" and has):
        if not has:
            raise EmptyInputError("no point is classified ground (class 2); use --ground filter "
                                  "to run the ground filter")
        return cls == ASPRS.GROUND, "classified"
    from ..ground import ground_mask
    from .ground import ground_config

    cfg = ground_config(None)
    mask = ground_mask(cloud.xyz, method=cfg.method, **cfg.method_params())
    if not mask.any():
        raise EmptyInputError(f"the ground filter ({cfg.method}) found no ground point")
    logger.info("DTM from %d points found by the %s ground filter", int(mask.sum()), cfg.method)
    return mask, f"filter ({cfg.method})"


def rasterize_points(cloud, *, product="dsm", cell=0.5, ground="auto", max_gap=None):
    """A raster of one product from a point cloud.

    Parameters
    ----------
    cloud : PointCloud
        Points with their CRS and local origin.
    product : {"dsm", "dtm", "ndsm", "intensity", "rgb"}
        See :data:`PRODUCTS`.
    cell : float
        Cell size (metres); the grid's edges are on multiples of it in the
        CRS's units (``cell / xy_unit``).
    ground : {"auto", "classified", "filter"}
        DTM ground points: class 2 (``auto`` when the cloud has some),
        or the ground filter's.
    max_gap : float, optional
        DSM, intensity, rgb: empty cells at most this far (m) from a filled
        one take its value; others are nodata. None fills all.

    Returns
    -------
    dict
        ``array`` (H, W) or (3, H, W) in CRS units (heights: the CRS's
        vertical unit), ``transform`` (affine), ``mask`` (H, W, valid),
        ``ground`` (source, or None) and ``points``.

    Raises
    ------
    InputError
        Unknown product, bad cell, missing attribute.
    EmptyInputError
        No points, or no ground for a DTM.
    """
    from affine import Affine

    from ..ground._grid import GridSpec, centre_surface, inpaint
    from ..segment.gridding import aligned_grid, cell_index, cell_max, cell_mean, fill_nearest

    if product not in PRODUCTS:
        raise InputError(f"product must be one of {', '.join(PRODUCTS)}, got {product!r}")
    if ground not in GROUND_SOURCES:
        raise InputError(f"ground must be one of {', '.join(GROUND_SOURCES)}, got {ground!r}")
    if not (cell is not None and np.isfinite(cell) and cell > 0):
        raise InputError(f"cell must be > 0 (metres), got {cell!r}")
    if max_gap is not None and not max_gap >= 0:
        raise InputError(f"max_gap must be >= 0 (metres), got {max_gap!r}")
    if len(cloud) == 0:
        raise EmptyInputError("the input holds no points")
    need = {"intensity": ("intensity",), "rgb": ("red", "green", "blue")}.get(product, ())
    missing = [k for k in need if k not in cloud.attributes]
    if missing:
        raise InputError(f"the points carry no {'/'.join(missing)}: cannot make a {product} raster")
    world = cloud.to_world(cloud.xyz)
    cw = cell / cloud.xy_unit  # the cell in CRS units
    spec = aligned_grid((world[:, 0].min(), world[:, 1].min(), world[:, 0].max(),
                         world[:, 1].max()), cell=cw)
    transform = Affine(cw, 0.0, spec.x0, 0.0, -cw, spec.y_top)
    cls = cloud.attributes.get("classification")
    keep = np.ones(len(cloud), bool) if cls is None else ~np.isin(cls, NOISE_CLASSES)
    if not keep.any():
        raise EmptyInputError("every point is classified noise")
    flat = cell_index(world[keep, :2], spec)
    gap = None if max_gap is None else max_gap / cell
    src = None

    def surface():
        return fill_nearest(cell_max(world[keep, 2], flat, spec.shape), max_distance=gap)

    def terrain():
        nonlocal src
        mask, src = _ground(cloud, ground)
        mask &= keep
        # the centre-surface kernel works in the grid's frame: CRS units
        g = centre_surface(world[mask], GridSpec(spec.x0, spec.y_top, cw, spec.shape))
        return inpaint(g)

    if product == "dsm":
        arr = surface()
    elif product == "dtm":
        arr = terrain()
    elif product == "ndsm":
        arr = surface() - terrain()
    else:
        vals = np.column_stack([cloud.attributes[k][keep] for k in need]).astype(np.float64)
        arr = fill_nearest(cell_mean(vals[:, 0] if len(need) == 1 else vals, flat, spec.shape),
                           max_distance=gap)
    valid = np.isfinite(arr) if arr.ndim == 2 else np.isfinite(arr).all(axis=0)
    return {"array": arr, "transform": transform, "mask": valid, "ground": src,
            "points": int(keep.sum()), "cell_crs": cw}


def rasterize_files(paths, output, *, product="dsm", cell=0.5, crs=None, ground="auto",
                    max_gap=None, allow_no_crs=False) -> dict:
    """Read LAS/LAZ tiles as one area and write one product as a GeoTIFF.

    Parameters
    ----------
    paths : str, Path or sequence of them
        Tiles of one area (one CRS).
    output : str or Path
        GeoTIFF written under a temporary name and renamed on success.
        Heights and intensity are float32 with nodata -9999; colour is
        uint16 with nodata 0.
    crs : str, optional
        Supplies or overrides the tiles' CRS; a CRS is required unless
        ``allow_no_crs``.
    allow_no_crs : bool
        Tiles without a CRS (and no ``crs``) give a raster without one, with a
        warning (cells and heights taken as metres), instead of a
        :class:`CRSError`: a raster is read into other tools, which would
        otherwise place it nowhere without telling.
    product, cell, ground, max_gap
        See :func:`rasterize_points`.

    Returns
    -------
    dict
        ``points``, ``shape``, ``cell``, ``product``, ``ground``, ``output``,
        ``seconds``.

    Raises
    ------
    FileFormatError, CRSError, InputError, EmptyInputError
    """
    from ..io.las import read_points
    from ..io.raster import Raster, write_raster

    t0 = time.perf_counter()
    if product not in PRODUCTS:
        raise InputError(f"product must be one of {', '.join(PRODUCTS)}, got {product!r}")
    if allow_no_crs and crs is not None:
        raise InputError("--crs and --no-crs exclude each other")
    cloud = read_points(paths, crs=crs)
    if cloud.crs is None:
        if not allow_no_crs:
            raise CRSError("the input has no CRS: pass --crs EPSG:xxxx, or --no-crs to write "
                           "the raster without one")
        logger.warning("the input has no CRS: the raster will have none (cells and heights "
                       "taken as metres; pass --crs EPSG:xxxx to set one)")
    from ..classify.outliers import far_points

    far = far_points(cloud.xyz[:, :2])
    if far.any():  # a few stray returns far away: the raster covers the survey
        logger.warning("%d point(s) far from the rest of the survey left out of the raster",
                       int(far.sum()))
        cloud = cloud.subset(~far)
    cloud.require_area("the input", "rasterize")
    res = rasterize_points(cloud, product=product, cell=cell, ground=ground, max_gap=max_gap)
    arr = res["array"]
    if product == "rgb":
        out = np.where(res["mask"][None], np.clip(np.rint(np.nan_to_num(arr)), 1, 65535), 0)
        write_raster(output, Raster(out, res["transform"], cloud.crs, res["mask"]),
                     dtype="uint16", nodata=0)
    else:
        write_raster(output, Raster(arr, res["transform"], cloud.crs, res["mask"]))
    return {"points": res["points"], "shape": list(arr.shape[-2:]), "cell": float(cell),
            "product": product, "ground": res["ground"], "output": str(output),
            "seconds": round(time.perf_counter() - t0, 3)}
