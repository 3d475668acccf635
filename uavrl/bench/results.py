"""A suite's results file: versioned JSON, with a Markdown table and a figure beside it.

The JSON (``format`` ``uavrl-bench-results``, ``version`` :data:`VERSION`) holds the suite, the submission (its name,
the command or call that produced it, the training budget its submitter stated), one entry per task (its spec and
start seed, the per-start raw values and normalised scores per training run, the evaluation's metrics, the
references: the per-start reference and random values, U*, the fewest steps or their bound, the mission's optimum
or bound), the aggregate (:mod:`uavrl.bench.stats`), and the uavrl, torch and torchrl versions and the hardware.
"""

from __future__ import annotations

import json
import platform
from pathlib import Path

import uavrl
from uavrl.experiment.io import save_text
from uavrl.experiment.plots import pyplot, save_figure

FORMAT, VERSION = "uavrl-bench-results", 1


def environment() -> dict:
    """Versions and hardware the results were computed with."""
    import os

    import tensordict
    import torch
    import torchrl

    return {
        "uavrl": uavrl.__version__,
        "torch": torch.__version__,
        "torchrl": torchrl.__version__,
        "tensordict": tensordict.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "device": "cpu",
    }


def new_results(suite: str, name: str, budget: dict, source: str, partial: bool = False) -> dict:
    """An empty results file of ``suite`` for the submission ``name`` (tasks are appended as they are scored)."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "suite": suite,
        "protocol": "partial: a subset of the suite's tasks" if partial else "full",
        "submission": {"name": name, "source": source, "budget": budget},
        "environment": environment(),
        "tasks": [],
    }


def read(path) -> dict:
    """The results file at ``path``, refused in one line when it is not one this version reads."""
    try:
        results = json.loads(Path(path).read_text())
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: not a readable results file ({err})") from None
    if not isinstance(results, dict) or results.get("format") != FORMAT:
        raise ValueError(f"{path}: not a uavrl benchmark results file (no format {FORMAT!r})")
    if results.get("version") != VERSION:
        raise ValueError(f"{path}: results version {results.get('version')!r}, this uavrl reads version {VERSION}")
    return results


def _budget_words(budget: dict) -> str:
    parts = []
    if budget.get("env_steps") is not None:
        parts.append(f"{int(budget['env_steps']):,} env steps")
    if budget.get("cpu_seconds") is not None:
        parts.append(f"{float(budget['cpu_seconds']):,.0f} CPU s")
    if budget.get("gpu_seconds") is not None:
        parts.append(f"{float(budget['gpu_seconds']):,.0f} GPU s")
    return ", ".join(parts) or "not stated"


def interval(value: float, ci) -> str:
    """``0.912 [0.887, 0.934]``."""
    return f"{value:.3f} [{ci[0]:.3f}, {ci[1]:.3f}]"


def markdown(results: dict) -> str:
    """The results as a Markdown table: one row per task, then the aggregate."""
    sub = results["submission"]
    lines = [
        f"**{sub['name']}** on suite `{results['suite']}` ({results['protocol']} protocol); budget: "
        f"{_budget_words(sub['budget'])}; `{sub['source']}`",
        "",
        "| task | score (0 random, 1 reference) | reference | value | U / U* | reach 0.999 U* | steps / fewest |",
        "|---|---|---|---|---|---|---|",
    ]
    for task in results["tasks"]:
        ref = task["references"]["reference"]["kind"]
        if task["status"] != "scored":
            lines.append(f"| {task['task']} | n/a | {ref} | {task['reason']} | | | |")
            continue
        s = task["summary"]
        mean_value = sum(v for run in task["values"] for v in run) / sum(len(run) for run in task["values"])
        steps = f"{s['eval/step_ratio_999']:.2f}" if "eval/step_ratio_999" in s else "-"
        fewest = "" if task["references"]["min_steps_exact"] else " (bound)"
        lines.append(
            f"| {task['task']} | {task['mean_score']:.3f} | {ref} | {mean_value:.4g} | {s['eval/optimality']:.3f} | "
            f"{s['eval/reach_999']:.3f} | {steps}{fewest} |"
        )
    agg = results.get("aggregate", {})
    if agg.get("tasks"):
        lines += [
            "",
            f"Over {len(agg['tasks'])} tasks x {agg['rows']} starts: IQM {interval(agg['iqm'], agg['iqm_ci'])}, "
            f"mean {interval(agg['mean'], agg['mean_ci'])}, median {interval(agg['median'], agg['median_ci'])}, "
            f"optimality gap {interval(agg['optimality_gap'], agg['optimality_gap_ci'])} "
            f"({agg['confidence']:.0%} stratified bootstrap CIs, {agg['reps']} replications, rliable).",
        ]
    return "\n".join(lines) + "\n"


def figure(results_list: list[dict], path) -> None:
    """Per task the mean normalised score of each results file, and the performance profiles (score distributions
    with their CIs), side by side, as a PNG: one colour per results file in both panels, one legend under them (with
    each file's IQM), n/a where a policy cannot act."""
    from matplotlib.patches import Patch

    plt = pyplot()
    count = len(results_list)
    colours = plt.get_cmap("tab10" if count <= 10 else "tab20")
    fig = plt.figure(figsize=(11, 4.4 + 0.16 * count), layout="constrained")
    bars, profile = fig.subplots(1, 2, width_ratios=[3, 2])
    names = list(dict.fromkeys(t["task"] for r in results_list for t in r["tasks"]))
    width = 0.8 / max(1, count)
    handles = []
    for k, results in enumerate(results_list):
        colour, label = colours(k % colours.N), results["submission"]["name"]
        by_task = {t["task"]: t for t in results["tasks"]}
        for i, name in enumerate(names):
            task = by_task.get(name, {})
            if task.get("status") == "scored":
                bars.bar(i + k * width, task["mean_score"], width=width, color=colour)
            elif task.get("status") == "n/a":  # a task it cannot act in: said where its bar would be
                bars.text(i + k * width, 0.02, "n/a", ha="center", va="bottom", fontsize=6, color=colour, rotation=90)
        agg = results.get("aggregate", {})
        if agg.get("profile"):
            p = agg["profile"]
            scored = len(agg["tasks"])
            label += f" (IQM {agg['iqm']:.2f}{'' if scored == len(names) else f' over {scored} of {len(names)} tasks'})"
            profile.plot(p["taus"], p["fraction"], color=colour)
            profile.fill_between(p["taus"], p["ci_low"], p["ci_high"], color=colour, alpha=0.15)
        handles.append(Patch(color=colour, label=label))
    bars.set_xticks([i + width * (count - 1) / 2 for i in range(len(names))], names, rotation=30, ha="right")
    bars.set_xlim(-0.6, len(names) - 0.4 + width * (count - 1))  # every task's place, scored or not
    bars.axhline(1.0, color="grey", lw=0.8, ls="--")
    bars.axhline(0.0, color="grey", lw=0.8)
    bars.set_ylabel("normalised score (0 random, 1 reference)")
    bars.set_title(f"suite {results_list[0]['suite']}: mean score per task")
    profile.set_xlabel("normalised score threshold tau")
    profile.set_ylabel("fraction of (start, task) with score > tau")
    profile.set_title("performance profile (95% CI)")
    if not profile.lines:
        profile.text(0.5, 0.5, "no task scored", ha="center", va="center", transform=profile.transAxes)
    fig.legend(handles=handles, loc="outside lower center", ncol=2 if count > 1 else 1, fontsize=7, frameon=False)
    save_figure(fig, Path(path))


def save(results: dict, path) -> list[Path]:
    """Write ``path`` (the JSON) and beside it ``.md`` (the table) and ``.png`` (the figure); the paths written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_text(json.dumps(results, indent=1, sort_keys=True) + "\n", path)  # atomic: a reader never sees half a file
    table = path.with_suffix(".md")
    save_text(markdown(results), table)
    png = path.with_suffix(".png")
    figure([results], png)
    return [path, table, png]
