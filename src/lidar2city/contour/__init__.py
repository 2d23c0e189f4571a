"""Active contours (snakes) for building outlines from a DSM.

Initial contours from the nDSM, a roughness filter and Canny edges
(:mod:`.initial`); gradient vector flow (:mod:`.gvf`); semi-implicit snakes with
GVF, regional and altitudinal variance energies (:mod:`.snake`); the pipeline
and its configuration (:mod:`.outlines`); rasterisation and scoring domain
(:mod:`.raster`).
"""

from .gvf import edge_map, gradient_vector_flow
from .initial import (
    aspect_coherence,
    building_regions,
    initial_contours,
    linked_edges,
    roughness_index,
)
from .outlines import (
    DEFAULT_WEIGHTS,
    WEIGHT_BOUNDS,
    WEIGHT_NAMES,
    ActiveContourConfig,
    ContourScene,
    active_contour_outlines,
    contours_to_polygons,
    normalize_weights,
    prepare_scene,
    run_scene,
)
from .raster import (
    PixelFrame,
    evaluation_domain,
    object_segments,
    rasterize_polygons,
    reference_neighbourhood_domain,
)
from .snake import evolve_contours, resample_contour

__all__ = [
    "aspect_coherence", "edge_map", "gradient_vector_flow", "building_regions", "initial_contours", "linked_edges",
    "roughness_index", "DEFAULT_WEIGHTS", "WEIGHT_BOUNDS", "WEIGHT_NAMES", "ActiveContourConfig",
    "ContourScene", "active_contour_outlines", "contours_to_polygons", "normalize_weights",
    "prepare_scene", "run_scene", "PixelFrame", "evaluation_domain", "rasterize_polygons",
    "reference_neighbourhood_domain", "object_segments",
    "evolve_contours", "resample_contour",
]
