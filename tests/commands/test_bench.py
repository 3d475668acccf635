"""The benchmark (uavrl.bench): held-out starts, the references' cache, rliable's statistics, scoring, the command."""

import json
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from uavrl.bench.run import NotApplicable, score_suite
from uavrl.bench.stats import BOOTSTRAP_SEED, aggregate, probability_of_improvement, score_matrix
from uavrl.bench.tasks import SEED_BASE, SUITES, TASKS, training_seed_bound

pytest.importorskip("rliable")


def oracle(env):
    from uavrl.agents.baselines import OraclePolicy

    return OraclePolicy(env.cfg)


def random_policy(env):
    from uavrl.agents.baselines import RandomPolicy

    return RandomPolicy(seed=0)


@pytest.fixture(scope="module")
def scored(tmp_path_factory):
    """The tiny suite scored for the oracle and the random policy, references cached in a fresh directory."""
    directory = tmp_path_factory.mktemp("cache")
    return {
        "cache": directory,
        "oracle": score_suite("tiny", oracle, name="oracle", cache_dir=directory),
        "random": score_suite("tiny", random_policy, name="random", cache_dir=directory),
    }


def test_held_out_starts_are_disjoint_from_every_training_seed():
    """Every task's start streams lie in [2^62, 2^63), one block per task, above every world seed a training command
    draws (seed < 2^17, within the step budget) and apart from the evaluation's eval.seed."""
    from uavrl.agents.dqn.agent import DQNAgent
    from uavrl.agents.evaluation import EVAL_SEED, NUM_STARTS
    from uavrl.schema import STEP_BUDGET

    blocks = sorted((task.seed, task.seed + task.num_starts) for task in TASKS.values())
    assert all(a_end <= b_start for (_, a_end), (b_start, _) in zip(blocks, blocks[1:], strict=False))
    assert SEED_BASE <= blocks[0][0] and blocks[-1][1] <= 2**63
    bound = training_seed_bound(2**17, STEP_BUDGET)
    assert bound < SEED_BASE and EVAL_SEED + NUM_STARTS < SEED_BASE
    # the bound holds for the DQN's own seeding at its extremes (the last seed, the last possible iteration)
    for seed, iteration in ((0, 0), (2**17 - 1, 0), (2**17 - 1, STEP_BUDGET - 1)):
        world_seed = DQNAgent._world_seed(SimpleNamespace(seed=seed), iteration)
        assert world_seed + 2**24 - 1 < bound
    # and for the tabular learner's (seed + episode x runs + run, at most one seed per team step)
    assert 2**17 - 1 + STEP_BUDGET < bound


def test_scores_are_normalised_from_random_to_the_exact_reference(scored):
    oracle_results, random_results = scored["oracle"], scored["random"]
    by_task = {t["task"]: t for t in oracle_results["tasks"]}
    # the random policy is the zero of every task, by construction, to rounding
    assert all(abs(t["mean_score"]) < 1e-9 for t in random_results["tasks"])
    tiny = by_task["tiny_3x3"]
    assert tiny["references"]["reference"]["kind"] == "exact best return V*_H"
    assert 0.95 < tiny["mean_score"] <= 1 + 1e-9
    # no policy beats the exact optimum of a start
    assert all(v <= r + 1e-9 for v, r in zip(tiny["values"][0], tiny["references"]["reference"]["values"], strict=True))
    energy = by_task["tiny_energy"]
    assert energy["references"]["reference"]["kind"] == "exact mission optimum"
    assert energy["mean_score"] < 1  # the oracle ignores the batteries
    assert len(tiny["values"][0]) == TASKS["tiny_3x3"].num_starts
    assert oracle_results["environment"]["torch"] and oracle_results["submission"]["name"] == "oracle"


def test_aggregates_are_rliables_own(scored):
    from rliable import library, metrics

    results = scored["oracle"]
    matrix, names = score_matrix(results)
    assert matrix.shape == (32, 2) and names == ["tiny_3x3", "tiny_energy"]
    agg = results["aggregate"]
    assert agg["iqm"] == metrics.aggregate_iqm(matrix)
    state = np.random.get_state()
    np.random.seed(BOOTSTRAP_SEED)
    point, interval = library.get_interval_estimates(
        {"x": matrix}, lambda x: np.array([metrics.aggregate_iqm(x)]), reps=agg["reps"]
    )
    np.random.set_state(state)
    assert agg["iqm"] == point["x"][0]
    assert agg["iqm_ci"] == [interval["x"][0][0], interval["x"][1][0]]
    assert aggregate(results) == agg  # the same scores, the same intervals, bit for bit


def test_probability_of_improvement(scored):
    p = probability_of_improvement(scored["oracle"], scored["random"])
    assert p["tasks"] == ["tiny_3x3", "tiny_energy"] and p["probability"] > 0.8 and p["ci"][0] <= p["probability"]


def test_a_policy_that_cannot_act_is_not_applicable_not_failed(scored):
    def only_small(env):
        if env.cfg.energy != "none":
            raise NotApplicable("no energy")
        return oracle(env)

    results = score_suite("tiny", only_small, name="small", cache_dir=scored["cache"])
    statuses = {t["task"]: t["status"] for t in results["tasks"]}
    assert statuses == {"tiny_3x3": "scored", "tiny_energy": "n/a"}
    assert results["aggregate"]["tasks"] == ["tiny_3x3"]


def test_suites_hold_the_tasks_asked_for():
    assert [t.name for t in SUITES["paper"]] == ["paper_6x6", "reference_code"]
    local = {t.name: dict(t.options) for t in SUITES["decentralised"]}
    assert {o["comm_radius"] for o in local.values()} == {0.0, 1.0, 2.0, 4.0, None}
    assert all(o["observation"] == "local" for o in local.values()) and len(local) == 12
    assert local["dec_n10_20x20_r2_m4"]["message_size"] == 4
    assert {dict(t.options)["num_uavs"] for t in SUITES["zero_shot"]} == {2, 6, 10, 20, 50}
    assert {dict(t.options)["layout"] for t in SUITES["zero_shot"]} == {"line", "random"}


def test_rescoring_a_checkpoint_reproduces_its_results_bit_for_bit(tmp_path, scored):
    """A tiny tabular run scored twice by the command: the same file but for nothing; n/a where it cannot act."""
    run = tmp_path / "run"
    python = sys.executable
    subprocess.run(
        [python, "-m", "uavrl.train", "agent=tabular", "env.grid=[3,3]", "agent.episodes=4", "env.max_steps=50",
         "agent.runs=2", "eval.num_starts=4", "progress=false", f"run_dir={run}"],
        check=True, capture_output=True, cwd=tmp_path,
    )  # fmt: skip
    outputs = []
    for k in range(2):
        out = tmp_path / f"r{k}.json"
        subprocess.run(
            [python, "-m", "uavrl.bench", "tiny", f"checkpoint={run}", f"out={out}", f"cache_dir={scored['cache']}"],
            check=True, capture_output=True, cwd=tmp_path,
        )  # fmt: skip
        outputs.append(json.loads(out.read_text()))
    assert outputs[0] == outputs[1]
    tasks = {t["task"]: t for t in outputs[0]["tasks"]}
    assert tasks["tiny_energy"]["status"] == "n/a" and tasks["tiny_3x3"]["status"] == "scored"
    assert len(tasks["tiny_3x3"]["values"]) == 2  # one row per independent run of the tabular agent
    assert (
        outputs[0]["submission"]["budget"]["env_steps"] == json.loads((run / "metrics.json").read_text())["env_steps"]
    )
    compared = subprocess.run(
        [python, "-m", "uavrl.bench", "compare", str(tmp_path / "r0.json"), str(tmp_path / "r1.json")],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    assert "P(tabular" in compared.stdout and "= 0.500" in compared.stdout


@pytest.mark.parametrize(
    "args, message",
    [
        (["tiny", "agent=foo"], "agent=foo is invalid: give one of random, oracle, planner"),
        (["tiny"], "give one of checkpoint=<run dir> or agent=<baseline>"),
        (["cor", "agent=random"], "'cor' is invalid: give a suite"),
        (["tiny", "agent=random", "budget.env_steps=many"], "budget.env_steps=many is invalid"),
        (["tiny", "agent=random", "horizon=3"], "horizon=3 is invalid: unknown setting"),
        (["tiny", "checkpoint=no/such/run"], "checkpoint=no/such/run does not exist"),
    ],
)
def test_bad_input_is_one_line_before_torch(args, message, bench_refusal_before_torch):
    line, torch_loaded = bench_refusal_before_torch(args)
    assert message in line and not torch_loaded


def test_leaderboard_page_from_results_files(tmp_path, scored, monkeypatch):
    from uavrl.bench import leaderboard
    from uavrl.bench.leaderboard import MARKER, suite_table, write
    from uavrl.bench.results import save

    for name in ("oracle", "random"):
        save(scored[name], tmp_path / "results" / f"{name}.json")
    lines = suite_table("tiny", [scored["random"], scored["oracle"]])
    assert lines[2].startswith("| oracle |") and "`python`" in lines[2]  # best IQM first, its command
    page = tmp_path / "docs" / "leaderboard.md"
    page.parent.mkdir()
    page.write_text("# Leaderboard\n\nkept\n\n" + MARKER + "\nold\n")
    write(tmp_path / "results", page)
    text = page.read_text()
    assert text.startswith("# Leaderboard\n\nkept") and "\nold\n" not in text and "### Not yet scored" not in text
    threads = scored["oracle"]["environment"]["torch_threads"]
    assert f"{threads} torch thread{'' if threads == 1 else 's'}." in text  # where the rows were scored
    waiting = [("oracle", "tiny", "already scored"), ("an agent to come", "tiny", "python -m uavrl.bench tiny ...")]
    monkeypatch.setattr(leaderboard, "NOT_YET_SCORED", waiting)
    write(tmp_path / "results", page)
    text = page.read_text()
    assert "### Not yet scored" in text and "| an agent to come |" in text and "already scored" not in text
