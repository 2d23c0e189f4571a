"""Building footprints from classified points: regions, sub-cell outlines, simplification,
regularisation (``REGULARIZERS``)."""

from .extract import Footprint, FootprintsConfig, extract_footprints, grid_lengths
from .grid import Grid, building_fraction, building_regions, point_spacing
from .regularizers import REGULARIZERS, outline_direction
from .trace import simplify_polygon, trace_regions

__all__ = [
    "Footprint", "FootprintsConfig", "extract_footprints", "grid_lengths",
    "Grid", "building_fraction", "building_regions",
    "point_spacing", "REGULARIZERS", "outline_direction", "simplify_polygon", "trace_regions",
]
