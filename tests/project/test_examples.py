"""Every script of ``examples/`` runs to the end as ``python examples/<name>.py``, from a directory of its own, and
prints and writes what it says it does.

Each example is run as a subprocess from a fresh temporary directory (so whatever it writes lands there, and it must
find the library from anywhere), with matplotlib's non-interactive backend; then :data:`CHECKS` reads one or two things
it printed or wrote (numbers within their range, the policies ordered as they must be, the files of a run or a
report).  An example that imports an optional extra's package is skipped, naming the extra, when that package is
missing.
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
NUMBER = r"(-?\d+(?:\.\d+)?)"


def printed(pattern: str, stdout: str) -> list[float]:
    """The numbers ``pattern``'s groups match in each line that it matches (one list per line, flattened)."""
    found = [float(v) for match in re.finditer(pattern, stdout) for v in match.groups()]
    assert found, f"{pattern!r} not in the output:\n{stdout[-2000:]}"
    return found


def fractions(pattern: str, stdout: str, count: int | None = None) -> list[float]:
    """The numbers ``pattern`` matches, each a fraction in [0, 1] (``count``: how many lines must match)."""
    values = printed(pattern, stdout)
    assert count is None or len(values) == count, (pattern, values)
    assert all(0.0 <= v <= 1.0 for v in values), (pattern, values)
    return values


def check_training_log(stdout: str, iterations: int) -> None:
    """A TorchRL training loop's log: one line per iteration, the evaluation's final U / U* a fraction."""
    fractions(r"iteration \d+: episode reward -?[\d.]+, evaluation: final U / U\* " + NUMBER, stdout, iterations)
    assert re.search(r"trained in [\d.]+ s", stdout)


def check_yardstick(stdout: str, _: Path) -> None:
    """The three policies as the example describes them (the rule reaches 0.999 U* from some starts, random almost
    never; the oracle's return is the best possible), and the exact solver's count of optimal configurations."""
    pattern = r"return ratio (-?[\d.]+), reach 0.999 U\* ([\d.]+), final U/U\* ([\d.]+)"
    random, rule, oracle = (printed(pattern, stdout)[k : k + 3] for k in (0, 3, 6))
    assert random[1] < rule[1] and oracle[0] >= 0.99 and oracle[0] > max(random[0], rule[0]), (random, rule, oracle)
    configurations, optimal = printed(
        r"(\d+) configurations, (\d+) of them optimal", re.sub(r"(\d),(\d)", r"\1\2", stdout)
    )
    assert 0 < optimal < configurations


def check_files(*names: str):
    """A check that each of ``names`` (paths under the example's directory) was written and is not empty."""

    def check(_: str, directory: Path) -> None:
        for name in names:
            assert (directory / name).stat().st_size > 0, name

    return check


def check_all(*checks):
    def check(stdout: str, directory: Path) -> None:
        for one in checks:
            one(stdout, directory)

    return check


# what each example must print or write, beyond running to the end: (stdout, its directory) -> asserts
CHECKS = {
    "plot_01_torchrl_loop": lambda out, _: fractions(r"random policy, final U / U\*: " + NUMBER, out, 1),
    "plot_02_torchrl_mappo": lambda out, _: check_training_log(out, 10),
    "plot_03_torchrl_qmix_vdn": lambda out, _: check_training_log(out, 30),
    "plot_04_gymnasium_sb3_pettingzoo": lambda out, _: (
        printed(r"256 worlds: \(256, (\d+), \d+\)", out),  # one batched World: [worlds, UAVs, observation]
        fractions(r"MaskablePPO, 4,096 steps: return ratio -?[\d.]+, final U/U\* " + NUMBER, out, 1),
    ),
    "plot_05_yardstick": check_yardstick,
    "plot_06_custom_channel_and_reward": lambda out, _: (
        re.search(r"'fading': 'LogNormalShadowing'.*'reward': 'ProportionalFairReward'", out)
        or pytest.fail(f"the world's parts not printed as replaced:\n{out[-2000:]}")
    ),
    "plot_07_energy_mission": lambda out, _: fractions(r"\d+ bit/Hz, " + NUMBER + " of the bound", out, 2),
    "plot_08_size_free_zero_shot": check_all(
        check_files("runs/examples/size_free/checkpoint.pt", "runs/examples/size_free/metrics.json"),
        lambda out, _: fractions(
            r"(?m)^(?:size-free DQN \(tiny run\)|oracle planner|uniform random): final U/U\* " + NUMBER, out, 3
        ),
    ),
    "plot_09_reproduce_paper": check_all(
        check_files(*(f"reproduction/example/{name}" for name in ("table2.md", "fig3_sum_utility.png"))),
        lambda out, _: re.search(r"^\| 6x6 \|", out, re.MULTILINE) or pytest.fail(f"no 6x6 row:\n{out[-2000:]}"),
    ),
    "plot_10_ray_study": check_files("runs/examples/study/report.md", "runs/examples/study/paper_6x6_metrics.png"),
    "tour": check_all(
        check_files("runs/tour/dqn/metrics.json", "runs/tour/dqn/checkpoint.pt"),
        lambda out, _: fractions(r"random actions end at " + NUMBER + " of it on average", out, 1),
        lambda out, _: fractions(r"reach 0.999 U\* " + NUMBER + r", final U/U\* " + NUMBER, out, 2),
    ),
}


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
    CHECKS[example.stem](result.stdout, tmp_path)


def test_every_example_has_its_checks():
    assert sorted(CHECKS) == [path.stem for path in EXAMPLES]
