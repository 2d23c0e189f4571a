"""Segmentation: building regions from rasters (DSM, DTM, orthoimage)."""
