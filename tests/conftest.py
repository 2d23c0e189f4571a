"""Shared fixtures: the real data folder (LIDAR2CITY_DATA) and small helpers."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


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
