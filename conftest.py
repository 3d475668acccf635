"""Docstring examples of the package run as tests, imported under their installed names.

``pytest`` collects ``>>>`` examples from every module of the package folders
(``uavrl/``, ``envs/``, ``agents/``: the installed ``uavrl``, ``uavrl.envs``
and ``uavrl.agents``, see ``[tool.setuptools.package-dir]`` in pyproject.toml).
``--doctest-modules`` would import ``envs/env.py`` as a second module
``envs.env`` beside the installed ``uavrl.envs.env`` (two copies of every
class, and numba caches that name a module the installed package lacks); this
collector imports each file by its installed name instead.

It also gives CI's legs a way to fail on a skip: with ``--no-skip`` (or the
environment variable ``UAVRL_NO_SKIP=1``) a test that skips fails instead,
its reason kept, so a leg that installed an extra cannot pass by skipping
the tests of that extra.  The examples of the optional extras' modules carry
the marker ``gym`` of the [gym] extra, as its tests do.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import tomllib
from pathlib import Path

import pytest
from _pytest.doctest import DoctestModule

ROOT = Path(__file__).resolve().parent
_PACKAGE_DIRS = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
FOLDERS = {ROOT / folder: package for package, folder in _PACKAGE_DIRS.items() if package.count(".") <= 1}
# modules of an optional extra: their examples run where the extra is installed (pip install -e ".[benchmarl]",
# pip install -e ".[gym]", pip install -e ".[bench]")
NEEDS = {
    "uavrl.bench.run": "rliable",
    "uavrl.bench.stats": "rliable",
    "uavrl.agents.benchmarl": "benchmarl",
    "uavrl.benchmarl": "benchmarl",
    "uavrl.experiment.benchmarl": "benchmarl",
    "uavrl.envs.adapters.gym_env": "gymnasium",
    "uavrl.envs.adapters.pettingzoo_env": "pettingzoo",
}
EXTRA_MARKS = {"gymnasium": "gym", "pettingzoo": "gym"}  # the marker of the [gym] extra's tests


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
    if name is not None and "from uavrl.envs._moved import alias" in file_path.read_text():
        return None  # an old path of a moved module: its examples run under the module's own name
    if name is not None and (name not in NEEDS or importlib.util.find_spec(NEEDS[name]) is not None):
        return InstalledDoctestModule.from_parent(parent, path=file_path)
    return None


def pytest_addoption(parser):
    parser.addoption(
        "--no-skip",
        action="store_true",
        default=os.environ.get("UAVRL_NO_SKIP") == "1",
        help="a test that skips fails instead (CI's legs: every test they select must run); also UAVRL_NO_SKIP=1",
    )


def pytest_collection_modifyitems(config, items):
    for item in items:
        if isinstance(item.parent, InstalledDoctestModule):
            mark = EXTRA_MARKS.get(NEEDS.get(installed_name(item.parent.path)))
            if mark is not None:
                item.add_marker(mark)


def _fail_a_skip(report, config) -> None:
    if report.skipped and not hasattr(report, "wasxfail") and config.getoption("no_skip"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        report.outcome = "failed"
        report.longrepr = f"skipped under --no-skip (UAVRL_NO_SKIP=1), where every selected test must run: {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    _fail_a_skip(outcome.get_result(), item.config)


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    """A test file that skips whole (a module-level ``importorskip``) fails too under ``--no-skip``."""
    outcome = yield
    _fail_a_skip(outcome.get_result(), collector.config)
