"""Validation of outputs: CityJSON schema and solid geometry (val3dity's checks)."""

from .solid import CODES, Issue, check_solid, parts_overlap, solid_error_codes

__all__ = ["CODES", "Issue", "check_solid", "solid_error_codes", "parts_overlap"]
