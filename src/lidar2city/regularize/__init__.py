"""Footprint and topology regularisation: building direction and the 2-D snake."""

from .direction import aligned_fraction, dominant_direction, from_frame, segments_of, to_frame
from .snake import SnakeConfig, adjust_planar_graph, regularize_polygon, regularize_polygons

__all__ = [
    "SnakeConfig",
    "adjust_planar_graph",
    "aligned_fraction",
    "dominant_direction",
    "from_frame",
    "regularize_polygon",
    "regularize_polygons",
    "segments_of",
    "to_frame",
]
