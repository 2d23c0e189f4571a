"""The one exception hierarchy of lidar2city.

Every error the package raises on purpose derives from :class:`Lidar2CityError`.
Bad input also derives from :class:`ValueError` (wrong values) or
:class:`OSError` (files), so callers may catch either. Algorithm outcomes
(a fit that failed, a solver that did not converge) have their own branch,
:class:`AlgorithmError`: a batch records them per building and goes on.
"""

__all__ = [
    "Lidar2CityError",
    "InputError",
    "FileFormatError",
    "NotEditableError",
    "CRSError",
    "ConfigError",
    "EmptyInputError",
    "AlgorithmError",
    "FitError",
    "ConvergenceError",
    "DependencyError",
]


class Lidar2CityError(Exception):
    """Base class of all lidar2city errors."""


class InputError(Lidar2CityError, ValueError):
    """Input values are invalid (NaN coordinates, wrong shape, bad option)."""


class EmptyInputError(InputError):
    """The input holds nothing to work on (no points, no ground, no footprint)."""


class ConfigError(InputError):
    """A configuration value is invalid; the message names ``stage.field``."""


class CRSError(InputError):
    """A coordinate reference system is missing, unknown or inconsistent."""


class FileFormatError(Lidar2CityError, OSError):
    """A file is missing, unreadable or not in the expected format."""


class NotEditableError(FileFormatError):
    """A model that can be shown but not edited (from another tool, or a CityJSONSeq)."""


class DependencyError(Lidar2CityError, ImportError):
    """An optional dependency is needed; the message says which extra to install."""


class AlgorithmError(Lidar2CityError):
    """An algorithm could not produce a result for this input."""


class FitError(AlgorithmError):
    """A model could not be fitted (too few points, degenerate geometry)."""


class ConvergenceError(AlgorithmError):
    """An iterative method did not converge."""
