"""Floating models: parametric building primitives fitted to footprints and LiDAR.

Each primitive is a small model with a datum point (``x``, ``y`` the plan
centre, ``z`` the ground height), a pose (translation and ``azimuth``, the
direction of the length / ridge axis in degrees counter-clockwise from +x;
tilt and swing fixed at 0) and shape parameters:

===========  ==========================================================
box          length, width, height (flat roof above the datum)
gable        + roof_height (ridge above the eaves, ridge along the
             length) and ridge_offset (0 for a symmetric roof)
hip          + roof_height, hip_length (horizontal run of the end faces)
shed         + roof_height (rise from the low eave at -width/2 to the
             high eave at +width/2; slope = atan(roof_height / width))
prism        the footprint polygon (vertices fitted) and height
prism_gable  a gable roof (ridge point x, y, azimuth, width, height,
             roof_height) over the fitted polygon
prism_shed   a shed roof over the fitted polygon
===========  ==========================================================

``height`` is the eave height above the datum (for flat roofs the roof
height). Fitting runs in two steps, as in the floating-model method:

1. **Plan (LSMDF)**: the footprint boundary is resampled at a fixed interval
   and the plan parameters minimise the squared distances of the samples
   (within a buffer) to the model edges (:mod:`lidar2city.fit.lsm`); polygon
   plans keep right angles when the footprint is rectilinear. When building
   points around the footprint are given (``context``), the roof outline
   seen in them along the free edges (not along shared walls) is added as a
   second group of observations of the same edges moved by an unknown
   overhang (one per edge direction), with data snooping; the footprint
   fixes the overhang, the LiDAR the shape.
2. **Heights**: the datum from a DTM or ground points; the roof parameters
   from the building's points transformed into the model's local frame
   ``(u, v, z)``: flat roofs from the refined histogram mode of the heights,
   sloped roofs by robust least squares of the points' perpendicular
   distances to the roof faces (the eave / ridge profile), keeping only
   points within a buffer of the model and iterating.

Standard deviations come from ``(J^T J)^-1 s0^2`` of each step, with s0 not
below the a-priori sigma (``footprint_sigma`` for footprints), the footprint
samples counted as the vertices they interpolate, and the plan uncertainty
propagated into the eave heights (an eave moves along the roof slope with
its wall).

:func:`fit_best` fits every candidate and picks one by the Bayesian
information criterion (see its docstring); :func:`fit_primitive` is the
semi-automatic entry point (a chosen primitive from approximate parameters).

References
----------
The floating-model seed (parametric primitives fitted by least-squares model
matching to map data, eq. 1-2); Schwarz, G. (1978), Estimating the dimension
of a model, *Annals of Statistics* 6(2) — the BIC; Baarda, W. (1968), A
testing procedure for use in geodetic networks — data snooping.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import math
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np

from ..config import field
from ..datamodel import Solid, Surface
from ..errors import ConfigError, FitError, InputError
from .lsm import (
    drop_observation,
    fit_polygon,
    fit_rectangle,
    fit_rectilinear,
    outline_observations,
    polygon_rings,
    rectangle_approx,
    rectangle_corners,
    resample_rings,
    segment_distances,
    solve_least_squares,
)

logger = logging.getLogger(__name__)

__all__ = [
    "PrimitivesConfig",
    "FitFailure",
    "Primitive",
    "BoxPrimitive",
    "GablePrimitive",
    "HipPrimitive",
    "ShedPrimitive",
    "PrismPrimitive",
    "PRIMITIVES",
    "fit_primitive",
    "fit_best",
    "histogram_mode",
    "bilinear",
    "datum_from_ground",
    "main_polygon",
]


@dataclass(frozen=True)
class PrimitivesConfig:
    """Stage ``primitives``: floating-model fitting of one primitive per footprint."""

    candidates: tuple[str, ...] = field(("box", "gable", "hip", "shed", "prism", "prism_gable", "prism_shed"),
                              "primitives tried by the automatic choice")
    plan_interval: float = field(0.5, "footprint boundary resampling interval, metres")
    plan_buffer: float = field(1.0, "footprint samples farther than this from the model edges are ignored, metres")
    roof_buffer: float = field(1.0, "roof points farther than this from the roof faces are ignored, metres")
    roof_loss_scale: float = field(0.2, "soft-L1 scale of the roof residuals (chimneys, dormers), metres")
    footprint_sigma: float = field(0.1, "a-priori accuracy of footprint vertices, metres (model choice)")
    roof_sigma_floor: float = field(0.02, "smallest roof residual sigma used by the model choice, metres")
    rectilinear_tolerance: float = field(10.0, "prism footprints with all edges within this many degrees of two perpendicular directions keep right angles (0: never)")
    prism_simplify: float = field(0.2, "Douglas-Peucker tolerance of the prism's approximate polygon, metres")
    lidar_outline: bool = field(True, "refine the plan with the roof outline seen in the LiDAR (free edges, unknown overhangs)")
    outline_strip: float = field(1.5, "half-width of the strip searched for the LiDAR roof outline along each edge, metres")
    outline_sigma: float = field(0.05, "smallest standard deviation of a LiDAR outline observation, metres")
    outline_max_shift: float = field(0.5, "LiDAR outline refinements moving a corner farther than this are rejected, metres")
    mode_bin: float = field(0.1, "histogram bin of the flat-roof height mode, metres")
    ground_buffer: float = field(5.0, "ground points within this distance outside a footprint give its datum, metres")
    ground_percentile: float = field(50.0, "percentile of those ground heights taken as datum (lower for unclassified points)")
    min_points: int = field(5, "fewest roof points for a fit")
    min_roof_height: float = field(0.25, "sloped roofs rising less than this (or than 3 std) count as flat, metres")
    max_slope: float = field(75.0, "steepest roof face, degrees")
    min_hip_length: float = field(0.5, "hips shorter than this (or than 3 std) are not significant, metres")

    def __post_init__(self):
        object.__setattr__(self, "candidates", tuple(self.candidates))
        unknown = sorted(set(self.candidates) - set(PRIMITIVES))
        if unknown or not self.candidates:
            raise ConfigError(f"primitives.candidates: {unknown or 'empty'} not among {', '.join(PRIMITIVES)}")
        for name in ("plan_interval", "plan_buffer", "roof_buffer", "roof_loss_scale", "outline_strip", "outline_sigma", "outline_max_shift",
                     "footprint_sigma", "roof_sigma_floor", "mode_bin", "ground_buffer"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"primitives.{name}: must be > 0, got {getattr(self, name)}")
        if not 0 <= self.ground_percentile <= 100:
            raise ConfigError(f"primitives.ground_percentile: must be in [0, 100], got {self.ground_percentile}")


class FitFailure:
    """A failed fit: falsy, carrying the primitive kind and the reason."""

    def __init__(self, kind: str, reason: str):
        self.kind = kind
        self.reason = reason

    def __bool__(self) -> bool:
        return False

    def __repr__(self) -> str:
        return f"FitFailure({self.kind!r}, {self.reason!r})"


# ---------------------------------------------------------------------------
# helpers


def histogram_mode(z, *, bin: float = 0.1, window: float | None = None) -> float:
    """The mode of heights: the fullest histogram bin, refined by the mean around it.

    Parameters
    ----------
    z : ndarray (N,)
    bin : float
        Bin width (metres). The counts are smoothed with a [1, 2, 1] kernel.
    window : float, optional
        Half-width of the refinement window (default ``3 * bin``); the mean of
        the heights within it is taken, twice.
    """
    z = np.asarray(z, dtype=np.float64)
    if len(z) == 0:
        raise FitError("no heights for a mode")
    window = 3 * bin if window is None else window
    lo = z.min()
    nb = int((z.max() - lo) / bin) + 1
    counts = np.bincount(((z - lo) / bin).astype(np.int64), minlength=nb).astype(float)
    smooth = np.convolve(np.pad(counts, 1), [1.0, 2.0, 1.0], mode="valid")
    m = lo + (np.argmax(smooth) + 0.5) * bin
    for _ in range(2):
        sel = np.abs(z - m) <= window
        if sel.any():
            m = float(z[sel].mean())
    return float(m)


def bilinear(grid, rows, cols) -> np.ndarray:
    """Bilinear interpolation of ``grid`` (H, W) at fractional pixel-centre indices.

    ``rows``/``cols`` are in pixel-centre units (0 = centre of the first pixel);
    outside the grid or next to NaN gives NaN.
    """
    grid = np.asarray(grid, dtype=np.float64)
    rows = np.asarray(rows, dtype=np.float64)
    cols = np.asarray(cols, dtype=np.float64)
    h, w = grid.shape
    r0 = np.floor(rows).astype(np.int64)
    c0 = np.floor(cols).astype(np.int64)
    fr, fc = rows - r0, cols - c0
    r0c, c0c = np.clip(r0, 0, h - 1), np.clip(c0, 0, w - 1)
    r1c, c1c = np.clip(r0 + 1, 0, h - 1), np.clip(c0 + 1, 0, w - 1)
    out = (grid[r0c, c0c] * (1 - fr) * (1 - fc) + grid[r0c, c1c] * (1 - fr) * fc
           + grid[r1c, c0c] * fr * (1 - fc) + grid[r1c, c1c] * fr * fc)
    outside = (rows < -0.5) | (cols < -0.5) | (rows > h - 0.5) | (cols > w - 0.5)
    return np.where(outside, np.nan, out)


def datum_from_ground(ground_z, *, percentile: float = 50.0) -> tuple[float, float]:
    """Datum height and its standard deviation from ground heights around a building.

    The ``percentile`` of the heights; the std is the spread (1.4826 MAD)
    over sqrt(n), times 1.2533 (efficiency of the median).
    """
    g = np.asarray(ground_z, dtype=np.float64)
    if len(g) == 0:
        raise FitError("no ground heights for the datum")
    z = float(np.percentile(g, percentile))
    mad = 1.4826 * float(np.median(np.abs(g - np.median(g))))
    return z, 1.2533 * mad / math.sqrt(len(g))


def main_polygon(geom):
    """The polygon of a footprint (the largest part of a MultiPolygon)."""
    if geom is None or geom.is_empty:
        raise FitError("empty footprint")
    if geom.geom_type == "MultiPolygon":
        return max(geom.geoms, key=lambda g: g.area)
    if geom.geom_type != "Polygon":
        raise FitError(f"footprint is a {geom.geom_type}, not a polygon")
    return geom


def _frame(xy, x, y, az_deg):
    a = math.radians(az_deg)
    dx, dy = xy[:, 0] - x, xy[:, 1] - y
    return dx * math.cos(a) + dy * math.sin(a), -dx * math.sin(a) + dy * math.cos(a)


def _to_world(u, v, x, y, az_deg):
    a = math.radians(az_deg)
    return x + u * math.cos(a) - v * math.sin(a), y + u * math.sin(a) + v * math.cos(a)


def _gable_jac(q, v, width, r):
    """Jacobian of the perpendicular roof distances ``r`` of a gable (eave height, rise,
    ridge offset ``q``) with respect to ``q``: rows points, columns parameters."""
    s = 2.0 * q[1] / width
    k2 = 1.0 + s * s
    k = math.sqrt(k2)
    t = v - q[2]
    return np.column_stack([np.full(len(v), -1.0 / k),
                            -(1.0 - 2.0 * np.abs(t) / width) / k - r * s * (2.0 / width) / k2,
                            -s * np.sign(t) / k])


_BLAS_CONTROLLER = None


def _one_blas_thread(func):
    """Run ``func`` with BLAS limited to one thread.

    The fits solve many small or skinny systems (3 roof parameters over 30k
    points, 80 polygon coordinates): multi-threaded OpenBLAS spends far more
    time waking its threads than computing (4x the CPU on a 2-core machine).
    Without ``threadpoolctl`` the BLAS keeps its threads.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        global _BLAS_CONTROLLER
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # pragma: no cover - optional speed-up
            limit = contextlib.nullcontext()
        else:
            if _BLAS_CONTROLLER is None:
                import scipy.optimize  # noqa: F401 - load scipy's BLAS before the controller looks

                _BLAS_CONTROLLER = ThreadpoolController()
            limit = _BLAS_CONTROLLER.limit(limits=1, user_api="blas")
        with limit:
            return func(*args, **kwargs)

    return wrapper


def _trunc_rss(r, c):
    return float(np.minimum(np.asarray(r) ** 2, c * c).sum())


# ---------------------------------------------------------------------------
# primitives


class Primitive:
    """Base of the fitted primitives.

    Attributes
    ----------
    params : dict of str to float
        Parameter values (metres, degrees), see the module docstring.
    std : dict of str to float
        Their standard deviations.
    info : dict
        Fit statistics: ``residual_rmse`` (roof points used, metres),
        ``plan_rmse`` (footprint samples used, metres), ``iterations``,
        ``n_points``, ``n_samples``, ``bic``.
    """

    kind: ClassVar[str] = ""
    roof_names: ClassVar[tuple] = ()

    #: optional parameters and their defaults
    defaults: ClassVar[dict] = {}

    def __init__(self, params: dict, std: dict | None = None, info: dict | None = None):
        self.params = {**self.defaults, **params}
        self.std = dict(std or {})
        self.info = dict(info or {})

    def __bool__(self) -> bool:
        return True

    def __repr__(self) -> str:
        p = ", ".join(f"{k}={v:.3f}" for k, v in self.params.items())
        return f"{type(self).__name__}({p})"

    # geometry ------------------------------------------------------------
    def outline(self) -> np.ndarray:
        """Plan outline (counter-clockwise, open), shape (K, 2)."""
        p = self.params
        return rectangle_corners(p["x"], p["y"], p["azimuth"], p["length"], p["width"])

    def roof_z(self, xy) -> tuple[np.ndarray, np.ndarray]:
        """Roof height and roof slope (tan) at plan positions (N, 2)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        p = self.params
        u, v = _frame(xy, p["x"], p["y"], p["azimuth"])
        q = np.array([p["z"] + p["height"]] + [p[n] for n in self.roof_names])
        return self._roof(q, u, v, p["length"], p["width"])

    @staticmethod
    def _roof(q, u, v, length, width):  # pragma: no cover - overridden
        raise NotImplementedError

    def residuals(self, points) -> np.ndarray:
        """Signed perpendicular distances of points (N, 3) to the roof faces (above +)."""
        points = np.asarray(points, dtype=np.float64)
        zr, s = self.roof_z(points[:, :2])
        return (points[:, 2] - zr) / np.sqrt(1.0 + s * s)

    def _local_vertices(self) -> np.ndarray:
        """Vertices in the (u, v, z) frame: base 0-3, eaves 4-7, ridge 8-9 (or apex 8)."""
        raise NotImplementedError

    def _faces(self) -> list[tuple[str, list[int]]]:
        raise NotImplementedError

    def corners(self) -> np.ndarray:
        """3-D corners of the model (the solid's vertices), shape (K, 3)."""
        return self.to_solid().vertices

    def to_solid(self) -> Solid:
        """The closed solid: shared vertices, outward counter-clockwise faces, semantics."""
        p = self.params
        luv = self._local_vertices()
        x, y = _to_world(luv[:, 0], luv[:, 1], p["x"], p["y"], p["azimuth"])
        verts = np.column_stack([x, y, luv[:, 2]])
        surfaces = [Surface([np.asarray(f, dtype=np.int64)], sem) for sem, f in self._faces()]
        return Solid(verts, surfaces)

    def derived(self) -> dict:
        """Derived quantities (roof slope in degrees...)."""
        return {}


class _Rectangular(Primitive):
    """Primitives on a rectangular plan (x, y, azimuth, length, width)."""

    def _base(self):
        p = self.params
        ln, wd, z0, ze = p["length"], p["width"], p["z"], p["z"] + p["height"]
        uv = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]) * [ln, wd]
        return np.vstack([np.column_stack([uv, np.full(4, z0)]),
                          np.column_stack([uv, np.full(4, ze)])])

    def _walls(self, ends=None):
        ends = ends or {}
        walls = []
        for i in range(4):
            j = (i + 1) % 4
            walls.append(("WallSurface", [i, j, 4 + j] + ends.get(i, []) + [4 + i]))
        return walls


class BoxPrimitive(_Rectangular):
    """A box: rectangle plan, flat roof at ``height`` above the datum."""

    kind = "box"
    roof_names = ()

    @staticmethod
    def _roof(q, u, v, length, width):
        return np.full(u.shape, q[0]), np.zeros(u.shape)

    @staticmethod
    def _roof_jac(q, u, v, length, width, r):
        return np.full((len(u), 1), -1.0)

    def _local_vertices(self):
        return self._base()

    def _faces(self):
        return [("GroundSurface", [0, 3, 2, 1])] + self._walls() + [("RoofSurface", [4, 5, 6, 7])]


class GablePrimitive(_Rectangular):
    """A gable-roof house: ridge along the length, ``roof_height`` above the eaves.

    ``ridge_offset`` moves the ridge across (towards +v) from the centre line
    (0 for a symmetric roof); both faces keep the slope
    ``2 roof_height / width``, so the eaves are at ``height -+ slope *
    ridge_offset`` and ``height`` is their mean. The footprint fixes the
    walls, the points the ridge: noise in the footprint does not tilt the roof.
    """

    kind = "gable"
    roof_names = ("roof_height", "ridge_offset")
    defaults = {"ridge_offset": 0.0}

    @staticmethod
    def _roof(q, u, v, length, width):
        s = 2.0 * q[1] / width
        return q[0] + q[1] - s * np.abs(v - q[2]), np.full(u.shape, s)

    @staticmethod
    def _roof_jac(q, u, v, length, width, r):
        return _gable_jac(q, v, width, r)

    def _local_vertices(self):
        p = self.params
        b = self._base()
        s = 2.0 * p["roof_height"] / p["width"]
        dz = s * p["ridge_offset"]
        b[4:6, 2] -= dz
        b[6:8, 2] += dz
        zr = p["z"] + p["height"] + p["roof_height"]
        ridge = np.array([[-p["length"] / 2, p["ridge_offset"], zr], [p["length"] / 2, p["ridge_offset"], zr]])
        return np.vstack([b, ridge])

    def _faces(self):
        return ([("GroundSurface", [0, 3, 2, 1])] + self._walls({1: [9], 3: [8]})
                + [("RoofSurface", [4, 5, 9, 8]), ("RoofSurface", [6, 7, 8, 9])])

    def derived(self):
        p = self.params
        return {"roof_slope": math.degrees(math.atan2(2 * p["roof_height"], p["width"]))}


class HipPrimitive(_Rectangular):
    """A hip-roof house: gable plus end faces running ``hip_length`` from the end walls."""

    kind = "hip"
    roof_names = ("roof_height", "hip_length")

    @staticmethod
    def _roof(q, u, v, length, width):
        ze, rh, hl = q
        side = 1.0 - 2.0 * np.abs(v) / width
        end = (length / 2.0 - np.abs(u)) / max(hl, 1e-9)
        use_end = end < side
        s = np.where(use_end, rh / max(hl, 1e-9), 2.0 * rh / width)
        return ze + rh * np.minimum(side, end), s

    @staticmethod
    def _roof_jac(q, u, v, length, width, r):
        _, rh, hl = q
        h = max(hl, 1e-9)
        side = 1.0 - 2.0 * np.abs(v) / width
        e = length / 2.0 - np.abs(u)
        use_end = e / h < side
        s = np.where(use_end, rh / h, 2.0 * rh / width)
        k2 = 1.0 + s * s
        k = np.sqrt(k2)
        ds_drh = np.where(use_end, 1.0 / h, 2.0 / width)
        dzr_drh = np.where(use_end, e / h, side)
        # the end faces: zr = ze + rh e / hl and s = rh / hl both move with hl
        dr_dhl = np.where(use_end, (rh * e / (h * h)) / k + r * s * rh / (h * h * k2), 0.0) if hl > 1e-9 \
            else np.zeros(len(u))
        return np.column_stack([-1.0 / k, -dzr_drh / k - r * s * ds_drh / k2, dr_dhl])

    def _apex(self):
        return self.params["length"] - 2 * self.params["hip_length"] < 1e-3

    def _local_vertices(self):
        p = self.params
        zr = p["z"] + p["height"] + p["roof_height"]
        if self._apex():
            return np.vstack([self._base(), [[0.0, 0.0, zr]]])
        r = p["length"] / 2 - p["hip_length"]
        return np.vstack([self._base(), [[-r, 0.0, zr], [r, 0.0, zr]]])

    def _faces(self):
        faces = [("GroundSurface", [0, 3, 2, 1])] + self._walls()
        if self._apex():
            return faces + [("RoofSurface", [4, 5, 8]), ("RoofSurface", [5, 6, 8]),
                            ("RoofSurface", [6, 7, 8]), ("RoofSurface", [7, 4, 8])]
        return faces + [("RoofSurface", [4, 5, 9, 8]), ("RoofSurface", [5, 6, 9]),
                        ("RoofSurface", [6, 7, 8, 9]), ("RoofSurface", [7, 4, 8])]

    def derived(self):
        p = self.params
        return {"roof_slope": math.degrees(math.atan2(2 * p["roof_height"], p["width"])),
                "hip_slope": math.degrees(math.atan2(p["roof_height"], p["hip_length"]))}


class ShedPrimitive(_Rectangular):
    """A shed (mono-pitch) roof rising ``roof_height`` from v = -width/2 to +width/2."""

    kind = "shed"
    roof_names = ("roof_height",)

    @staticmethod
    def _roof(q, u, v, length, width):
        s = q[1] / width
        return q[0] + s * (v + width / 2.0), np.full(u.shape, s)

    @staticmethod
    def _roof_jac(q, u, v, length, width, r):
        s = q[1] / width
        k2 = 1.0 + s * s
        k = math.sqrt(k2)
        return np.column_stack([np.full(len(u), -1.0 / k), -((v + width / 2.0) / width) / k - r * s / (width * k2)])

    def _local_vertices(self):
        b = self._base()
        b[6:8, 2] += self.params["roof_height"]
        return b

    def _faces(self):
        return [("GroundSurface", [0, 3, 2, 1])] + self._walls() + [("RoofSurface", [4, 5, 6, 7])]

    def derived(self):
        p = self.params
        return {"roof_slope": math.degrees(math.atan2(p["roof_height"], p["width"]))}


def _vplane(c0, g, x, y, az_deg):
    """Plane ``z = c0 + g * v`` (v across the azimuth from (x, y)) as ``(a, b, c)`` of a + b X + c Y."""
    t = math.radians(az_deg)
    st, ct = math.sin(t), math.cos(t)
    return [c0 + g * (x * st - y * ct), -g * st, g * ct]


class PrismPrimitive(Primitive):
    """A polygonal prism: the fitted footprint polygon extruded to a flat roof.

    ``rings`` holds the fitted rings in local plan coordinates (exterior
    counter-clockwise, holes clockwise, open).
    """

    kind = "prism"
    roof_names = ()

    def __init__(self, params, std=None, info=None, rings=None):
        super().__init__(params, std, info)
        self.rings = [np.asarray(r, dtype=np.float64) for r in (rings or [])]

    def outline(self):
        return self.rings[0]

    def polygon(self):
        """The fitted plan as a shapely Polygon."""
        import shapely

        return shapely.Polygon(self.rings[0], self.rings[1:])

    def roof_z(self, xy):
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.full(len(xy), self.params["z"] + self.params["height"]), np.zeros(len(xy))

    def to_solid(self):
        z0 = self.params["z"]
        zt = z0 + self.params["height"]
        n = sum(len(r) for r in self.rings)
        plan = np.vstack(self.rings)
        verts = np.vstack([np.column_stack([plan, np.full(n, z0)]),
                           np.column_stack([plan, np.full(n, zt)])])
        offs = np.concatenate([[0], np.cumsum([len(r) for r in self.rings])])
        ground, roof, walls = [], [], []
        for o0, o1 in zip(offs[:-1], offs[1:], strict=True):
            idx = np.arange(o0, o1)
            ground.append(idx[::-1].copy())
            roof.append(idx + n)
            for i, j in zip(idx, np.roll(idx, -1), strict=True):
                walls.append(Surface([np.array([i, j, j + n, i + n])], "WallSurface"))
        return Solid(verts, [Surface(ground, "GroundSurface")] + walls + [Surface(roof, "RoofSurface")])


class PrismGablePrimitive(PrismPrimitive):
    """A gable roof over a polygonal footprint (L-shaped houses, irregular plots).

    ``x``, ``y`` is a point of the ridge line (the one nearest the footprint
    centroid), ``azimuth`` its direction; the roof falls by ``roof_height``
    over ``width / 2`` on both sides, reaching ``height`` above the datum at
    ``|v| = width / 2``. The solid is the polygon up to the lower envelope of
    the two roof planes (:func:`lidar2city.fit.envelope.envelope_solid`).
    """

    kind = "prism_gable"
    roof_names = ("roof_height", "ridge_offset")

    _roof = staticmethod(GablePrimitive._roof)
    _roof_jac = staticmethod(GablePrimitive._roof_jac)

    def roof_z(self, xy):
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        p = self.params
        u, v = _frame(xy, p["x"], p["y"], p["azimuth"])
        return self._roof(np.array([p["z"] + p["height"], p["roof_height"], 0.0]), u, v,
                          1.0, p["width"])

    def planes(self):
        p = self.params
        ze = p["z"] + p["height"]
        s = 2.0 * p["roof_height"] / p["width"]
        top = ze + p["roof_height"]
        return [_vplane(top, -s, p["x"], p["y"], p["azimuth"]), _vplane(top, s, p["x"], p["y"], p["azimuth"])]

    def to_solid(self):
        from .envelope import envelope_solid

        return envelope_solid(self.polygon(), self.planes(), self.params["z"])

    def derived(self):
        p = self.params
        return {"roof_slope": math.degrees(math.atan2(2 * p["roof_height"], p["width"]))}


class PrismShedPrimitive(PrismGablePrimitive):
    """A shed roof over a polygonal footprint: one plane rising ``roof_height`` over ``width``.

    ``x``, ``y`` is the centre of the footprint's minimum rotated rectangle,
    ``height`` the roof height above the datum at ``v = -width / 2``.
    """

    kind = "prism_shed"
    roof_names = ("roof_height",)

    _roof = staticmethod(ShedPrimitive._roof)
    _roof_jac = staticmethod(ShedPrimitive._roof_jac)

    def roof_z(self, xy):
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        p = self.params
        u, v = _frame(xy, p["x"], p["y"], p["azimuth"])
        return self._roof(np.array([p["z"] + p["height"], p["roof_height"]]), u, v, 1.0, p["width"])

    def planes(self):
        p = self.params
        g = p["roof_height"] / p["width"]
        return [_vplane(p["z"] + p["height"] + p["roof_height"] / 2, g, p["x"], p["y"], p["azimuth"])]

    def derived(self):
        p = self.params
        return {"roof_slope": math.degrees(math.atan2(p["roof_height"], p["width"]))}


PRIMITIVES: dict[str, type[Primitive]] = {
    "box": BoxPrimitive,
    "gable": GablePrimitive,
    "hip": HipPrimitive,
    "shed": ShedPrimitive,
    "prism": PrismPrimitive,
    "prism_gable": PrismGablePrimitive,
    "prism_shed": PrismShedPrimitive,
}

PrimitiveName = Literal["box", "gable", "hip", "shed", "prism", "prism_gable", "prism_shed"]


# ---------------------------------------------------------------------------
# fitting


def _fit_roof(cls, q0, bounds, points, plan, *, buffer, loss_scale, min_points, max_outer=6):
    """Iterated robust least squares of roof parameters ``q`` to points near the roof."""
    x, y, az, ln, wd = plan
    u, v = _frame(points[:, :2], x, y, az)
    z = points[:, 2]

    def resid(q, uu, vv, zz):
        zr, s = cls._roof(q, uu, vv, ln, wd)
        return (zz - zr) / np.sqrt(1.0 + s * s)

    q = np.asarray(q0, dtype=np.float64)
    sel = np.ones(len(z), dtype=bool)
    prev = None
    nfev = 0
    std = np.zeros_like(q)
    for _ in range(max_outer):
        if sel.sum() < max(min_points, len(q) + 1):
            raise FitError(f"{int(sel.sum())} roof points within {buffer} m of the {cls.kind} roof")
        obs = (u[sel], v[sel], z[sel])
        q, std, _, nf, _ = solve_least_squares(lambda qq, obs=obs: resid(qq, *obs), q,
                                               jac=lambda qq, obs=obs: cls._roof_jac(qq, obs[0], obs[1], ln, wd,
                                                                                     resid(qq, *obs)),
                                               bounds=bounds, loss="soft_l1", f_scale=loss_scale)
        nfev += nf
        sel = np.abs(resid(q, u, v, z)) <= buffer
        if prev is not None and np.array_equal(sel, prev):
            break
        prev = sel
    r = resid(q, u[sel], v[sel], z[sel])
    return q, std, r, sel, nfev


def _roof_start(kind, z, ln, wd):
    lo, hi = np.percentile(z, [5, 95])
    rh = max(hi - lo, 0.2)
    q = {"box": [lo], "gable": [lo, rh, 0.0], "hip": [lo, rh, min(wd / 2, ln / 2 * 0.95)],
         "shed": [lo, hi - lo]}[kind]
    return q


def _bic(roof_r, n_roof_params, plan_d, n_plan_params, n_vertices, cfg: PrimitivesConfig):
    """BIC of a candidate: roof term (unknown sigma) + plan term (known footprint sigma)."""
    n_r = len(roof_r)
    rss = _trunc_rss(roof_r, cfg.roof_buffer)
    roof = n_r * math.log(max(rss / n_r, cfg.roof_sigma_floor ** 2)) + n_roof_params * math.log(n_r)
    n_p = len(plan_d)
    n_eff = max(n_vertices, n_plan_params)
    plan = (n_eff / n_p) * _trunc_rss(plan_d, 2 * cfg.plan_buffer) / cfg.footprint_sigma ** 2
    plan += n_plan_params * math.log(n_eff)
    return roof + plan, roof, plan


def _rect_from_approx(approx, polygon):
    base = rectangle_approx(polygon)
    if not approx:
        return base
    names = ("x", "y", "azimuth", "length", "width")
    return np.array([float(approx.get(n, b)) if approx.get(n) is not None else b
                     for n, b in zip(names, base, strict=True)])


def _sample_sigma(cfg, n_samples, polygon):
    """Std of one boundary sample such that all count as the footprint's vertices."""
    nv = sum(len(r) for r in polygon_rings(polygon))
    return cfg.footprint_sigma * math.sqrt(max(n_samples, 1) / max(nv, 1))


def _density(points, polygon):
    return len(points) / polygon.area if polygon.area > 0 else 0.0


def _decorrelate(plan, polygon):
    """Footprint-only std devs: the resampled boundary holds only the vertices' information.

    The samples are interpolated between the footprint's vertices, so the
    normal matrix is scaled down by ``n_samples / n_vertices``.
    """
    nv = sum(len(r) for r in polygon_rings(polygon))
    f = max(math.sqrt(max(int(plan.used.sum()), 1) / max(nv, 1)), 1.0)
    return dataclasses.replace(plan, std=plan.std * f)


def _determined(std: dict) -> tuple[dict, dict]:
    """The finite std devs, and an info entry naming the parameters the data do not determine
    (e.g. the ridge offset of a gable with no rise): no std is reported for those."""
    ok = {k: float(v) for k, v in std.items() if math.isfinite(v)}
    bad = sorted(k for k in std if k not in ok)
    return ok, ({"undetermined": ", ".join(bad)} if bad else {})


def _finite_max(std) -> float:
    """Largest finite standard deviation (0 when none is)."""
    std = np.asarray(std, dtype=np.float64)
    std = std[np.isfinite(std)]
    return float(std.max()) if len(std) else 0.0


def _vertex_std(plan):
    """Standard deviations of the determined polygon vertices, their RMS, the undetermined count.

    A vertex the footprint samples do not fix (e.g. the end of an edge with a
    single sample: only the weak prior holds it) has NaN std devs from the
    fit; it is counted, not averaged in as a huge number. The vertices the
    data determine give the RMS (NaN when there is none).
    """
    vstd = plan.std.reshape(-1, 2)
    ok = np.isfinite(vstd).all(axis=1)
    vstd = vstd[ok]
    rms = float(np.sqrt(np.mean(vstd ** 2))) if len(vstd) else math.nan
    return vstd, rms, int((~ok).sum())


def _shift_limit(cfg, corner_std):
    """Largest corner move accepted from the LiDAR outline: 3 std of the footprint-only corners
    (at least 3 a-priori footprint sigmas in 2-D), at most ``outline_max_shift``."""
    return min(cfg.outline_max_shift, 3.0 * max(corner_std, math.sqrt(2.0) * cfg.footprint_sigma))


def _snoop(fit, outline, *, k: float = 3.0, max_drop: int = 3):
    """Fit with the outline observations, dropping the worst while its residual exceeds k sigma.

    Data snooping (Baarda): an outline piece contradicting the footprint and
    the other pieces (a dormer, a gutter, a lower annex) is removed. Returns
    None when fewer than 2 observations remain.
    """
    for _ in range(max_drop + 1):
        if len(outline) < 2:
            return None
        f = fit(outline)
        w = np.abs(f.extra.get("outline_residuals", np.zeros(0))) / outline.sigma
        if len(w) == 0 or w.max() <= k:
            return f
        outline = drop_observation(outline, int(np.argmax(w)))
    return None


def _plan_rectangle(polygon, samples, approx, cfg, context=None, density=0.0):
    plan = _decorrelate(fit_rectangle(samples, _rect_from_approx(approx, polygon), buffer=cfg.plan_buffer,
                                      sigma_floor=cfg.footprint_sigma), polygon)
    if not cfg.lidar_outline or context is None or len(context) == 0 or density <= 0:
        return plan
    c = rectangle_corners(*plan.params)
    outline = outline_observations(np.asarray(context)[:, :2], c, np.roll(c, -1, axis=0), density=density,
                                   family=np.array([0, 1, 0, 1]), strip=cfg.outline_strip,
                                   sigma=cfg.outline_sigma)
    if len(outline) < 2:
        return plan
    refined = _snoop(lambda o: fit_rectangle(samples, plan.params, buffer=cfg.plan_buffer, outline=o,
                                             sample_sigma=_sample_sigma(cfg, int(plan.used.sum()), polygon),
                                             sigma_floor=1.0),
                     outline)
    if refined is None:
        return plan
    shift = np.hypot(*(rectangle_corners(*refined.params) - c).T).max()
    sx, sy, saz, sl, sw = plan.std
    corner_std = math.sqrt(sx ** 2 + sy ** 2 + (sl / 2) ** 2 + (sw / 2) ** 2
                           + (max(plan.params[3:5]) / 2 * math.radians(saz)) ** 2)
    if shift > _shift_limit(cfg, corner_std):
        logger.debug("LiDAR outline moved a corner by %.2f m: kept the footprint-only plan", shift)
        return plan
    return refined


def _check_inputs(footprint, points):
    polygon = main_polygon(footprint)
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {points.shape}")
    return polygon, points


def _finish_rect(cls, plan, q, qstd, datum, samples, orientation_swap=False):
    x, y, az, ln, wd = plan.params
    sx, sy, saz, sl, sw = plan.std
    if orientation_swap:
        az, ln, wd, sl, sw = az + 90.0, wd, ln, sw, sl
    z0, z0std = datum
    params = {"x": x, "y": y, "z": z0, "azimuth": az % 360.0, "length": ln, "width": wd,
              "height": q[0] - z0}
    std = {"x": sx, "y": sy, "z": z0std, "azimuth": saz, "length": sl, "width": sw,
           "height": math.hypot(qstd[0], z0std)}
    for name, val, sd in zip(cls.roof_names, q[1:], qstd[1:], strict=True):
        params[name] = float(val)
        std[name] = float(sd)
    # the eaves sit where the walls are: plan (width) uncertainty moves them along the slope
    if cls is not BoxPrimitive:
        slope = 2.0 * q[1] / wd if cls is not ShedPrimitive else q[1] / wd
        dz = abs(slope) * sw / 2.0
        std["height"] = math.hypot(std["height"], dz)
        std["roof_height"] = math.hypot(std["roof_height"], dz if cls is not ShedPrimitive else 2 * dz)
    if cls is ShedPrimitive and params["roof_height"] < 0:
        # canonical: rising towards +v; turn the model by 180 degrees
        params["azimuth"] = (params["azimuth"] + 180.0) % 360.0
        params["height"] += params["roof_height"]
        params["roof_height"] = -params["roof_height"]
    elif cls is not ShedPrimitive:
        if params["azimuth"] % 360.0 >= 180.0 and "ridge_offset" in params:
            params["ridge_offset"] = -params["ridge_offset"]
        params["azimuth"] %= 180.0
    model = cls({k: float(v) for k, v in params.items()}, *_determined(std))
    low = float(model._local_vertices()[4:, 2].min()) - z0
    if low <= 0:
        raise FitError(f"roof below the datum (lowest eave {low:.2f} m above it)")
    c = model.outline()
    d = segment_distances(samples, c, np.roll(c, -1, axis=0)).min(axis=1)
    return model, d


@_one_blas_thread
def fit_primitive(kind: str, footprint, points, *, datum=(0.0, 0.0), approx: dict | None = None,
                  context=None, config: PrimitivesConfig | None = None):
    """Fit one primitive of a chosen kind (semi-automatic mode).

    Parameters
    ----------
    kind : {'box', 'gable', 'hip', 'shed', 'prism'}
    footprint : shapely Polygon or MultiPolygon
        Local metric plan (the largest part of a MultiPolygon is used).
    points : ndarray, shape (N, 3)
        The building's points (roof points; those inside the footprint).
    datum : (float, float)
        Ground height at the building and its standard deviation.
    approx : dict, optional
        Approximate parameters to start from (any of ``x, y, azimuth, length,
        width, height, roof_height, hip_length``, local metres / degrees). The
        azimuth fixes the ridge direction of gable / hip / shed roofs (the
        shed's high side may flip). Missing ones come from the footprint's
        minimum rotated rectangle and the point heights.
    context : ndarray, shape (M, 2) or (M, 3), optional
        Building points around the footprint (inside and up to
        ``outline_strip`` outside): the roof outline seen in them refines
        the plan (``lidar_outline``).
    config : PrimitivesConfig, optional

    Returns
    -------
    Primitive or FitFailure
        The fitted model, or a falsy failure with the reason.
    """
    cfg = config or PrimitivesConfig()
    if kind not in PRIMITIVES:
        raise InputError(f"kind must be one of {', '.join(PRIMITIVES)}, got {kind!r}")
    try:
        polygon, points = _check_inputs(footprint, points)
        samples = resample_rings(polygon_rings(polygon), cfg.plan_interval)
        if kind.startswith("prism"):
            pp = _prism_plan(polygon, samples, cfg, context, _density(points, polygon))
            return _fit_prism_kind(PRIMITIVES[kind], pp, points, datum, cfg, approx)[0]
        plan = _plan_rectangle(polygon, samples, approx, cfg, context, _density(points, polygon))
        return _fit_rect_kind(PRIMITIVES[kind], plan, polygon, points, samples, datum, cfg,
                              approx, swap=False)[0]
    except FitError as exc:
        return FitFailure(kind, str(exc))


def _fit_rect_kind(cls, plan, polygon, points, samples, datum, cfg, approx, *, swap):
    if len(points) < cfg.min_points:
        raise FitError(f"{len(points)} points (fewer than {cfg.min_points})")
    x, y, az, ln, wd = plan.params
    geo = (x, y, az + 90.0, wd, ln) if swap else (x, y, az, ln, wd)
    ln_g, wd_g = geo[3], geo[4]
    if cls is BoxPrimitive:
        q0 = [histogram_mode(points[:, 2], bin=cfg.mode_bin)]
        bounds = None
    else:
        q0 = _roof_start(cls.kind, points[:, 2], ln_g, wd_g)
        tmax = math.tan(math.radians(cfg.max_slope))
        if cls is HipPrimitive:
            bounds = ([-np.inf, 0.0, 0.05], [np.inf, tmax * wd_g / 2, ln_g / 2.0])
        elif cls is GablePrimitive:
            bounds = ([-np.inf, 0.0, -0.45 * wd_g], [np.inf, tmax * wd_g / 2, 0.45 * wd_g])
        else:
            bounds = ([-np.inf, -tmax * wd_g], [np.inf, tmax * wd_g])
    if approx:
        z0 = datum[0]
        if approx.get("height") is not None:
            q0[0] = z0 + float(approx["height"])
        for i, name in enumerate(cls.roof_names, start=1):
            if approx.get(name) is not None:
                q0[i] = float(approx[name])
        if bounds is not None:
            q0 = list(np.clip(q0, np.asarray(bounds[0]) + 1e-6, np.asarray(bounds[1]) - 1e-6))
    q, qstd, r, sel, nfev = _fit_roof(cls, q0, bounds, points, geo, buffer=cfg.roof_buffer,
                                       loss_scale=cfg.roof_loss_scale, min_points=cfg.min_points)
    if cls is not BoxPrimitive and abs(q[1]) < max(cfg.min_roof_height, 3.0 * qstd[1]):
        raise FitError(f"roof rise {abs(q[1]):.2f} m +- {qstd[1]:.2f} not significant (flat)")
    if cls is HipPrimitive and q[2] < max(cfg.min_hip_length, 3.0 * qstd[2]):
        raise FitError(f"hip length {q[2]:.2f} m +- {qstd[2]:.2f} not significant (a gable)")
    model, plan_d = _finish_rect(cls, plan, q, qstd, datum, samples, orientation_swap=swap)
    all_r = model.residuals(points)
    bic, broof, bplan = _bic(all_r, len(q), plan_d, 5, len(polygon_rings(polygon)[0]), cfg)
    model.info.update(_fit_info(r, plan, nfev, sel, bic, broof, bplan))
    return model, bic


def _fit_info(r, plan, nfev, sel, bic, broof, bplan) -> dict:
    """What a fitted model reports: residuals, iterations, observations, BIC terms."""
    return {
        "residual_rmse": float(np.sqrt(np.mean(r ** 2))),
        "plan_rmse": float(np.sqrt(np.mean(plan.residuals ** 2))) if len(plan.residuals) else 0.0,
        "iterations": int(plan.iterations + nfev),
        "n_points": int(sel.sum()),
        "n_samples": int(plan.used.sum()),
        "n_outline": int(plan.extra.get("n_outline", 0)),
        "bic": bic, "bic_roof": broof, "bic_plan": bplan,
    }


def _prism_plan(polygon, samples, cfg, context=None, density=0.0):
    """LSMDF of the simplified footprint polygon (shared by all prism kinds).

    Rectilinear footprints (every edge within ``rectilinear_tolerance`` of
    two perpendicular directions) are fitted with right angles enforced
    (:func:`~lidar2city.fit.lsm.fit_rectilinear`), others vertex by vertex.
    """
    import shapely

    simple = shapely.simplify(polygon, cfg.prism_simplify, preserve_topology=True)
    if simple.is_empty or simple.area <= 0 or simple.geom_type != "Polygon":
        simple = polygon
    rings = polygon_rings(simple)

    def fit(approx_rings, az=None, **kw):
        if cfg.rectilinear_tolerance > 0:
            f = fit_rectilinear(samples, approx_rings, azimuth=az, buffer=cfg.plan_buffer,
                                tolerance=cfg.rectilinear_tolerance, **kw)
            if f is not None:
                return f
        return fit_polygon(samples, approx_rings, buffer=cfg.plan_buffer, **kw)

    plan = _decorrelate(fit(rings, sigma_floor=cfg.footprint_sigma), polygon)
    if cfg.lidar_outline and context is not None and len(context) and density > 0:
        flat = plan.params.reshape(-1, 2)
        offs = plan.extra["offsets"]
        sizes = np.diff(offs)
        i1 = np.concatenate([o + (np.arange(n) + 1) % n for o, n in zip(offs[:-1], sizes, strict=True)])
        a, b = flat, flat[i1]
        az = plan.extra.get("azimuth", rectangle_approx(simple)[2])
        ang = (np.degrees(np.arctan2(b[:, 1] - a[:, 1], b[:, 0] - a[:, 0])) - az) % 180.0
        fam = np.where((ang < 20) | (ang > 160), 0, np.where(np.abs(ang - 90) < 20, 1, 2))
        outline = outline_observations(np.asarray(context)[:, :2], a, b, density=density, family=fam,
                                       strip=cfg.outline_strip, sigma=cfg.outline_sigma)
        if len(outline) >= 2:
            approx = [flat[o0:o1] for o0, o1 in zip(offs[:-1], offs[1:], strict=True)]
            refined = _snoop(lambda o: fit(approx, plan.extra.get("azimuth"), outline=o,
                                           sample_sigma=_sample_sigma(cfg, int(plan.used.sum()), polygon),
                                           sigma_floor=1.0),
                             outline)
            moved = None
            if refined is not None and refined.params.size == flat.size:
                moved = refined.params.reshape(-1, 2) - flat
            limit = _shift_limit(cfg, math.sqrt(2.0) * _finite_max(plan.std))
            if moved is not None and np.hypot(*moved.T).max() <= limit:
                plan = refined
    flat = plan.params.reshape(-1, 2)
    offs = plan.extra["offsets"]
    fitted = [flat[a:b] for a, b in zip(offs[:-1], offs[1:], strict=True)]
    fitted_poly = shapely.Polygon(fitted[0], fitted[1:])
    if not fitted_poly.is_valid or fitted_poly.area <= 0:
        # the fit crossed edges (tiny features): keep the approximate rings
        fitted = rings
        fitted_poly = simple
    a = np.vstack(fitted)
    b = np.vstack([np.roll(rr, -1, axis=0) for rr in fitted])
    plan_d = segment_distances(samples, a, b).min(axis=1)
    return {"rings": fitted, "polygon": fitted_poly, "plan": plan, "plan_d": plan_d,
            "n_vertices": len(a), "n_plan_params": int(plan.extra.get("n_params", 2 * len(a))), "n_footprint_vertices": sum(len(r) for r in polygon_rings(polygon))}


def _fit_prism_kind(cls, pp, points, datum, cfg, approx=None, *, swap=False):
    if len(points) < cfg.min_points:
        raise FitError(f"{len(points)} points (fewer than {cfg.min_points})")
    plan = pp["plan"]
    z0, z0std = datum
    vstd, vertex_std, undetermined = _vertex_std(plan)
    if len(vstd) == 0:
        raise FitError("no footprint vertex determined by the boundary samples")
    z = points[:, 2]
    tmax = math.tan(math.radians(cfg.max_slope))
    if cls is PrismPrimitive:
        h0 = histogram_mode(z, bin=cfg.mode_bin)
        if approx and approx.get("height") is not None:
            h0 = z0 + float(approx["height"])
        q, qstd, r, sel, nfev = _fit_roof(BoxPrimitive, [h0], None, points, (0.0, 0.0, 0.0, 1.0, 1.0),
                                          buffer=cfg.roof_buffer, loss_scale=cfg.roof_loss_scale,
                                          min_points=cfg.min_points)
        if q[0] - z0 <= 0:
            raise FitError(f"roof below the datum (height {q[0] - z0:.2f} m)")
        c = pp["polygon"].centroid
        params = {"x": c.x, "y": c.y, "z": z0, "azimuth": 0.0, "height": q[0] - z0}
        std = {"x": float(np.sqrt(np.mean(vstd[:, 0] ** 2))) if len(vstd) else vertex_std,
               "y": float(np.sqrt(np.mean(vstd[:, 1] ** 2))) if len(vstd) else vertex_std,
               "z": z0std, "height": math.hypot(qstd[0], z0std)}
    else:
        x, y, az, ln, wd = rectangle_approx(pp["polygon"])
        if approx and approx.get("azimuth") is not None:
            az = float(approx["azimuth"])
            if abs(((az - rectangle_approx(pp["polygon"])[2]) + 45.0) % 180.0 - 45.0) > 45.0:
                ln, wd = wd, ln
        if swap:
            az, ln, wd = az + 90.0, wd, ln
        lo, hi = np.percentile(z, [5, 95])
        if cls is PrismGablePrimitive:
            q0 = [lo, max(hi - lo, 0.2), 0.0]
            bounds = ([-np.inf, 0.0, -wd / 2], [np.inf, tmax * wd / 2, wd / 2])
        else:
            q0 = [lo, hi - lo]
            bounds = ([-np.inf, -tmax * wd], [np.inf, tmax * wd])
        if approx:
            if approx.get("height") is not None:
                q0[0] = z0 + float(approx["height"])
            if approx.get("roof_height") is not None:
                q0[1] = float(approx["roof_height"])
        q, qstd, r, sel, nfev = _fit_roof(cls, q0, bounds, points, (x, y, az, ln, wd),
                                          buffer=cfg.roof_buffer, loss_scale=cfg.roof_loss_scale,
                                          min_points=cfg.min_points)
        if abs(q[1]) < max(cfg.min_roof_height, 3.0 * qstd[1]):
            raise FitError(f"roof rise {abs(q[1]):.2f} m +- {qstd[1]:.2f} not significant (flat)")
        t = math.radians(az)
        d = np.array([math.cos(t), math.sin(t)])
        nrm = np.array([-math.sin(t), math.cos(t)])
        ze, rh = q[0], q[1]
        if cls is PrismGablePrimitive:
            ridge = np.array([x, y]) + q[2] * nrm
            c = np.array(pp["polygon"].centroid.coords[0])
            ridge = ridge + ((c - ridge) @ d) * d
            x, y = ridge
            az %= 180.0
        elif rh < 0:
            az, ze, rh = az + 180.0, ze + rh, -rh
        params = {"x": float(x), "y": float(y), "z": z0, "azimuth": az % 360.0, "width": float(wd),
                  "height": ze - z0, "roof_height": float(rh)}
        std = {"x": vertex_std, "y": vertex_std, "z": z0std, "height": math.hypot(qstd[0], z0std),
               "roof_height": float(qstd[1])}
        if cls is PrismGablePrimitive:
            std["ridge_offset"] = float(qstd[2])
    std["vertex"] = vertex_std
    params["vertices"] = float(pp["n_vertices"])
    model = cls({k: float(v) for k, v in params.items()}, *_determined(std), rings=pp["rings"])
    if cls is not PrismPrimitive:
        model.to_solid()  # raises FitError when the roof does not close over the polygon
    bic, broof, bplan = _bic(model.residuals(points), len(q), pp["plan_d"], pp["n_plan_params"],
                             pp["n_footprint_vertices"], cfg)
    model.info.update(_fit_info(r, plan, nfev, sel, bic, broof, bplan))
    if undetermined:
        model.info["n_undetermined"] = undetermined
    return model, bic


@_one_blas_thread
def fit_best(footprint, points, *, datum=(0.0, 0.0), context=None,
             config: PrimitivesConfig | None = None):
    """Fit every candidate primitive and choose one by BIC (automatic mode).

    Candidates: a box, gable, hip and shed on the LSMDF rectangle (gable, hip
    and shed in both ridge directions), and a flat prism, a gable and a shed
    roof over the fitted footprint polygon. First the plan family is chosen
    from the footprint alone (the polygon only with a plan BIC lower by 2
    than the rectangle's), then the roof within it by the whole BIC (the
    plan terms being equal there); a sloped roof rising less than
    ``min_roof_height`` or 3 std, and a hip shorter than ``min_hip_length``
    or 3 std, are not candidates. The BIC is

    ``BIC = n_r ln(max(RSS_r / n_r, s_r^2)) + k_r ln(n_r)
    + (n_v / n_s) RSS_p / sigma_fp^2 + k_p ln(n_v)``

    - roof term: ``RSS_r`` the sum of squared perpendicular distances of all
      ``n_r`` points to the roof, each truncated at ``roof_buffer`` (a dormer
      or tree does not decide the roof type), with unknown variance floored at
      ``roof_sigma_floor``; ``k_r`` roof parameters (box and prism 1, shed and
      prism_shed 2, gable, hip and prism_gable 3);
    - plan term: ``RSS_p`` the squared distances of the ``n_s`` boundary
      samples to the model outline (truncated at twice ``plan_buffer``) with
      the known footprint accuracy ``footprint_sigma``; the samples are
      interpolated between the ``n_v`` footprint vertices, so they count as
      ``n_v`` observations; ``k_p`` plan parameters (5 for a rectangle, 1 + one
      per edge for a rectilinear polygon, 2 per vertex otherwise).

    Parameters
    ----------
    footprint : shapely Polygon or MultiPolygon
        Local metric plan (the largest part of a MultiPolygon is used).
    points : ndarray, shape (N, 3)
        The building's roof points (inside the footprint).
    datum : (float, float)
        Ground height and its standard deviation.
    context : ndarray, shape (M, 2) or (M, 3), optional
        Building points around the footprint for the LiDAR outline.
    config : PrimitivesConfig, optional

    Returns
    -------
    best : Primitive or FitFailure
    fits : dict of str to Primitive or FitFailure
        Every candidate (``"gable"`` and ``"gable90"`` for the two ridge directions...).

    Examples
    --------
    >>> import numpy as np, shapely
    >>> from lidar2city.fit.primitives import GablePrimitive, fit_best
    >>> truth = GablePrimitive({"x": 0, "y": 0, "z": 0, "azimuth": 0, "length": 12,
    ...                         "width": 8, "height": 5, "roof_height": 3})
    >>> xy = np.stack(np.meshgrid(np.arange(-5.9, 6, 0.5), np.arange(-3.9, 4, 0.5)), -1).reshape(-1, 2)
    >>> pts = np.column_stack([xy, truth.roof_z(xy)[0]])
    >>> best, _ = fit_best(shapely.box(-6, -4, 6, 4), pts)
    >>> best.kind, round(best.params["roof_height"], 3)
    ('gable', 3.0)
    """
    cfg = config or PrimitivesConfig()
    fits: dict = {}
    try:
        polygon, points = _check_inputs(footprint, points)
        samples = resample_rings(polygon_rings(polygon), cfg.plan_interval)
        plan = pplan = None
        if any(not k.startswith("prism") for k in cfg.candidates):
            try:
                plan = _plan_rectangle(polygon, samples, None, cfg, context, _density(points, polygon))
            except FitError as exc:
                for k in cfg.candidates:
                    if not k.startswith("prism"):
                        fits[k] = FitFailure(k, f"rectangle plan: {exc}")
        if any(k.startswith("prism") for k in cfg.candidates):
            try:
                pplan = _prism_plan(polygon, samples, cfg, context, _density(points, polygon))
            except FitError as exc:
                for k in cfg.candidates:
                    if k.startswith("prism"):
                        fits[k] = FitFailure(k, f"polygon plan: {exc}")
    except FitError as exc:
        return FitFailure("auto", str(exc)), fits
    scores = {}
    for kind in cfg.candidates:
        variants = [("", False)] if kind in ("box", "prism") else [("", False), ("90", True)]
        for suffix, swap in variants:
            name = kind + suffix
            try:
                if kind.startswith("prism"):
                    if pplan is None:
                        continue
                    model, bic = _fit_prism_kind(PRIMITIVES[kind], pplan, points, datum, cfg, swap=swap)
                elif plan is None:
                    continue
                else:
                    model, bic = _fit_rect_kind(PRIMITIVES[kind], plan, polygon, points, samples,
                                                datum, cfg, None, swap=swap)
            except FitError as exc:
                fits[name] = FitFailure(kind, str(exc))
                continue
            fits[name] = model
            scores[name] = bic
    if not scores:
        reasons = "; ".join(f"{k}: {f.reason}" for k, f in fits.items())
        return FitFailure("auto", f"no primitive could be fitted ({reasons})"), fits
    # 1. plan family (rectangle or polygon) from the footprint evidence alone,
    # 2. the roof within the family by the whole BIC (equal plan terms there)
    families = {"rect": [k for k in scores if not k.startswith("prism")],
                "poly": [k for k in scores if k.startswith("prism")]}
    plan_terms = {f: min(fits[k].info["bic_plan"] for k in ks) for f, ks in families.items() if ks}
    # the polygon family needs positive evidence (a BIC lower by 2) over the rectangle
    if "rect" in plan_terms and "poly" in plan_terms:
        family = "poly" if plan_terms["poly"] < plan_terms["rect"] - 2.0 else "rect"
    else:
        family = next(iter(plan_terms))
    best = min(families[family], key=scores.get)
    fits[best].info["family"] = family
    return fits[best], fits
