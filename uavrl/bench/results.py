"""A suite's results file: versioned JSON, with a Markdown table and a figure beside it.

The JSON (``format`` ``uavrl-bench-results``, ``version`` :data:`VERSION`) holds the suite, the submission (its name,
the command or call that produced it, the training budget its submitter stated), one entry per task (its spec and
start seed, the per-start raw values and normalised scores per training run, the evaluation's metrics, the
references: the per-start reference and random values, U*, the fewest steps or their bound, the mission's optimum
or bound), the aggregate (:mod:`uavrl.bench.stats`), and the uavrl, torch and torchrl versions and the hardware.
"""

from __future__ import annotations

import json
import math
import os
import platform
import re
import unicodedata
from os import PathLike
from pathlib import Path

import uavrl
from uavrl.bench.tasks import BUDGET, SUITES
from uavrl.envs.errors import InvalidType
from uavrl.envs.rules import Rule, flag, interval, one_of, optional, whole
from uavrl.experiment.io import nearest_existing, quoted, read_regular_text, save_text, special_kind
from uavrl.experiment.plots import pyplot, save_figure

FORMAT, VERSION = "uavrl-bench-results", 1
PARTIAL = "partial: a subset of the suite's tasks"


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
        "protocol": PARTIAL if partial else "full",
        "submission": {"name": name, "source": source, "budget": budget},
        "environment": environment(),
        "tasks": [],
    }


# A results file is untrusted input (anyone can write one): it is read only when it has the structure, types and
# finite values every reader of it (the table, the leaderboard, compare, the statistics) relies on.  A schema is a
# dict (keys ending in ``?`` optional, ``*`` any other key; no other key allowed), a one-element list (each item)
# or a Rule (uavrl.envs.rules) of a value.
def _numbers(depth: int, words: str) -> Rule:
    def accepts(value, depth=depth):
        if depth == 0:
            return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        return isinstance(value, list) and all(accepts(item, depth - 1) for item in value)

    return Rule(accepts, f"it must be {words}")


NUMBER = _numbers(0, "a finite number")
NUMBERS = _numbers(1, "a list of finite numbers (one per start)")
TABLE = _numbers(2, "a list of lists of finite numbers (one list per training run, one number per start)")
TEXT = Rule(lambda v: isinstance(v, str) and v.isprintable() and len(v) <= 4000, "it must be one line of text")
PAIR = Rule(lambda v: NUMBERS.accepts(v) and len(v) == 2, "it must be [low, high], two finite numbers")
METRICS = {"*": NUMBER}
REFERENCES = {
    "value": TEXT,
    "reference": {"kind": TEXT, "values": NUMBERS},
    "random": NUMBERS,
    "planner": TEXT,
    "planner_summary": METRICS,
    "u_star": NUMBERS,
    "u_star_gap": NUMBER,
    "min_steps": TABLE,
    "min_steps_levels": [TEXT],
    "min_steps_exact": flag(),
    "delivered_bound?": NUMBERS,
    "delivered_optimum?": NUMBERS,
}
TASK = {
    "task": TEXT,
    "spec": Rule(lambda v: isinstance(v, dict), "it must be an object"),
    "horizon": whole(1),
    "references": REFERENCES,
    "status": one_of("scored", "n/a"),
    "reason?": TEXT,
    "values?": TABLE,
    "scores?": TABLE,
    "mean_score?": NUMBER,
    "summary?": METRICS,
}
ESTIMATES = {
    f"{name}{ci}?": PAIR if ci else NUMBER for name in ("iqm", "mean", "median", "optimality_gap") for ci in ("", "_ci")
}
SCHEMA = {
    "format": one_of(FORMAT),
    "version": one_of(VERSION),
    "suite": one_of(*SUITES, what="suites"),
    "protocol": one_of("full", PARTIAL),
    "submission": {
        "name": TEXT,
        "source": TEXT,
        "train_command?": TEXT,
        "budget": {f"{key}?": rule for key, rule in BUDGET.items()},  # the rule a submission's budget is checked by
    },
    "environment": {
        **{
            key: TEXT for key in ("uavrl", "torch", "torchrl", "tensordict", "python", "machine", "processor", "device")
        },
        "cpus": optional(whole(1), "unknown"),
        "torch_threads": whole(1),
    },
    "tasks": [TASK],
    "aggregate": {
        "tasks": [TEXT],
        "note?": TEXT,
        "rows?": whole(1),
        "reps?": whole(1),
        "confidence?": interval(0.0, 1.0, low_open=True),
        **ESTIMATES,
        "profile?": {key: NUMBERS for key in ("taus", "fraction", "ci_low", "ci_high")},
    },
}


class Invalid(ValueError):
    """A field of a JSON document that breaks its schema: ``field=value is invalid: why``, or ``field is missing``."""


def _shown(value) -> str:
    try:
        text = "{...}" if isinstance(value, dict) else json.dumps(value)
    except RecursionError:  # a list nested deeper than json writes
        text = "[...]"
    return text if len(text) <= 60 else text[:57] + "..."


def conform(value, schema, field: str = "") -> None:
    """An :class:`Invalid` naming the first field of ``value`` (``field`` its place) that breaks ``schema``."""
    if isinstance(schema, Rule):
        if not schema.accepts(value):
            raise Invalid(f"{field}={_shown(value)} is invalid: {schema.allowed}")
    elif isinstance(schema, list):
        if not isinstance(value, list):
            raise Invalid(f"{field}={_shown(value)} is invalid: it must be a list")
        for k, item in enumerate(value):
            conform(item, schema[0], f"{field}[{k}]")
    else:
        if not isinstance(value, dict):
            raise Invalid(f"{field or 'the file'}={_shown(value)} is invalid: it must be an object")
        known = {key.rstrip("?"): sub for key, sub in schema.items()}
        for key in schema:
            if not key.endswith("?") and key != "*" and key not in value:
                raise Invalid(f"{field}{'.' if field else ''}{key} is missing")
        for key, item in value.items():
            place = f"{field}{'.' if field else ''}{key}"
            if key not in known and "*" not in known:
                raise Invalid(f"{place} is invalid: no such field (allowed: {', '.join(k for k in known if k != '*')})")
            conform(item, known.get(key, known.get("*")), place)


def checked(results) -> None:
    """:func:`check_results` of results given in Python (to :func:`save`), refused naming them."""
    if not isinstance(results, dict):
        raise InvalidType("results", results, "give a results dict as uavrl.bench.run.score_suite returns it")
    try:
        check_results(results)
    except Invalid as err:
        raise Invalid(f"results is invalid: {err}") from None


def check_results(results) -> None:
    """An :class:`Invalid` naming the first field of ``results`` that is not as :func:`uavrl.bench.run.score_suite`
    writes it: its schema, then what ties the fields together (the suite's tasks, each once, with the suite's specs;
    a score per start and run; the mean score and the aggregate's tasks as the scores say)."""
    conform(results, SCHEMA)
    suite = {task.name: task for task in SUITES[results["suite"]]}
    seen, rows, scored = set(), set(), []
    for k, task in enumerate(results["tasks"]):
        field, name = f"tasks[{k}]", task["task"]
        if name not in suite:
            raise Invalid(f"{field}.task={_shown(name)} is invalid: suite {results['suite']} has {', '.join(suite)}")
        if name in seen:
            raise Invalid(f"{field}.task={_shown(name)} is invalid: the task is given twice")
        seen.add(name)
        if task["spec"] != suite[name].spec():
            raise Invalid(f"{field}.spec is invalid: it is not task {name}'s of this uavrl (other starts or model)")
        starts = suite[name].num_starts
        for key in ("random", "u_star"):
            if len(task["references"][key]) != starts:
                raise Invalid(f"{field}.references.{key} is invalid: it must hold {starts} values, one per start")
        needs = ("values", "scores", "mean_score", "summary") if task["status"] == "scored" else ("reason",)
        missing = [key for key in needs if key not in task]
        if missing:
            raise Invalid(f"{field}.{missing[0]} is missing (a task whose status is {task['status']} holds it)")
        if task["status"] != "scored":
            continue
        values, scores = task["values"], task["scores"]
        if (
            not scores
            or [len(run) for run in values] != [len(run) for run in scores]
            or {len(r) for r in scores} != {starts}
        ):
            raise Invalid(f"{field}.scores is invalid: one list of {starts} scores per run, as many runs as values")
        flat = [score for run in scores for score in run]
        if not math.isclose(task["mean_score"], sum(flat) / len(flat), rel_tol=1e-9, abs_tol=1e-12):
            raise Invalid(f"{field}.mean_score={_shown(task['mean_score'])} is invalid: it is not its scores' mean")
        for key in ("eval/optimality", "eval/reach_999"):
            if key not in task["summary"]:
                raise Invalid(f"{field}.summary.{key} is missing")
        rows.add(len(flat))
        scored.append(name)
    if len(rows) > 1:
        raise Invalid("tasks is invalid: its tasks were scored from different numbers of starts or runs")
    if results["protocol"] == "full" and seen != set(suite):
        raise Invalid(f"tasks is invalid: a full protocol scores every task of suite {results['suite']}")
    agg = results["aggregate"]
    if agg["tasks"] != scored:
        raise Invalid(f"aggregate.tasks={_shown(agg['tasks'])} is invalid: the scored tasks are {_shown(scored)}")
    if scored:
        needed = ("rows", "reps", "confidence", *(key.rstrip("?") for key in ESTIMATES), "profile")
        missing = [key for key in needed if key not in agg]
        if missing:
            raise Invalid(f"aggregate.{missing[0]} is missing (an aggregate over scored tasks holds it)")
        if agg["rows"] not in rows or len({len(v) for v in agg["profile"].values()}) != 1:
            raise Invalid("aggregate is invalid: its rows or its profile's lists do not match the scores")


def read(path, within=None) -> dict:
    """The results file at ``path``, refused in one line that names it (and the field) when it is not one this
    version writes (:func:`check_results`); ``within``: the directory it was found in, which it may not link out of."""
    if not isinstance(path, (str, PathLike)) or not str(path):
        raise InvalidType("path", path, "give the results file's path")
    try:
        text = read_regular_text(path, within=within)
    except OSError as err:
        raise Invalid(f"{quoted(path)} cannot be read ({err.strerror or err})") from None
    try:
        results = json.loads(text)
    except RecursionError:
        raise Invalid(f"{quoted(path)} nests deeper than a results file does") from None
    except ValueError as err:
        raise Invalid(f"{quoted(path)} is not valid JSON ({err})") from None
    if not isinstance(results, dict) or results.get("format") != FORMAT:
        raise Invalid(f"{quoted(path)}: not a uavrl benchmark results file (no format {FORMAT!r})")
    if type(results.get("version")) is not int or results["version"] != VERSION:  # true == 1 in Python
        raise Invalid(
            f"{quoted(path)}: results version {_shown(results.get('version'))}, this uavrl reads version {VERSION}"
        )
    try:
        check_results(results)
    except Invalid as err:
        raise Invalid(f"{quoted(path)}: {err}") from None
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
    if not isinstance(results, dict) or not isinstance(results.get("submission"), dict):
        raise InvalidType("results", results, "give a results dict as uavrl.bench.run.score_suite returns it")
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
    for index, task in enumerate(results["tasks"]):
        name, ref = markdown_text(task["task"]), markdown_text(task["references"]["reference"]["kind"])
        if task["status"] != "scored":
            lines.append(f"| {name} | n/a | {ref} | {markdown_text(task['reason'])} | | | |")
            continue
        if not NUMBER.accepts(task["mean_score"]):  # the numbers the table prints: as results.read checks them
            raise Invalid(f"results is invalid: tasks[{index}].mean_score={task['mean_score']!r}: {NUMBER.allowed}")
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
        columns = min(2, 1 + count // 9)  # a third column would squeeze the profiles to a sliver
        profile.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=7, frameon=False, ncol=columns)
    else:
        profile.text(0.5, 0.5, "no task scored", ha="center", va="center", transform=profile.transAxes)
    save_figure(fig, Path(path))


def outputs(path) -> list[Path]:
    """The files a results file ``path`` comes with: the JSON, its table ``.md`` and its figure ``.png``."""
    path = Path(path)
    return [path, path.with_suffix(".md"), path.with_suffix(".png")]


def check_out(path, setting: str = "out") -> None:
    """Refuse in one line, before any scoring, a results file ``path`` (given as ``setting``) the benchmark may not
    write: one not ending in ``.json``; one whose folder cannot be made; a JSON there that is no results file of
    uavrl's; a ``.md`` or ``.png`` beside it when no results file of uavrl's is there (a user's notes or figure).
    The table and figure beside a results file of uavrl's are its own, replaced with it."""
    if not isinstance(path, (str, PathLike)) or not str(path):
        raise InvalidType(setting, path, "give the results file's path (a .json file)")
    path = Path(path)
    given = f"{setting}={quoted(path)}"
    if path.suffix != ".json":
        raise Invalid(f"{given} is invalid: give a .json file (its table .md and figure .png go beside it)")
    folder = nearest_existing(path.parent)
    if not folder.is_dir():
        raise NotADirectoryError(
            f"{given} is invalid: {quoted(folder)} is {special_kind(folder) or 'a file'}, not a folder"
        )
    if not os.access(folder, os.W_OK | os.X_OK):
        raise PermissionError(f"{given} is invalid: the folder {quoted(folder)} is not writable")
    ours = False
    if os.path.lexists(path):
        try:
            read(path)
            ours = True
        except ValueError as err:
            raise FileExistsError(
                f"{given} is invalid: it exists and is no uavrl results file ({err}); give another {setting} "
                "(it is not overwritten)"
            ) from None
    for beside in outputs(path)[1:]:
        if os.path.lexists(beside) and (not ours or special_kind(beside) is not None):
            raise FileExistsError(
                f"{given} is invalid: {quoted(beside)} exists beside it and the benchmark did not write it; give "
                f"another {setting}, or move that file away (it is not overwritten)"
            )


def save(results: dict, path) -> list[Path]:
    """Write ``path`` (the JSON) and beside it ``.md`` (the table) and ``.png`` (the figure); the paths written.
    Files of those names that the benchmark did not write are refused first, in one line (:func:`check_out`)."""
    checked(results)
    check_out(path, "path")
    path, table, png = outputs(path)
    save_text(json.dumps(results, indent=1, sort_keys=True) + "\n", path)  # atomic: a reader never sees half a file
    save_text(markdown(results), table)
    figure([results], png)
    return [path, table, png]
