"""CRS helpers: parse user CRS strings and find metres per CRS unit.

Pure functions on :class:`pyproj.CRS` objects; no file access.
"""

from __future__ import annotations

from .errors import CRSError

__all__ = ["parse_crs", "unit_factors", "ogc_url"]


def parse_crs(value):
    """Return a :class:`pyproj.CRS` from a user string (``EPSG:28992``, WKT, PROJ) or CRS.

    ``None`` stays ``None``.

    Raises
    ------
    CRSError
        If the string is not a CRS pyproj knows.
    """
    if value is None:
        return None
    from pyproj import CRS
    from pyproj.exceptions import CRSError as _PyprojCRSError

    if isinstance(value, CRS):
        return value
    try:
        return CRS.from_user_input(value)
    except _PyprojCRSError as exc:
        raise CRSError(f"unknown CRS {value!r}: {str(exc).splitlines()[0]}") from None


def _axis_factor(crs) -> float | None:
    try:
        axes = crs.axis_info
    except Exception:  # pragma: no cover - pyproj internal failures
        return None
    for axis in axes:
        if axis.unit_name and axis.unit_conversion_factor:
            if axis.unit_name in ("degree", "radian", "grad"):
                return None
            return float(axis.unit_conversion_factor)
    return None


def unit_factors(crs) -> tuple[float, float]:
    """Metres per CRS unit horizontally and vertically.

    A compound CRS gives its horizontal and vertical parts; a projected CRS
    alone gives its linear unit for both (LAS convention: z in the same unit
    as x and y). Without a CRS, metres are assumed.

    Raises
    ------
    CRSError
        For a geographic CRS (degrees): project the data first.
    """
    if crs is None:
        return 1.0, 1.0
    if crs.is_geographic and not crs.is_compound:
        raise CRSError(
            f"CRS {crs.name!r} is geographic (degrees); lidar2city needs a projected CRS in "
            "metres or feet: reproject the points (e.g. PDAL filters.reprojection; --crs only "
            "relabels them)"
        )
    if crs.is_compound:
        horizontal, vertical = crs.sub_crs_list[0], crs.sub_crs_list[-1]
        if horizontal.is_geographic:
            raise CRSError(f"CRS {crs.name!r} has a geographic horizontal part; use a projected CRS")
        xy = _axis_factor(horizontal) or 1.0
        z = _axis_factor(vertical) or xy
        return xy, z
    xy = _axis_factor(crs) or 1.0
    return xy, xy


def ogc_url(crs) -> str | None:
    """The OGC definition URL of a CRS (``https://www.opengis.net/def/crs/EPSG/0/7415``).

    Returns ``None`` when the CRS has no EPSG code.
    """
    if crs is None:
        return None
    code = crs.to_epsg(min_confidence=70)
    if code is None and crs.is_compound:
        parts = [p.to_epsg(min_confidence=70) for p in crs.sub_crs_list]
        if all(parts):
            # no single code: name the horizontal one, the usual choice in CityJSON
            code = parts[0]
    if code is None:
        return None
    return f"https://www.opengis.net/def/crs/EPSG/0/{code}"
