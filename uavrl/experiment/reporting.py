"""The report command's body (``python -m uavrl.report``, :mod:`uavrl.report`): a study's runs read, grouped and
summarized in ``report.md`` and its figures.

Each cell's seeds give the mean of each yardstick metric with a 95% percentile-bootstrap confidence interval (numpy,
a fixed seed: the same runs give the same report) and, with 5 seeds or more, the interquartile mean; a run whose
files cannot be used is skipped with a warning (the command's doc, :mod:`uavrl.report`, says which).

Example:
    >>> iqm([1.0, 2.0, 3.0, 4.0, 100.0])
    3.0
    >>> bootstrap_ci([0.0, 1.0], resamples=1000, seed=0)
    (0.0, 1.0)
"""

from __future__ import annotations

import json
import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from uavrl.envs.limits import default_horizon
from uavrl.envs.rules import Rule, rules_of, shown, whole
from uavrl.experiment.io import (
    EVENTS,
    DamagedRun,
    Manifest,
    make_dirs,
    quoted,
    read_small_text,
    save_text,
    special_kind,
)
from uavrl.experiment.plots import pyplot, save_figure
from uavrl.experiment.runs import BASELINE_AGENTS, flat_settings
from uavrl.experiment.saved import SavedYamlLoader
from uavrl.schema import RunSchema

# the yardstick first (agents/evaluation.py), then the paper's final utility and the cost
METRICS = {
    "eval/return_ratio": "return ratio",
    "eval/reach_999": "reach 0.999 U*",
    "eval/steps_to_999": "steps to 0.999 U*",
    "eval/step_ratio_999": "steps / fewest (0.999 U*)",
    "eval/optimality": "final U/U*",
    # a mission under an energy model (docs/model.md, What the numbers mean); missing for env.energy=none
    "eval/delivered_bit_per_hz": "delivered bit/Hz",
    "eval/delivered_ratio": "delivered / bound",
    "eval/first_leave_steps": "first leaves (step)",
    "eval/service_lost_steps": "service lost (step)",
    "eval/energy_per_bit": "energy per bit",
    "train_seconds": "training s",
}
CONFIDENCE = 0.95
FEW_SEEDS = 3  # cells with fewer seeds are flagged
IQM_SEEDS = 5  # the interquartile mean is shown from this many seeds on
# settings that never change a run's results (or are the seed itself): not used to tell runs apart
IGNORED = {
    "seed",
    "run_dir",
    "sweep_dir",
    "resume",
    "checkpoint",
    "print_json",
    "progress",
    "num_threads",
    "train.checkpoint_every",
}
CURVE_TAG = "train/sum_utility"  # per training episode; divided by env.max_steps: utility per step


def iqm(values) -> float:
    """Interquartile mean: the mean of the values left after dropping the lowest and highest 25% (as
    ``scipy.stats.trim_mean(values, 0.25)``: ``floor(n / 4)`` values from each end)."""
    ordered = np.sort(np.asarray(values, dtype=float))
    cut = len(ordered) // 4
    return float(ordered[cut : len(ordered) - cut].mean())


def bootstrap_ci(values, resamples: int = 10_000, seed: int = 0, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean: ``resamples`` draws of ``n`` values with replacement, the
    ``(1 - confidence) / 2`` and ``(1 + confidence) / 2`` quantiles (numpy's linear) of their means.  NaN for one
    value.

    Args:
        values: the values, one per seed.
        resamples: the bootstrap's draws.
        seed: seeds the draws.
        confidence: the interval's coverage.

    Example:
        >>> low, high = bootstrap_ci([1.0, 2.0, 3.0, 4.0], resamples=1000, seed=0)
        >>> low < 2.5 < high
        True
    """
    values = np.asarray(values, dtype=float)
    if len(values) < 2:
        return float("nan"), float("nan")
    draws = np.random.default_rng(seed).integers(0, len(values), size=(resamples, len(values)))
    means = values[draws].mean(axis=1)
    low, high = np.quantile(means, [(1 - confidence) / 2, (1 + confidence) / 2])
    return float(low), float(high)


def bootstrap_band(curves: np.ndarray, resamples: int = 2_000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Pointwise percentile-bootstrap band of the mean of ``curves`` ``[seeds, points]``; NaN for one curve.

    Args:
        curves: one curve per seed, ``[seeds, points]``.
        resamples: the bootstrap's draws.
        seed: seeds the draws.

    Returns:
        The band's low and high edges, ``[points]`` each.
    """
    if len(curves) < 2:
        nan = np.full(curves.shape[1], np.nan)
        return nan, nan
    draws = np.random.default_rng(seed).integers(0, len(curves), size=(resamples, len(curves)))
    means = curves[draws].mean(axis=1)
    return tuple(np.quantile(means, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2], axis=0))


@dataclass
class Run:
    path: Path
    config: dict  # flat: dotted setting -> value, as saved (never resolved)
    metrics: dict  # metric -> finite float; a NaN, infinite or null metric is missing
    agent: str  # agent.name, or for a BenchMARL run its metrics' "agent" (benchmarl_<algorithm>)

    @property
    def seed(self) -> int:
        return self.config["seed"]

    @property
    def setting(self) -> str:
        return self.config.get("scenario.name") or self.config["env.name"]


@dataclass
class Cell:
    setting: str
    agent: str  # the agent's name and what tells its runs apart
    runs: list[Run] = field(default_factory=list)

    @property
    def is_baseline(self) -> bool:
        return self.runs[0].agent in BASELINE_AGENTS

    def values(self, metric: str) -> list[float]:
        return [run.metrics[metric] for run in self.runs if metric in run.metrics]


NAME = Rule(
    lambda v: isinstance(v, str) and re.fullmatch(r"[A-Za-z0-9_.+-]+", v) is not None,
    "it must be a name of letters, digits and _ . + -",
)
GRID = Rule(
    lambda v: isinstance(v, tuple) and len(v) > 0 and all(whole(1).accepts(g) for g in v),
    "it must be a list of whole numbers >= 1, e.g. [6, 6]",
)
RUN = rules_of(RunSchema)
# what the report reads of a run's config.yaml: the grouping, the setting's description, the curves' scale
REQUIRED_SETTINGS: dict[str, Rule] = {
    "seed": RUN["seed"],
    "env.name": NAME,
    "env.preset": NAME,
    "env.grid": GRID,
    "env.num_uavs": whole(1),
    "env.max_steps": whole(1),
    "eval.num_starts": RUN["eval.num_starts"],
    "eval.gamma": RUN["eval.gamma"],
}
OPTIONAL_SETTINGS: dict[str, Rule] = {
    "eval.horizon": RUN["eval.horizon"],
    "scenario.name": NAME,
    "agent.name": NAME,
}


def brief(value) -> str:
    """A value as typed (:func:`uavrl.envs.rules.shown`), cut to 60 characters for a one-line message."""
    text = shown(value)
    return text if len(text) <= 60 else text[:57] + "..."


def kind(value) -> str:
    return {list: "a list", dict: "an object", str: "a string", bool: "true or false", type(None): "null"}.get(
        type(value), "a number"
    )


def strings(value):
    """Every string in a value read from YAML."""
    if isinstance(value, str):
        yield value
    elif isinstance(value, (list, tuple)):
        for item in value:
            yield from strings(item)
    elif isinstance(value, dict):
        for item in value.values():
            yield from strings(item)


def read_config(path: Path) -> dict:
    """A saved ``config.yaml``, flat, as written: an interpolation (``${...}``) is refused, never resolved."""
    text = read_small_text(path)
    try:
        data = yaml.load(text, Loader=SavedYamlLoader)
    except yaml.MarkedYAMLError as err:
        where = f" at line {err.problem_mark.line + 1}" if err.problem_mark else ""
        raise DamagedRun(f"config.yaml is not valid YAML ({' '.join(str(err.problem).split())}{where})") from None
    except RecursionError:
        raise DamagedRun("config.yaml nests deeper than uavrl ever writes") from None
    except yaml.YAMLError as err:
        raise DamagedRun(f"config.yaml is not valid YAML ({' '.join(str(err).split())})") from None
    if not isinstance(data, dict):
        raise DamagedRun(f"config.yaml holds {kind(data)}, not a mapping of settings")
    config = {name: tuple(v) if isinstance(v, list) else v for name, v in flat_settings(data).items()}
    for name, value in config.items():
        if any("${" in text for text in strings(value)):
            raise DamagedRun(
                f"config.yaml: {name}={brief(value)} is an interpolation, which uavrl never saves (its configs are "
                "resolved): not resolved"
            )
    return config


def read_metrics(path: Path) -> tuple[dict, object]:
    """The report's metrics of a saved ``metrics.json`` as finite floats (NaN, infinite and null ones left out) and
    the agent and setting it names (``{"agent": ..., "env": ...}``, None where it names none)."""
    text = read_small_text(path)
    if not text.strip():
        raise DamagedRun("metrics.json is empty")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise DamagedRun(
            f"metrics.json is not valid JSON, truncated or damaged ({err.msg} at line {err.lineno})"
        ) from None
    except RecursionError:
        raise DamagedRun("metrics.json nests deeper than uavrl ever writes") from None
    except ValueError as err:  # an integer of over 4,300 digits
        raise DamagedRun(f"metrics.json cannot be read ({str(err).split(':')[0]})") from None
    if not isinstance(data, dict):
        raise DamagedRun(f"metrics.json holds {kind(data)}, not an object of metrics")
    if not any(name in data for name in METRICS):
        raise DamagedRun(f"metrics.json holds none of the report's metrics ({', '.join(METRICS)})")
    metrics = {}
    for name in (*METRICS, "eval/sum_utility", "eval/horizon"):
        value = data.get(name)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise DamagedRun(f"metrics.json: {name}={brief(value)} is not a number")
        try:
            number = float(value)
        except OverflowError:  # a JSON integer beyond float's range
            continue
        if math.isfinite(number):
            metrics[name] = number
    return metrics, {"agent": data.get("agent"), "env": data.get("env")}


def checked(config: dict, rules: dict[str, Rule], required: bool) -> None:
    for name, rule in rules.items():
        if name not in config:
            if required:
                raise DamagedRun(f"config.yaml has no {name} (not the config.yaml of a uavrl run)")
            continue
        if not rule.accepts(config[name]):
            raise DamagedRun(f"config.yaml: {name}={brief(config[name])} is invalid: {rule.allowed}")


def load_run(run_dir: Path) -> Run:
    """The run in ``run_dir``; :class:`DamagedRun` when its files cannot be used."""
    metrics, named = read_metrics(run_dir / "metrics.json")
    config = read_config(run_dir / "config.yaml")
    for name in ("agent", "env"):  # a run's metrics name its agent and setting: another run's metrics.json is refused
        if isinstance(named[name], str) and config.get(f"{name}.name", named[name]) != named[name]:
            raise DamagedRun(
                f"metrics.json is {name}={named[name]}'s, but config.yaml is {name}.name={config[name + '.name']}'s: "
                "it belongs to another run"
            )
    for events in sorted(run_dir.glob(EVENTS)):  # the curves' files: a FIFO would block TensorBoard's reader
        if special_kind(events) is not None:
            raise DamagedRun(f"{events.name} is {special_kind(events)}, not a regular file")
    checked(config, REQUIRED_SETTINGS, required=True)
    checked(config, OPTIONAL_SETTINGS, required=False)
    agent = config.get("agent.name", named["agent"])
    if not NAME.accepts(agent):
        where = "metrics.json: agent" if "agent.name" not in config else "config.yaml: agent.name"
        raise DamagedRun(f"{where}={brief(agent)} is invalid: {NAME.allowed}")
    return Run(run_dir, config, metrics, agent)


def find_runs(paths) -> tuple[list[Run], list[tuple[Path, str]]]:
    """Every run directory (one holding ``metrics.json`` and ``config.yaml``) under ``paths``, in path order, and
    those skipped with why."""
    runs, skipped = [], []
    for path in paths:
        given = Path(path)
        if not given.is_dir():
            raise FileNotFoundError(f"{quoted(given)}: no such directory (give run directories or sweep directories)")
        for metrics_file in sorted(given.rglob("metrics.json")):
            run_dir = metrics_file.parent
            if not (run_dir / "config.yaml").exists():
                continue  # not a run directory of uavrl.train
            try:
                runs.append(load_run(run_dir))
            except DamagedRun as err:
                skipped.append((run_dir, str(err)))
    return runs, skipped


def differing(runs: list[Run], keep) -> list[str]:
    """The settings (``keep(name)`` true) whose values are not the same in all ``runs``."""
    names = sorted({name for run in runs for name in run.config if keep(name) and name not in IGNORED})
    return [name for name in names if len({repr(run.config.get(name)) for run in runs}) > 1]


def group(runs: list[Run]) -> dict[str, list[Cell]]:
    """Cells by setting; within a setting, by agent and the settings that differ between that agent's runs."""
    by_setting: dict[str, list[Run]] = {}
    for run in runs:
        by_setting.setdefault(run.setting, []).append(run)
    cells = {}
    for setting, setting_runs in by_setting.items():
        # model and evaluation settings that differ split the setting (env.max_steps is an agent's training budget)
        split = differing(setting_runs, lambda n: n.startswith(("env.", "eval.")) and n != "env.max_steps")
        by_cell: dict[tuple, Cell] = {}
        for run in setting_runs:
            label = " ".join([setting, *(f"{n}={shown(run.config.get(n), label=True)}" for n in split)])
            same_agent = [r for r in setting_runs if r.agent == run.agent]
            variant = differing(same_agent, lambda n: not n.startswith(("env.", "eval.")) or n == "env.max_steps")
            agent = " ".join([run.agent, *(f"{n}={shown(run.config.get(n), label=True)}" for n in variant)])
            by_cell.setdefault((label, agent), Cell(label, agent)).runs.append(run)
        for (label, _), cell in by_cell.items():
            cells.setdefault(label, []).append(cell)
    for label in cells:  # learners first, then the baselines; each by name
        cells[label].sort(key=lambda c: (c.is_baseline, c.agent))
        for cell in cells[label]:
            cell.runs.sort(key=lambda r: (r.seed, str(r.path)))
    return dict(sorted(cells.items()))


def summary(values: list[float], resamples: int, seed: int) -> str:
    """``mean [low, high]`` (and ``IQM x`` from 5 values); ``-`` without values.

    Args:
        values: one value per seed.
        resamples: the bootstrap's resamples (:func:`bootstrap_ci`).
        seed: seeds the bootstrap.

    Example:
        >>> summary([0.9, 1.0], resamples=1000, seed=0)
        '0.95 [0.9, 1]'
    """
    if not values:
        return "-"
    low, high = bootstrap_ci(values, resamples, seed)
    text = f"{np.mean(values):.4g}" + ("" if np.isnan(low) else f" [{low:.4g}, {high:.4g}]")
    if len(values) >= IQM_SEEDS:
        text += f"; IQM {iqm(values):.4g}"
    return text


def seeds_cell(cell: Cell) -> str:
    seeds = [run.seed for run in cell.runs]
    text = f"{len(seeds)} ({', '.join(map(str, seeds))})"
    return f"**{text} < {FEW_SEEDS}**" if len(seeds) < FEW_SEEDS else text


def table(cells: list[Cell], resamples: int, seed: int) -> list[str]:
    lines = [
        "| agent | seeds | " + " | ".join(METRICS.values()) + " |",
        "|---|---|" + "---|" * len(METRICS),
    ]
    for cell in cells:
        row = [cell.agent + (" (baseline)" if cell.is_baseline else ""), seeds_cell(cell)]
        for metric in METRICS:
            values = cell.values(metric)
            text = summary(values, resamples, seed)
            if values and len(values) < len(cell.runs):
                text += f" (n={len(values)})"  # the metric exists only where a start reached the level
            row.append(text)
        lines.append("| " + " | ".join(row) + " |")
    return lines


def describe(run: Run) -> str:
    c = run.config
    grid = "x".join(map(str, c["env.grid"]))
    parts = [f"{grid} grid, {c['env.num_uavs']} UAVs, preset {c['env.preset']}"]
    parts += [f"{key} {c[f'env.{key}']}" for key in ("layout", "fading") if c.get(f"env.{key}") is not None]
    parts.append(f"evaluation: {c['eval.num_starts']} starts, gamma {c['eval.gamma']}")
    return "; ".join(parts)


def curves(cell: Cell) -> tuple[np.ndarray, np.ndarray] | None:
    """Team steps and ``[seeds, points]`` utility per step of the training episodes, on the first run's steps."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    series = []
    for run in cell.runs:
        events = EventAccumulator(str(run.path), size_guidance={"scalars": 0})
        events.Reload()
        if CURVE_TAG not in events.Tags()["scalars"]:
            continue
        points = events.Scalars(CURVE_TAG)
        steps = np.array([p.step for p in points], dtype=float)
        series.append((steps, np.array([p.value for p in points]) / run.config["env.max_steps"]))
    if not series:
        return None
    steps = series[0][0]
    return steps, np.stack([np.interp(steps, s, v) for s, v in series])


def file_stem(label: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in label)


def seeds_count(n: int) -> str:
    """``1 seed``, ``2 seeds``."""
    return f"{n} seed" if n == 1 else f"{n} seeds"


# the baselines' reference lines: (line style, colour), one per baseline in name order
BASELINE_STYLES = (("--", "black"), (":", "black"), ("-.", "0.45"), ((0, (6, 2, 1, 2, 1, 2)), "0.45"))


def baseline_lines(ax, cells: list[Cell], value) -> list:
    """The baselines' mean of ``value(run)`` as reference lines (every baseline, each its own style); the lines
    drawn, labelled with the baseline and its seeds."""
    drawn = []
    for i, cell in enumerate(c for c in cells if c.is_baseline):
        values = [value(run) for run in cell.runs if value(run) is not None]
        if values:
            style, colour = BASELINE_STYLES[i % len(BASELINE_STYLES)]
            label = f"{cell.agent} (baseline, {seeds_count(len(cell.runs))})"
            drawn.append(ax.axhline(np.mean(values), linestyle=style, color=colour, linewidth=1.2, label=label))
    return drawn


def legend_columns(handles, most: int) -> int:
    """Columns of a legend under the figure: one where a label is long (it would run off the figure), else ``most``
    at most."""
    longest = max((len(h.get_label()) for h in handles), default=0)
    return 1 if longest > 40 else max(1, min(len(handles), most))


def padded_limits(values: list[float]) -> tuple[float, float]:
    """Axis limits that hold every value with a margin (a line on an edge is hidden by the frame)."""
    low, high = min(values), max(values)
    pad = 0.08 * (high - low) if high > low else 0.05 * max(abs(high), 1.0)
    return low - pad, high + pad


def metrics_figure(label: str, cells: list[Cell], out: Path, resamples: int, seed: int) -> Path | None:
    """Per metric, one panel: each learner's seeds (grey) and mean with its interval (its colour), the baselines'
    means as lines; one legend for the figure below the panels, naming every agent with its seeds.  None, and no
    figure, where no run has a metric to plot (each NaN, infinite or null)."""
    from matplotlib.lines import Line2D

    learners = [c for c in cells if not c.is_baseline]
    plotted = [m for m in METRICS if m != "train_seconds" and any(c.values(m) for c in cells)]
    if not plotted:
        return None
    columns = min(len(plotted), 4)
    rows = -(-len(plotted) // columns)
    figure, axes = pyplot().subplots(
        rows, columns, figsize=(max(3.1 * columns, 6.4), 2.5 * rows + 1.2), squeeze=False, layout="constrained"
    )
    baselines_drawn: dict[str, Line2D] = {}
    for ax, metric in zip(axes.flat, plotted, strict=False):
        shown_values = []
        for x, cell in enumerate(learners):
            values = cell.values(metric)
            if not values:
                continue
            low, high = bootstrap_ci(values, resamples, seed)
            mean = float(np.mean(values))
            ax.plot([x] * len(values), values, "o", color="0.6", markersize=3)  # the seeds
            error = None if np.isnan(low) else [[mean - low], [high - mean]]
            ax.errorbar([x], [mean], yerr=error, fmt="s", color=f"C{x}", capsize=4)
            shown_values += [*values, *([] if np.isnan(low) else [low, high])]
        for line in baseline_lines(ax, cells, lambda run, metric=metric: run.metrics.get(metric)):
            baselines_drawn.setdefault(line.get_label(), line)
            shown_values.append(line.get_ydata()[0])
        ax.set_xticks([])  # the legend names the agents by colour
        ax.set_xlim(-0.6, max(len(learners), 1) - 0.4)
        ax.set_ylim(*padded_limits(shown_values))
        ax.set_title(METRICS[metric], fontsize=10)
        ax.tick_params(labelsize=8)
    for ax in axes.flat[len(plotted) :]:
        ax.set_axis_off()
    handles = [
        Line2D([], [], marker="s", linestyle="", color=f"C{x}", label=f"{cell.agent} ({seeds_count(len(cell.runs))})")
        for x, cell in enumerate(learners)
    ]
    if learners:
        handles.append(Line2D([], [], marker="o", linestyle="", color="0.6", markersize=3, label="one seed"))
    handles += sorted(baselines_drawn.values(), key=lambda line: line.get_label())
    figure.legend(
        handles=handles, loc="outside lower center", ncol=legend_columns(handles, 3), fontsize=8, frameon=False
    )
    what = "mean over seeds with its 95% bootstrap interval" if learners else "the baselines' mean over seeds"
    figure.suptitle(f"{label}: {what}", fontsize=10)
    return save_figure(figure, out / f"{file_stem(label)}_metrics.png")


def eval_horizon(run: Run) -> int:
    """The evaluation's steps per rollout: ``eval.horizon``, the mission's (``eval/horizon``, an energy model), or
    :func:`uavrl.envs.limits.default_horizon`."""
    return run.config.get("eval.horizon") or run.metrics.get("eval/horizon") or default_horizon(run.config["env.grid"])


def evaluated_utility_per_step(run: Run) -> float | None:
    utility = run.metrics.get("eval/sum_utility")
    return None if utility is None else utility / eval_horizon(run)


def curves_figure(label: str, cells: list[Cell], out: Path, seed: int) -> Path | None:
    drawn = [(cell, curves(cell)) for cell in cells if not cell.is_baseline]
    drawn = [(cell, found) for cell, found in drawn if found is not None]
    if not drawn:
        return None
    figure, ax = pyplot().subplots(figsize=(7, 4.8), layout="constrained")
    banded = False
    for x, (cell, (steps, values)) in enumerate(drawn):
        low, high = bootstrap_band(values, seed=seed)
        ax.plot(steps, values.mean(axis=0), color=f"C{x}", label=f"{cell.agent} ({seeds_count(len(values))})")
        if not np.isnan(low).all():
            ax.fill_between(steps, low, high, color=f"C{x}", alpha=0.25)
            banded = True
    lines = baseline_lines(ax, cells, evaluated_utility_per_step)
    ax.set_xlabel("team steps")
    ax.set_ylabel("utility per step (bit/s/Hz)")
    handles, labels = ax.get_legend_handles_labels()
    figure.legend(
        handles, labels, loc="outside lower center", ncol=legend_columns(handles, 2), fontsize=8, frameon=False
    )
    what = "mean over seeds" + (" with its 95% bootstrap band" if banded else "")
    baselines = "; lines: the baselines' greedy evaluation" if lines else ""
    ax.set_title(
        f"{label}: utility per step of the training episodes (exploration included),\n{what}{baselines}", fontsize=9
    )
    return save_figure(figure, out / f"{file_stem(label)}_curves.png")


def claim_report_files(out: Path, stems: list[str]) -> None:
    """Record the files this report writes into ``out`` (``.uavrl-written.json``): a ``report.md`` or figure of
    those names that uavrl did not write there is refused (FileExistsError), never overwritten.  A folder an earlier
    uavrl reported into (its ``report.md`` and no record) is taken to hold report's files under their names."""
    import os

    names = ["report.md", *(f"{stem}_{kind}.png" for stem in stems for kind in ("metrics", "curves"))]
    if os.path.lexists(out) and not out.is_dir():
        raise NotADirectoryError(f"--out={quoted(out)} is {special_kind(out) or 'a file'}, not a directory")
    manifest = Manifest(out, "--out", ".uavrl-report-files.json")
    earlier = out / "report.md"
    if not os.path.lexists(manifest.path) and earlier.is_file():
        with open(earlier, "rb") as file:
            if file.read(len(REPORT_TITLE)) == REPORT_TITLE:
                found = [out / "report.md", *out.glob("*_metrics.png"), *out.glob("*_curves.png")]
                manifest.files = {manifest._name(path) for path in found if path.is_file()}
    paths = [out / name for name in names]
    manifest.check_writable(paths)
    make_dirs(out)
    manifest.record(*paths)


REPORT_TITLE = b"# Study report\n"


def report(paths, out, resamples: int = 10_000, seed: int = 0) -> Path:
    """Write ``report.md`` and the figures to ``out``; returns the path of ``report.md``.

    Args:
        paths: run directories, or folders searched for them (a run directory holds ``metrics.json`` and
            ``config.yaml``); damaged ones are skipped with a warning, none at all is a one-line error.
        out: the folder the report and its figures are written to.
        resamples: the bootstrap's resamples for each interval.
        seed: seeds the bootstrap.
    """
    out = Path(out)
    runs, skipped = find_runs(paths)
    if not runs and len(skipped) == 1:  # the one run given: why it cannot be reported is the whole error
        raise DamagedRun(f"{quoted(skipped[0][0])}: {skipped[0][1]}; no other run to report")
    for run_dir, why in skipped:
        print(f"warning: skipped {quoted(run_dir)}: {why}", file=sys.stderr)
    if not runs:
        damaged = f" ({len(skipped)} with damaged files, skipped)" if skipped else ""
        raise FileNotFoundError(
            f"no run directory (with metrics.json and config.yaml) under {' '.join(quoted(p) for p in paths)}{damaged}"
        )
    cells = group(runs)
    claim_report_files(out, [file_stem(label) for label in cells])
    lines = [
        "# Study report",
        "",
        f"{len(runs)} runs from {', '.join(map(str, paths))}. Each cell: mean over seeds with its 95% "
        f"percentile-bootstrap interval in brackets ({resamples:,} resamples, seed {seed}); from {IQM_SEEDS} "
        f"seeds on, also the interquartile mean (IQM). Seed counts below {FEW_SEEDS} are in bold: their interval is "
        "not to be trusted (with one seed there is none). `(n=k)`: the metric exists for k seeds only (steps are "
        "counted over the starts that reach the level). The yardstick's metrics are described in docs/yardstick.md "
        "(What is measured); random, oracle and planner are the baselines.",
    ]
    for label, setting_cells in cells.items():
        lines += ["", f"## {label}", "", describe(setting_cells[0].runs[0]), "", *table(setting_cells, resamples, seed)]
        figure = metrics_figure(label, setting_cells, out, resamples, seed)
        if figure is None:
            lines += ["", "No metric to plot: each is NaN, infinite or null in these runs' metrics.json."]
        else:
            lines += ["", f"![{label}: metrics]({figure.name})"]
        curve_figure = curves_figure(label, setting_cells, out, seed)
        if curve_figure is not None:
            lines += ["", f"![{label}: learning curves]({curve_figure.name})"]
    lines += ["", "Runs:", "", *(f"- `{run.path}`" for cell in cells.values() for c in cell for run in c.runs)]
    if skipped:
        lines += ["", "Skipped (their files cannot be used):", "", *(f"- `{path}`: {why}" for path, why in skipped)]
    path = out / "report.md"
    save_text("\n".join(lines) + "\n", path)
    return path
