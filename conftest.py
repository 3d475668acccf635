"""Docstring examples of the package run as tests, imported under their installed names.

``pytest`` collects ``>>>`` examples from every module of the package folders
(``uavrl/``, ``envs/``, ``agents/``: the installed ``uavrl``, ``uavrl.envs``
and ``uavrl.agents``, see ``[tool.setuptools.package-dir]`` in pyproject.toml).
``--doctest-modules`` would import ``envs/env.py`` as a second module
``envs.env`` beside the installed ``uavrl.envs.env`` (two copies of every
class, and numba caches that name a module the installed package lacks); this
collector imports each file by its installed name instead.
"""

from __future__ import annotations

import importlib
import importlib.util
import tomllib
from pathlib import Path

from _pytest.doctest import DoctestModule

ROOT = Path(__file__).resolve().parent
_PACKAGE_DIRS = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
FOLDERS = {ROOT / folder: package for package, folder in _PACKAGE_DIRS.items() if package.count(".") <= 1}
# modules of an optional extra: their examples run where the extra is installed (pip install -e ".[benchmarl]",
# pip install -e ".[gym]")
NEEDS = {
    "uavrl.agents.benchmarl": "benchmarl",
    "uavrl.benchmarl": "benchmarl",
    "uavrl.envs.adapters.gym_env": "gymnasium",
    "uavrl.envs.adapters.pettingzoo_env": "pettingzoo",
}


def installed_name(path: Path) -> str | None:
    """``uavrl.envs.env`` for ``envs/env.py``; None outside the package folders."""
    for folder, package in FOLDERS.items():
        if path.is_relative_to(folder) and not path.is_relative_to(ROOT / "configs"):
            parts = path.relative_to(folder).with_suffix("").parts
            return ".".join([package, *parts]).removesuffix(".__init__")
    return None


class InstalledDoctestModule(DoctestModule):
    def _getobj(self):
        return importlib.import_module(installed_name(self.path))


def pytest_collect_file(file_path: Path, parent):
    name = installed_name(file_path) if file_path.suffix == ".py" else None
    if name is not None and (name not in NEEDS or importlib.util.find_spec(NEEDS[name]) is not None):
        return InstalledDoctestModule.from_parent(parent, path=file_path)
    return None
