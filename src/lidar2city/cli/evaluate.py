"""``lidar2city evaluate <what>``: compare results with references."""

from __future__ import annotations

from ._lazy import LazyGroup

command = LazyGroup(
    name="evaluate", prefix="evaluate_",
    help="Compare a result with a reference (ground: ISPRS type I/II, total error, kappa).",
)
