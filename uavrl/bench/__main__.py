"""``python -m uavrl.bench``: score a policy on a suite, compare two results files, write the leaderboard.

    python -m uavrl.bench <suite> checkpoint=<run dir> [budget.env_steps=N] [budget.cpu_seconds=S] [out=file.json]
    python -m uavrl.bench <suite> agent=random|oracle|planner
    python -m uavrl.bench compare A.json B.json
    python -m uavrl.bench leaderboard [results=benchmarks/results/leaderboard] [out=docs/leaderboard.md]
    python -m uavrl.bench list

Settings (``key=value``): ``checkpoint`` (a run directory of ``python -m uavrl.train`` or a checkpoint file in one)
or ``agent`` (a baseline by name); ``name`` (the submission's name; default the agent and run); ``out`` (the results
JSON; default ``bench/<suite>/<name>.json``, the table ``.md`` and figure ``.png`` beside it); the training budget
``budget.env_steps``, ``budget.cpu_seconds``, ``budget.gpu_seconds`` (a run directory's own env steps by default);
``train_command`` (the command that trained the policy, carried into the results and the leaderboard);
``tasks=[a,b]`` (a subset of the suite: a partial protocol); ``cache_dir`` (the references' cache); ``num_threads``
(torch's CPU threads, default 1: the same scores bit for bit; at most ``uavrl.schema.MAX_THREADS``, as every command).
A bad setting is refused in one line before torch is imported: an ``out`` the benchmark may not write (a file of a
user's of its name or beside it, :func:`uavrl.bench.results.check_out`) and a ``cache_dir`` that cannot be written
among them.
"""

from __future__ import annotations

import re
import sys

from uavrl.bench import cache
from uavrl.bench.leaderboard import leaderboard_command
from uavrl.bench.results import TEXT, check_out, interval, read
from uavrl.bench.stats import probability_of_improvement
from uavrl.bench.tasks import SUITES, SUITES_TEXT, TASKS, check_budget
from uavrl.envs._moved import moved_names
from uavrl.envs.rules import refuse, whole_within
from uavrl.experiment.checkpoints import checkpoint_files, no_checkpoint
from uavrl.experiment.saved import load_run_checkpoint
from uavrl.schema import MAX_THREADS

# uavrl 0.2's names of this module that moved to the library (score_command, baseline_factory, ...): deprecated
# aliases
__getattr__ = moved_names(__name__, "uavrl.bench.scoring")

BASELINES = ("random", "oracle", "planner")
SETTINGS = (
    "checkpoint",
    "agent",
    "name",
    "out",
    "budget.env_steps",
    "budget.cpu_seconds",
    "budget.gpu_seconds",
    "tasks",
    "cache_dir",
    "num_threads",
    "train_command",
)
USAGE = (
    f"usage: python -m uavrl.bench <suite: {SUITES_TEXT}> checkpoint=<run dir> | agent=<{'|'.join(BASELINES)}>; "
    "python -m uavrl.bench compare A.json B.json; python -m uavrl.bench leaderboard; python -m uavrl.bench list"
)


def parse(args: list[str]) -> dict:
    """The command line's ``key=value`` settings, checked: a one-line ValueError naming what was typed."""
    settings = {}
    for arg in args:
        key, sep, value = arg.partition("=")
        if not sep:
            raise ValueError(f"{arg!r} is invalid: settings are key=value ({', '.join(SETTINGS)})")
        if key not in SETTINGS:
            raise ValueError(f"{arg} is invalid: unknown setting {key!r}; the settings are {', '.join(SETTINGS)}")
        if key in settings:
            raise ValueError(f"{arg} is invalid: {key} was given twice")
        if not value:  # an empty path would be the working directory
            raise ValueError(f"{arg} is invalid: give a value ({key}=<...>)")
        settings[key] = value
    budget = check_budget({key.removeprefix("budget."): v for key, v in settings.items() if key.startswith("budget.")})
    settings |= {f"budget.{key}": number for key, number in budget.items()}
    if "num_threads" in settings:
        typed = settings["num_threads"]
        refuse(
            "num_threads", int(typed) if typed.isdigit() and len(typed) < 20 else typed, whole_within(1, MAX_THREADS)
        )
        settings["num_threads"] = int(typed)
    for key in ("name", "train_command"):  # as a results file holds them (uavrl.bench.results.read)
        if key in settings and not (settings[key].strip() and TEXT.accepts(settings[key])):
            raise ValueError(f"{key}={settings[key]!r} is invalid: {TEXT.allowed} (at most 4,000 characters)")
    if "tasks" in settings:
        typed = settings["tasks"]
        listed = typed[1:-1] if typed.startswith("[") and typed.endswith("]") else typed
        settings["tasks"] = [task.strip() for task in listed.split(",")]
        if not all(re.fullmatch(r"[\w.-]+", task) for task in settings["tasks"]):
            raise ValueError(
                f"tasks={typed} is invalid: give task names, e.g. tasks=[tiny_3x3] (python -m uavrl.bench list)"
            )
        if len(set(settings["tasks"])) < len(settings["tasks"]):
            raise ValueError(f"tasks={typed} is invalid: a task is named twice")
    if ("checkpoint" in settings) == ("agent" in settings):
        raise ValueError("give one of checkpoint=<run dir> or agent=<baseline> (not both, not neither)")
    if "agent" in settings and settings["agent"] not in BASELINES:
        raise ValueError(f"agent={settings['agent']} is invalid: give one of {', '.join(BASELINES)}")
    if "checkpoint" in settings:
        if not checkpoint_files(settings["checkpoint"]):
            raise ValueError(no_checkpoint(settings["checkpoint"], "checkpoint"))
    if "out" in settings:
        check_out(settings["out"])
    if "cache_dir" in settings:
        cache.check_dir(settings["cache_dir"])
    if "checkpoint" in settings:  # last, with torch alone: no checkpoint of its run is refused before TorchRL loads
        load_run_checkpoint(settings["checkpoint"])
    return settings


def compare_command(args: list[str]) -> None:
    """``python -m uavrl.bench compare A.json B.json``: P(A > B) with its CI, and each file's IQM."""
    if len(args) != 2:
        raise ValueError(f"compare {' '.join(args)} is invalid: give two results files, compare A.json B.json")
    a, b = read(args[0]), read(args[1])
    p = probability_of_improvement(a, b)
    for path, r in ((args[0], a), (args[1], b)):
        agg = r.get("aggregate", {})
        iqm = interval(agg["iqm"], agg["iqm_ci"]) if agg.get("tasks") else "n/a"
        print(f"{r['submission']['name']} ({path}): IQM {iqm}")
    print(
        f"P({a['submission']['name']} > {b['submission']['name']}) = {interval(p['probability'], p['ci'])} over "
        f"{len(p['tasks'])} task{'s' if len(p['tasks']) > 1 else ''} of suite {a['suite']} (95% stratified bootstrap "
        "CI, rliable)"
    )


def list_command() -> None:
    """``python -m uavrl.bench list``: the suites and their tasks."""
    for suite, tasks in SUITES.items():
        print(f"{suite}:")
        for task in tasks:
            print(f"  {task.name}: {task.about} ({task.num_starts} starts from seed {task.seed})")


def main(argv: list[str]) -> None:
    """``python -m uavrl.bench``: the command word, then its arguments (the module doc).

    Args:
        argv: the arguments after ``python -m uavrl.bench``.
    """
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE + "\n" + __doc__)
        return
    command, rest = argv[0], argv[1:]
    if command == "compare":
        compare_command(rest)
    elif command == "leaderboard":
        leaderboard_command(rest)
    elif command == "list":
        if rest:
            raise ValueError(f"{' '.join(rest)} is invalid: list takes no arguments; it prints every suite's tasks")
        list_command()
    elif command in SUITES:
        settings = parse(rest)
        from uavrl.bench.scoring import score_command  # torch, TorchRL, the agents: once the settings are good

        score_command(command, settings)
    else:
        hint = " (a task; give its suite)" if command in TASKS else ""
        raise ValueError(f"{command!r} is invalid{hint}: give a suite ({SUITES_TEXT}), compare, leaderboard or list")


if __name__ == "__main__":
    try:
        main(sys.argv[1:])
    except (ValueError, OSError, ImportError) as err:  # the refusals, and a file that could not be written
        raise SystemExit(f"error: {err}") from None
