"""python -m uavrl.report: its statistics against values computed by hand, its grouping, tables and figures."""

import json
import math

import numpy as np
import pytest
import yaml

from uavrl.report import bootstrap_band, bootstrap_ci, iqm, main, report


@pytest.mark.parametrize(
    "values, expected",
    [
        ([5.0], 5.0),  # n < 4: nothing is dropped
        ([1.0, 2.0, 3.0], 2.0),
        ([1.0, 2.0, 3.0, 4.0, 100.0], 3.0),  # floor(5 / 4) = 1 dropped at each end: (2 + 3 + 4) / 3
        ([8.0, 1.0, 7.0, 2.0, 6.0, 3.0, 5.0, 4.0], 4.5),  # 2 dropped at each end: (3 + 4 + 5 + 6) / 4
        ([0.0] * 3 + [10.0] * 7, 50.0 / 6),  # n = 10: 2 dropped at each end, one 0 and five 10s left
    ],
)
def test_iqm_by_hand(values, expected):
    assert iqm(values) == pytest.approx(expected, abs=1e-12)


def test_iqm_is_scipys_trimmed_mean():
    from scipy.stats import trim_mean

    rng = np.random.default_rng(3)
    for n in range(1, 13):
        values = rng.normal(size=n)
        assert iqm(values) == pytest.approx(trim_mean(values, 0.25), abs=1e-12)


def test_bootstrap_ci_by_hand():
    """Two values a < b: a resample's mean is a, (a + b) / 2 or b with probabilities 1/4, 1/2, 1/4."""
    # 95%: the 2.5% and 97.5% quantiles fall in the atoms at a and b
    assert bootstrap_ci([0.0, 4.0]) == (0.0, 4.0)
    # 20%: the 40% and 60% quantiles both fall in the atom at the midpoint (cumulative 1/4 .. 3/4)
    assert bootstrap_ci([0.0, 4.0], confidence=0.2) == (2.0, 2.0)
    # three values: each extreme mean has probability 1/27 > 2.5%
    assert bootstrap_ci([0.0, 1.0, 3.0]) == (0.0, 3.0)
    assert bootstrap_ci([2.0, 2.0, 2.0]) == (2.0, 2.0)
    assert all(math.isnan(bound) for bound in bootstrap_ci([1.0]))


def test_bootstrap_ci_matches_the_exact_bootstrap_distribution():
    """Four values: 4^4 = 256 equally likely resamples; the sampled interval lies within a few draws' worth of the
    exact quantiles and is the same on every call with the same seed."""
    values = np.array([0.0, 1.0, 2.0, 10.0])
    grids = np.stack(np.meshgrid(*[values] * 4, indexing="ij"), -1).reshape(-1, 4)
    exact = np.quantile(grids.mean(1), [0.025, 0.975])
    low, high = bootstrap_ci(values, resamples=20_000, seed=7)
    assert (low, high) == pytest.approx(tuple(exact), abs=0.3)
    assert bootstrap_ci(values, resamples=20_000, seed=7) == (low, high)
    spread = np.random.default_rng(0).normal(size=6)  # no atoms: another seed moves the interval a little
    assert bootstrap_ci(spread, seed=1) != bootstrap_ci(spread, seed=2)
    assert bootstrap_ci(spread, seed=1) == pytest.approx(bootstrap_ci(spread, seed=2), abs=0.05)


def test_bootstrap_band_is_pointwise():
    curves = np.array([[0.0, 10.0], [4.0, 10.0]])
    low, high = bootstrap_band(curves)
    assert low.tolist() == [0.0, 10.0] and high.tolist() == [4.0, 10.0]
    assert np.isnan(bootstrap_band(curves[:1])[0]).all()


def write_run(path, agent, seed, metrics, settings=None, scenario=None):
    """A run directory as uavrl.train leaves it (config.yaml and metrics.json; no curves)."""
    path.mkdir(parents=True)
    cfg = {
        "seed": seed,
        "env": {"name": "paper", "preset": "paper", "grid": [6, 6], "num_uavs": 2, "max_steps": 30, "layout": None},
        "eval": {"num_starts": 64, "gamma": 0.9, "horizon": None},
        "agent": {"name": agent, **(settings or {})},
        "scenario": scenario,
    }
    (path / "config.yaml").write_text(yaml.safe_dump(cfg))
    (path / "metrics.json").write_text(json.dumps({"eval/sum_utility": 200.0, **metrics}))


@pytest.fixture
def study(tmp_path):
    root = tmp_path / "study"
    for seed, ratio in enumerate([0.9, 1.0]):
        write_run(root / "vdn" / f"seed={seed}", "dqn", seed, {"eval/return_ratio": ratio}, {"mixer": "vdn"})
    for seed, ratio in enumerate([1.0, 2.0, 3.0, 4.0, 100.0]):
        write_run(root / "qmix" / f"seed={seed}", "dqn", seed, {"eval/return_ratio": ratio}, {"mixer": "qmix"})
    write_run(root / "oracle" / "seed=0", "oracle", 0, {"eval/return_ratio": 0.9998})
    write_run(root / "other" / "seed=0", "random", 0, {"eval/return_ratio": -0.02}, None, {"name": "rayleigh"})
    return root


def test_report_tables_flag_few_seeds_and_show_the_iqm(study, tmp_path):
    path = report([study], tmp_path / "out", resamples=1000)
    text = path.read_text()
    assert "## paper" in text and "## rayleigh" in text
    rows = {line.split(" | ")[0].lstrip("| "): line for line in text.splitlines() if line.startswith("| ")}
    # two seeds: mean 0.95, interval [0.9, 1] (the atoms of the two values), flagged; no IQM below 5 seeds
    assert "| **2 (0, 1) < 3** | 0.95 [0.9, 1] |" in rows["dqn agent.mixer=vdn"]
    # five seeds: IQM (2 + 3 + 4) / 3 = 3 beside the mean 22
    assert "| 5 (0, 1, 2, 3, 4) | 22 [" in rows["dqn agent.mixer=qmix"] and "; IQM 3 |" in rows["dqn agent.mixer=qmix"]
    assert rows["oracle (baseline)"].startswith("| oracle (baseline) | **1 (0) < 3** | 0.9998 |")
    assert (tmp_path / "out" / "paper_metrics.png").stat().st_size > 10_000
    assert (tmp_path / "out" / "rayleigh_metrics.png").exists()
    assert not (tmp_path / "out" / "paper_curves.png").exists()  # no TensorBoard events: no curves to draw
    assert report([study], tmp_path / "again", resamples=1000).read_text() == text.replace("/out", "/again")


@pytest.mark.parametrize(
    "argv, words",
    [
        (["{tmp}/nowhere"], "nowhere: no such directory"),
        (["{tmp}/empty"], "no run directory"),
        (["{tmp}/empty", "{tmp}/empty"], "--out is needed with several directories"),
        (["{tmp}/empty", "--resamples", "0"], "--resamples=0 is invalid"),
        (["{tmp}/empty", "--seed", "x"], "argument --seed: invalid int value: 'x'"),
    ],
)
def test_report_mistakes_are_one_line(argv, words, tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit) as refused:
        main([arg.format(tmp=tmp_path) for arg in argv])
    message = str(refused.value.code)
    assert message.startswith("error: ") and "\n" not in message and words in message, message
