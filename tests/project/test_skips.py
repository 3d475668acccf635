"""CI cannot pass by skipping: ``--no-skip`` turns a skip into a failure, and every test of the [gym] extra is marked
``gym`` so that CI's Gymnasium leg (``-m gym --no-skip``) runs it."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
GYM_MODULES = {"gymnasium", "pettingzoo", "stable_baselines3", "sb3_contrib"}

SKIPPING = """
import pytest

def test_runs():
    assert True

def test_skips():
    pytest.skip("an extra is missing")
"""


def run_pytest(tmp_path, *options, env=None):
    (tmp_path / "test_example.py").write_text(SKIPPING)
    argv = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist", "-p", "conftest"]
    return subprocess.run(
        [*argv, "-c", os.devnull, "--rootdir", str(tmp_path), *options, str(tmp_path / "test_example.py")],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})},
    )


@pytest.mark.slow
def test_a_skip_fails_under_no_skip(tmp_path):
    assert run_pytest(tmp_path).returncode == 0  # skips pass by default
    for options, env in (((), {"UAVRL_NO_SKIP": "1"}), (("--no-skip",), None)):
        result = run_pytest(tmp_path, *options, env=env)
        assert result.returncode == 1 and "1 failed, 1 passed" in result.stdout, result.stdout
        assert "skipped under --no-skip (UAVRL_NO_SKIP=1), where every selected test must run" in result.stdout


def needs_gym(function: ast.FunctionDef) -> bool:
    """The test imports, or import-skips, a module of the [gym] extra or an adapter."""
    for node in ast.walk(function):
        if isinstance(node, ast.Call) and ast.unparse(node.func).endswith("importorskip") and node.args:
            if isinstance(node.args[0], ast.Constant) and node.args[0].value in GYM_MODULES:
                return True
        names = [alias.name for alias in node.names] if isinstance(node, ast.Import) else []
        names += [node.module or ""] if isinstance(node, ast.ImportFrom) else []
        if any(name.split(".")[0] in GYM_MODULES or name.startswith("uavrl.envs.adapters") for name in names):
            return True
    return False


def gym_marked(decorators) -> bool:
    return any("mark.gym" in ast.unparse(decorator) for decorator in decorators)


def test_every_test_of_the_gym_extra_is_marked_gym():
    """A test that imports (or import-skips) the [gym] extra's modules carries ``pytest.mark.gym``, itself or its file:
    otherwise CI's Gymnasium leg would not run it, and every other leg skips it."""
    unmarked, files = [], sorted((ROOT / "tests").rglob("test_*.py"))
    assert len(files) > 50  # every test file, in the folders that mirror the package
    for path in files:
        tree = ast.parse(path.read_text())
        module_marked = any(
            isinstance(node, ast.Assign)
            and any(isinstance(t, ast.Name) and t.id == "pytestmark" for t in node.targets)
            and "mark.gym" in ast.unparse(node.value)
            for node in tree.body
        )
        for node in tree.body:
            if not isinstance(node, ast.FunctionDef) or not node.name.startswith("test_"):
                continue
            if needs_gym(node) and not (module_marked or gym_marked(node.decorator_list)):
                unmarked.append(f"{path.name}::{node.name}")
    assert unmarked == []
