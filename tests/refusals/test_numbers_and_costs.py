"""Bad numbers and sizes, refused before any work: one line naming the setting, its value and what is allowed.

Physics that would give NaN, infinite or everywhere-zero rates (uavrl/envs/limits.py), and runs whose memory or
team steps exceed a budget (uavrl/costs.py, World's memory_budget), from the command line and the Python API.
"""

import math
import random
import re

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from uavrl.agents.baselines import RandomPolicy
from uavrl.agents.evaluation import evaluate
from uavrl.envs import InvalidOption, UAVSpectrumEnv, World, make_config
from uavrl.envs.limits import world_bytes

# (command and overrides, words the one-line error must contain)
CLI_CASES = [
    ("train ++env.p_u=1e308", "env.p_u=1e+308 is invalid: the SNR product g1 g2"),
    ("train ++env.p_u=1e-308", "env.p_u=1e-308 is invalid: a UAV in the best cell adds only"),
    ("train ++env.cell_size=1e-300", "env.cell_size=1e-300 is invalid: the channel gain g0 d^-alpha"),
    ("train ++env.cell_size=1e300", "env.cell_size=1e+300 is invalid: a UAV in the best cell"),
    ("train ++env.noise=1e-300", "env.noise=1e-300 is invalid: the SNR product"),
    ("train ++env.p_pt=1e-300", "env.p_pt=1e-300 is invalid: a UAV in the best cell"),
    ("train ++env.p_s=1e300", "env.p_s=1e+300 is invalid: the SNR product"),
    ("train ++env.alpha=200", "env.alpha=200 is invalid"),
    ("train ++env.altitude=1e-300", "env.altitude=1e-300 is invalid: the channel gain"),
    ("train ++env.g0=1e300", "env.g0=1e+300 is invalid"),
    ("train ++env.beta1=1e40", "env.beta1=1e+40 is invalid: delta rewards"),
    ("train env.layout=random ++env.p_s=1e-290", "env.p_s=1e-290 is invalid"),
    ("train env=reference_code ++env.reference_gain=1e-300", "env.reference_gain=1e-300 is invalid"),
    ("train env=reference_code env.grid=[16,6]", "env.grid=(16, 6) is invalid: E sits on a UAV cell"),
    ("train env=reference_code env.num_uavs=1 agent=random", "env.num_uavs=1 is invalid with the authors'"),
    ("train env.max_steps=1000000000000", "env.max_steps=1000000000000 is invalid: training"),
    ("train agent.episodes=1000000000000", "raise train.step_budget=<steps>"),
    ("train agent=dqn env.max_steps=1000000000000", "raise agent.memory_budget=<bytes>"),
    ("train agent=dqn agent.iterations=1000000000000", "agent.iterations=1000000000000 is invalid"),
    ("train agent=dqn agent.buffer_size=10000000000", "agent.buffer_size=10000000000 is invalid: the replay buffer"),
    ("train agent=dqn agent.worlds=100000000", "agent.worlds=100000000 is invalid"),
    ("train eval.num_starts=1000000000", "eval.num_starts=1000000000 is invalid: the evaluation"),
    ("train agent=dqn eval.num_starts=1000000000", "eval.num_starts=1000000000 is invalid: the evaluation"),
    ("train agent=random eval.horizon=1000000000000", "eval.horizon=1000000000000 is invalid"),
    ("train agent.runs=100000000", "agent.runs=100000000 is invalid"),
    # the evaluation's bound tables on 1000x1000 are estimated up front (they fit the default budget)
    ("train agent=dqn env.grid=[1000,1000] agent.memory_budget=1000000000", "over agent.memory_budget=1000000000"),
    ("train eval.video=true eval.video_starts=1000", "eval.video_starts=1000 is invalid: the video's frames"),
    # evaluate and render refuse before reading the checkpoint (none here): no model needs less than these
    ("evaluate checkpoint=run eval.num_starts=1000000000", "eval.num_starts=1000000000 is invalid: the evaluation"),
    ("evaluate checkpoint=run eval.video=true eval.video_starts=100000", "eval.video_starts=100000 is invalid"),
    ("render checkpoint=run eval.video_starts=1000000000", "eval.video_starts=1000000000 is invalid: the video"),
    ("train train.step_budget=0", "train.step_budget=0 is invalid"),
    ("train agent=oracle agent.memory_budget=0", "agent.memory_budget=0 is invalid"),
    ("reproduce table2 steps=1000000000000", "steps=1000000000000 is invalid: training on 2x2"),
    ("reproduce table2 episodes=1000000000000", "raise step_budget=<steps>"),
    ("reproduce table2 eval_starts=1000000000", "eval_starts=1000000000 is invalid: the evaluation"),
    ("reproduce table2 runs=100000000", "runs=100000000 is invalid: the team Q tables on 2x2"),
    ("reproduce table2 grids=[2] num_uavs=21 steps=10", "num_uavs=21 is invalid"),
    ("reproduce table2 memory_budget=0", "memory_budget=0 is invalid"),
    ("reproduce table2 step_budget=-1", "step_budget=-1 is invalid"),
    # the round's options: n-step returns, the lookahead, the demonstrations; an energy model's battery
    (
        "train agent=dqn agent.n_step=1000000000000",
        "error: agent.n_step=1000000000000 is invalid with env.max_steps=30: a target sums at most the rewards of its "
        "episode; give a whole number in [1, 30]",
    ),
    (
        "train agent=dqn eval.lookahead=12 eval.lookahead_width=0",
        "error: eval.lookahead=12 is invalid: the lookahead's deepest level, K^eval.lookahead configurations a start "
        "(eval.num_starts = 64; with eval.lookahead 12, K 36) needs about 4.1e+24 bytes, over "
        "agent.memory_budget=4294967296: lower eval.lookahead, give eval.lookahead_width=<candidates per node>, or "
        "raise agent.memory_budget=<bytes>",
    ),
    (
        "train agent=dqn eval.lookahead=12",
        "error: eval.lookahead=12 is invalid: the lookahead's deepest level, K^eval.lookahead configurations a start "
        "(eval.num_starts = 64; with eval.lookahead 12, K 8) needs about",
    ),
    (
        "train agent=dqn eval.lookahead=1000000000",
        "error: eval.lookahead=1000000000 is invalid: it must be a whole number in [0, 100]",
    ),
    (
        "train agent=dqn agent.network=set agent.mixer=vdn agent.demonstrations=oracle "
        "agent.demo_transitions=1000000000000",
        "error: agent.demo_transitions=1000000000000 is invalid: the oracle's demonstrations (agent.demo_transitions "
        "= 1,000,000,000,000; with env.num_uavs 2) needs about",
    ),
    (
        "train agent=dqn env.energy=rotary_wing env.base=[-1,0] env.battery_wh=1e12",
        "error: env.battery_wh=1e12 is invalid: the evaluation (eval.num_starts x eval.horizon (null: the whole "
        "mission) = 64 x 27,100,895,583,948; with the cells of env.grid 36, env.num_uavs 2) needs about 1.4e+18 bytes, "
        "over agent.memory_budget=4294967296: change env.battery_wh, give eval.horizon=<smaller>, or raise "
        "agent.memory_budget=<bytes>",
    ),
    (
        "train env.energy=follow_up env.base=[-1,0] env.recharge_steps=5 env.num_spares=1000000 agent=dqn",
        "error: env.num_spares=1000000 is invalid: the training worlds",
    ),
]


@pytest.mark.parametrize("line, words", CLI_CASES, ids=[line for line, _ in CLI_CASES])
def test_command_line_numbers_are_refused_at_once(line, words, tmp_path, command_exit, capsys):
    """Refused before any work (how long it takes is benchmarks/bad_override_latency.py's to measure)."""
    error = command_exit(line, tmp_path)
    assert isinstance(error, str) and error.startswith("error: ") and "\n" not in error, error
    assert words in error, error
    assert capsys.readouterr() == ("", ""), "something ran (a progress line, a warning)"
    assert sorted(p.name for p in tmp_path.iterdir()) == [], "a refused command wrote files"


@pytest.mark.parametrize(
    "overrides",
    [
        [],
        ["agent=dqn"],
        ["agent=random"],
        ["agent=oracle", "env.grid=[10,10]", "env.num_uavs=6"],
        ["agent=dqn", "env.grid=[1000,1000]", "train.time_budget=3"],
        ["agent=tabular", "agent.method=value_iteration"],
        *([f"scenario={name}", f"agent={agent}"] for name, agent in (("large_20x20", "dqn"), ("n6_10x10", "dqn"))),
        *([f"scenario={name}", "agent=tabular"] for name in ("paper_6x6", "rayleigh", "reference_code")),
        ["scenario=random_layouts", "agent=dqn"],
        ["env=reference_code", "agent=random"],
    ],
    ids=str,
)
def test_the_shipped_settings_pass_the_cost_checks(overrides, compose_cfg):
    """The shipped settings pass, and the same settings with a memory budget of one byte do not: the checks that
    pass them do count what these settings cost."""
    from uavrl.train import check_settings

    check_settings(compose_cfg(*overrides))
    with pytest.raises(ValueError, match=r"memory_budget"):
        check_settings(compose_cfg(*overrides, "agent.memory_budget=1"))


def test_the_paper_protocol_passes_the_cost_checks(compose_cfg):
    """The paper's protocol passes; with a budget of one team step, or of one byte, it is refused: the checks that
    pass it do count its steps and its memory."""
    from uavrl.reproduce import check_settings

    check_settings(compose_cfg("overwrite=true", config_name="reproduce"))
    for budget in ("step_budget", "memory_budget"):
        with pytest.raises(ValueError, match=budget):
            check_settings(compose_cfg("overwrite=true", f"{budget}=1", config_name="reproduce"))


def actions(env):
    return TensorDict({("agents", "action"): torch.zeros(env.num_worlds, env.num_uavs, dtype=torch.long)}, [2])


def reset_with(mask):
    env = UAVSpectrumEnv(batch_size=2, grid=(3, 3))
    return env.reset(TensorDict({"_reset": mask}, batch_size=[2]))


def partly_reset_then_step():
    env = UAVSpectrumEnv(batch_size=2, grid=(3, 3))
    env.reset(TensorDict({"_reset": torch.zeros(2, 1, dtype=torch.bool)}, batch_size=[2]))
    return env.step(actions(env))


def stepped_without_action():
    env = UAVSpectrumEnv(batch_size=2, grid=(3, 3))
    env.reset()
    return env.step(TensorDict({}, batch_size=[2]))


# (call, exception type, words)
API_CASES = [
    (lambda: UAVSpectrumEnv(batch_size=True), InvalidOption, "batch_size=True is invalid"),
    (lambda: UAVSpectrumEnv(batch_size=2.0), InvalidOption, "batch_size=2.0 is invalid"),
    (lambda: UAVSpectrumEnv(batch_size=torch.tensor(4)), InvalidOption, "batch_size=tensor(4) is invalid"),
    (lambda: UAVSpectrumEnv(batch_size=[2, 3]), InvalidOption, "batch_size=[2, 3] is invalid"),
    (lambda: UAVSpectrumEnv(device="mps"), InvalidOption, "device='mps' is invalid"),
    (lambda: UAVSpectrumEnv(device="meta"), InvalidOption, "device='meta' is invalid"),
    (lambda: UAVSpectrumEnv(batch_size=10**9), InvalidOption, "batch_size=1000000000 is invalid"),
    (
        lambda: UAVSpectrumEnv(grid=(1000, 1000), batch_size=64, memory_budget=10**9),
        InvalidOption,
        "raise memory_budget",
    ),
    (lambda: UAVSpectrumEnv(memory_budget=0), InvalidOption, "memory_budget=0 is invalid"),
    (lambda: World(make_config(), batch_size=10**9), InvalidOption, "batch_size=1000000000 is invalid"),
    (lambda: UAVSpectrumEnv(p_u=1e308), InvalidOption, "p_u=1e+308 is invalid"),
    (lambda: UAVSpectrumEnv(p_u=1e-308), InvalidOption, "p_u=1e-308 is invalid"),
    (lambda: UAVSpectrumEnv(cell_size=1e-300), InvalidOption, "cell_size=1e-300 is invalid"),
    (lambda: UAVSpectrumEnv(preset="reference_code", alpha=100.0), InvalidOption, "alpha=100.0 is invalid"),
    (lambda: UAVSpectrumEnv(layout="random", fading="rayleigh", g0=1e200), InvalidOption, "g0=1e+200 is invalid"),
    (lambda: UAVSpectrumEnv(direct_links=True, p_pt=1e300), InvalidOption, "p_pt=1e+300 is invalid"),
    (stepped_without_action, InvalidOption, "step() got no ('agents', 'action')"),
    (lambda: reset_with(torch.ones(2, 2, dtype=torch.bool)), InvalidOption, "'_reset' has shape (2, 2)"),
    (lambda: reset_with(torch.ones(2, 1)), InvalidOption, "'_reset' has dtype torch.float32"),
    (lambda: reset_with(torch.ones(2, 1, dtype=torch.long)), InvalidOption, "'_reset' has dtype torch.int64"),
    (lambda: reset_with(torch.ones(2, 1, dtype=torch.bool, device="meta")), InvalidOption, "'_reset' has device meta"),
    (partly_reset_then_step, RuntimeError, "before every world was reset"),
    (
        lambda: evaluate(RandomPolicy(), make_config(), num_starts=10**9),
        InvalidOption,
        "lower num_starts, or raise memory_budget",
    ),
    (
        lambda: evaluate(RandomPolicy(), make_config(), horizon=10**12),
        InvalidOption,
        "lower horizon, or raise memory_budget",
    ),
]


# memory refusals name the argument that grows it: the worlds where one fits, else the spares, the team or the grid
ENERGY = dict(energy="follow_up", base=(-1, 0), recharge_steps=3)
API_CASES += [
    (
        lambda: UAVSpectrumEnv(batch_size=2, grid=(3, 3), num_spares=10**6, **ENERGY),
        InvalidOption,
        "num_spares=1000000 is invalid: 2 worlds of 1000002 UAVs on 3x3 need about 200,002,980,015,876 bytes (182 "
        "TiB), over memory_budget=4,294,967,296 bytes: lower num_spares, or raise memory_budget",
    ),
    (
        lambda: UAVSpectrumEnv(batch_size=2, grid=(100_000, 100_000)),
        InvalidOption,
        "grid=(100000, 100000) is invalid: 2 worlds of 2 UAVs on 100000x100000 need about 10,200,000,005,704 bytes "
        "(9.28 TiB), over memory_budget=4,294,967,296 bytes: lower grid, or raise memory_budget",
    ),
    (
        lambda: UAVSpectrumEnv(batch_size=2, grid=(1000, 1000), num_uavs=200_000),
        InvalidOption,
        "num_uavs=200000 is invalid: 2 worlds of 200000 UAVs on 1000x1000 need about",
    ),
    (
        lambda: UAVSpectrumEnv(batch_size=2, grid=(3, 3)).rollout(10**12, break_when_any_done=False),
        InvalidOption,
        "rollout(max_steps=1000000000000) is invalid: 1,000,000,000,000 steps of 2 worlds need about "
        "1,424,000,000,000,000 bytes (1.3e+03 TiB), over memory_budget=4,294,967,296 bytes: use fewer steps, or raise "
        "the env's memory_budget",
    ),
    (
        lambda: UAVSpectrumEnv(batch_size=2, grid=(3, 3), memory_budget=10**6).rollout(
            10_000, break_when_any_done=False
        ),
        InvalidOption,
        "rollout(max_steps=10000) is invalid: 10,000 steps of 2 worlds need about",
    ),
]


@pytest.mark.parametrize("call, error, words", API_CASES, ids=[words for _, _, words in API_CASES])
def test_python_api_numbers_are_one_line(call, error, words):
    with pytest.raises(error) as raised:
        call()
    assert type(raised.value) is error or error is InvalidOption, type(raised.value)
    assert "\n" not in str(raised.value) and words in str(raised.value), str(raised.value)


def test_valid_batch_sizes_and_masks_still_work():
    for batch_size in (3, [3], (3,), torch.Size([3]), np.int64(3)):
        assert UAVSpectrumEnv(batch_size=batch_size, grid=(3, 3)).batch_size == torch.Size([3])
    env = UAVSpectrumEnv(batch_size=3, grid=(3, 3))
    env.reset()
    for mask in (torch.tensor([True, False, True]), torch.tensor([[False], [True], [False]])):
        env.reset(TensorDict({"_reset": mask}, batch_size=[3]))
    # a partial first reset, then the rest: every world has cells, so a step is allowed
    fresh = UAVSpectrumEnv(batch_size=2, grid=(3, 3))
    fresh.reset(TensorDict({"_reset": torch.tensor([True, False])}, batch_size=[2]))
    fresh.reset(TensorDict({"_reset": torch.tensor([False, True])}, batch_size=[2]))
    fresh.step(actions(fresh))


def test_a_raised_memory_budget_allows_a_batch_it_refused():
    cfg = make_config(grid=(3, 3))
    need = world_bytes(cfg, 50_000)
    with pytest.raises(InvalidOption, match="memory_budget"):
        World(cfg, 50_000, memory_budget=need - 1)
    assert World(cfg, 50_000, memory_budget=need).num_worlds == 50_000


def random_options(rng: random.Random) -> tuple[str, dict]:
    """A preset and options drawn over hundreds of orders of magnitude, on small grids."""
    preset = rng.choice(["paper", "paper", "reference_code"])
    options = {
        name: 10 ** rng.uniform(low, high)
        for name, low, high in (
            ("p_pt", -40, 40),
            ("p_s", -40, 40),
            ("p_u", -40, 40),
            ("noise", -60, 20),
            ("cell_size", -30, 30),
            ("altitude", -30, 10),
            ("alpha", -3, 2.5),
            ("g0", -40, 40),
            ("reference_gain", -30, 30),
        )
        if rng.random() < 0.35
    }
    options |= {"layout": rng.choice(["line", "random"]), "fading": rng.choice(["none", "rayleigh"])}
    if preset == "paper":
        options["direct_links"] = rng.random() < 0.3
    grid = (rng.randint(1, 6), rng.randint(2, 6))
    return preset, {**options, "grid": grid, "num_uavs": rng.randint(2, min(3, grid[0] * grid[1])), "max_steps": 3}


def test_accepted_numbers_give_finite_rates_and_a_positive_optimum():
    """Every option set the checks accept steps with finite observations, rates and rewards, and has 0 < U* < inf;
    the checks refuse a good share of the draws (they are not vacuous)."""
    rng, accepted, refused = random.Random(0), 0, 0
    while accepted < 40:
        preset, options = random_options(rng)
        try:
            cfg = make_config(preset, **options)
        except InvalidOption:
            refused += 1
            continue
        accepted += 1
        world = World(cfg, 3, seed=accepted)
        first = world.reset()
        u_star = world.optimum()[0]
        assert torch.isfinite(u_star).all() and (u_star > 0).all(), (preset, options, u_star)
        assert torch.isfinite(first["observation"]).all(), (preset, options)
        for _ in range(3):
            out, reward, _ = world.step(torch.randint(0, 6, (3, cfg.num_uavs)))
            assert torch.isfinite(reward.float()).all() and torch.isfinite(out["observation"]).all(), options
            assert torch.isfinite(out["utility"]).all(), (preset, options)
    assert refused >= 10


@pytest.mark.parametrize("name", ["p_u", "noise", "cell_size", "altitude", "alpha"])
def test_the_range_a_refusal_gives_is_accepted_at_both_ends(name):
    refused = {"p_u": 1e308, "noise": 1e-300, "cell_size": 1e-300, "altitude": 1e-300, "alpha": 300.0}[name]
    with pytest.raises(InvalidOption) as raised:
        make_config(grid=(4, 6), **{name: refused})
    ends = re.search(r"it must (?:lie in \[(\S+), (\S+)\]|be at most (\S+))$", str(raised.value))
    assert ends, str(raised.value)
    for end in (float(e) for e in ends.groups() if e):
        world = World(make_config(grid=(4, 6), **{name: end}), 2)
        world.reset()
        u_star = world.optimum()[0]
        assert torch.isfinite(u_star).all() and (u_star > 0).all()
        assert math.isfinite(float(world.cell_contributions.max()))


def test_a_rollout_that_ends_with_its_episode_is_not_refused_for_its_max_steps():
    """TorchRL's rollout stops where an episode ends (``break_when_any_done``, its default): only the episode's steps
    are held, so a large ``max_steps`` is no cost there."""
    env = UAVSpectrumEnv(batch_size=2, grid=(3, 3), max_steps=5)
    assert env.rollout(10**12).shape == torch.Size([2, 5])


def test_the_batterys_refusal_does_not_advise_the_grid(command_exit, tmp_path):
    """The mission's horizon follows from the battery and the grid together: a smaller grid alone would not bring a
    huge battery's evaluation within the budget, so it is not advised."""
    error = command_exit("train env.energy=rotary_wing env.base=[-1,0] env.battery_wh=1e12", tmp_path)
    assert error.startswith("error: env.battery_wh=1e12 is invalid") and "lower env.grid" not in error, error


def test_n_step_returns_count_in_the_batch_memory(compose_cfg):
    """MultiStep copies the batch's frames: at a budget between the two, one-step returns pass and 30-step ones are
    refused, naming the batch."""
    from uavrl.config import model_config
    from uavrl.costs import Factor, dqn_costs
    from uavrl.train import check_settings

    big = ("agent=dqn", "agent.worlds=100000", "train.time_budget=1000000", "train.step_budget=10000000000000")

    def batch_bytes(n_step):
        cfg = compose_cfg(*big, f"agent.n_step={n_step}")
        model = model_config(cfg)
        memory = dqn_costs(cfg, model, Factor("env.max_steps", model.max_steps))[0]
        return next(part for part in memory if "batch of" in part.what).amount

    one, thirty = batch_bytes(1), batch_bytes(30)
    assert thirty > 2 * one
    budget = f"agent.memory_budget={(one + thirty) // 2}"
    check_settings(compose_cfg(*big, "agent.n_step=1", budget))
    with pytest.raises(ValueError, match=r"each iteration's batch of transitions .* with agent.n_step 30"):
        check_settings(compose_cfg(*big, "agent.n_step=30", budget))


def test_the_lookahead_is_estimated_for_an_evaluated_checkpoint_too(compose_cfg):
    """``python -m uavrl.evaluate eval.lookahead=...`` is estimated on the saved agent before anything is built."""
    from uavrl.config import model_config
    from uavrl.costs import check_evaluation_costs

    saved = compose_cfg("agent=dqn")
    cfg = compose_cfg("eval.lookahead=12", "eval.lookahead_width=0")
    with pytest.raises(ValueError, match=r"^eval.lookahead=12 is invalid: the lookahead's deepest level"):
        check_evaluation_costs(cfg, saved, model_config(saved), video=False)
    check_evaluation_costs(compose_cfg("eval.lookahead=2"), saved, model_config(saved), video=False)


def test_the_lookahead_depth_is_refused_in_python_as_on_the_command_line():
    from uavrl.agents.lookahead_rules import check_lookahead

    with pytest.raises(ValueError) as refused:
        check_lookahead(None, 10**9, "RandomAgent")
    assert str(refused.value) == "eval.lookahead=1000000000 is invalid: it must be a whole number in [0, 100]"


def test_a_dqn_agent_built_in_python_names_its_worlds(compose_cfg):
    """Its training env's batch is ``agent.worlds``: a refusal names that, not the env's internal ``batch_size``."""
    from uavrl.agents.dqn import DQNAgent
    from uavrl.config import model_config

    cfg = compose_cfg("agent=dqn", "agent.worlds=10000000000")
    with pytest.raises(InvalidOption) as refused:
        DQNAgent(model_config(cfg), cfg, "cpu", 0)
    assert str(refused.value).startswith(
        "agent.worlds=10000000000 is invalid: 10,000,000,000 worlds of 2 UAVs on 6x6 need about "
    ) and str(refused.value).endswith(
        "over agent.memory_budget=4,294,967,296 bytes: use fewer worlds, or raise memory_budget"
    )


@pytest.mark.gym
def test_the_gymnasium_vector_env_names_its_num_envs():
    """Its worlds are ``num_envs`` (it takes no memory_budget): a refusal names them, not the World's batch_size."""
    pytest.importorskip("gymnasium")
    from uavrl.envs.adapters.gym_env import UAVSpectrumVectorEnv

    with pytest.raises(InvalidOption) as refused:
        UAVSpectrumVectorEnv(num_envs=10**10)
    assert str(refused.value) == (
        "num_envs=10000000000 is invalid: 10,000,000,000 worlds of 2 UAVs on 6x6 need about 15,200,001,073,520 bytes "
        "(13.8 TiB), over memory_budget=4,294,967,296 bytes: use fewer worlds"
    )
