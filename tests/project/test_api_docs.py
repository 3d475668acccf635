"""Every object of the API reference documents its arguments: each name the pages of docs/api/ list (autosummary
entries under a ``currentmodule``) has a docstring that names every parameter of its signature (a class: of its
``__init__``, its own or one inherited from a uavrl class; one inherited from TorchRL, Gymnasium or BenchMARL is
theirs to document), and so does each public method with a docstring that the class's page shows. Parameters
whose names start with ``_`` are private and left out.

A module whose optional extra is not installed (BenchMARL, Gymnasium, PettingZoo) is checked from its source
instead (the same signatures and docstrings, parsed), so the check covers every page whatever is installed.
Imports only: no environment is built.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import re
import sys
import traceback
import types
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
API_PAGES = sorted((ROOT / "docs" / "api").glob("*.md"))
CURRENT_MODULE = re.compile(r"^\s*(?:\.\. currentmodule::|```\{currentmodule\})\s+(?P<module>[\w.]+)")
AUTOSUMMARY = re.compile(r"^\s*\.\. autosummary::")
# an autosummary entry: an indented dotted name alone on its line (options such as :toctree: start with a colon)
ENTRY = re.compile(r"^\s+(?P<name>[A-Za-z_][\w.]*)\s*$")


@dataclass(frozen=True)
class ApiObject:
    page: str
    module: str
    name: str

    @property
    def path(self) -> str:
        return f"{self.module}.{self.name}"


def api_objects(page: str, text: str) -> list[ApiObject]:
    """The autosummary entries of one API page, each with the ``currentmodule`` in force above it."""
    found, module, in_autosummary = [], None, False
    for line in text.splitlines():
        if match := CURRENT_MODULE.match(line):
            module, in_autosummary = match["module"], False
        elif AUTOSUMMARY.match(line):
            in_autosummary = True
        elif in_autosummary and (match := ENTRY.match(line)):
            if module is None:
                raise AssertionError(f"{page}: {match['name']} is listed before any currentmodule")
            found.append(ApiObject(page, module, match["name"]))
        elif in_autosummary and line.strip() and not line.startswith((" ", "\t")):
            in_autosummary = False  # the block ended at the first line back at the margin
    return found


def all_api_objects() -> list[ApiObject]:
    return [obj for page in API_PAGES for obj in api_objects(page.name, page.read_text())]


def public(parameters) -> list[str]:
    return [name for name in parameters if name not in ("self", "cls") and not name.startswith("_")]


def missing_names(doc: str, parameters: list[str]) -> list[str]:
    return [name for name in parameters if not re.search(rf"\b{re.escape(name)}\b", doc)]


def init_owner(cls: type) -> type | None:
    """The class whose ``__init__`` builds ``cls`` when it is a uavrl class (``cls`` itself or a uavrl base), else
    None (``object``'s, or a library's: not ours to document)."""
    for klass in cls.__mro__:
        if "__init__" in vars(klass):
            return klass if klass.__module__.split(".")[0] == "uavrl" else None
    return None


def shown_methods(cls: type) -> dict:
    """The methods the class's page shows: its own public ones with a docstring (autodoc leaves out the others)."""
    shown = {}
    for name, member in vars(cls).items():
        function = member.__func__ if isinstance(member, classmethod | staticmethod) else member
        if not name.startswith("_") and inspect.isfunction(function) and function.__doc__:
            shown[name] = function
    return shown


def check_object(obj) -> list[str]:
    """What the docstring of a function or class lacks: the whole docstring, or the parameters it does not name
    (a class: those of its ``__init__``, and those of each method its page shows, in that method's docstring)."""
    if inspect.isclass(obj):
        owner = init_owner(obj)
        docs = [obj.__doc__] if owner is None else [obj.__doc__, owner.__doc__, owner.__init__.__doc__]
        doc = "\n".join(d for d in docs if d)
        parameters = [] if owner is None else public(list(inspect.signature(owner.__init__).parameters))
        methods = [
            f"method {name!r}: parameter {parameter!r} not named"
            for name, method in shown_methods(obj).items()
            for parameter in missing_names(method.__doc__, public(list(inspect.signature(method).parameters)))
        ]
    else:
        doc = obj.__doc__ or ""
        parameters = public(list(inspect.signature(obj).parameters))
        methods = []
    if not doc.strip():
        return ["no docstring"]
    return [f"parameter {name!r} not named" for name in missing_names(doc, parameters)] + methods


def _function_parameters(node: ast.FunctionDef | ast.AsyncFunctionDef) -> list[str]:
    args = node.args
    names = [a.arg for a in (*args.posonlyargs, *args.args, *args.kwonlyargs)]
    names += [a.arg for a in (args.vararg, args.kwarg) if a is not None]
    return public(names)


def source_file(module: str, error: ModuleNotFoundError) -> Path:
    """The file of ``module`` whose import ``error`` stopped: the module-level frame of that name in the traceback
    (``uavrl.envs.gym_env`` is an alias of ``uavrl.envs.adapters.gym_env``, a spec without a file of its own)."""
    stem = module.rpartition(".")[2]
    for frame, _ in traceback.walk_tb(error.__traceback__):
        if frame.f_code.co_name == "<module>" and Path(frame.f_code.co_filename).stem == stem:
            return Path(frame.f_code.co_filename)
    raise error


def check_source(path: Path, name: str) -> list[str]:
    """:func:`check_object` read from the module's source, for a module whose optional extra is not installed."""
    tree = ast.parse(path.read_text())
    node = next((n for n in tree.body if getattr(n, "name", None) == name), None)
    if node is None:
        return [f"not defined in {path}"]
    doc, methods = ast.get_docstring(node) or "", []
    if isinstance(node, ast.ClassDef):
        functions = [n for n in node.body if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]
        init = next((n for n in functions if n.name == "__init__"), None)
        parameters = [] if init is None else _function_parameters(init)  # inherited: the base's to document
        doc += "\n" + ((init and ast.get_docstring(init)) or "")
        methods = [
            f"method {method.name!r}: parameter {parameter!r} not named"
            for method in functions
            if not method.name.startswith("_") and ast.get_docstring(method)
            for parameter in missing_names(ast.get_docstring(method), _function_parameters(method))
        ]
    else:
        parameters = _function_parameters(node)
    if not doc.strip():
        return ["no docstring"]
    return [f"parameter {name!r} not named" for name in missing_names(doc, parameters)] + methods


def check(item: ApiObject) -> list[str]:
    try:
        obj = importlib.import_module(item.module)
    except ModuleNotFoundError as error:
        if error.name is None or error.name.split(".")[0] == "uavrl":
            raise
        # an optional extra (BenchMARL, Gymnasium) is not installed
        return check_source(source_file(item.module, error), item.name)
    for part in item.name.split("."):
        obj = getattr(obj, part)
    return check_object(obj)


def test_the_pages_list_the_api():
    """The parse finds every page's entries (a parse that finds nothing would pass everything)."""
    objects = all_api_objects()
    pages = {obj.page for obj in objects}
    with_autosummary = {page.name for page in API_PAGES if ".. autosummary::" in page.read_text()}
    assert with_autosummary and pages == with_autosummary
    assert len(objects) > 100
    assert ApiObject("evaluation.md", "uavrl.agents.evaluation", "evaluate") in objects


@pytest.mark.parametrize("item", all_api_objects(), ids=lambda item: item.path)
def test_every_argument_is_documented(item: ApiObject):
    problems = check(item)
    assert not problems, f"{item.path} (docs/api/{item.page}): " + "; ".join(problems)


def test_an_undocumented_function_fails(monkeypatch):
    """A public function added to a page without its arguments in the docstring is caught, as is one without a
    docstring, and a documented one passes."""
    import uavrl.agents.evaluation

    def half_documented(policy, horizon: int = 5):
        """Plays ``policy``."""

    def undocumented(x):
        pass

    def documented(policy, *, horizon: int = 5, **kwargs):
        """Plays ``policy`` for ``horizon`` steps; ``kwargs``: more settings."""

    for function in (half_documented, undocumented, documented):
        monkeypatch.setattr(uavrl.agents.evaluation, function.__name__, function, raising=False)
    page = "```{eval-rst}\n.. currentmodule:: uavrl.agents.evaluation\n\n.. autosummary::\n   :toctree: generated\n\n"
    page += "   evaluate\n   half_documented\n   undocumented\n   documented\n```\n"
    problems = {item.name: check(item) for item in api_objects("planted.md", page)}
    assert problems == {
        "evaluate": [],
        "half_documented": ["parameter 'horizon' not named"],
        "undocumented": ["no docstring"],
        "documented": [],
    }


def test_a_class_is_checked_against_its_init(monkeypatch):
    """A class's ``__init__`` arguments, its own or inherited from a uavrl class, must be named; a class whose
    ``__init__`` comes from a library is not ours to document."""
    module = types.ModuleType("uavrl._planted")
    monkeypatch.setitem(sys.modules, module.__name__, module)

    class Base:
        """Takes ``cfg``."""

        def __init__(self, cfg, device="cpu"):
            pass

    class Child(Base):
        """A child of Base."""

        def shown(self, steps, seed=0):
            """Runs for ``steps`` steps."""

        def not_shown(self, steps):  # no docstring: autodoc leaves it out
            pass

    class FromLibrary(ValueError):
        """A ValueError."""

    for klass in (Base, Child):
        klass.__module__ = module.__name__
    assert check_object(Base) == ["parameter 'device' not named"]
    assert check_object(Child) == ["parameter 'device' not named", "method 'shown': parameter 'seed' not named"]
    assert check_object(FromLibrary) == []


def test_a_module_of_a_missing_extra_is_read_from_its_source(tmp_path, monkeypatch):
    """Without the extra installed, the source is checked: a planted module that imports a missing library."""
    (tmp_path / "planted_extra.py").write_text(
        "import a_library_that_is_not_installed\n\n"
        "class Task(a_library_that_is_not_installed.Base):\n"
        '    """A task."""\n\n'
        "    def __init__(self, cfg, seed):\n"
        '        """``cfg``: the model."""\n\n'
        "    def step(self, action):\n"
        '        """One step."""\n\n'
        "def run(task, steps):\n"
        '    """Runs ``task`` for ``steps`` steps."""\n'
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    assert check(ApiObject("planted.md", "planted_extra", "Task")) == [
        "parameter 'seed' not named",
        "method 'step': parameter 'action' not named",
    ]
    assert check(ApiObject("planted.md", "planted_extra", "run")) == []
