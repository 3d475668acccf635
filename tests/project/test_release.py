"""The release's version is written once (pyproject.toml) and every other place that names it agrees."""

import re
import tomllib
from importlib.metadata import metadata
from pathlib import Path

import yaml

import uavrl

ROOT = Path(__file__).resolve().parents[2]
# a released entry's heading in Keep a Changelog's format: ## [0.2.0] - 2026-12-03
RELEASE_HEADING = re.compile(r"^## \[(\d+\.\d+\.\d+)\] - (\d{4}-\d{2}-\d{2})$", re.MULTILINE)


def newest_changelog_entry():
    """``(version, date)`` of CHANGELOG.md's first released entry."""
    found = RELEASE_HEADING.search((ROOT / "CHANGELOG.md").read_text(encoding="utf-8"))
    assert found, "CHANGELOG.md has no '## [X.Y.Z] - YYYY-MM-DD' heading"
    return found.group(1), found.group(2)


def test_the_version_is_pyprojects_everywhere():
    written = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["version"]
    installed = metadata("uavrl")["Version"]
    assert installed == written, f"installed metadata says {installed}: reinstall (pip install -e .)"
    assert uavrl.__version__ == written
    assert newest_changelog_entry()[0] == written


def test_the_citation_names_the_newest_release():
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    version, date = newest_changelog_entry()
    assert (citation["version"], str(citation["date-released"])) == (version, date)
    assert citation["license"] == metadata("uavrl")["License-Expression"] == "MIT"


def test_the_version_is_read_once_and_no_other_name_lazily():
    version = uavrl.__version__
    assert vars(uavrl)["__version__"] == version  # after the first read, an ordinary attribute
    assert not hasattr(uavrl, "no_such_name")
