"""Shared fixtures: the real data folder (LIDAR2CITY_DATA) and small helpers."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# the same examples on every run (CI must not turn red by chance);
# `pytest --hypothesis-profile=explore` searches anew
settings.register_profile("ci", derandomize=True, deadline=None)
settings.register_profile("explore", deadline=None, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

ROOT = Path(__file__).resolve().parents[1]


class RunCrash(BaseException):
    """A crash of the whole run (not a task failure the executor would retry)."""


@pytest.fixture
def crash_after_first_block(monkeypatch):
    """Every block after the first crashes the run (``monkeypatch.undo()`` lifts it);
    returns the exception class raised."""
    from lidar2city.tools import task

    real = task.run_block

    def run_block(spec, options):
        if spec.index > 0:
            raise RunCrash
        return real(spec, options)

    monkeypatch.setattr(task, "run_block", run_block)
    return RunCrash


def data_dir() -> Path:
    """``$LIDAR2CITY_DATA`` or ``../shared/data`` beside the checkout."""
    env = os.environ.get("LIDAR2CITY_DATA")
    return Path(env) if env else ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def data():
    """Path to the shared real data; skips the test when the folder is absent."""
    d = data_dir()
    if not (d / "README.md").exists():
        pytest.skip(f"real data not found at {d} (set LIDAR2CITY_DATA)")
    return d


@pytest.fixture
def runner():
    from click.testing import CliRunner

    return CliRunner()


@pytest.fixture(scope="session")
def raw_town():
    """``make(folder, **make_town options) -> (town, raw cloud)``.

    A synthetic town with its classes wiped (a raw tile), written to
    ``folder / "whole.laz"``, and its footprints to ``folder / "fp.gpkg"``.
    """
    import numpy as np

    from lidar2city.datamodel import ASPRS
    from lidar2city.io.las import write_points
    from lidar2city.io.vector import write_polygons
    from lidar2city.synthetic import make_town

    def make(folder, **options):
        town = make_town(**options)
        raw = town.cloud.with_attributes(
            classification=np.full(len(town.cloud), ASPRS.UNCLASSIFIED, dtype=np.uint8))
        write_points(folder / "whole.laz", raw)
        write_polygons(folder / "fp.gpkg", town.footprints.geometries, {"id": town.footprints.ids},
                       origin=town.cloud.origin, crs=town.cloud.crs)
        return town, raw

    return make


@pytest.fixture(scope="session")
def edit_town(tmp_path_factory):
    """A classified synthetic town (gable b00, hip b01, flat b02, L-shaped b03) written as
    ``town.laz`` + ``fp.gpkg`` and reconstructed at LoD1.2 + 2.2 into ``model.city.json``
    (the editing and viewer tests copy the model before changing it)."""
    from types import SimpleNamespace

    from lidar2city.io.las import write_points
    from lidar2city.io.vector import write_polygons
    from lidar2city.synthetic import make_town
    from lidar2city.tools.reconstruct import reconstruct

    d = tmp_path_factory.mktemp("edit_town")
    town = make_town(size=(120.0, 90.0), density=6.0, seed=5)
    write_points(d / "town.laz", town.cloud)
    write_polygons(d / "fp.gpkg", town.footprints.geometries, {"id": town.footprints.ids},
                   origin=town.cloud.origin, crs=town.cloud.crs)
    reconstruct([d / "town.laz"], d / "model.city.json", footprints=d / "fp.gpkg",
                lods=("1.2", "2.2"))
    return SimpleNamespace(town=town, dir=d, laz=d / "town.laz", footprints=d / "fp.gpkg",
                           model=d / "model.city.json")
