"""GeoTIFF (any GDAL raster) reading and writing with rasterio."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..crs import unit_factors
from ..errors import CRSError, EmptyInputError, FileFormatError, InputError
from ._atomic import atomic_path, check_input_file

logger = logging.getLogger(__name__)

__all__ = ["Raster", "read_raster", "write_raster", "check_surface", "check_same_grid"]


@dataclass(frozen=True, eq=False)
class Raster:
    """A georeferenced grid.

    Parameters
    ----------
    array : ndarray, shape (H, W) or (B, H, W)
        Values. Single-band rasters read with ``read_raster`` are float64 with
        NaN where the source had nodata; multi-band ones keep their dtype.
    transform : affine.Affine
        Pixel (col, row) to world (CRS units) transform of the pixel corners.
    crs : pyproj.CRS or None
    mask : ndarray of bool, shape (H, W), optional
        True where the pixel holds data (all bands).
    """

    array: np.ndarray
    transform: object
    crs: object = None
    mask: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.array.shape[-2:]

    @property
    def xy_unit(self) -> float:
        """Metres per CRS horizontal unit."""
        return unit_factors(self.crs)[0]

    @property
    def cell_size(self) -> float:
        """Pixel size in metres (square pixels assumed; the mean of both axes otherwise)."""
        t = self.transform
        return float((abs(t.a) + abs(t.e)) / 2.0 * self.xy_unit)

    def pixel_centers(self, rows, cols) -> np.ndarray:
        """World coordinates (CRS units) of pixel centres, shape (..., 2)."""
        t = self.transform
        rows = np.asarray(rows, dtype=np.float64) + 0.5
        cols = np.asarray(cols, dtype=np.float64) + 0.5
        x = t.c + cols * t.a + rows * t.b
        y = t.f + cols * t.d + rows * t.e
        return np.stack([x, y], axis=-1)

    def world_to_pixel(self, xy) -> np.ndarray:
        """Fractional (row, col) of world coordinates, shape (..., 2)."""
        inv = ~self.transform
        xy = np.asarray(xy, dtype=np.float64)
        col = inv.a * xy[..., 0] + inv.b * xy[..., 1] + inv.c
        row = inv.d * xy[..., 0] + inv.e * xy[..., 1] + inv.f
        return np.stack([row, col], axis=-1)


def read_raster(path, *, bands=None, crs=None) -> Raster:
    """Read a raster GDAL understands.

    Parameters
    ----------
    bands : int or sequence of int, optional
        1-based band indices. Default: band 1 for one-band rasters (returned as
        float64 (H, W) with NaN for nodata), all bands otherwise (B, H, W).
    crs : str or pyproj.CRS, optional
        Overrides or supplies the CRS.

    Raises
    ------
    FileFormatError
        Missing or unreadable file.
    """
    import rasterio
    from pyproj import CRS

    from ..crs import parse_crs

    p = check_input_file(path)
    try:
        # PAM off: reading must not leave X.tif.aux.xml beside the user's file
        with rasterio.Env(GDAL_PAM_ENABLED="NO"), rasterio.open(p) as ds:
            if bands is None:
                bands = 1 if ds.count == 1 else list(range(1, ds.count + 1))
            data = ds.read(bands, masked=True)
            transform = ds.transform
            file_crs = CRS.from_wkt(ds.crs.to_wkt()) if ds.crs else None
    except rasterio.errors.RasterioIOError as exc:
        raise FileFormatError(f"{str(p)!r} is not a readable raster: {str(exc).splitlines()[0]}") from None
    resolved = parse_crs(crs) if crs is not None else file_crs
    mask = ~np.ma.getmaskarray(data)
    if data.ndim == 3:
        mask = mask.all(axis=0)
    if isinstance(bands, int):
        arr = np.ma.filled(data.astype(np.float64), np.nan)
    else:
        arr = np.ma.getdata(data)
    if isinstance(bands, int) and not np.isfinite(arr[mask]).all():
        mask &= np.isfinite(arr)
        arr = np.where(mask, arr, np.nan)
    return Raster(arr, transform, resolved, mask)


#: heights below this (in the raster's units) are no data: lower than any land (the Dead
#: Sea's shore is at -430 m, -1411 ft), above the sentinels tools write (-9999, -32768, -3.4e38)
LOWEST_SURFACE = -2000.0


def check_surface(raster: Raster, name) -> Raster:
    """A DSM / DTM input must carry a CRS and hold at least one valid pixel.

    Returns the raster with heights below :data:`LOWEST_SURFACE` made no data, with
    a warning: a float raster whose nodata is NaN (or another value) holding the
    -9999 of another tool's gaps gave buildings 10 km under the terrain.

    Raises
    ------
    CRSError
        No CRS (outputs must carry one; pass a raster with its CRS), or a geographic one.
    EmptyInputError
        Every pixel is nodata.
    """
    if raster.crs is None:
        raise CRSError(f"{str(name)!r} has no CRS; write the raster with its CRS (e.g. "
                       "gdal_edit.py -a_srs EPSG:xxxx)")
    if raster.crs.is_geographic and not raster.crs.is_compound:
        raise CRSError(f"{str(name)!r} is in {raster.crs.name!r}, geographic (degrees): "
                       "reproject the raster to a projected CRS in metres or feet (e.g. "
                       "gdalwarp -t_srs EPSG:xxxx)")
    valid = raster.mask if raster.mask is not None else np.isfinite(raster.array)
    if raster.array.ndim == 2:
        with np.errstate(invalid="ignore"):
            low = valid & (raster.array < LOWEST_SURFACE)
        if low.any():
            logger.warning("%s: %d pixel(s) below %g (down to %g) taken as no data: lower than "
                           "any land, another tool's no-data value", Path(name).name,
                           int(low.sum()), LOWEST_SURFACE, float(raster.array[low].min()))
            valid = valid & ~low
            raster = Raster(np.where(valid, raster.array, np.nan), raster.transform, raster.crs,
                            valid)
    if not np.any(valid):
        raise EmptyInputError(f"{str(name)!r} holds no valid pixel (all nodata)")
    return raster


def check_same_grid(ref: Raster, other: Raster, what) -> None:
    """``other`` must lie on ``ref``'s grid (shape and transform) and in its CRS.

    Raises
    ------
    InputError
    """
    if ref.shape != other.shape or not np.allclose(tuple(ref.transform)[:6],
                                                   tuple(other.transform)[:6]):
        raise InputError(f"{what} is not on the DSM's grid (shape {other.shape} vs {ref.shape}, "
                         f"transform {tuple(other.transform)[:6]} vs {tuple(ref.transform)[:6]}); "
                         "resample it onto the DSM grid first")
    if ref.crs is not None and other.crs is not None and \
            not ref.crs.equals(other.crs, ignore_axis_order=True):
        raise InputError(f"{what} is in {other.crs.name}, the DSM in {ref.crs.name}")


def _gdal_crs(crs):
    """The CRS as GDAL should get it: ``EPSG:code`` when it is one, else its WKT.

    From the WKT of a compound CRS (EPSG:7415, RD New + NAP height) GDAL writes
    GeoTIFF keys that read back as a vertical datum named 'Ibiza' and no code.
    """
    if crs is None:
        return None
    auth = crs.to_authority(min_confidence=100)
    if auth is not None and auth[0] == "EPSG":
        return f"EPSG:{auth[1]}"
    return crs.to_wkt()


def write_raster(path, raster: Raster, *, nodata=-9999.0, dtype="float32") -> None:
    """Write a raster as a tiled, deflate-compressed GeoTIFF (temp name, then rename).

    NaN values (and pixels outside ``raster.mask``) are written as ``nodata``.
    """
    import rasterio

    arr = np.asarray(raster.array)
    if arr.ndim not in (2, 3):
        raise InputError(f"raster array must be 2-D or 3-D, got shape {arr.shape}")
    bands = arr[None] if arr.ndim == 2 else arr
    out = bands.astype(dtype, copy=True)
    if np.issubdtype(out.dtype, np.floating):
        invalid = ~np.isfinite(out)
        if raster.mask is not None:
            invalid |= ~raster.mask[None]
        out[invalid] = nodata
    h, w = out.shape[1:]
    profile = {
        "driver": "GTiff", "height": h, "width": w, "count": out.shape[0], "dtype": dtype,
        "transform": raster.transform, "nodata": nodata, "compress": "deflate",
        "crs": _gdal_crs(raster.crs),
    }
    if h >= 256 and w >= 256:
        profile.update(tiled=True, blockxsize=256, blockysize=256)
    with atomic_path(path) as tmp, rasterio.open(tmp, "w", **profile) as ds:
        ds.write(out)
