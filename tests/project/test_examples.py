"""Every script of ``examples/`` runs to the end as ``python examples/<name>.py``, from a directory of its own.

Each example is run as a subprocess from a fresh temporary directory (so whatever it writes lands there, and it must
find the library from anywhere), with matplotlib's non-interactive backend.  An example that imports an optional
extra's package is skipped, naming the extra, when that package is missing.
"""

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow
EXAMPLES = sorted((Path(__file__).resolve().parents[2] / "examples").glob("*.py"))
EXTRAS = {  # a package an example may import -> the extra that installs it
    "gymnasium": "gym",
    "pettingzoo": "gym",
    "stable_baselines3": "gym",
    "sb3_contrib": "gym",
    "ray": "ray",
    "hydra_plugins.hydra_ray_launcher": "ray",
}
IMPORT = re.compile(r"^\s*(?:import|from)\s+([\w.]+)", re.MULTILINE)


def missing_extra(source: str) -> str | None:
    """The reason to skip an example whose source imports a package of an extra that is not installed."""
    for module in IMPORT.findall(source):
        for package, extra in EXTRAS.items():
            if (module == package or module.startswith(package + ".")) and importlib.util.find_spec(package) is None:
                return f'{package} is missing: pip install -e ".[{extra}]"'
    return None


def test_the_examples_are_found():
    assert len(EXAMPLES) >= 10


@pytest.mark.parametrize("example", EXAMPLES, ids=[path.stem for path in EXAMPLES])
def test_example_runs(example, tmp_path):
    reason = missing_extra(example.read_text())
    if reason:
        pytest.skip(reason)
    env = {**os.environ, "MPLBACKEND": "Agg"}
    result = subprocess.run(
        [sys.executable, str(example)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-4000:]
