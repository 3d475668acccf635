"""The benchmark command's scoring (``python -m uavrl.bench <suite> ...``, :mod:`uavrl.bench.__main__`): a baseline's
or a run directory's policies scored on a suite (:func:`uavrl.bench.run.score_suite`), the results written."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import torch

from uavrl.agents.baselines import OraclePolicy, RandomPolicy
from uavrl.agents.planner import PlannerPolicy
from uavrl.agents.schema import network_refusal
from uavrl.bench import cache
from uavrl.bench.results import check_out, markdown, save
from uavrl.bench.run import RANDOM_SEED, NotApplicable, score_suite
from uavrl.bench.tasks import BUDGET
from uavrl.config import model_config
from uavrl.experiment.io import quoted, read_small_text
from uavrl.experiment.runs import agent_label
from uavrl.experiment.saved import load_agent, output_dir


def baseline_factory(agent: str):
    """A policy factory (:func:`uavrl.bench.run.score_suite`) of a baseline by name."""

    def factory(env):
        if agent == "random":
            return RandomPolicy(seed=RANDOM_SEED)
        return OraclePolicy(env.cfg) if agent == "oracle" else PlannerPolicy(env.cfg)

    return factory


def checkpoint_factory(path):
    """``(policy factory, the run's saved config, its agent)`` of a run directory: each of the run's independent
    runs' greedy policies where the run's policy can act (a per-size policy in its own model, a size-free network in
    any team and grid of it), :class:`~uavrl.bench.run.NotApplicable` elsewhere.  The settings that only shape
    training (the reward, the episode length) are the run's own."""
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
    """The training CPU seconds a run directory recorded (``metrics.json``'s ``train_cpu_seconds``), or nothing when
    it has no metrics.json; a metrics.json that cannot say them is refused in one line."""
    path = output_dir(checkpoint) / "metrics.json"
    if not path.exists():
        return {}
    refusal = f"checkpoint={quoted(checkpoint)}: cannot read the training's CPU seconds"
    try:
        metrics = json.loads(read_small_text(path, within=output_dir(checkpoint)))
    except (ValueError, RecursionError) as err:  # DamagedRun (a FIFO, a huge file, a link out), not JSON
        raise ValueError(f"{refusal} ({err}): give budget.cpu_seconds=<seconds>") from None
    seconds = metrics.get("train_cpu_seconds") if isinstance(metrics, dict) else None
    if seconds is None:
        return {}
    if not BUDGET["cpu_seconds"].accepts(seconds):
        raise ValueError(f"{refusal} (metrics.json: train_cpu_seconds={seconds!r}): give budget.cpu_seconds=<seconds>")
    return {"cpu_seconds": float(seconds)}


def score_command(suite: str, settings: dict) -> None:
    """``python -m uavrl.bench <suite> ...`` (:mod:`uavrl.bench.__main__`'s doc): the suite scored, the results
    written and their table printed.

    Args:
        suite: the suite's name (``uavrl.bench.tasks.SUITES``).
        settings: the command line's settings, checked (:func:`uavrl.bench.__main__.parse`).
    """
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
        if "cpu_seconds" not in budget:
            budget.update(run_costs(settings["checkpoint"]))
        source = f"python -m uavrl.bench {suite} checkpoint={settings['checkpoint']}"
    if "tasks" in settings:
        source += f" tasks=[{','.join(settings['tasks'])}]"
    name = settings.get("name", name)
    out = Path(settings.get("out") or Path("bench") / suite / f"{name.replace(':', '-').replace('/', '-')}.json")
    check_out(out)  # before any scoring: the default out too (score_suite checks the cache before its work)
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
    written = save(results, out)
    print(markdown(results))
    print("wrote " + ", ".join(str(p) for p in written))
