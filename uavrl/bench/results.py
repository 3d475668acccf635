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
import re
import unicodedata
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


# what a string from a file may not bring into a page: line breaks and other control or format characters (shown as
# a space); the characters that start Markdown or MyST markup (emphasis, links, headings, tables, code, math,
# attributes: backslash-escaped) and HTML (``<``, ``>``, ``&``: character references, since MyST renders raw HTML)
_CONTROL = {"Cc", "Cf", "Cs", "Zl", "Zp"}
_MARKUP = {**{ord(c): "\\" + c for c in "\\`*_[]{}#|$~"}, ord("<"): "&lt;", ord(">"): "&gt;", ord("&"): "&amp;"}


def markdown_text(value, code: bool = False) -> str:
    """``value``, a string read from a file (a submission's name, a command, a version), as Markdown for a table cell
    that shows its text and makes no markup: no HTML, link, heading, emphasis, math or new row.

    Control characters and line breaks become spaces, the ends trimmed; with ``code``, the text is an inline code
    span (fenced by one backtick more than its longest run of backticks, ``|`` escaped as a table cell needs), else
    the characters that start Markdown, MyST or HTML markup are escaped.

    Example:
        >>> markdown_text("</td><script>x</script> # [a](b)")
        '&lt;/td&gt;&lt;script&gt;x&lt;/script&gt; \\\\# \\\\[a\\\\](b)'
        >>> markdown_text("echo `date` | tee", code=True)
        '``echo `date` \\\\| tee``'
    """
    text = "".join(" " if unicodedata.category(ch) in _CONTROL else ch for ch in str(value)).strip()
    if not code:
        return text.translate(_MARKUP)
    if not text:
        return ""
    fence = "`" * (max(map(len, re.findall("`+", text)), default=0) + 1)
    pad = " " if text[0] == "`" or text[-1] == "`" else ""  # a space between the fence and a backtick of the text
    return f"{fence}{pad}{text.replace('|', chr(92) + '|')}{pad}{fence}"


def markdown(results: dict) -> str:
    """The results as Markdown: the submission, then a row per task, then the aggregate; every string of the file
    escaped (:func:`markdown_text`)."""
    sub = results["submission"]
    lines = [
        "| submission | suite | protocol | budget | command |",
        "|---|---|---|---|---|",
        f"| {markdown_text(sub['name'])} | {markdown_text(results['suite'], code=True)} | "
        f"{markdown_text(results['protocol'])} | {_budget_words(sub['budget'])} | "
        f"{markdown_text(sub['source'], code=True)} |",
        "",
        "| task | score (0 random, 1 reference) | reference | value | U / U* | reach 0.999 U* | steps / fewest |",
        "|---|---|---|---|---|---|---|",
    ]
    for task in results["tasks"]:
        name, ref = markdown_text(task["task"]), markdown_text(task["references"]["reference"]["kind"])
        if task["status"] != "scored":
            lines.append(f"| {name} | n/a | {ref} | {markdown_text(task['reason'])} | | | |")
            continue
        s = task["summary"]
        mean_value = sum(v for run in task["values"] for v in run) / sum(len(run) for run in task["values"])
        steps = f"{s['eval/step_ratio_999']:.2f}" if "eval/step_ratio_999" in s else "-"
        fewest = "" if task["references"]["min_steps_exact"] else " (bound)"
        lines.append(
            f"| {name} | {task['mean_score']:.3f} | {ref} | {mean_value:.4g} | {s['eval/optimality']:.3f} | "
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


def _figure_label(value, most: int = 48) -> str:
    """A string from a file as matplotlib text: one line, ``$`` escaped (no mathtext), at most ``most`` characters."""
    text = " ".join("".join(" " if unicodedata.category(ch) in _CONTROL else ch for ch in str(value)).split())
    return (text if len(text) <= most else text[: most - 1] + "\N{HORIZONTAL ELLIPSIS}").replace("$", r"\$")


def figure(results_list: list[dict], path) -> None:
    """The results files of one suite side by side, as a PNG: a heatmap of the mean normalised score of each file
    (a row, best IQM first) on each task (a column; grey and hatched, n/a, where the policy cannot act), each row's IQM
    with its 95% CI beside it, and under them the performance profiles (score distributions with their CIs), one
    colour per file in the IQM panel and the profiles."""
    import numpy as np
    from matplotlib.colors import Normalize

    plt = pyplot()
    ranked = sorted(results_list, key=lambda r: -(r.get("aggregate", {}).get("iqm") or float("-inf")))
    count = len(ranked)
    names = list(dict.fromkeys(t["task"] for r in ranked for t in r["tasks"]))
    palette = plt.get_cmap("tab20").colors
    colours = [*palette[0::2], *palette[1::2]]  # ten distinct hues first, then their light shades
    fig = plt.figure(figsize=(8.5, 3.9 + 0.27 * count), layout="constrained")  # read at the docs page's width
    top, bottom = fig.subfigures(2, 1, height_ratios=[1.1 + 0.27 * count, 3.2])
    heat, iqm = top.subplots(1, 2, sharey=True, width_ratios=[max(2, len(names)), 2.2])
    profile = bottom.subplots()
    norm, cmap = Normalize(0.0, 1.0), plt.get_cmap("viridis")
    scores = np.full((count, len(names)), np.nan)
    for row, results in enumerate(ranked):
        by_task = {t["task"]: t for t in results["tasks"]}
        for col, name in enumerate(names):
            task = by_task.get(name, {})
            if task.get("status") == "scored":
                scores[row, col] = value = task["mean_score"]
                ink = "white" if norm(value) < 0.55 else "black"
                heat.text(col, row, f"{value:.2f}", ha="center", va="center", fontsize=8, color=ink)
            else:  # a task it cannot act in (n/a) or did not score (-): grey, hatched
                heat.add_patch(plt.Rectangle((col - 0.5, row - 0.5), 1, 1, facecolor="0.88", hatch="///", ec="0.7"))
                heat.text(col, row, "n/a" if task else "-", ha="center", va="center", fontsize=7, color="0.35")
    heat.imshow(np.ma.masked_invalid(scores), cmap=cmap, norm=norm, aspect="auto")
    heat.set_xticks(range(len(names)), [_figure_label(n, 24) for n in names], rotation=20, ha="right", fontsize=8)
    heat.set_yticks(range(count), [_figure_label(r["submission"]["name"]) for r in ranked], fontsize=8)
    heat.set_xlim(-0.5, len(names) - 0.5)
    heat.set_ylim(count - 0.5, -0.5)
    heat.tick_params(length=0)
    heat.set_title("mean normalised score per task (0 random, 1 reference)", fontsize=9)
    for row, results in enumerate(ranked):
        colour, agg = colours[row % len(colours)], results.get("aggregate", {})
        if not agg.get("tasks"):
            iqm.text(0.5, row, "no task scored", ha="center", va="center", fontsize=7, color="0.35")
            continue
        low, high = agg["iqm_ci"]
        iqm.errorbar(agg["iqm"], row, xerr=[[agg["iqm"] - low], [high - agg["iqm"]]], fmt="o", color=colour, ms=4)
        scored = f" ({len(agg['tasks'])}/{len(names)})" if len(agg["tasks"]) < len(names) else ""
        iqm.annotate(
            f"{agg['iqm']:.2f}{scored}", (high, row), xytext=(4, 0), textcoords="offset points", va="center", fontsize=7
        )
        if agg.get("profile"):
            p = agg["profile"]
            label = _figure_label(results["submission"]["name"], 36)
            profile.plot(p["taus"], p["fraction"], color=colour, label=label, lw=1.2)
            profile.fill_between(p["taus"], p["ci_low"], p["ci_high"], color=colour, alpha=0.12, lw=0)
    iqm.axvline(1.0, color="grey", lw=0.8, ls="--")
    iqm.axvline(0.0, color="grey", lw=0.8)
    iqm.set_xlim(min(-0.1, *(r.get("aggregate", {}).get("iqm_ci", [0])[0] - 0.1 for r in ranked)), 1.45)
    iqm.tick_params(axis="x", labelsize=7)
    iqm.tick_params(axis="y", length=0)
    iqm.set_title("IQM [95% CI] (tasks scored)", fontsize=9)
    profile.set_xlabel("normalised score threshold tau", fontsize=8)
    profile.set_ylabel("fraction of (start, task)\nwith score > tau", fontsize=8)
    profile.tick_params(labelsize=7)
    profile.set_title(f"suite {_figure_label(ranked[0]['suite'])}: performance profiles (95% CI)", fontsize=9)
    if profile.lines:
        profile.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=7, frameon=False, ncol=1 + count // 9)
    else:
        profile.text(0.5, 0.5, "no task scored", ha="center", va="center", transform=profile.transAxes)
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
