"""Per-stage configuration: one frozen dataclass per stage, loaded from TOML.

Each algorithm package defines its stage's dataclass, with field names equal
to the keyword arguments of the stage's function and a ``doc`` in each field's
metadata. :data:`STAGES` names them (lazily, as ``module:Class``) so a run
config file ``run.toml`` looks like::

    [ground]
    method = "smrf"
    cell = 1.0

    [lod1]
    roof_percentile = 70

Errors name ``stage.field``. The resolved configuration (defaults filled in)
is written into every output's metadata by :func:`resolved_dict`.
"""

from __future__ import annotations

import dataclasses
import importlib
import tomllib
import types
import typing
from pathlib import Path

from .errors import ConfigError, FileFormatError

__all__ = ["STAGES", "stage_class", "build_stage", "read_config", "load_config", "stage_config",
           "resolved_dict", "field"]

#: sections a run file may hold that configure no stage (the ``[tune]`` record that
#: ``lidar2city tune`` writes beside the weights it found)
METADATA_SECTIONS = frozenset({"tune"})

#: stage name -> "module:Class" of its frozen dataclass.
STAGES: dict[str, str] = {
    "active_contour": "lidar2city.contour.outlines:ActiveContourConfig",
    "classify": "lidar2city.classify:ClassifyConfig",
    "dsm_buildings": "lidar2city.segment.dsm:BuildingMaskConfig",
    "dsm_dtm": "lidar2city.segment.dsm:DtmConfig",
    "dsm_lod1": "lidar2city.tools.dsm:Lod1DsmConfig",
    "dsm_roofs": "lidar2city.segment.dsm:RoofRegionsConfig",
    "footprints": "lidar2city.footprints:FootprintsConfig",
    "ground": "lidar2city.ground:GroundConfig",
    "lod1": "lidar2city.lod.lod1:Lod1Config",
    "lod22": "lidar2city.roof.building:Lod22Config",
    "polygon_fit": "lidar2city.fit.polygon:PolygonFitConfig",
    "primitives": "lidar2city.fit.primitives:PrimitivesConfig",
    "snake": "lidar2city.regularize.snake:SnakeConfig",
}


def field(default, doc: str, **kwargs):
    """A dataclass field with a default and a documentation string."""
    if isinstance(default, (list, dict, set)):
        return dataclasses.field(default_factory=lambda: type(default)(default),
                                 metadata={"doc": doc}, **kwargs)
    return dataclasses.field(default=default, metadata={"doc": doc}, **kwargs)


def stage_class(stage: str):
    """The dataclass of ``stage``."""
    try:
        target = STAGES[stage]
    except KeyError:
        raise ConfigError(
            f"unknown config section [{stage}]; known: {', '.join(sorted(STAGES))}"
        ) from None
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)


def _check_type(stage, name, value, annotation):
    origin = typing.get_origin(annotation)
    if annotation is typing.Any:
        return value
    if origin in (typing.Union, types.UnionType):
        for arg in typing.get_args(annotation):
            try:
                return _check_type(stage, name, value, arg)
            except ConfigError:
                continue
        raise ConfigError(f"{stage}.{name}: {value!r} is not a {annotation}")
    if origin is typing.Literal:
        allowed = typing.get_args(annotation)
        if value not in allowed:
            raise ConfigError(f"{stage}.{name}: {value!r} is not one of {', '.join(map(repr, allowed))}")
        return value
    if annotation is type(None):
        if value is None:
            return value
        raise ConfigError(f"{stage}.{name}: expected nothing, got {value!r}")
    if origin in (tuple, list) or annotation in (tuple, list):  # tuple[int, ...] or tuple
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{stage}.{name}: expected a list, got {value!r}")
        return tuple(value) if tuple in (origin, annotation) else list(value)
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{stage}.{name}: expected a number, got {value!r}")
        return float(value)
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{stage}.{name}: expected an integer, got {value!r}")
        return value
    if annotation is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{stage}.{name}: expected true or false, got {value!r}")
        return value
    if annotation is str:
        if not isinstance(value, str):
            raise ConfigError(f"{stage}.{name}: expected a string, got {value!r}")
        return value
    return value


def build_stage(stage: str, values: dict | None = None, cls=None):
    """Instantiate the dataclass of ``stage`` from ``values``, checking names and types."""
    cls = cls or stage_class(stage)
    values = dict(values or {})
    hints = typing.get_type_hints(cls)
    fields = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - fields)
    if unknown:
        raise ConfigError(f"{stage}.{unknown[0]}: unknown option; known: {', '.join(sorted(fields))}")
    checked = {k: _check_type(stage, k, v, hints[k]) for k, v in values.items()}
    try:
        return cls(**checked)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{stage}: {exc}") from None


def read_config(source=None) -> dict:
    """The sections of a run configuration: ``None`` gives ``{}``, a dict is copied, a path is
    read as TOML.

    Raises
    ------
    FileFormatError
        The file does not exist.
    ConfigError
        It is not valid TOML, or a section is not a table.
    """
    if source is None:
        data = {}
    elif isinstance(source, dict):
        data = dict(source)
    else:
        path = Path(source)
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise FileFormatError(f"{str(path)!r}: no such config file") from None
        except UnicodeDecodeError:
            raise ConfigError(f"{str(path)!r} is not a text TOML file") from None
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{str(path)!r} is not valid TOML: {exc}") from None
    for stage, section in data.items():
        if not isinstance(section, dict):
            raise ConfigError(f"[{stage}] must be a table of options")
    return {k: v for k, v in data.items() if k not in METADATA_SECTIONS}


def load_config(source=None) -> dict:
    """Read a TOML file (path) or a dict of sections; return ``{stage: dataclass}``.

    Stages absent from the source get their defaults; unknown sections are errors.
    """
    data = read_config(source)
    for stage in data:
        if stage not in STAGES:
            raise ConfigError(f"unknown config section [{stage}]; known: {', '.join(sorted(STAGES))}")
    return {stage: build_stage(stage, data.get(stage)) for stage in STAGES}


def stage_config(stage: str, source=None, **overrides):
    """One stage's resolved dataclass from a run configuration.

    Parameters
    ----------
    stage : str
        A key of :data:`STAGES`.
    source : None, path, dict of sections, or the stage's dataclass
        The whole run configuration (its other sections' names are checked too).
    **overrides
        Field values taking precedence (e.g. command-line options); ``None``
        values are ignored.
    """
    cls = stage_class(stage)
    if isinstance(source, cls):
        values = dataclasses.asdict(source)
    else:
        # only this stage's class is imported (start-up time); the other sections'
        # names are checked, their values when their own stage reads them
        data = read_config(source)
        for name in data:
            if name not in STAGES:
                raise ConfigError(f"unknown config section [{name}]; known: {', '.join(sorted(STAGES))}")
        values = dict(data.get(stage, {}))
    values.update({k: v for k, v in overrides.items() if v is not None})
    return build_stage(stage, values, cls=cls)


def resolved_dict(configs: dict) -> dict:
    """``{stage: {field: value}}`` of resolved configs, for output metadata."""
    return {stage: dataclasses.asdict(cfg) for stage, cfg in configs.items()}
