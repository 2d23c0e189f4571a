"""Pixel <-> local metric frames, polygon rasterisation and the scoring domain."""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from ..errors import InputError

__all__ = ["PixelFrame", "rasterize_polygons", "evaluation_domain", "reference_neighbourhood_domain",
           "object_segments"]


class PixelFrame:
    """Maps ``(row, col)`` pixel-centre coordinates to local metres and back.

    Parameters
    ----------
    transform : affine.Affine or 6-sequence, optional
        Pixel-corner ``(col, row)`` to world (CRS units), as in GDAL/rasterio.
        Default: a north-up grid of ``cell`` metres with its top-left corner
        at the origin, ``x = col * cell``, ``y = -row * cell``.
    cell : float
        Pixel size in metres (used only when ``transform`` is None).
    origin : (float, float)
        World coordinates of the local frame's origin (CRS units).
    xy_unit : float
        Metres per CRS unit.
    """

    def __init__(self, transform=None, *, cell=1.0, origin=(0.0, 0.0), xy_unit=1.0):
        if transform is None:
            a, b, c, d, e, f = float(cell), 0.0, 0.0, 0.0, -float(cell), 0.0
        else:
            a, b, c, d, e, f = (float(x) for x in tuple(transform)[:6])
        det = a * e - b * d
        if det == 0:
            raise InputError("the raster transform is singular")
        self.m = np.array([[a, b, c], [d, e, f]])
        self.inv = np.linalg.inv(np.vstack([self.m, [0, 0, 1]]))[:2]
        self.origin = np.asarray(origin, dtype=np.float64)[:2]
        self.xy_unit = float(xy_unit)

    def to_local(self, rc) -> np.ndarray:
        """Local metric ``(x, y)`` of pixel-centre coordinates ``(row, col)``, shape (..., 2)."""
        rc = np.asarray(rc, dtype=np.float64)
        col, row = rc[..., 1] + 0.5, rc[..., 0] + 0.5
        x = self.m[0, 0] * col + self.m[0, 1] * row + self.m[0, 2]
        y = self.m[1, 0] * col + self.m[1, 1] * row + self.m[1, 2]
        return (np.stack([x, y], axis=-1) - self.origin) * self.xy_unit

    def to_pixel(self, xy) -> np.ndarray:
        """Pixel-centre ``(row, col)`` of local metric ``(x, y)``, shape (..., 2)."""
        w = np.asarray(xy, dtype=np.float64) / self.xy_unit + self.origin
        col = self.inv[0, 0] * w[..., 0] + self.inv[0, 1] * w[..., 1] + self.inv[0, 2]
        row = self.inv[1, 0] * w[..., 0] + self.inv[1, 1] * w[..., 1] + self.inv[1, 2]
        return np.stack([row - 0.5, col - 0.5], axis=-1)


def rasterize_polygons(polygons, shape, frame: PixelFrame | None = None) -> np.ndarray:
    """Boolean mask of the pixels whose centre lies in any of ``polygons``.

    Parameters
    ----------
    polygons : sequence of shapely Polygon / MultiPolygon (local metres) or None
    shape : (H, W)
    frame : PixelFrame, optional
        Default: pixel coordinates are the metric ones (``PixelFrame(cell=1)``).

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    import shapely
    from affine import Affine
    from rasterio.features import rasterize

    frame = frame or PixelFrame()
    geoms = [g for g in polygons if g is not None and not g.is_empty]
    if not geoms:
        return np.zeros(shape, dtype=bool)

    def to_corner(c):
        rc = frame.to_pixel(c)
        return np.column_stack([rc[:, 1] + 0.5, rc[:, 0] + 0.5])

    px = shapely.transform(np.asarray(geoms, dtype=object), to_corner)
    return rasterize(list(px), out_shape=tuple(shape), transform=Affine.identity(),
                     fill=0, default_value=1, dtype="uint8").astype(bool)


def evaluation_domain(reference, objects=None, *, buffer=3, edge_margin=3) -> np.ndarray:
    """Pixels where a reference footprint set can be trusted as complete.

    Reference footprint sets cover part of a raster and leave out buildings
    cut by its edge, so scoring on every pixel would count real buildings as
    false positives. The domain is:

    1. the bounding box of the reference buildings grown by ``buffer`` pixels
       (outside it the reference says nothing);
    2. minus ``edge_margin`` pixels along the raster border;
    3. minus every connected object of ``objects`` (e.g. nDSM > 3 m) that
       touches the raster border: a building cut by the edge is missing from
       the reference, and neither prediction nor reference is scored on it.

    Parameters
    ----------
    reference : ndarray of bool, shape (H, W)
        Rasterised reference buildings.
    objects : ndarray of bool, shape (H, W), optional
        Above-ground objects.

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    ref = np.asarray(reference, dtype=bool)
    h, w = ref.shape
    dom = np.zeros_like(ref)
    if not ref.any():
        raise InputError("the reference holds no building pixel")
    rows, cols = np.nonzero(ref)
    r0, r1 = max(rows.min() - buffer, 0), min(rows.max() + buffer + 1, h)
    c0, c1 = max(cols.min() - buffer, 0), min(cols.max() + buffer + 1, w)
    dom[r0:r1, c0:c1] = True
    if edge_margin > 0:
        dom[:edge_margin] = dom[-edge_margin:] = False
        dom[:, :edge_margin] = dom[:, -edge_margin:] = False
    if objects is not None:
        obj = np.asarray(objects, dtype=bool)
        if obj.shape != ref.shape:
            raise InputError(f"objects {obj.shape} and reference {ref.shape} differ in shape")
        lab, n = ndi.label(obj)
        if n:
            border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
            cut = np.isin(lab, border[border > 0])
            dom &= ~(cut & ~ref)
    return dom


def object_segments(objects, *, min_distance=3, sigma=1.0) -> np.ndarray:
    """Building-scale pieces of an above-ground mask: watershed on its distance transform.

    Touching buildings (and trees) form one connected blob in a height mask;
    the distance-transform watershed cuts blobs at their necks, one piece per
    local maximum of the (Gaussian-smoothed) distance to the background that
    is at least ``min_distance`` pixels from any other.

    Parameters
    ----------
    objects : ndarray of bool, shape (H, W)

    Returns
    -------
    ndarray of int32, shape (H, W)
        0 background, 1..n pieces.
    """
    from skimage.feature import peak_local_max
    from skimage.segmentation import watershed

    obj = np.asarray(objects, dtype=bool)
    if not obj.any():
        return np.zeros(obj.shape, np.int32)
    dist = ndi.distance_transform_edt(obj)
    blobs, _ = ndi.label(obj, structure=np.ones((3, 3), bool))
    smooth = ndi.gaussian_filter(dist, sigma) if sigma > 0 else dist
    peaks = peak_local_max(smooth, min_distance=int(min_distance), labels=blobs, exclude_border=False)
    markers = np.zeros(obj.shape, np.int32)
    markers[tuple(peaks.T)] = np.arange(1, len(peaks) + 1)
    # blobs without a peak (tiny) get one marker at their most interior pixel
    missing = np.setdiff1d(np.arange(1, blobs.max() + 1), np.unique(blobs[markers > 0]))
    if len(missing):
        pos = ndi.maximum_position(dist, blobs, missing)
        for k, (r, c) in enumerate(pos, start=len(peaks) + 1):
            markers[r, c] = k
    return watershed(-smooth, markers, mask=obj, connectivity=2).astype(np.int32)


def reference_neighbourhood_domain(reference, objects, *, buffer=5, edge_margin=3,
                                   min_distance=3) -> np.ndarray:
    """Pixels near the reference footprints, where an incomplete reference can be trusted.

    Reference footprint sets often hold only some of the buildings of the
    area they span (the Alexandria west half: 56 footprints among many more
    unreferenced buildings inside their bounding box). Scoring on a bounding
    box then counts every correctly found unreferenced building as false
    positives. This domain keeps only what the reference speaks about:

    1. pixels within ``buffer`` pixels (Euclidean) of a reference building;
    2. minus the above-ground pieces (``objects`` cut into building-scale
       pieces by :func:`object_segments`, independent of any method's output)
       that hold no reference pixel: an unreferenced building or tree, standing
       alone or in a row against a referenced one, is not scored (neither as a
       false positive nor as a true negative) -- the reference says nothing
       about it. Pieces overlapping a reference building stay in, so outlines
       spilling over a tree or a neighbour merged into that piece are
       penalised, as are outlines spilling onto the ground around the
       reference;
    3. minus ``edge_margin`` pixels along the raster border.

    Parameters
    ----------
    reference : ndarray of bool, shape (H, W)
        Rasterised reference buildings.
    objects : ndarray of bool, shape (H, W)
        Above-ground objects (e.g. nDSM > 3 m).
    buffer : float
        Width of the ring of surroundings kept around each reference building
        (pixels); its ground pixels score false positives of outlines that
        spill over.
    edge_margin : int
        Pixels left out along the raster border.
    min_distance : int
        ``min_distance`` of :func:`object_segments` (pixels).

    Returns
    -------
    ndarray of bool, shape (H, W)

    Raises
    ------
    InputError
        Empty reference, or shapes differ.
    """
    ref = np.asarray(reference, dtype=bool)
    obj = np.asarray(objects, dtype=bool)
    if obj.shape != ref.shape:
        raise InputError(f"objects {obj.shape} and reference {ref.shape} differ in shape")
    if not ref.any():
        raise InputError("the reference holds no building pixel")
    if buffer < 0:
        raise InputError(f"buffer must be >= 0, got {buffer}")
    dom = ndi.distance_transform_edt(~ref) <= float(buffer)
    lab = object_segments(obj, min_distance=min_distance)
    n = int(lab.max())
    if n:
        touched = np.zeros(n + 1, bool)
        touched[np.unique(lab[ref])] = True
        touched[0] = True
        dom &= touched[lab]
    if edge_margin > 0:
        dom[:edge_margin] = dom[-edge_margin:] = False
        dom[:, :edge_margin] = dom[:, -edge_margin:] = False
    return dom
