"""Sphinx configuration of the documentation site: MyST pages, the API reference from the docstrings, the examples
gallery (sphinx-gallery runs every ``examples/*.py``).

Build (warnings are errors): ``python -m sphinx -W --keep-going -b html docs docs/_build/html``, then check its
internal links offline: ``python docs/check_links.py docs/_build/html``.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import uavrl

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent

project = "uavrl"
author = "uavrl contributors"
copyright = "uavrl contributors"
release = uavrl.__version__
version = ".".join(release.split(".")[:2])

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "auto_examples/*.zip", "figures/README*"]
templates_path = ["_templates"]

# MyST: ``{eval-rst}`` blocks for autosummary, ``$...$`` maths, anchors for every heading down to ###, so that
# [text](page.md#a-heading) links resolve (the offline link check verifies each one)
myst_enable_extensions = ["colon_fence", "dollarmath", "deflist", "attrs_inline"]
myst_heading_anchors = 3

# the API reference: one generated page per public object, named by its public import path
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": True, "member-order": "bysource"}
autodoc_typehints = "description"
autodoc_typehints_format = "short"
# a method documents itself or not at all: the docstrings TorchRL, Gymnasium and PettingZoo give the methods we
# override are theirs to format (and change), not reST this build can vouch for
autodoc_inherit_docstrings = False
# the docstrings are reST prose with the occasional Google-style ``Args:`` section
napoleon_google_docstring = True
napoleon_numpy_docstring = True
napoleon_use_rtype = False

# Optional extras that the docs leg (pip install ".[docs,gym,ray]") does not install are mocked, so their modules'
# pages build from the docstrings alone. BenchMARL is one: it pins torchrl 0.11 and torch 2.13 (the [benchmarl]
# extra), a set the docs leg need not resolve beside Ray; its task and callback subclass BenchMARL classes that a mock
# stands in for. Gymnasium and PettingZoo are installed there (the adapters' pages show their real bases); a local
# build without them mocks them the same way.
OPTIONAL_EXTRAS = ["benchmarl", "gymnasium", "pettingzoo", "stable_baselines3", "sb3_contrib"]
autodoc_mock_imports = [name for name in OPTIONAL_EXTRAS if importlib.util.find_spec(name) is None]

# no intersphinx: CI builds without network, and a missing inventory would be a warning
intersphinx_mapping: dict = {}

# the examples gallery: every examples/*.py runs at build time (a failing example fails the build), its printed
# output and its matplotlib figures are shown under its code
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": str(DOCS / "auto_examples"),
    "filename_pattern": r"/.*\.py$",  # every example runs, not only plot_*.py
    "ignore_pattern": r"__init__\.py|/_",
    "abort_on_example_error": True,
    "image_scrapers": ("matplotlib",),
    "matplotlib_animations": False,
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "default_thumb_file": None,
    "show_memory": False,
    "plot_gallery": "True",
}
os.environ.setdefault("MPLBACKEND", "Agg")

html_theme = "furo"
html_title = f"uavrl {release}"
html_show_sourcelink = False


def init_signature(app, what, name, obj, options, signature, return_annotation):
    """A class whose base defines ``__new__(*args, **kwargs)`` (TorchRL's ``EnvBase``, tensordict's modules) shows the
    arguments of its own ``__init__`` instead."""
    if what != "class" or signature != "(*args, **kwargs)" or "__init__" not in vars(obj):
        return None
    import inspect

    parameters = list(inspect.signature(obj.__init__).parameters.values())[1:]  # without self
    return str(inspect.Signature(parameters)), return_annotation


def setup(app):
    app.connect("autodoc-process-signature", init_signature)
