"""Building models by level of detail: LoD1.2 / LoD1.3 prisms (pure algorithms)."""

from .heights import ground_height, roof_height
from .lod1 import LODS, Lod1Config, reconstruct_building
from .lod13 import height_parts, height_regions
from .prism import clean_polygon, lod12_solid, lod12_solids, prism_solid

__all__ = ["Lod1Config", "LODS", "reconstruct_building", "lod12_solid", "lod12_solids",
           "prism_solid", "clean_polygon", "roof_height", "ground_height", "height_parts",
           "height_regions"]
