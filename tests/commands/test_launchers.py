"""Sweeps through Hydra's Ray and joblib launchers, and the report on their runs (``pip install -e ".[ray]"``).

Skipped without the launchers; CI installs them and runs this file (``.ci/run``).
"""

import json

import pytest

pytest.importorskip("hydra_plugins.hydra_ray_launcher", reason='the Ray launcher: pip install -e ".[ray]"')
pytest.importorskip("hydra_plugins.hydra_joblib_launcher", reason='the joblib launcher: pip install -e ".[ray]"')

pytestmark = pytest.mark.slow
LAUNCHERS = {
    "ray": ["hydra/launcher=ray", "+hydra.launcher.ray.init.num_cpus=2"],  # a local Ray instance of 2 CPUs
    "joblib": ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"],
}
JOB = "agent.episodes=2,agent.runs=2,agent=tabular,env.max_steps=20,eval.num_starts=4"


@pytest.fixture(scope="module")
def swept(tmp_path_factory, run_sweep, tiny_tabular):
    """Two jobs (seeds 0 and 1) through each launcher, into ``<root>/<launcher>``."""
    root = tmp_path_factory.mktemp("launchers")
    for name, launcher in LAUNCHERS.items():
        run_sweep(root, *launcher, *tiny_tabular, "seed=0,1", f"sweep_dir={name}")
    return root, {name: sorted(p.parent for p in (root / name).rglob("metrics.json")) for name in LAUNCHERS}


@pytest.mark.parametrize("launcher", LAUNCHERS)
def test_each_launcher_writes_the_jobs_run_directories(launcher, swept):
    root, runs = swept
    assert runs[launcher] == [root / launcher / JOB / "seed=0", root / launcher / JOB / "seed=1"]


def test_the_launchers_give_the_same_results(swept):
    """Same seed, same result (bit for bit on CPU), whichever launcher ran the job."""
    root, runs = swept
    for ray_run, joblib_run in zip(runs["ray"], runs["joblib"], strict=True):
        ray_metrics, joblib_metrics = (json.loads((run / "metrics.json").read_text()) for run in (ray_run, joblib_run))
        assert {k: v for k, v in ray_metrics.items() if k.startswith("eval/")} == {
            k: v for k, v in joblib_metrics.items() if k.startswith("eval/")
        }


def test_the_report_on_a_ray_sweep(swept):
    from uavrl.experiment.reporting import report

    root, _ = swept
    text = report([root / "ray"], root / "ray").read_text()
    (row,) = [line for line in text.splitlines() if line.startswith("| tabular |")]
    cells = row.split(" | ")
    assert cells[1] == "**2 (0, 1) < 3**"  # both seeds, flagged as fewer than 3
    low, high = (float(x) for x in cells[2].split("[")[1].rstrip("]").split(", "))  # the return ratio's interval
    assert low <= float(cells[2].split(" ")[0]) <= high
    assert (root / "ray" / "paper_metrics.png").stat().st_size > 10_000
    assert (root / "ray" / "paper_curves.png").stat().st_size > 10_000
