"""Scoring a policy on a suite: greedy rollouts from each task's held-out starts, against its references.

:func:`score_suite` takes a *policy factory*: a callable given the task's environment
(:class:`~uavrl.envs.UAVSpectrumEnv`, one world per start) that returns a TorchRL policy (reads the observation keys,
writes ``("agents", "action")``), or raises :class:`NotApplicable` where the policy cannot act (a per-size network on
another team size): that task is then marked n/a, never failed.  A factory may return a list of policies (one per
independent training run); each is scored from the same starts.

Example (the oracle planner on the smoke-sized suite):
    >>> from uavrl.agents.baselines import OraclePolicy
    >>> results = score_suite("tiny", lambda env: OraclePolicy(env.cfg), name="oracle", cache_dir=None)
    >>> [round(task["mean_score"], 2) for task in results["tasks"]]  # doctest: +SKIP
"""

from __future__ import annotations

import time
from functools import lru_cache
from os import PathLike
from pathlib import Path

import torch

from uavrl.agents.baselines import OraclePolicy, RandomPolicy
from uavrl.agents.evaluation import greedy_metrics, greedy_rollout
from uavrl.agents.planner import PlannerPolicy
from uavrl.agents.references import LEVELS, placements, start_references, u_star_gap
from uavrl.bench import cache
from uavrl.bench.results import TEXT, new_results
from uavrl.bench.stats import aggregate
from uavrl.bench.tasks import SUITES, SUITES_TEXT, TASKS, Task, check_budget
from uavrl.cli import compose_config
from uavrl.config import model_config
from uavrl.envs import InvalidOption, InvalidType
from uavrl.envs.env import UAVSpectrumEnv
from uavrl.envs.limits import evaluation_horizon

RANDOM_SEED = 0  # the random policy every score is normalised by


class NotApplicable(Exception):
    """Raised by a policy factory for a task its policy cannot act in (the message says why)."""


@lru_cache(maxsize=None)
def _scenario(name: str):
    """``(model config, evaluation horizon or None)`` of a scenario, as ``python -m uavrl.train scenario=<name>``
    composes it."""
    cfg = compose_config("config", [f"scenario={name}", "agent=random"])
    return model_config(cfg), cfg.eval.horizon


def model(task: Task):
    """The task's :class:`~uavrl.envs.ModelConfig`, its episodes as long as its horizon."""
    cfg, _ = _scenario(task.scenario)
    cfg = cfg.replace(**dict(task.options))
    return cfg.replace(max_steps=horizon(task, cfg))


def horizon(task: Task, cfg=None) -> int:
    """Steps per rollout: the scenario's ``eval.horizon``, else the evaluation's default for the task's model."""
    base, steps = _scenario(task.scenario)
    return int(steps) if steps is not None else evaluation_horizon(cfg or base.replace(**dict(task.options)))


def _tensor(values) -> dict:
    return None if values is None else {"dtype": str(values.dtype).removeprefix("torch."), "values": values.tolist()}


def _untensor(entry):

    return None if entry is None else torch.tensor(entry["values"], dtype=getattr(torch, entry["dtype"]))


def task_env(task: Task, device="cpu"):
    """The task's environment, one world per start, seeded at its starts (not yet reset), on the torch ``device``."""
    return UAVSpectrumEnv(batch_size=task.num_starts, config=model(task), seed=task.seed, device=device)


def _started(task: Task, device="cpu"):
    """``(env, start tensordict, U* [B])`` of the task's starts."""
    env = task_env(task, device)
    start = env.reset()
    return env, start, env.optimum()[0]


def _rollout(task: Task, policy, device="cpu") -> dict:
    """One greedy rollout per start of ``policy``: the world, start, U*, the steps' outputs and the batteries."""

    env, start, u_star = _started(task, device)
    with torch.no_grad():
        steps, batteries = greedy_rollout(env, policy, start, env.cfg.max_steps)
    return {"world": env.world, "start": start, "u_star": u_star, "steps": steps, "batteries": batteries}


def _values(task: Task, played: dict):
    """Per start: the raw value (the discounted gain J; under an energy model the data delivered, bit/Hz) and the
    mean-channel utilities ``[B, H + 1]``."""
    world, start, steps = played["world"], played["start"], played["steps"]
    positions = torch.cat([placements(start).unsqueeze(1), placements(steps)], 1)  # with levels (x, y, level)
    tasks = torch.cat([start["tasks"].unsqueeze(1), steps["tasks"]], 1)
    utility = world.utility(positions, tasks)[2]
    if world.energy is None:
        discount = task.gamma ** torch.arange(utility.shape[1] - 1, dtype=torch.float64)
        return (utility.diff(dim=1) * discount).sum(-1), utility
    return utility[:, 1:].sum(-1) * world.cfg.slot_s, utility


def _summary(task: Task, played: dict, references: dict) -> dict:
    """The evaluation's ``eval/...`` metrics (:func:`uavrl.agents.evaluation.greedy_metrics`) of the rollouts."""
    return greedy_metrics(
        played["world"],
        played["start"],
        played["steps"],
        played["u_star"],
        references,
        task.gamma,
        played["batteries"],
    )


def _start_references(task: Task) -> tuple[dict, dict]:
    """The evaluation's references of the task's starts (:func:`uavrl.agents.evaluation.start_references`) and, as JSON,
    the certified quantities: U*, its gap, the fewest steps or their bound, the mission's optimum or bound."""
    env, start, u_star = _started(task)
    refs = start_references(env.world, start, u_star, env.cfg.max_steps, task.gamma)
    u_start = env.world.utility(placements(start), start["tasks"])[2]
    stored = {
        "u_star": _tensor(u_star),
        "u_start": _tensor(u_start),
        "u_star_gap": u_star_gap(env.world, u_star),
        "best_return": _tensor(refs["best_return"]),
        "min_steps": _tensor(refs["min_steps"]),
        "min_steps_levels": list(LEVELS),
        "exact": bool(refs["exact"]),
    }
    for key in ("delivered_bound", "horizon_bound", "delivered_optimum"):
        if key in refs:
            stored[key] = _tensor(refs[key])
    return refs, stored


def evaluation_references(stored: dict) -> dict:
    """The references :func:`uavrl.agents.evaluation.greedy_metrics` reads, rebuilt from their JSON form."""
    refs = {
        "best_return": _untensor(stored["best_return"]),
        "min_steps": _untensor(stored["min_steps"]),
        "exact": stored["exact"],
    }
    for key in ("delivered_bound", "horizon_bound", "delivered_optimum"):
        if key in stored:
            refs[key] = _untensor(stored[key])
    return refs


def compute_references(task: Task) -> dict:
    """A task's references as JSON (module doc of :mod:`uavrl.bench.tasks`): the certified quantities, the random
    policy's and the planner's per-start values and metrics, and the reference a score of 1 means."""
    began = time.process_time()
    _, stored = _start_references(task)
    refs = evaluation_references(stored)
    cfg = model(task)
    planner_name = "oracle" if cfg.energy == "none" else "planner"
    baselines = {}
    for name, policy in (
        ("random", RandomPolicy(seed=RANDOM_SEED)),
        (planner_name, OraclePolicy(cfg) if planner_name == "oracle" else PlannerPolicy(cfg)),
    ):
        played = _rollout(task, policy)
        values, _ = _values(task, played)
        baselines[name] = {"values": values.tolist(), "summary": _summary(task, played, refs)}
    if cfg.energy == "none" and refs["best_return"] is not None:
        reference = {"kind": "exact best return V*_H", "values": refs["best_return"].tolist()}
    elif cfg.energy != "none" and refs.get("delivered_optimum") is not None:
        reference = {"kind": "exact mission optimum", "values": refs["delivered_optimum"].tolist()}
    else:
        words = "oracle planner" if planner_name == "oracle" else "energy-aware planner"
        reference = {"kind": f"the {words} (no exact optimum fits)", "values": baselines[planner_name]["values"]}
    return {
        "starts": stored,
        "baselines": baselines,
        "planner": planner_name,
        "reference": reference,
        "value": "discounted gain J (gamma {})".format(task.gamma)
        if cfg.energy == "none"
        else "delivered data (bit/Hz)",
        "horizon": cfg.max_steps,
        "cpu_seconds": time.process_time() - began,
    }


def task_references(task: Task, cache_dir: Path | None) -> dict:
    """:func:`compute_references`, from the cache when it holds them (:mod:`uavrl.bench.cache`)."""
    return cache.cached(cache_dir, cache.entry_key(task), lambda: compute_references(task))


FLOOR = 0.1  # a start's gap from random to the reference counts as at least this share of the task's mean gap


def normalised(values, random_values, reference_values) -> list[float]:
    """Per start ``(value - random) / (reference - random)``, with the random policy's and the reference's values
    of that start, so the random policy scores 0 and the reference 1 on every start.  A start where random comes
    within :data:`FLOOR` of the task's mean gap of the reference (the start is at or near U* already) is divided by
    that floor instead, so no start's score explodes."""
    gaps = [high - low for low, high in zip(random_values, reference_values, strict=True)]
    mean_gap = sum(gaps) / len(gaps)
    if not mean_gap > 0:
        raise ValueError(
            f"the reference does not beat the random policy (mean gap {mean_gap}): no score can be normalised"
        )
    return [(v - low) / max(gap, FLOOR * mean_gap) for v, low, gap in zip(values, random_values, gaps, strict=True)]


def score_task(task: Task, policies, references: dict, name: str = "the submission") -> dict:
    """One task's entry of a results file for ``policies`` (one per independent training run); a one-line ValueError
    naming the submission ``name`` for a policy that played a forbidden action wherever its ``action_mask`` forbade
    any (the env plays them as no move: nothing the policy chose would be scored).  A mask check per rollout: the
    scores of a policy that plays allowed actions are untouched."""
    refs = evaluation_references(references["starts"])
    values, scores, summaries = [], [], []
    for policy in policies:
        played = _rollout(task, policy)
        masked = ~played["steps"]["unmasked"]  # where a choice was forbidden
        if masked.any() and not played["steps"]["legal"][masked].any():
            raise InvalidOption(
                "policy_factory",
                message=f"{name}: its policy played an action that ('agents', 'action_mask') forbids wherever the mask "
                f"forbade any ({int(masked.sum())} UAV steps) on task {task.name}: the env plays such an action as no "
                "move; choose among the actions the mask allows",
            )
        run_values, _ = _values(task, played)
        values.append(run_values.tolist())
        scores.append(
            normalised(values[-1], references["baselines"]["random"]["values"], references["reference"]["values"])
        )
        summaries.append(_summary(task, played, refs))
    flat = [s for run in scores for s in run]
    return {
        "status": "scored",
        "values": values,
        "scores": scores,
        "mean_score": sum(flat) / len(flat),
        "summary": _mean_summary(summaries),
    }


def _mean_summary(summaries: list[dict]) -> dict:
    out = {}
    for key in dict.fromkeys(k for s in summaries for k in s):
        values = [s[key] for s in summaries if key in s]
        out[key] = min(values) if key == "eval/optimality_min" else sum(values) / len(values)
    return out


def suite_tasks(suite: str) -> list[Task]:
    """The tasks of ``suite`` (a suite's name), a one-line error naming the suites otherwise."""
    if not isinstance(suite, str) or suite not in SUITES:
        raise InvalidOption("suite", suite, f"give one of {SUITES_TEXT}")
    return SUITES[suite]


def check_submission(policy_factory, name, source, tasks, train_command, progress, cache_dir) -> None:
    """:func:`score_suite`'s arguments beside the suite and the budget, refused in one line before any work: what
    a results file will hold of them must be one line of text (:data:`uavrl.bench.results.TEXT`, as its reader
    demands), the tasks distinct names, the factory and ``progress`` callables."""
    if not callable(policy_factory):
        raise InvalidType("policy_factory", policy_factory, "give a callable env -> policy (module doc)")
    for argument, value in (("name", name), ("source", source), ("train_command", train_command)):
        if (value is not None or argument != "train_command") and not (TEXT.accepts(value) and value.strip()):
            raise InvalidOption(argument, value, TEXT.allowed.replace("it must be", "give") + ", not empty")
    if tasks is not None:
        names = list(tasks) if isinstance(tasks, (list, tuple)) else None
        if not names or not all(isinstance(task, str) for task in names):
            raise InvalidOption("tasks", tasks, "give a list of the suite's task names, or None for all")
        if len(set(names)) < len(names):
            raise InvalidOption("tasks", tasks, "a task is named twice")
    if progress is not None and not callable(progress):
        raise InvalidType("progress", progress, "give a callable taking one line, or None")
    if cache_dir is not None and not (isinstance(cache_dir, (str, PathLike)) and str(cache_dir)):
        raise InvalidOption("cache_dir", cache_dir, "give a directory's path, or None to keep no cache")


def score_suite(
    suite: str,
    policy_factory,
    *,
    name: str,
    budget: dict | None = None,
    source: str = "python",
    cache_dir: Path | None | cache.DefaultDir = cache.DEFAULT_DIR,
    tasks: list[str] | None = None,
    train_command: str | None = None,
    progress=None,
) -> dict:
    """Score the policies ``policy_factory`` makes (module doc) on every task of ``suite``: the results as a dict
    (:mod:`uavrl.bench.results`; :func:`uavrl.bench.results.save` writes them).

    Args:
        suite: a suite's name (:data:`uavrl.bench.tasks.SUITES`).
        policy_factory: ``env -> policy`` (or a list of policies, one per training run); raises
            :class:`NotApplicable` where it cannot act.
        name: the submission's name in tables and the leaderboard.
        budget: what training cost, as the submitter states it (``env_steps``, ``cpu_seconds``, ``gpu_seconds``:
            :func:`~uavrl.bench.tasks.check_budget`); refused in one line before any work where a value breaks its
            rule.
        source: how the policies were obtained (the command that reproduces the results).
        cache_dir: where the references are kept (None: computed, not kept; by default ``$UAVRL_BENCH_CACHE``, else
            ``~/.cache/uavrl/bench``).
        tasks: score only these tasks of the suite (the results then say the protocol is partial).
        train_command: the command that trained the policies, if any (carried into the results).
        progress: a callable given one line per task scored.
    """
    if isinstance(cache_dir, cache.DefaultDir):
        cache_dir = cache.default_dir()
    chosen = suite_tasks(suite)
    check_submission(policy_factory, name, source, tasks, train_command, progress, cache_dir)
    budget = check_budget(budget)
    if cache_dir is not None:
        cache.check_dir(cache_dir)  # before any reference is computed
    if tasks is not None:
        unknown = [t for t in tasks if t not in {task.name for task in chosen}]
        if unknown:
            raise InvalidOption("tasks", unknown[0], f"suite {suite} has {', '.join(t.name for t in chosen)}")
        chosen = [task for task in chosen if task.name in tasks]
    results = new_results(suite, name, budget, source, partial=tasks is not None)
    if train_command:
        results["submission"]["train_command"] = train_command
    for task in chosen:
        began = time.process_time()
        references = task_references(task, cache_dir)
        entry = {"task": task.name, "spec": task.spec(), "horizon": horizon(task)}
        entry["references"] = _reference_summary(references)
        try:
            policies = policy_factory(task_env(task))
        except NotApplicable as why:
            entry.update(status="n/a", reason=str(why))
        else:
            policies = policies if isinstance(policies, list) else [policies]
            if not policies or not all(callable(policy) for policy in policies):
                returned = policies[0] if len(policies) == 1 else policies
                raise InvalidType(
                    "policy_factory",
                    message=f"{name}: its policy_factory returned {returned!r} for task {task.name}: return a TorchRL "
                    "policy (it writes ('agents', 'action')), a list of them, or raise NotApplicable",
                )
            entry.update(score_task(task, policies, references, name))
        results["tasks"].append(entry)
        if progress is not None:
            progress(f"{_progress_line(entry)} ({time.process_time() - began:.1f} CPU s)")

    results["aggregate"] = aggregate(results)
    return results


def _reference_summary(references: dict) -> dict:
    """What a results file records of a task's references: the per-start reference and random values, the
    certified quantities, and the baselines' metrics."""
    starts = references["starts"]
    return {
        "value": references["value"],
        "reference": references["reference"],
        "random": references["baselines"]["random"]["values"],
        "planner": references["planner"],
        "planner_summary": references["baselines"][references["planner"]]["summary"],
        "u_star": starts["u_star"]["values"],
        "u_star_gap": starts["u_star_gap"],
        "min_steps": starts["min_steps"]["values"],
        "min_steps_levels": starts["min_steps_levels"],
        "min_steps_exact": starts["exact"],
        **{key: starts[key]["values"] for key in ("delivered_bound", "delivered_optimum") if starts.get(key)},
    }


def _progress_line(entry: dict) -> str:
    if entry["status"] != "scored":
        return f"{entry['task']}: n/a ({entry['reason']})"
    return f"{entry['task']}: mean normalised score {entry['mean_score']:.3f}"


def task_by_name(name: str) -> Task:
    """A task of any suite by its name."""
    if name not in TASKS:
        raise InvalidOption("task", name, f"give one of {', '.join(TASKS)}")
    return TASKS[name]
