"""python -m uavrl.report: its statistics against values computed by hand, its grouping, tables and figures."""

import json
import math
import shlex
import warnings

import numpy as np
import pytest
import yaml

from uavrl.experiment.reporting import bootstrap_band, bootstrap_ci, iqm, report
from uavrl.report import main


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
        (["{tmp}/no where"], "/no where': no such directory"),
        (
            ["{tmp}/damaged"],
            "damaged/run: metrics.json holds a list, not an object of metrics; no other run to report",
        ),
        (["{tmp}/empty"], "no run directory"),
        (["{tmp}/empty", "{tmp}/empty"], "--out is needed with several directories"),
        (["{tmp}/empty", "--resamples", "0"], "--resamples=0 is invalid"),
        (["{tmp}/empty", "--seed", "x"], "argument --seed: invalid int value: 'x'"),
    ],
)
def test_report_mistakes_are_one_line(argv, words, tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "damaged" / "run").mkdir(parents=True)
    (tmp_path / "damaged" / "run" / "metrics.json").write_text("[]")
    (tmp_path / "damaged" / "run" / "config.yaml").write_text(GOOD_CONFIG)
    with pytest.raises(SystemExit) as refused:
        main([arg.format(tmp=tmp_path) for arg in argv])
    message = str(refused.value.code)
    assert message.startswith("error: ") and "\n" not in message and words in message, message


GOOD_METRICS = json.dumps({"eval/return_ratio": 0.5, "eval/sum_utility": 200.0})
GOOD_CONFIG = yaml.safe_dump(
    {
        "seed": 7,
        "env": {"name": "paper", "preset": "paper", "grid": [6, 6], "num_uavs": 2, "max_steps": 30},
        "eval": {"num_starts": 64, "gamma": 0.9, "horizon": None},
        "agent": {"name": "tabular"},
        "scenario": None,
    }
)
LAUGHS = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join([f'*{chr(97 + i)}'] * 10)}]\n" for i in range(8)
)

# (case, metrics.json, config.yaml, the reason the one-line warning gives); None: the good file
DAMAGED_RUNS = [
    ("truncated metrics", '{"eval/return_ratio": 0.5, "eval/op', None, "metrics.json is not valid JSON"),
    ("empty metrics", "", None, "metrics.json is empty"),
    ("metrics {}", "{}", None, "metrics.json holds none of the report's metrics"),
    ("metrics list", "[0.5, 1.0]", None, "metrics.json holds a list, not an object of metrics"),
    ("metrics string", '{"eval/return_ratio": "0.5"}', None, "metrics.json: eval/return_ratio='0.5' is not a number"),
    ("metrics object", '{"eval/optimality": {"v": 1}}', None, "eval/optimality={'v': 1} is not a number"),
    ("metrics bool", '{"eval/optimality": true}', None, "metrics.json: eval/optimality=true is not a number"),
    ("metrics nested", "[" * 100_000, None, "metrics.json nests deeper than uavrl ever writes"),
    ("metrics 5000 digits", '{"eval/optimality": ' + "9" * 5000 + "}", None, "Exceeds the limit (4300 digits)"),
    ("metrics huge", " " * (1 << 20) + "{}", None, "metrics.json holds 1,048,578 bytes, more than uavrl writes"),
    ("metrics not utf-8", b"\xff\xfe{}", None, "metrics.json is not UTF-8 text"),
    ("metrics fifo", "fifo", None, "metrics.json is a FIFO, not a regular file"),
    (
        "another run's metrics",
        json.dumps({"eval/return_ratio": 0.5, "agent": "dqn", "env": "paper"}),
        None,
        "metrics.json is agent=dqn's, but config.yaml is agent.name=tabular's: it belongs to another run",
    ),
    (
        "another setting's metrics",
        json.dumps({"eval/return_ratio": 0.5, "agent": "tabular", "env": "a2g_urban"}),
        None,
        "metrics.json is env=a2g_urban's, but config.yaml is env.name=paper's: it belongs to another run",
    ),
    ("invalid yaml", None, "seed: [1\nenv: {", "config.yaml is not valid YAML"),
    ("config list", None, "- seed\n- env\n", "config.yaml holds a list, not a mapping of settings"),
    ("empty config", None, "", "config.yaml holds null, not a mapping of settings"),
    ("undefined ${...}", None, GOOD_CONFIG.replace("name: paper", "name: ${nowhere}", 1), "env.name='${nowhere}'"),
    ("${oc.env:HOME}", None, GOOD_CONFIG.replace("preset: paper", "preset: ${oc.env:HOME}"), "is an interpolation"),
    ("seed abc", None, GOOD_CONFIG.replace("seed: 7", "seed: abc"), "config.yaml: seed='abc' is invalid: it must be"),
    ("seed float", None, GOOD_CONFIG.replace("seed: 7", "seed: 7.5"), "config.yaml: seed=7.5 is invalid"),
    ("grid", None, GOOD_CONFIG.replace("- 6\n", "- 0\n", 1), "config.yaml: env.grid=[0, 6] is invalid"),
    ("no env", None, "seed: 1\nagent: {name: dqn}\n", "config.yaml has no env.name"),
    ("bad agent", None, GOOD_CONFIG.replace("name: tabular", "name: '| x |'"), "agent.name='| x |' is invalid"),
    ("python tag", None, "seed: !!python/object/apply:os.system [touch marker]\n", "config.yaml is not valid YAML"),
    ("yaml aliases", None, LAUGHS, "an alias (*name), which uavrl never writes"),
    ("yaml nested", None, "seed: " + "[" * 100_000, "config.yaml nests deeper than uavrl ever writes"),
]


@pytest.mark.parametrize("metrics, config, why", [case[1:] for case in DAMAGED_RUNS], ids=[c[0] for c in DAMAGED_RUNS])
def test_report_skips_a_damaged_run_in_one_line(metrics, config, why, study, tmp_path, monkeypatch, capsys):
    """The study's good runs are reported; the damaged one is named, quoted, with why, on one line of stderr."""
    import os

    bad = study / "damaged run" / "seed=7"
    bad.mkdir(parents=True)
    for name, given, good in (("metrics.json", metrics, GOOD_METRICS), ("config.yaml", config, GOOD_CONFIG)):
        content = good if given is None else given
        if content == "fifo":
            os.mkfifo(bad / name)
        else:
            (bad / name).write_bytes(content if isinstance(content, bytes) else content.encode())
    monkeypatch.chdir(tmp_path)
    main([str(study), "--out", str(tmp_path / "out"), "--resamples", "200"])
    out, err = capsys.readouterr()
    assert out == f"report: {tmp_path / 'out' / 'report.md'} (figures beside it)\n"
    assert err.startswith(f"warning: skipped {shlex.quote(str(bad))}: ") and err.count("\n") == 1, err
    assert why in err, err
    text = (tmp_path / "out" / "report.md").read_text()
    assert "6 runs from" not in text and "9 runs from" in text  # the study's nine, not the damaged one
    assert "| dqn agent.mixer=vdn |" in text and "## rayleigh" in text and "| tabular |" not in text
    skipped = text.split("Skipped")[1].strip().splitlines()[-1]
    assert skipped.startswith(f"- `{bad}`: ") and why in skipped
    assert os.environ["HOME"] not in text and not (tmp_path / "marker").exists()


def test_nan_infinite_and_null_metrics_are_shown_missing(tmp_path):
    root = tmp_path / "study"
    write_run(root / "a", "dqn", 0, {"eval/return_ratio": 0.5, "eval/optimality": float("nan")})
    write_run(root / "b", "dqn", 1, {"eval/return_ratio": float("inf"), "eval/optimality": None})
    write_run(root / "c", "oracle", 0, {"eval/return_ratio": float("-inf"), "eval/sum_utility": float("nan")})
    write_run(root / "d", "random", 0, {})  # beyond float's range: as infinite
    (root / "d" / "metrics.json").write_text('{"eval/return_ratio": 1e400, "eval/optimality": ' + "9" * 400 + "}")
    text = report([root], tmp_path / "out", resamples=200).read_text()
    rows = {line.split(" | ")[0].lstrip("| "): line.split(" | ") for line in text.splitlines() if line.startswith("| ")}
    header = rows["agent"]
    ratio, optimality = header.index("return ratio"), header.index("final U/U*")
    assert rows["dqn"][ratio] == "0.5 (n=1)" and rows["dqn"][optimality] == "-"
    assert rows["oracle (baseline)"][ratio] == "-"
    assert rows["random (baseline)"][ratio] == "-" and rows["random (baseline)"][optimality] == "-"
    table = "\n".join(line for line in text.splitlines() if line.startswith("| ")).lower()
    assert "nan" not in table and "inf" not in table


def test_a_benchmarl_run_is_reported_under_its_algorithm(tmp_path):
    run = tmp_path / "study" / "benchmarl"
    write_run(run, "dqn", 0, {"eval/return_ratio": 0.7, "agent": "benchmarl_qmix"})
    saved = yaml.safe_load((run / "config.yaml").read_text())
    del saved["agent"]
    (run / "config.yaml").write_text(yaml.safe_dump(saved))
    text = report([tmp_path / "study"], tmp_path / "out", resamples=200).read_text()
    assert "| benchmarl_qmix | **1 (0) < 3** | 0.7 |" in text


def laid_out_figures(monkeypatch) -> dict:
    """The report's figures by file name, each drawn as saved (its layout applied), kept open to be inspected."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    import uavrl.experiment.reporting as module

    figures, save = {}, module.save_figure

    def keep(figure, path):
        saved = save(figure, path)
        FigureCanvasAgg(figure).draw()  # pyplot let go of it when saved
        figures[path.name] = figure
        return saved

    monkeypatch.setattr(module, "save_figure", keep)
    return figures


def drawn_inside(figure) -> bool:
    """Whether everything the figure draws (ticks, labels, titles, legends) lies whole inside it: a cut tick label
    or a legend off the edge reaches beyond."""
    drawn, frame = figure.get_tightbbox(figure.canvas.get_renderer()), figure.bbox_inches
    return drawn.x0 >= -0.01 and drawn.y0 >= -0.01 and drawn.x1 <= frame.x1 + 0.01 and drawn.y1 <= frame.y1 + 0.01


def legend_labels(figure) -> list[str]:
    return [text.get_text() for legend in figure.legends for text in legend.get_texts()]


def write_curves(run_dir, values) -> None:
    from uavrl.experiment.logger import RunLogger

    logger = RunLogger(run_dir)
    for step, value in enumerate(values, start=1):
        logger.log({"train/sum_utility": value}, 100 * step)
    logger.close()


def test_report_figures_fit_with_a_legend_and_no_warning(tmp_path, monkeypatch):
    """Long agent labels, one- and two-seed cells and three baselines: every label inside the figure, one legend
    naming each agent with its seeds (singular for one), every baseline drawn, every value inside the y-limits, a
    curves title that promises only what is drawn, and no warning (matplotlib's tight_layout gave up on such labels,
    cutting them)."""
    root = tmp_path / "study"
    long = {"mixer": "qmix", "objective": "utility", "gamma": 0.7}
    for seed, ratio in enumerate([0.5, 0.55]):
        write_run(root / f"long{seed}", "dqn", seed, {"eval/return_ratio": ratio, "eval/optimality": 0.95}, long)
        write_curves(root / f"long{seed}", [210.0 + seed, 240.0, 300.0])
    write_run(root / "vdn", "dqn", 0, {"eval/return_ratio": 0.9, "eval/optimality": 0.99}, {**long, "mixer": "vdn"})
    write_curves(root / "vdn", [200.0, 330.0])
    for agent, ratio in (("oracle", 1.0), ("planner", 0.99), ("random", -0.02)):
        write_run(root / agent, agent, 0, {"eval/return_ratio": ratio, "eval/optimality": ratio})
    figures = laid_out_figures(monkeypatch)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report([root], tmp_path / "out", resamples=200)
    metrics, curves = figures["paper_metrics.png"], figures["paper_curves.png"]
    assert drawn_inside(metrics) and drawn_inside(curves)
    labels = legend_labels(metrics)
    assert "dqn agent.mixer=qmix (2 seeds)" in labels and "dqn agent.mixer=vdn (1 seed)" in labels
    assert {"oracle (baseline, 1 seed)", "planner (baseline, 1 seed)", "random (baseline, 1 seed)"} <= set(labels)
    for ax in metrics.axes:
        low, high = ax.get_ylim()
        values = [y for line in ax.get_lines() for y in line.get_ydata()]
        assert values and all(low < y < high for y in values)  # none on an edge, hidden by the frame
        assert len([line for line in ax.get_lines() if "baseline" in line.get_label()]) == 3
    assert "dqn agent.mixer=vdn (1 seed)" in legend_labels(curves)
    (ax,) = curves.axes
    legend = curves.legends[0].get_window_extent()
    assert not legend.overlaps(ax.get_window_extent())  # the legend covers no curve
    assert "lines: the baselines' greedy evaluation" in ax.get_title()  # eval/sum_utility: write_run's 200


def test_the_curves_title_names_no_baseline_lines_when_none_is_drawn(tmp_path, monkeypatch):
    root = tmp_path / "study"
    write_run(root / "dqn", "dqn", 0, {"eval/return_ratio": 0.5})
    write_curves(root / "dqn", [200.0, 300.0])
    figures = laid_out_figures(monkeypatch)
    report([root], tmp_path / "out", resamples=200)
    title = figures["paper_curves.png"].axes[0].get_title()
    assert (
        "lines" not in title and "band" not in title and legend_labels(figures["paper_curves.png"]) == ["dqn (1 seed)"]
    )
