"""``lidar2city evaluate``: compare results with references (subcommands in ``evaluate_*.py``)."""
from ._lazy import LazyGroup

command = LazyGroup(name="evaluate", prefix="evaluate_", help="Compare results with references.")
