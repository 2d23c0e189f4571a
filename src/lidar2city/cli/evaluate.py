"""``lidar2city evaluate <what>``: compare results with references."""

from ._lazy import LazyGroup

command = LazyGroup(name="evaluate", prefix="evaluate_", help="Compare results with references.")
