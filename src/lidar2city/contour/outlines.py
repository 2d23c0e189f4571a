"""Building outlines from a DSM by active contours: configuration and pipeline."""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi

from ..config import field
from ..errors import ConfigError, InputError
from .gvf import edge_map, gradient_vector_flow
from .initial import _filled, building_regions, initial_contours, linked_edges
from .raster import PixelFrame
from .snake import evolve_contours

logger = logging.getLogger(__name__)

__all__ = ["WEIGHT_NAMES", "WEIGHT_BOUNDS", "LOG_WEIGHT_BOUNDS", "DEFAULT_WEIGHTS", "UNTUNED_WEIGHTS", "ActiveContourConfig", "normalize_weights",
           "ContourScene", "start_signed_distance", "prepare_scene", "run_scene", "contours_to_polygons",
           "active_contour_outlines"]

#: Initial contour choices (``ActiveContourConfig.init``).
INITIALISATIONS = ("roofs", "edges")
#: The energy weights, in chromosome order: Kass's elasticity and rigidity, the GVF
#: edge force, the regional and altitudinal variance energies and the anchor to the
#: initial contour.
WEIGHT_NAMES = ("alpha", "beta", "gamma", "mu", "epsilon", "anchor")
#: Range searched by the genetic algorithm for every weight.
WEIGHT_BOUNDS = (0.0, 3.0)
#: Range of log10 of every weight searched by the GA on its (default) log scale: 0.01 to 10.
LOG_WEIGHT_BOUNDS = (-2.0, 1.0)
#: Weights used when none are given: tuned by the GA (objective 1 - kappa, population
#: 12, 8 generations, seed 0) on the Alexandria west half, 2 m DSM without orthoimage,
#: scored around the reference footprints (``reference_neighbourhood_domain``), with the
#: split / half-height / aspect-coherence initialisation and localised region
#: statistics (benchmarks/bench_active_contour.py). Retune for other data with
#: ``lidar2city tune``.
#: The anchor (issue 16) is hand-set to 1, as in the untuned weights.
DEFAULT_WEIGHTS = {"alpha": 0.488, "beta": 0.206, "gamma": 1.879, "mu": 2.896, "epsilon": 1.817,
                   "anchor": 1.0}
#: Hand-set weights before tuning (kept as the untuned baseline of the benchmark).
UNTUNED_WEIGHTS = {"alpha": 0.2, "beta": 0.2, "gamma": 1.0, "mu": 1.0, "epsilon": 1.0, "anchor": 1.0}


@dataclass(frozen=True)
class ActiveContourConfig:
    """Stage ``active_contour``: snake outlines of buildings from a DSM."""

    alpha: float = field(DEFAULT_WEIGHTS["alpha"], "Elasticity weight (|v'|^2, per pixel spacing).")
    beta: float = field(DEFAULT_WEIGHTS["beta"], "Rigidity weight (|v''|^2).")
    gamma: float = field(DEFAULT_WEIGHTS["gamma"], "Weight of the gradient-vector-flow edge force.")
    mu: float = field(DEFAULT_WEIGHTS["mu"], "Weight of the regional variance energy (image or DSM inside vs outside).")
    epsilon: float = field(DEFAULT_WEIGHTS["epsilon"], "Weight of the altitudinal variance energy (nDSM inside vs outside).")
    anchor: float = field(DEFAULT_WEIGHTS["anchor"], "Weight of the anchor to the initial regions: a normal force toward the initial region's edge, proportional to the signed distance from it (pixels, clipped to 1), so the image forces move a good start only where they agree (0: off).")
    force_offset: float | None = field(None, "The image forces (GVF, regional and altitudinal) act on each vertex from this distance (m) outside it: a DSM keeping the highest point per cell shows roofs reaching half a cell beyond the walls on average, and eaves overhang them; None: the inset the initial regions had (the roof regions' edge_inset as applied at this cell size, 0 for init='edges'); 0: at the vertex.")
    min_height: float = field(3.0, "Candidate building pixels are higher than this above the terrain (m).")
    max_roughness: float = field(1.0, "Regions whose median roughness index (terrain ruggedness / cell) exceeds this are vegetation.")
    min_area: float = field(20.0, "Smallest building region kept (m2).")
    split_distance: float = field(6.0, "Joined candidate regions are cut by a distance-transform watershed into pieces whose centres are at least this far apart (m, rounded to whole pixels; 0: no split).")
    min_aspect_coherence: float = field(0.1, "Regions whose four-fold slope-direction coherence is below this are dropped (tree crowns slope every way, buildings a few ways 90 degrees apart; 0: off).")
    relative_height: float = field(0.5, "Each piece keeps its pixels higher than this share of its 90th height percentile (a blurred wall's mid-height; drops low crowns and sheds leaning on buildings; 0: off).")
    canny_sigma: float = field(1.0, "Gaussian sigma of the Canny edge detector (pixels).")
    max_gap: int = field(1, "Edge gaps up to this many pixels are closed.")
    min_edge_length: int = field(4, "Edge chains shorter than this (pixels) are dropped.")
    init: str = field("roofs", "Initial contours: 'roofs' (the smooth roof regions of lidar2city.segment.dsm.roof_regions with its default [dsm_roofs] options: the DSM blobs that footprints --dsm fits) or 'edges' (the seed's: the nDSM mask above min_height cut by linked Canny edges, split at necks, vegetation dropped by roughness and aspect).")
    edge_map: str = field("gradient", "Edge map of the GVF: 'canny' (blurred linked Canny edges of the DSM: walls) or 'gradient' (gradient magnitude, also strong on pitched roofs).")
    edge_sigma: float = field(0.5, "Gaussian sigma of the edge map for the GVF (pixels); small keeps the two walls of narrow buildings apart.")
    gvf_mu: float = field(0.2, "GVF diffusion weight.")
    gvf_iterations: int = field(200, "Maximum GVF iterations.")
    tau: float = field(0.5, "Time step of the semi-implicit snake iteration.")
    max_step: float = field(1.0, "Largest external-force move per iteration (pixels).")
    step_decay: float = field(0.9, "Factor applied to max_step after every resampling period (damps oscillations).")
    max_iter: int = field(150, "Maximum snake iterations.")
    tol: float = field(0.02, "Convergence: RMS vertex move per iteration below this (pixels).")
    spacing: float = field(1.0, "Vertex spacing after resampling (pixels).")
    resample_every: int = field(5, "Resample contours and update region statistics every N iterations.")
    band: float = field(6.0, "Width of the outside band for region statistics (m; used when local_sigma is 0).")
    local_sigma: float = field(6.0, "Gaussian window (m) of the localised region statistics (Lankton & Tannenbaum 2008): each vertex compares the inside and outside next to it; 0: one inside mean per contour and a band outside it.")
    smooth: float = field(0.7, "Gaussian sigma applied to the region-term images (pixels; 0: none).")
    simplify: float = field(0.25, "Douglas-Peucker tolerance of the output outlines (pixels; 0: none). The start contour runs 0.35-0.5 pixel from the nearest pixel centres (the 0.5 iso-line of the region mask), so a quarter pixel keeps every pixel of a contour that did not move; half a pixel cuts the corners of convex outlines inward.")

    def __post_init__(self):
        for name in WEIGHT_NAMES:
            w = getattr(self, name)
            if not np.isfinite(w) or w < 0:
                raise ConfigError(f"active_contour.{name}: must be >= 0, got {w}")
        if self.force_offset is not None and not (np.isfinite(self.force_offset) and self.force_offset >= 0):
            raise ConfigError(f"active_contour.force_offset: must be >= 0, got {self.force_offset}")
        for name in ("tau", "spacing", "max_step", "tol", "band", "gvf_mu"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"active_contour.{name}: must be > 0, got {getattr(self, name)}")
        for name in ("max_iter", "gvf_iterations", "resample_every", "min_edge_length"):
            if getattr(self, name) < 1:
                raise ConfigError(f"active_contour.{name}: must be >= 1, got {getattr(self, name)}")
        if self.init not in INITIALISATIONS:
            raise ConfigError(f"active_contour.init: must be one of {', '.join(INITIALISATIONS)}, got {self.init!r}")
        if self.edge_map not in ("canny", "gradient"):
            raise ConfigError(f"active_contour.edge_map: must be 'canny' or 'gradient', got {self.edge_map!r}")
        if not 0 < self.step_decay <= 1:
            raise ConfigError(f"active_contour.step_decay: must be in (0, 1], got {self.step_decay}")
        if self.local_sigma < 0:
            raise ConfigError(f"active_contour.local_sigma: must be >= 0, got {self.local_sigma}")
        if self.split_distance < 0:
            raise ConfigError(f"active_contour.split_distance: must be >= 0, got {self.split_distance}")
        if not 0 <= self.min_aspect_coherence <= 1:
            raise ConfigError(f"active_contour.min_aspect_coherence: must be in [0, 1], got {self.min_aspect_coherence}")
        if not 0 <= self.relative_height < 1:
            raise ConfigError(f"active_contour.relative_height: must be in [0, 1), got {self.relative_height}")
        if self.max_gap < 0 or self.min_area < 0 or self.simplify < 0 or self.smooth < 0:
            raise ConfigError("active_contour.max_gap, min_area, simplify and smooth must be >= 0")

    def with_weights(self, weights) -> ActiveContourConfig:
        """A copy with the five weights from a mapping or a 5-sequence."""
        return dataclasses.replace(self, **normalize_weights(weights))


def normalize_weights(weights) -> dict:
    """``{name: float}`` for the weights from a mapping or a sequence in WEIGHT_NAMES order."""
    if weights is None:
        return dict(DEFAULT_WEIGHTS)
    if isinstance(weights, dict):
        unknown = sorted(set(weights) - set(WEIGHT_NAMES))
        if unknown:
            raise ConfigError(f"active_contour.{unknown[0]}: unknown weight; known: {', '.join(WEIGHT_NAMES)}")
        out = dict(DEFAULT_WEIGHTS)
        out.update({k: float(v) for k, v in weights.items()})
    else:
        values = [float(v) for v in weights]
        if len(values) != len(WEIGHT_NAMES):
            raise ConfigError(f"expected {len(WEIGHT_NAMES)} weights ({', '.join(WEIGHT_NAMES)}), got {len(values)}")
        out = dict(zip(WEIGHT_NAMES, values, strict=True))
    for k, v in out.items():
        if not np.isfinite(v) or v < 0:
            raise ConfigError(f"active_contour.{k}: must be >= 0, got {v}")
    return out


@dataclass(eq=False)
class ContourScene:
    """Everything the snakes need that does not depend on the five weights.

    Attributes
    ----------
    contours : list of ndarray (M, 2)
        Initial ``(row, col)`` contours, one per building region.
    labels : ndarray of int32 (H, W)
        The building regions they came from.
    gvf : ndarray (2, H, W)
        Gradient vector flow, magnitudes normalised to about <= 1.
    image : ndarray (H, W)
        Intensity of the regional term (grey orthoimage, or the DSM).
    ndsm : ndarray (H, W)
        Height above terrain, NaN filled.
    start_distance : ndarray (H, W)
        Signed distance (pixels) to the edge of the initial regions, > 0
        outside them: the anchor energy's field.
    cell : float
        Pixel size (m): the configuration's lengths in metres become pixels.
    inset : float
        Distance (m) by which the initial regions were moved inside the
        DSM's roof edges (``roof_regions``' ``edge_inset`` as applied).
    """

    contours: list
    labels: np.ndarray
    gvf: np.ndarray
    image: np.ndarray
    ndsm: np.ndarray
    start_distance: np.ndarray | None = None
    cell: float = 1.0
    inset: float = 0.0


def _grey(ortho, shape):
    o = np.asarray(ortho, dtype=np.float64)
    if o.ndim == 3:
        o = o[:3].mean(axis=0) if o.shape[0] <= 4 else o.mean(axis=-1)
    if o.shape != shape:
        raise InputError(f"orthoimage shape {o.shape} differs from the DSM's {shape}; resample it onto the DSM grid")
    return _filled(o)


def start_signed_distance(labels) -> np.ndarray:
    """Signed distance (pixels) to the edge of the hole-filled regions, > 0 outside.

    The edge is the pixel border between a region and the background: a
    boundary pixel centre is at -0.5, its outside neighbour at +0.5, so the
    bilinear zero crossing lies on the border, as the initial contour does
    (iso-line 0.5 of the region mask).

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        0 background, > 0 regions.

    Returns
    -------
    ndarray of float64, shape (H, W)
    """
    mask = ndi.binary_fill_holes(np.asarray(labels) > 0)
    if not mask.any():
        return np.full(mask.shape, 1.0)
    inside = ndi.distance_transform_edt(mask)
    outside = ndi.distance_transform_edt(~mask)
    return np.where(mask, 0.5 - inside, outside - 0.5)


def prepare_scene(dsm, ndsm, *, ortho=None, cell=1.0, config: ActiveContourConfig | None = None,
                  gvf_callback=None, roof_config=None) -> ContourScene:
    """Initial contours, GVF field and region images of a DSM (weight-independent).

    Parameters
    ----------
    dsm, ndsm : ndarray, shape (H, W)
        Surface heights and heights above terrain (m); NaN for no data.
    ortho : ndarray, shape (H, W) or (B, H, W), optional
        Orthoimage on the same grid; its grey level drives the regional term
        (the DSM does otherwise).
    cell : float
        Pixel size (m).
    roof_config : RoofRegionsConfig, optional
        Options of the roof regions (``config.init == "roofs"``).
    """
    cfg = config or ActiveContourConfig()
    z = _filled(dsm)
    nd = np.asarray(ndsm, dtype=np.float64)
    if nd.shape != z.shape:
        raise InputError(f"dsm {z.shape} and ndsm {nd.shape} differ in shape")
    if cell <= 0:
        raise InputError(f"cell must be > 0, got {cell}")
    nd = np.where(np.isfinite(nd), nd, 0.0)
    edges = linked_edges(z, sigma=cfg.canny_sigma, max_gap=cfg.max_gap, min_length=cfg.min_edge_length)
    if cfg.init == "roofs":
        from ..segment.dsm import RoofRegionsConfig, roof_regions

        rc = roof_config or RoofRegionsConfig()
        labels, _ = roof_regions(dsm, ndsm, cell=cell, **dataclasses.asdict(rc))
        # inset_regions drops the pixel rings k with (k - 1/2) cell <= edge_inset
        inset = np.floor(rc.edge_inset / cell + 0.5 + 1e-9) * cell
    else:
        inset = 0.0
        labels = building_regions(z, nd, cell=cell, min_height=cfg.min_height,
                                  max_roughness=cfg.max_roughness, min_area=cfg.min_area,
                                  split_distance=int(round(cfg.split_distance / cell)),
                                  relative_height=cfg.relative_height,
                                  min_aspect_coherence=cfg.min_aspect_coherence,
                                  edges=edges)
    contours = initial_contours(labels)
    if cfg.edge_map == "canny":
        f = ndi.gaussian_filter(edges.astype(np.float64), cfg.edge_sigma) if cfg.edge_sigma > 0 else edges * 1.0
        f = f / f.max() if f.max() > 0 else f
    else:
        f = edge_map(z, sigma=cfg.edge_sigma)
    g = gradient_vector_flow(f, mu=cfg.gvf_mu, max_iter=cfg.gvf_iterations, callback=gvf_callback)
    mag = np.hypot(g[0], g[1])
    scale = np.percentile(mag, 99.0)
    if scale > 0:
        g = g / scale
        mag = mag / scale
        big = mag > 1.0
        g[:, big] /= mag[big]
    image = z if ortho is None else _grey(ortho, z.shape)
    if cfg.smooth > 0:
        image = ndi.gaussian_filter(image, cfg.smooth)
        nd = ndi.gaussian_filter(nd, cfg.smooth)
    logger.info("%d initial contours", len(contours))
    return ContourScene(contours, labels, g, image, nd, start_signed_distance(labels), float(cell),
                        float(inset))


def run_scene(scene: ContourScene, weights=None, *, config: ActiveContourConfig | None = None,
              callback=None) -> list:
    """Evolve the scene's initial contours with the given weights; ``(row, col)`` contours."""
    cfg = (config or ActiveContourConfig())
    if weights is not None:
        cfg = cfg.with_weights(weights)
    return evolve_contours(
        scene.contours, scene.gvf, scene.image, scene.ndsm,
        alpha=cfg.alpha, beta=cfg.beta, gamma=cfg.gamma, mu=cfg.mu, epsilon=cfg.epsilon,
        anchor=cfg.anchor, start_distance=scene.start_distance, tau=cfg.tau, max_step=cfg.max_step, step_decay=cfg.step_decay, max_iter=cfg.max_iter, tol=cfg.tol,
        spacing=cfg.spacing, resample_every=cfg.resample_every, band=cfg.band / scene.cell,
        local_sigma=cfg.local_sigma / scene.cell,
        offset=(scene.inset if cfg.force_offset is None else cfg.force_offset) / scene.cell,
        callback=callback)


def contours_to_polygons(contours, frame: PixelFrame, *, simplify=0.5, min_area=0.0) -> list:
    """Valid shapely polygons (local metres) of closed ``(row, col)`` contours.

    Self-intersections are repaired (the largest polygonal part is kept);
    ``simplify`` is in pixels; polygons smaller than ``min_area`` m2 are dropped.
    Returns one entry per contour (``None`` for dropped ones).
    """
    import shapely

    out = []
    scale = float(np.sqrt(abs(np.linalg.det(frame.m[:, :2])))) * frame.xy_unit
    for c in contours:
        if c is None or len(c) < 3:
            out.append(None)
            continue
        poly = shapely.Polygon(frame.to_local(c))
        if not poly.is_valid:
            fixed = shapely.make_valid(poly)
            parts = [g for g in getattr(fixed, "geoms", [fixed]) if g.geom_type == "Polygon"]
            parts += [p for g in getattr(fixed, "geoms", []) if g.geom_type == "MultiPolygon" for p in g.geoms]
            poly = max(parts, key=lambda p: p.area) if parts else None
        if poly is not None and simplify > 0:
            poly = poly.simplify(simplify * scale, preserve_topology=True)
        if poly is None or poly.is_empty or poly.area <= min_area:
            out.append(None)
        else:
            out.append(poly)
    return out


def active_contour_outlines(dsm, ndsm, *, ortho=None, weights=None, cell=1.0, transform=None,
                            origin=(0.0, 0.0), xy_unit=1.0,
                            config: ActiveContourConfig | None = None, callback=None) -> list:
    """Building outlines from a DSM with GVF + region-energy snakes.

    Parameters
    ----------
    dsm, ndsm : ndarray, shape (H, W)
        Surface heights and heights above terrain (m), NaN for no data.
    ortho : ndarray, shape (H, W) or (B, H, W), optional
        Orthoimage on the DSM grid for the regional variance energy.
    weights : mapping or 5-sequence, optional
        ``alpha, beta, gamma, mu, epsilon, anchor``; default: those of ``config``.
    cell : float
        Pixel size (m); used for areas and, without ``transform``, coordinates.
    transform : affine.Affine, optional
        Pixel-corner to world transform of the raster; with ``origin`` and
        ``xy_unit`` it places outlines in the local metric frame (see
        :class:`PixelFrame`).
    config : ActiveContourConfig, optional
    callback : callable, optional
        ``callback(iteration, contours)`` from the snake iteration.

    Returns
    -------
    list of shapely.Polygon
        One outline per building found, in local metres.

    Examples
    --------
    >>> import numpy as np
    >>> dsm = np.zeros((40, 40)); dsm[10:30, 12:28] = 8.0
    >>> polys = active_contour_outlines(dsm, dsm, cell=1.0)
    >>> len(polys)
    1
    """
    cfg = config or ActiveContourConfig()
    if weights is not None:
        cfg = cfg.with_weights(weights)
    scene = prepare_scene(dsm, ndsm, ortho=ortho, cell=cell, config=cfg)
    contours = run_scene(scene, config=cfg, callback=callback)
    frame = PixelFrame(transform, cell=cell, origin=origin, xy_unit=xy_unit)
    polys = contours_to_polygons(contours, frame, simplify=cfg.simplify, min_area=0.5 * cfg.min_area)
    return [p for p in polys if p is not None]
