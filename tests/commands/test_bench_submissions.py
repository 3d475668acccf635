"""What a submission states and plays, checked by the benchmark before it scores (no rliable needed: every case here
is refused, or scored by one task's :func:`~uavrl.bench.run.score_task`, before any aggregate).

One budget rule (:func:`uavrl.bench.tasks.check_budget`) for ``score_suite(budget=...)`` and the command line's
``budget.<key>=``; a policy factory must return policies; a policy must not play what its action mask forbids."""

import math

import pytest
import torch

from uavrl.bench.run import score_suite, score_task, task_references
from uavrl.bench.tasks import TASKS, check_budget

BAD_BUDGETS = [
    ({"env_steps": -5, "cpu_seconds": math.nan}, "budget.env_steps=-5 is invalid: it must be a whole number >= 0"),
    ({"cpu_seconds": math.nan}, "budget.cpu_seconds=nan is invalid: it must be a finite number >= 0"),
    ({"gpu_seconds": math.inf}, "budget.gpu_seconds=inf is invalid: it must be a finite number >= 0"),
    ({"env_steps": 2.7}, "budget.env_steps=2.7 is invalid: it must be a whole number >= 0"),
    ({"env_steps": True}, "budget.env_steps=true is invalid: it must be a whole number >= 0"),
    ({"env_steps": "many"}, "budget.env_steps=many is invalid: it must be a whole number >= 0"),
    ({"steps": 2}, "budget.steps=2 is invalid: unknown key; a budget states env_steps, cpu_seconds, gpu_seconds"),
]


def oracle(env):
    from uavrl.agents.baselines import OraclePolicy

    return OraclePolicy(env.cfg)


@pytest.mark.parametrize("budget, message", BAD_BUDGETS, ids=[m.split(" is")[0] for _, m in BAD_BUDGETS])
def test_score_suite_refuses_a_bad_budget_before_any_work(budget, message, tmp_path):
    with pytest.raises(ValueError) as refused:
        score_suite("tiny", oracle, name="sub", budget=budget, cache_dir=tmp_path)
    assert str(refused.value) == message
    assert list(tmp_path.iterdir()) == [], "references were computed before the budget was checked"


@pytest.mark.parametrize(
    "typed, message",
    [
        ("budget.env_steps=2.7", "budget.env_steps=2.7 is invalid: it must be a whole number >= 0"),
        ("budget.env_steps=-5", "budget.env_steps=-5 is invalid: it must be a whole number >= 0"),
        ("budget.cpu_seconds=nan", "budget.cpu_seconds=nan is invalid: it must be a finite number >= 0"),
        ("budget.gpu_seconds=1e400", "budget.gpu_seconds=1e400 is invalid: it must be a finite number >= 0"),
    ],
)
def test_the_command_line_refuses_a_bad_budget_as_python_does_before_torch(typed, message, bench_refusal_before_torch):
    assert bench_refusal_before_torch(["tiny", "agent=random", typed]) == (message, False)


def test_a_budget_is_read_as_numbers_with_whole_env_steps():
    from uavrl.bench.__main__ import parse

    assert check_budget(None) == {}
    assert check_budget({"env_steps": 3.0, "cpu_seconds": 0}) == {"env_steps": 3, "cpu_seconds": 0.0}
    settings = parse(["agent=random", "budget.env_steps=1e6", "budget.cpu_seconds=12.5"])
    assert (settings["budget.env_steps"], settings["budget.cpu_seconds"]) == (1_000_000, 12.5)
    assert type(settings["budget.env_steps"]) is int
    with pytest.raises(TypeError, match=r"^budget=\[1\] is invalid: give a dict of env_steps"):
        check_budget([1])


def test_a_factory_that_returns_no_policy_is_refused_naming_the_submission():
    """TorchRL's rollout would play its random policy for ``None``: scored as the submission's, without a word."""
    with pytest.raises(TypeError) as refused:
        score_suite("tiny", lambda env: None, name="sub", cache_dir=None, tasks=["tiny_3x3"])
    assert str(refused.value) == (
        "sub: its policy_factory returned None for task tiny_3x3: return a TorchRL policy (it writes ('agents', "
        "'action')), a list of them, or raise NotApplicable"
    )


def playing(choose):
    """A policy that plays ``choose(mask [B, N, A]) -> [B, N]``."""

    def policy(td):
        td.set(("agents", "action"), choose(td.get(("agents", "action_mask"))))
        return td

    return policy


@pytest.fixture(scope="module")
def tiny():
    task = TASKS["tiny_3x3"]
    return task, task_references(task, None)


def test_a_policy_that_plays_what_its_mask_forbids_is_refused(tiny):
    """Wherever its mask forbids an action, it plays one: the env plays those as no move, so its score would be
    a policy that stays put, not what it chose."""
    task, references = tiny
    forbidden_first = playing(lambda mask: (~mask).float().argmax(-1))  # where nothing is forbidden: action 0
    with pytest.raises(ValueError) as refused:
        score_task(task, [forbidden_first], references, "sub")
    assert str(refused.value).startswith(
        "sub: its policy played an action that ('agents', 'action_mask') forbids wherever the mask forbade any ("
    )
    assert str(refused.value).endswith(
        "UAV steps) on task tiny_3x3: the env plays such an action as no move; choose among the actions the mask allows"
    )


def test_legal_policies_are_scored_as_before(tiny):
    """The check only reads the rollout: the oracle and the random policy score exactly the values their references
    hold (computed by the same rollouts, unchecked), and a policy that always moves up (forbidden on the top row
    only) is scored."""
    from uavrl.agents.baselines import OraclePolicy, RandomPolicy
    from uavrl.bench.run import RANDOM_SEED, model

    task, references = tiny
    for name, policy in (("oracle", OraclePolicy(model(task))), ("random", RandomPolicy(seed=RANDOM_SEED))):
        assert score_task(task, [policy], references)["values"] == [references["baselines"][name]["values"]]
    up = score_task(task, [playing(lambda mask: torch.zeros(mask.shape[:-1], dtype=torch.long))], references)
    assert up["status"] == "scored"


BAD_ARGUMENTS = [
    (dict(name=None), "name=None is invalid: give one line of text, not empty"),
    (dict(name=""), "name='' is invalid: give one line of text, not empty"),
    (dict(name="a\nb"), "name='a\\nb' is invalid: give one line of text, not empty"),
    (dict(source=None), "source=None is invalid: give one line of text, not empty"),
    (dict(train_command=123), "train_command=123 is invalid: give one line of text, not empty"),
    (dict(tasks=[]), "tasks=[] is invalid: give a list of the suite's task names, or None for all"),
    (dict(tasks="tiny_3x3"), "tasks='tiny_3x3' is invalid: give a list of the suite's task names, or None for all"),
    (dict(tasks=["tiny_3x3", "tiny_3x3"]), "tasks=['tiny_3x3', 'tiny_3x3'] is invalid: a task is named twice"),
    (dict(tasks=["nope"]), "tasks='nope' is invalid: suite tiny has tiny_3x3, tiny_energy"),
    (dict(progress="yes"), "progress='yes' is invalid: give a callable taking one line, or None"),
    (dict(cache_dir=""), "cache_dir='' is invalid: give a directory's path, or None to keep no cache"),
    (
        dict(suite=["tiny"]),
        "suite=['tiny'] is invalid: give one of paper, core, energy, zero_shot, city, decentralised, tiny",
    ),
    (dict(policy_factory="oracle"), "policy_factory='oracle' is invalid: give a callable env -> policy (module doc)"),
]


@pytest.mark.parametrize("changes, message", BAD_ARGUMENTS, ids=[m.split(" is")[0] for _, m in BAD_ARGUMENTS])
def test_score_suite_refuses_a_bad_argument_in_one_line_before_any_work(changes, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # cache_dir='' would be the working directory
    arguments = dict(suite="tiny", policy_factory=oracle, name="sub", cache_dir=tmp_path / "cache") | changes
    with pytest.raises((ValueError, TypeError)) as refused:
        score_suite(arguments.pop("suite"), arguments.pop("policy_factory"), **arguments)
    assert str(refused.value) == message
    assert list(tmp_path.iterdir()) == [], "something was written before the arguments were checked"


@pytest.mark.parametrize(
    ("typed", "message"),
    [
        ("tasks=[]", "tasks=[] is invalid: give task names, e.g. tasks=[tiny_3x3] (python -m uavrl.bench list)"),
        ("tasks=[[tiny_3x3]]", "tasks=[[tiny_3x3]] is invalid: give task names, e.g. tasks=[tiny_3x3] (python -m"),
        ("tasks=[tiny_3x3,tiny_3x3]", "tasks=[tiny_3x3,tiny_3x3] is invalid: a task is named twice"),
    ],
)
def test_the_command_line_refuses_a_bad_task_list(typed, message):
    from uavrl.bench.__main__ import parse

    with pytest.raises(ValueError) as refused:
        parse(["agent=random", typed])
    assert str(refused.value).startswith(message)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["tiny", "agent=random", "cache_dir="], "cache_dir= is invalid: give a value (cache_dir=<...>)"),
        (["tiny", "agent=random", "out="], "out= is invalid: give a value (out=<...>)"),
        (["leaderboard", "results="], "results= is invalid: give a path"),
        (["list", "paper"], "paper is invalid: list takes no arguments; it prints every suite's tasks"),
    ],
)
def test_the_command_line_refuses_an_empty_path_or_a_stray_argument(argv, message, tmp_path, monkeypatch):
    from uavrl.bench.__main__ import main

    monkeypatch.chdir(tmp_path)  # an empty path would be the working directory
    with pytest.raises(ValueError) as refused:
        main(argv)
    assert str(refused.value) == message and not any(tmp_path.iterdir())


def test_an_outside_policy_of_a_city_model_acts_in_that_models_held_out_cities_only(tmp_path):
    """``benchmarks/score_outside.py``: the model arguments ``sb3_yardstick.py --save`` keeps beside an SB3 model
    rebuild the model it trained on (read as data, checked by the script's parser); in a city, a policy acts in the
    ``city`` suite's held-out cities of that model (another environment, seed or the high-rise task's S and E
    height) and in no other team or grid (``run_city``)."""
    import json
    import sys
    from pathlib import Path

    from uavrl.agents.schema import run_city
    from uavrl.bench.run import model
    from uavrl.envs import make_config

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        from sb3_yardstick import model_flags, model_options, parse_args
        from score_outside import sb3_model
    finally:
        sys.path.pop(0)
    flags = model_flags(parse_args("--grid 10 10 --uavs 6 --city urban --altitudes 30 60 100 200 300".split()))
    (tmp_path / "ppo_seed0.json").write_text(json.dumps(flags))
    trained_on = make_config(**model_options(parse_args(sb3_model(tmp_path / "ppo_seed0.json"))))
    assert trained_on.city == "urban" and trained_on.num_levels == 5 and trained_on.num_uavs == 6
    for name, acts in [("city_urban_n6", True), ("city_highrise_n6", True), ("city_urban_n10", False)]:
        acting = model(TASKS[name]).replace(max_steps=trained_on.max_steps, reward=trained_on.reward)
        assert (acting.replace(**run_city(acting, trained_on)) == trained_on) is acts, name
    assert sb3_model(tmp_path / "missing.json") == []  # the paper's 6x6 model, as before the file
    (tmp_path / "bad.json").write_text(json.dumps({"grid": [6, 6]}))
    with pytest.raises(SystemExit, match="bad.json: not the model arguments sb3_yardstick.py writes"):
        sb3_model(tmp_path / "bad.json")


def test_an_outside_run_on_local_observations_is_named_and_reproduced_by_what_it_heard():
    """``benchmarks/score_outside.py``: BenchMARL runs of one algorithm at different radii get their own results files
    and names (as the DQN's rows name theirs), and their command trains on the same local observations; a central run
    keeps the name it had."""
    import sys
    from pathlib import Path

    from uavrl.envs import make_config

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        from score_outside import _local
    finally:
        sys.path.pop(0)
    n6 = {"grid": (10, 10), "num_uavs": 6}
    assert _local(make_config("paper", **n6)) == ("", "", "")
    assert _local(make_config("paper", **n6, observation="local", comm_radius=4)) == (
        " env.observation=local env.comm_radius=4",
        " local (n6-r4)",
        "-local-r4",
    )
    assert _local(make_config("paper", **n6, observation="local")) == (
        " env.observation=local",
        " local (n6-full)",
        "-local-full",
    )
    messages = make_config("paper", grid=(20, 20), num_uavs=10, observation="local", comm_radius=2, message_size=4)
    assert _local(messages) == (
        " env.observation=local env.comm_radius=2 env.message_size=4",
        " local (n10-r2-m4)",
        "-local-r2-m4",
    )
