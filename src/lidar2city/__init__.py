"""lidar2city: airborne LiDAR to 3D city models.

The package is layered (see ``STYLE.md`` of the project):

* algorithms (``ground``, ``classify``, ``segment``, ``snake``, ``regularize``,
  ``fit``, ``lod``, ``tune``, ``metrics``) are pure functions on arrays;
* ``io`` is the only code that touches files;
* ``tools`` composes them into file-level jobs; ``cli`` is a thin click layer.
"""

import logging

__version__ = "0.1.0"

logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = ["__version__"]
