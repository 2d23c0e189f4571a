"""Reading and writing active-contour weight files (TOML)."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

from ..errors import ConfigError, FileFormatError
from ._atomic import atomic_path, check_input_file

__all__ = ["read_weights", "write_weights", "read_stage_table"]

_NAMES = ("alpha", "beta", "gamma", "mu", "epsilon", "anchor")


def _load(path) -> dict:
    p = check_input_file(path)
    try:
        return tomllib.loads(Path(p).read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise FileFormatError(f"{str(p)!r} is not a text file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{str(p)!r} is not valid TOML: {exc}") from None


def read_stage_table(path, stage) -> dict:
    """The ``[stage]`` table of a run-config TOML file (empty if absent)."""
    table = _load(path).get(stage, {})
    if not isinstance(table, dict):
        raise ConfigError(f"{str(path)!r}: [{stage}] must be a table")
    return table


def read_weights(path) -> dict:
    """The active-contour weights of a TOML file.

    The weights are read from an ``[active_contour]`` table (the run-config
    section of the stage, so a weights file is also a valid run config) or,
    failing that, from the top level. Missing weights are not filled in here.

    Raises
    ------
    FileFormatError
        Missing or unreadable file.
    ConfigError
        Not TOML, unknown keys or non-numeric / negative values.
    """
    p = path
    data = _load(path)
    table = data.get("active_contour", {k: v for k, v in data.items() if k in _NAMES})
    if not isinstance(table, dict):
        raise ConfigError(f"{str(p)!r}: [active_contour] must be a table")
    weights = {k: v for k, v in table.items() if k in _NAMES}
    if not weights:
        raise ConfigError(f"{str(p)!r} holds none of the weights {', '.join(_NAMES)}")
    for k, v in weights.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise ConfigError(f"active_contour.{k}: expected a number >= 0, got {v!r}")
    return {k: float(v) for k, v in weights.items()}


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if isinstance(v, float) else str(v)
    s = str(v).replace("\\", "\\\\").replace('"', '\\"')
    return f'"{s}"'


def write_weights(path, weights: dict, *, metadata: dict | None = None) -> None:
    """Write the weights as an ``[active_contour]`` table (temp file, then rename).

    ``metadata`` (flat: numbers, strings, booleans) goes into a ``[tune]``
    table, e.g. the cost, seed and generations of the run that produced them.
    """
    unknown = sorted(set(weights) - set(_NAMES))
    if unknown:
        raise ConfigError(f"unknown weight {unknown[0]!r}; known: {', '.join(_NAMES)}")
    lines = ["# active-contour energy weights (lidar2city tune)", "[active_contour]"]
    lines += [f"{k} = {_toml_value(float(weights[k]))}" for k in _NAMES if k in weights]
    if metadata:
        lines += ["", "[tune]"]
        lines += [f"{k} = {_toml_value(v)}" for k, v in metadata.items() if v is not None]
    with atomic_path(path) as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n", encoding="utf-8")
