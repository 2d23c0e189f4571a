"""A click group whose subcommands are modules found and imported on demand.

Each module ``lidar2city.cli.<prefix><name>`` that defines ``command`` becomes
subcommand ``<name>`` (underscores shown as dashes). Importing only the module
that runs keeps start-up fast (numpy, scipy, laspy load only when needed).
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

import click

__all__ = ["LazyGroup"]


class LazyGroup(click.Group):
    """A click group that discovers ``<prefix>*.py`` subcommand modules in ``cli/``."""

    def __init__(self, *args, prefix: str = "", exclude=(), **kwargs):
        super().__init__(*args, **kwargs)
        self._prefix = prefix
        self._exclude = set(exclude)

    def _modules(self) -> dict[str, str]:
        here = str(Path(__file__).parent)
        found = {}
        for info in pkgutil.iter_modules([here]):
            name = info.name
            if name.startswith("_") or name in self._exclude:
                continue
            if self._prefix:
                if not name.startswith(self._prefix):
                    continue
                sub = name[len(self._prefix):]
            else:
                if "_" in name and name.split("_")[0] in {"evaluate"}:
                    continue
                sub = name
            found[sub.replace("_", "-")] = f"lidar2city.cli.{name}"
        return found

    def list_commands(self, ctx):
        return sorted(set(super().list_commands(ctx)) | set(self._modules()))

    def get_command(self, ctx, cmd_name):
        cmd = super().get_command(ctx, cmd_name)
        if cmd is not None:
            return cmd
        module = self._modules().get(cmd_name)
        if module is None:
            return None
        return importlib.import_module(module).command
