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
(torch's CPU threads, default 1: the same scores bit for bit).  A bad setting is refused in one line before torch is
imported.
"""

from __future__ import annotations

import sys
from pathlib import Path

from uavrl.bench.tasks import SUITES, SUITES_TEXT, TASKS

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
        settings[key] = value
    for key in ("budget.env_steps", "budget.cpu_seconds", "budget.gpu_seconds"):
        if key in settings:
            try:
                number = float(settings[key])
            except ValueError:
                number = -1.0
            if not number >= 0 or number == float("inf"):
                raise ValueError(f"{key}={settings[key]} is invalid: give a number >= 0")
            settings[key] = int(number) if key == "budget.env_steps" else number
    if "num_threads" in settings:
        if not settings["num_threads"].isdigit() or int(settings["num_threads"]) < 1:
            raise ValueError(f"num_threads={settings['num_threads']} is invalid: give a whole number >= 1")
        settings["num_threads"] = int(settings["num_threads"])
    if "tasks" in settings:
        settings["tasks"] = [t.strip() for t in settings["tasks"].strip("[]").split(",") if t.strip()]
        if not settings["tasks"]:
            raise ValueError(f"tasks={settings['tasks']} is invalid: name at least one task")
    if ("checkpoint" in settings) == ("agent" in settings):
        raise ValueError("give one of checkpoint=<run dir> or agent=<baseline> (not both, not neither)")
    if "agent" in settings and settings["agent"] not in BASELINES:
        raise ValueError(f"agent={settings['agent']} is invalid: give one of {', '.join(BASELINES)}")
    if "checkpoint" in settings:
        from uavrl.experiment.checkpoints import checkpoint_files, no_checkpoint

        if not checkpoint_files(settings["checkpoint"]):
            raise ValueError(no_checkpoint(settings["checkpoint"], "checkpoint"))
    return settings


def baseline_factory(agent: str):
    """A policy factory (:func:`uavrl.bench.run.score_suite`) of a baseline by name."""

    def factory(env):
        from uavrl.agents.baselines import OraclePolicy, RandomPolicy
        from uavrl.agents.planner import PlannerPolicy
        from uavrl.bench.run import RANDOM_SEED

        if agent == "random":
            return RandomPolicy(seed=RANDOM_SEED)
        return OraclePolicy(env.cfg) if agent == "oracle" else PlannerPolicy(env.cfg)

    return factory


def checkpoint_factory(path):
    """``(policy factory, the run's saved config, its agent)`` of a run directory: each of the run's independent
    runs' greedy policies where the run's policy can act (a per-size policy in its own model, a size-free network in
    any team and grid of it), :class:`~uavrl.bench.run.NotApplicable` elsewhere.  The settings that only shape
    training (the reward, the episode length) are the run's own."""
    from uavrl.agents.dqn.multisize import network_refusal
    from uavrl.bench.run import NotApplicable
    from uavrl.config import model_config
    from uavrl.experiment.saved import load_agent

    agent, saved, fallback = load_agent(path)
    if fallback:
        print(f"warning: {fallback}", file=sys.stderr)
    run = model_config(saved)

    def factory(env):
        acting = env.cfg.replace(reward=run.reward, max_steps=run.max_steps)
        refusal = network_refusal(saved, acting, run)
        if refusal:
            raise NotApplicable(refusal.split(";")[0])
        return [agent.policy_for(acting, r) for r in range(len(agent.policies()))]

    return factory, saved, agent


def run_costs(checkpoint) -> dict:
    """The training CPU seconds a run directory recorded (``metrics.json``'s ``train_cpu_seconds``), or nothing."""
    import json

    from uavrl.experiment.saved import output_dir

    try:
        metrics = json.loads((output_dir(checkpoint) / "metrics.json").read_text())
    except (OSError, ValueError):
        return {}
    return {"cpu_seconds": float(metrics["train_cpu_seconds"])} if "train_cpu_seconds" in metrics else {}


def score_command(suite: str, settings: dict) -> None:
    """``python -m uavrl.bench <suite> ...`` (module doc)."""
    import torch

    from uavrl.bench import cache
    from uavrl.bench.results import save
    from uavrl.bench.run import score_suite
    from uavrl.experiment.runs import agent_label

    torch.set_num_threads(settings.get("num_threads", 1))
    budget = {k.split(".", 1)[1]: v for k, v in settings.items() if k.startswith("budget.")}
    if "agent" in settings:
        factory, name = baseline_factory(settings["agent"]), settings["agent"]
        budget.setdefault("env_steps", 0)
        source = f"python -m uavrl.bench {suite} agent={settings['agent']}"
    else:
        factory, saved, agent = checkpoint_factory(settings["checkpoint"])
        name = f"{agent_label(saved)}:{Path(settings['checkpoint']).name}"
        budget.setdefault("env_steps", int(agent.env_steps))
        for key, value in run_costs(settings["checkpoint"]).items():
            budget.setdefault(key, value)
        source = f"python -m uavrl.bench {suite} checkpoint={settings['checkpoint']}"
    if "tasks" in settings:
        source += f" tasks=[{','.join(settings['tasks'])}]"
    name = settings.get("name", name)
    results = score_suite(
        suite,
        factory,
        name=name,
        budget=budget,
        source=source,
        cache_dir=Path(settings["cache_dir"]) if "cache_dir" in settings else cache.default_dir(),
        tasks=settings.get("tasks"),
        train_command=settings.get("train_command"),
        progress=lambda line: print(line, file=sys.stderr, flush=True),
    )
    out = Path(settings.get("out") or Path("bench") / suite / f"{name.replace(':', '-').replace('/', '-')}.json")
    written = save(results, out)
    from uavrl.bench.results import markdown

    print(markdown(results))
    print("wrote " + ", ".join(str(p) for p in written))


def compare_command(args: list[str]) -> None:
    """``python -m uavrl.bench compare A.json B.json``: P(A > B) with its CI, and each file's IQM."""
    if len(args) != 2:
        raise ValueError(f"compare {' '.join(args)} is invalid: give two results files, compare A.json B.json")
    from uavrl.bench.results import interval, read
    from uavrl.bench.stats import probability_of_improvement

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
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE + "\n" + __doc__)
        return
    command, rest = argv[0], argv[1:]
    if command == "compare":
        compare_command(rest)
    elif command == "leaderboard":
        from uavrl.bench.leaderboard import leaderboard_command

        leaderboard_command(rest)
    elif command == "list":
        list_command()
    elif command in SUITES:
        score_command(command, parse(rest))
    else:
        hint = " (a task; give its suite)" if command in TASKS else ""
        raise ValueError(f"{command!r} is invalid{hint}: give a suite ({SUITES_TEXT}), compare, leaderboard or list")


if __name__ == "__main__":
    try:
        main(sys.argv[1:])
    except (ValueError, FileNotFoundError, ImportError) as err:
        raise SystemExit(f"error: {err}") from None
