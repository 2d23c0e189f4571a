"""Data containers shared by the layers: point clouds, footprints, solids, results.

They hold arrays (and shapely geometries at the edges); they never read files.
Coordinates inside are *local metric*: metres, relative to an ``origin`` kept
in the CRS's own units, so float math stays precise and every threshold is in
metres whatever the CRS.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import EmptyInputError, InputError

__all__ = [
    "ASPRS",
    "PointCloud",
    "Footprints",
    "Surface",
    "Solid",
    "BuildingResult",
]


class ASPRS:
    """ASPRS LAS classification codes used by lidar2city."""

    CREATED = 0
    UNCLASSIFIED = 1
    GROUND = 2
    LOW_VEGETATION = 3
    MEDIUM_VEGETATION = 4
    HIGH_VEGETATION = 5
    BUILDING = 6
    NOISE = 7
    WATER = 9


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Points in local metric coordinates with their origin, CRS and attributes.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3), float64
        Coordinates in metres relative to ``origin``.
    origin : ndarray, shape (3,), float64
        World coordinates (CRS units) of the local origin.
    crs : pyproj.CRS or None
        Coordinate reference system of the world coordinates.
    xy_unit, z_unit : float
        Metres per CRS unit, horizontally and vertically (0.3048 for feet).
    attributes : dict of str to ndarray, shape (N,)
        Per-point attributes (``classification``, ``return_number``,
        ``number_of_returns``, ``intensity``, ``red``, ``green``, ``blue``...).

    Notes
    -----
    World coordinates are ``origin + xyz / (xy_unit, xy_unit, z_unit)``.
    """

    xyz: np.ndarray
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    crs: Any = None
    xy_unit: float = 1.0
    z_unit: float = 1.0
    attributes: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self):
        xyz = np.asarray(self.xyz, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InputError(f"xyz must have shape (N, 3), got {xyz.shape}")
        if not np.isfinite(xyz).all():
            bad = int((~np.isfinite(xyz).all(axis=1)).sum())
            raise InputError(f"{bad} point(s) have NaN or infinite coordinates")
        object.__setattr__(self, "xyz", xyz)
        object.__setattr__(self, "origin", np.asarray(self.origin, dtype=np.float64).reshape(3))
        for name, values in self.attributes.items():
            if len(values) != len(xyz):
                raise InputError(
                    f"attribute {name!r} has {len(values)} values for {len(xyz)} points"
                )

    def __len__(self) -> int:
        return len(self.xyz)

    @classmethod
    def from_world(cls, world_xyz, *, crs=None, xy_unit=1.0, z_unit=1.0, origin=None,
                   attributes=None, copy: bool = True) -> PointCloud:
        """Build a cloud from world coordinates (CRS units), choosing a local origin.

        The origin is the minimum corner (of the points with finite coordinates)
        rounded down to whole CRS units unless given. ``copy=False``: a float64
        ``world_xyz`` is converted in place and becomes the cloud's coordinates
        (no second N x 3 array while a tile is read).
        """
        world_xyz = np.asarray(world_xyz, dtype=np.float64)
        if world_xyz.ndim != 2 or world_xyz.shape[1] != 3:
            raise InputError(f"coordinates must have shape (N, 3), got {world_xyz.shape}")
        if origin is None:
            origin = np.zeros(3)
            if len(world_xyz):
                # 1-D reductions of the columns (an axis-0 one of the (N, 3) array is slower)
                cols = [world_xyz[:, d] for d in range(3)]
                finite = np.isfinite(cols[0]) & np.isfinite(cols[1]) & np.isfinite(cols[2])
                if finite.all():
                    origin[:2] = np.floor([np.min(cols[0]), np.min(cols[1])])
                elif finite.any():
                    origin[:2] = np.floor(world_xyz[finite, :2].min(axis=0))
        origin = np.asarray(origin, dtype=np.float64)
        scale = np.array([xy_unit, xy_unit, z_unit])
        local = world_xyz if not copy else world_xyz.copy()
        local -= origin
        local *= scale
        return cls(local, origin, crs, xy_unit, z_unit, dict(attributes or {}))

    @property
    def unit_scale(self) -> np.ndarray:
        """Metres per CRS unit along x, y, z, shape (3,)."""
        return np.array([self.xy_unit, self.xy_unit, self.z_unit])

    def to_world(self, local_xyz) -> np.ndarray:
        """Convert local metric coordinates (..., 3) or (..., 2) to world coordinates."""
        local_xyz = np.asarray(local_xyz, dtype=np.float64)
        d = local_xyz.shape[-1]
        return self.origin[:d] + local_xyz / self.unit_scale[:d]

    def to_local(self, world_xyz) -> np.ndarray:
        """Convert world coordinates (..., 3) or (..., 2) to local metric ones."""
        world_xyz = np.asarray(world_xyz, dtype=np.float64)
        d = world_xyz.shape[-1]
        return (world_xyz - self.origin[:d]) * self.unit_scale[:d]

    def get(self, name: str, default=None):
        """Per-point attribute ``name`` or ``default`` when absent."""
        return self.attributes.get(name, default)

    def subset(self, mask_or_index) -> PointCloud:
        """A new cloud with the selected points (same origin and CRS)."""
        return PointCloud(
            self.xyz[mask_or_index], self.origin, self.crs, self.xy_unit, self.z_unit,
            {k: v[mask_or_index] for k, v in self.attributes.items()},
        )

    def with_attributes(self, **attrs) -> PointCloud:
        """A new cloud with attributes replaced or added."""
        merged = dict(self.attributes)
        merged.update(attrs)
        return PointCloud(self.xyz, self.origin, self.crs, self.xy_unit, self.z_unit, merged)

    def require_points(self, what: str = "input") -> None:
        """Raise :class:`EmptyInputError` when there are no points."""
        if len(self) == 0:
            raise EmptyInputError(f"{what} has no points")

    def require_area(self, what: str = "input", purpose: str = "work") -> None:
        """Raise :class:`EmptyInputError` when the points cover no area (none, one point,
        every point at one XY or on one line): ``purpose`` says what needs an area."""
        self.require_points(what)
        # 1-D reductions of the columns: an axis-0 reduction of the (N, 2) view is ~10x slower
        x, y = self.xyz[:, 0], self.xyz[:, 1]
        size = np.array([np.max(x) - np.min(x), np.max(y) - np.min(y)]) * self.xy_unit
        if not (size > 0).all():
            raise EmptyInputError(f"{what} holds {len(self)} point(s) covering {size[0]:.1f} m x "
                                  f"{size[1]:.1f} m: no area to {purpose}")

    @property
    def bounds(self) -> np.ndarray:
        """Local metric bounds ``[xmin, ymin, zmin, xmax, ymax, zmax]``."""
        self.require_points()
        return np.concatenate([self.xyz.min(axis=0), self.xyz.max(axis=0)])


@dataclass(frozen=True, eq=False)
class Footprints:
    """Building footprints in local metric coordinates.

    Parameters
    ----------
    geometries : sequence of shapely Polygon or MultiPolygon
        In the same local metric frame as the point cloud they go with.
    ids : sequence of str
        An identifier per footprint (the source's id field, or the row number).
    attributes : dict of str to sequence
        Other per-footprint fields carried through to the output.
    """

    geometries: list
    ids: list
    attributes: dict[str, list] = field(default_factory=dict)

    def __post_init__(self):
        if len(self.geometries) != len(self.ids):
            raise InputError(f"{len(self.geometries)} footprints but {len(self.ids)} ids")

    def __len__(self) -> int:
        return len(self.geometries)


@dataclass(frozen=True, eq=False)
class Surface:
    """A planar polygon of a solid's boundary.

    Parameters
    ----------
    rings : list of ndarray of int
        Indices into the solid's vertices; the first ring is the exterior
        (counter-clockwise seen from outside the solid), the others holes.
    semantic : str
        ``"GroundSurface"``, ``"WallSurface"`` or ``"RoofSurface"``
        (CityJSON semantic types).
    """

    rings: list
    semantic: str


@dataclass(frozen=True, eq=False)
class Solid:
    """A closed boundary representation: shared vertices and oriented surfaces.

    ``vertices`` are local metric coordinates, shape (M, 3).
    """

    vertices: np.ndarray
    surfaces: list

    def __post_init__(self):
        object.__setattr__(self, "vertices", np.asarray(self.vertices, dtype=np.float64))


@dataclass(eq=False)
class BuildingResult:
    """What a batch produced for one building: models by LoD, status and attributes.

    ``solids`` maps a LoD ("1.2", "1.3", "2.2") to a :class:`Solid`, or to a list
    of them (a MultiSolid) when the footprint has several polygons.
    ``status`` is ``"ok"`` or ``"failed"``; ``reason`` says why when it failed.
    ``parts`` holds BuildingPart solids per LoD (LoD1.3 height clusters).
    """

    id: str
    footprint: Any = None
    solids: dict[str, Solid | list] = field(default_factory=dict)
    parts: dict[str, list] = field(default_factory=dict)
    status: str = "ok"
    reason: str = ""
    attributes: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"
