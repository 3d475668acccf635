"""The import paths of uavrl 0.2 whose modules moved in 0.3 still work, as the very module, with a warning."""

import subprocess
import sys

import pytest

MOVED = {
    "uavrl.evaluation": "uavrl.agents.evaluation",
    "uavrl.rules": "uavrl.envs.rules",
    "uavrl.compat": "uavrl.envs.compat",
}


@pytest.mark.parametrize("old, new", MOVED.items())
def test_an_old_path_is_the_moved_module_with_a_deprecation_warning(old, new):
    code = (
        "import warnings, importlib\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        f"    old = importlib.import_module({old!r})\n"
        f"assert old is importlib.import_module({new!r}), old\n"
        f"print([str(w.message) for w in caught if w.category is DeprecationWarning and {old!r} in str(w.message)])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert f"{old} moved to {new} in uavrl 0.3" in out


def test_the_library_imports_no_old_path():
    """Every module of the package, imported, leaves the old paths unimported (nothing of ours goes through them)."""
    extras = ("benchmarl", "adapters", "bench.run", "bench.stats", "__main__")  # modules of optional extras
    code = (
        "import pkgutil, importlib, sys\n"
        "for package in ('uavrl', 'uavrl.envs', 'uavrl.agents'):\n"
        "    for m in pkgutil.walk_packages(importlib.import_module(package).__path__, package + '.'):\n"
        f"        if m.name not in {tuple(MOVED)!r} and not any(e in m.name for e in {extras!r}):\n"
        "            importlib.import_module(m.name)\n"
        f"print(len(sys.modules), sorted(set({tuple(MOVED)!r}) & set(sys.modules)))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split(" ", 1)[1].strip() == "[]"


def test_evaluate_with_lookahead_keeps_its_old_path_with_a_warning():
    import warnings

    from uavrl.agents import evaluation, lookahead

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        moved = lookahead.evaluate_with_lookahead
    assert moved is evaluation.evaluate_with_lookahead
    assert any("moved to uavrl.agents.evaluation" in str(w.message) for w in caught)
