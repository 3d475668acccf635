"""The DQN with altitude levels and in cities: both networks' shapes and sizes, the greedy rules over positions (never
an invalid action), a train-save-load-evaluate round trip, training over a set of cities (agent.cities) and the
one-line refusals."""

import json

import pytest
import torch

from uavrl.agents import agent_class, network_sizes
from uavrl.agents.dqn import TeamQNet, ValidGreedy
from uavrl.agents.dqn.networks import JointActionMask, position_numbers, q_inputs
from uavrl.agents.dqn.setnet import SetQCore, SetQNet
from uavrl.agents.dqn.transitions import CompactTransitions, transition_keys
from uavrl.agents.schema import training_models
from uavrl.config import model_config
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.config import CLIMB, DESCEND
from uavrl.envs.limits import set_input_size
from uavrl.experiment.evaluating import evaluate_checkpoint
from uavrl.experiment.runs import size_free_teams
from uavrl.train import train

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

LEVELS = [30, 100, 300]
CITY = dict(altitudes_m=LEVELS, city="urban", grid=(4, 4), num_uavs=2)
TINY = [
    "agent=dqn",
    "env=a2g_urban",
    f"env.altitudes_m=[{','.join(map(str, LEVELS))}]",
    "env.city=urban",
    "env.num_uavs=2",
    "env.grid=[4,4]",
    "env.max_steps=6",
    "agent.worlds=4",
    "agent.hidden=16",
    "agent.depth=1",
    "agent.batch_size=32",
    "agent.buffer_size=500",
    "agent.updates=2",
    "agent.learning_starts=20",
    "agent.iterations=3",
    "eval.num_starts=4",
    "progress=false",
]
SET = ["agent.network=set", "agent.mixer=vdn", "agent.heads=2"]


def parameters(module) -> int:
    return sum(p.numel() for p in module.parameters())


@pytest.mark.parametrize("model", [dict(altitudes_m=LEVELS), CITY])
def test_the_networks_have_8_actions_and_the_joint_head_8_to_the_n(model):
    cfg = make_config("a2g_urban", **{"grid": (4, 4), "num_uavs": 2, **model})
    env = UAVSpectrumEnv(batch_size=3, config=cfg)
    td = env.reset()
    inputs = [td[k] for k in q_inputs(cfg)]
    assert q_inputs(cfg)[-1] == "levels" and cfg.num_actions == 8
    factored, joint = TeamQNet(env, "factored", hidden=16, depth=1), TeamQNet(env, "joint", hidden=16, depth=1)
    assert factored(*inputs).shape == (3, 2, 8) and joint(*inputs).shape == (3, 8**2)
    observation = env.observation_size
    for head, net in (("factored", factored), ("joint", joint)):
        counted = network_sizes.team_parameters(2, 8, False, head, 16, 1, levels=True)
        assert parameters(net) == counted
    assert parameters(factored) != network_sizes.team_parameters(2, 8, False, "factored", 16, 1)  # levels count
    core = SetQCore(8, energy=False, hidden=16, heads=2, depth=1, levels=True)
    assert parameters(core) == network_sizes.set_parameters(8, False, 16, 2, 1, levels=True)
    own, pairs = SetQNet(core, cfg.grid, env.world.dynamics.positions).features(*inputs)
    assert own.shape == (3, 2, set_input_size(False, levels=True)) and pairs.shape == (3, 2, 2, 3)
    # its own vertical features are the observation's (level, climb and descend contributions), before the others'
    assert torch.equal(own[..., -5:], td["agents", "observation"][..., observation - 6 : observation - 1])
    with pytest.raises(ValueError, match="exactly for a core of altitude levels"):
        SetQNet(core, cfg.grid)


def _valid(world, actions: torch.Tensor) -> torch.Tensor:
    """Whether each world's joint action ``actions`` ``[B, N]`` is valid (the World's own rule)."""
    A = world.cfg.joint_action_base
    joint = (actions * A ** torch.arange(actions.shape[-1])).sum(-1)
    return world.joint_action_mask().gather(-1, joint.unsqueeze(-1)).squeeze(-1)


@pytest.mark.parametrize("city", ["none", "urban", "highrise"])
def test_the_greedy_rules_never_pick_an_invalid_action(city):
    """Random values, and values that want to climb (above the top level), to descend (below the lowest, or into a
    roof) or to move into a building: the greedy valid action is valid in every world, and the joint head's mask is
    the World's."""
    place = {} if city == "none" else dict(city=city, environment=city)
    cfg = make_config("a2g_urban", altitudes_m=LEVELS, grid=(5, 5), num_uavs=3, **place)
    env = UAVSpectrumEnv(batch_size=256, config=cfg, seed=3)
    td = env.reset()
    numbers = position_numbers(env.world)
    greedy = ValidGreedy(env.neighbours, 5, cfg.num_actions, numbers)
    at = [td[k] for k in ("positions", "tasks", "levels")]
    mask = td["agents", "action_mask"]
    generator = torch.Generator().manual_seed(0)
    wanted = [torch.randn(256, 3, 8, generator=generator)]
    for action in (0, 1, 2, 3, CLIMB, DESCEND):  # each move far above the rest
        wanted.append(torch.randn(256, 3, 8, generator=generator) + 100.0 * (torch.arange(8) == action))
    top = td["levels"] == len(LEVELS) - 1
    assert top.any() and (~mask[..., CLIMB][top]).all()  # the env masks a climb at the top level
    for values in wanted:
        actions = greedy(values, mask, *at[:2], at[2])
        assert _valid(env.world, actions).all()
        assert mask.gather(-1, actions.unsqueeze(-1)).all()
    climbs = greedy(wanted[5], mask, *at)
    assert (climbs[top] != CLIMB).all() and (climbs[~top] == CLIMB).any()
    joint = JointActionMask(env.neighbours, 5, 3, numbers)
    assert torch.equal(joint(td["positions"], td["levels"]), env.world.joint_action_mask())


def test_the_replay_keeps_positions_and_rebuilds_the_transitions_bit_for_bit():
    """With levels a stored code's cell is the UAV's position: the rebuilt transitions, levels included, are the
    collected ones."""
    env = UAVSpectrumEnv(batch_size=4, config=make_config("a2g_urban", **CITY, max_steps=5), seed=2)
    full = env.rollout(5).reshape(-1)
    compact = CompactTransitions(env.world, [("agents", "action")])
    keys = transition_keys(env.world, [("agents", "action")])
    assert "levels" in keys and ("next", "levels") in keys
    stored = compact.inv(full.select(*keys))
    assert (stored["code"] >> 1).max() >= env.cfg.num_cells  # positions above the lowest level
    assert (compact(stored) == full.select(*keys)).all()


def test_a_uav_below_another_climbs_after_it():
    """The second pass with vertical moves: the lower UAV wants the upper's position, the upper climbs away."""
    cfg = make_config("a2g_urban", altitudes_m=LEVELS, grid=(3, 1), num_uavs=2)
    env = UAVSpectrumEnv(batch_size=1, config=cfg)
    greedy = ValidGreedy(env.neighbours, 3, cfg.num_actions, position_numbers(env.world))
    values = torch.zeros(1, 2, 8)
    values[..., CLIMB] = 9.0
    values[..., 5] = 1.0
    positions, levels = torch.tensor([[[0, 0], [0, 0]]]), torch.tensor([[0, 1]])
    allowed = torch.ones(1, 2, 8, dtype=torch.bool)
    assert greedy(values, allowed, positions, torch.tensor([[0, 0]]), levels).tolist() == [[CLIMB, CLIMB]]
    # the upper one at the top level cannot climb: both keep relaying, the lower one does not move into it
    allowed[0, 1, CLIMB] = False
    assert greedy(values, allowed, positions, torch.tensor([[1, 1]]), levels + 1).tolist() == [[5, 5]]


@pytest.mark.parametrize("network", [[], ["agent.head=joint"], SET])
def test_a_run_with_levels_in_a_city_saves_reloads_and_evaluates_the_same(tmp_path, compose_cfg, network):
    run_dir = train(compose_cfg(*TINY, *network, f"run_dir={tmp_path / 'run'}"))
    trained = json.loads((run_dir / "metrics.json").read_text())
    again = evaluate_checkpoint(compose_cfg(f"checkpoint={run_dir}", "eval.num_starts=4"))
    assert again == {key: trained[key] for key in again}  # every evaluation metric, the checkpoint's policy
    assert again["eval/u_star_bit_per_s"] > 0 and 0.0 <= again["eval/optimality"] <= 1.0
    state = torch.load(run_dir / "checkpoint.pt", weights_only=True)["agent"]
    assert state["iteration"] == 3
    with pytest.raises(ValueError, match=r"its policy was trained with altitude levels \(env.altitudes_m=\[30.0,"):
        evaluate_checkpoint(compose_cfg(f"checkpoint={run_dir}", "env.altitudes_m=null"), ["env.altitudes_m=null"])


def test_a_run_without_levels_is_refused_on_a_model_with_levels(tmp_path, compose_cfg):
    flat = [o for o in TINY if not o.startswith(("env.altitudes_m", "env.city"))]
    run_dir = train(compose_cfg(*flat, "agent.iterations=1", f"run_dir={tmp_path / 'run'}"))
    levels = f"env.altitudes_m=[{','.join(map(str, LEVELS))}]"
    with pytest.raises(ValueError) as err:
        evaluate_checkpoint(compose_cfg(f"checkpoint={run_dir}", levels), [levels])
    assert str(err.value) == (
        f"checkpoint={run_dir}: env.altitudes_m given: its policy was trained at one altitude (env.altitudes_m=null), "
        "and a UAV's observations and actions with altitude levels differ"
    )


def test_agent_cities_multiplies_the_groups(compose_cfg):
    cfg = compose_cfg(*TINY, *SET, "agent.sizes=[[2,4,4],[3,5,5]]", "agent.cities=[0,7,11]")
    models = training_models(model_config(cfg), cfg.agent)
    assert len(models) == 2 * 1 * 3
    assert [(m.num_uavs, m.city_seed) for m in models] == [(n, c) for n in (2, 3) for c in (0, 7, 11)]
    own = compose_cfg(*TINY, *SET, "env.city_seed=5")
    assert [m.city_seed for m in training_models(model_config(own), own.agent)] == [5]  # null: env.city_seed's


def test_a_size_free_run_trains_over_cities_and_acts_in_a_held_out_one(tmp_path, compose_cfg):
    cfg = compose_cfg(*TINY, *SET, "agent.cities=[0,1]", "agent.iterations=2", f"run_dir={tmp_path / 'run'}")
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), 0)
    assert [group.cfg.city_seed for group in agent.groups] == [0, 1]
    # the cities' buildings differ, so do the positions each group's network and greedy rule move between
    assert not torch.equal(*(group.env.neighbours for group in agent.groups))
    run_dir = train(cfg)
    held_out = "env.city_seed=4611686018427387905"  # the benchmark's held-out cities are size-free's to act in
    metrics = evaluate_checkpoint(compose_cfg(f"checkpoint={run_dir}", "eval.num_starts=4", held_out), [held_out])
    assert 0.0 <= metrics["eval/optimality"] <= 1.0
    assert json.loads((run_dir / "eval-2uav-4x4-urban4611686018427387905.json").read_text()) == metrics
    assert not (run_dir / "eval.json").exists()  # the run's own city's evaluation is another file
    assert size_free_teams(cfg, model_config(cfg)).endswith("in 2 urban cities (env.city_seed 0, 1)")


def test_a_per_size_run_in_a_city_acts_in_a_held_out_city_with_its_weights(tmp_path, compose_cfg):
    """The per-size network trained in one city acts in another of the same model (the benchmark's held-out cities):
    the same weights on that city's positions, every action allowed there; another grid is still refused."""
    from uavrl.agents.evaluation import evaluate
    from uavrl.experiment.saved import load_agent

    run_dir = train(compose_cfg(*TINY, f"run_dir={tmp_path / 'run'}"))
    agent, saved, _ = load_agent(run_dir)
    held_out = model_config(saved).replace(city_seed=4611686018427387905)
    policy = agent.policy_for(held_out)
    trained, acting = (p.policy.module[0] for p in (agent.policies()[0], policy))
    assert all(torch.equal(a, b) for a, b in zip(trained.parameters(), acting.parameters(), strict=True))
    assert not torch.equal(trained.module.neighbours, acting.module.neighbours)  # the buildings differ
    env = UAVSpectrumEnv(batch_size=16, config=held_out, seed=2)
    policy.bind_env(env)
    td = env.reset()
    for _ in range(6):
        td = policy(td)
        mask = td["agents", "action_mask"]
        assert mask.gather(-1, td["agents", "action"].unsqueeze(-1)).all()
        td = env.step(td)["next"]
    assert 0.0 <= evaluate(policy, held_out, num_starts=4)["eval/optimality"] <= 1.0
    longer = held_out.replace(max_steps=9)  # another episode length too: still the held-out city's positions
    agent.policy_for(longer).bind_env(UAVSpectrumEnv(batch_size=2, config=longer))
    metrics = evaluate_checkpoint(
        compose_cfg(f"checkpoint={run_dir}", "eval.num_starts=4", f"env.city_seed={held_out.city_seed}"),
        [f"env.city_seed={held_out.city_seed}"],
    )
    assert (run_dir / f"eval-2uav-4x4-urban{held_out.city_seed}.json").exists() and 0 <= metrics["eval/optimality"]
    with pytest.raises(ValueError, match="acts only in its run's model"):
        evaluate_checkpoint(compose_cfg(f"checkpoint={run_dir}", "env.grid=[5,5]"), ["env.grid=[5,5]"])


@pytest.mark.parametrize(
    "overrides, message",
    [
        (
            ["env.city=none", "agent.cities=[0,1]"],
            "agent.cities=[0,1] is invalid with env.city='none': the seeds lay out a city's buildings; give env.city",
        ),
        (
            ["agent.network=team", "agent.heads=4", "agent.cities=[0,1]"],
            "agent.cities=[0,1] is invalid with agent.network='team'",
        ),
        (
            [f"agent.cities=[{','.join(map(str, range(17)))}]"],
            "is invalid: give null (env.city_seed's city) or a list of 1 to 16 distinct city seeds",
        ),
        (["agent.cities=[4611686018427387904]"], "agent.cities=[4611686018427387904] is invalid: give null"),
        (["agent.cities=[3,3]"], "agent.cities=[3, 3] is invalid: give null"),
        (["agent.cities=[-1]"], "agent.cities=[-1] is invalid: give null"),
    ],
)
def test_bad_cities_are_refused_in_one_line(compose_cfg, overrides, message):
    cfg = compose_cfg(*TINY, *SET, *overrides)
    with pytest.raises(ValueError) as err:
        agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), 0)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_the_cost_check_counts_every_city(compose_cfg):
    """Each city is a group with its own worlds, batch and buffer: one city fits, sixteen are refused in one line."""
    from uavrl.costs import check_run_costs

    base = [*TINY, *SET, "agent.worlds=100000"]
    check_run_costs(one := compose_cfg(*base), model_config(one))
    many = compose_cfg(*base, f"agent.cities=[{','.join(map(str, range(16)))}]")
    with pytest.raises(ValueError, match=r"x groups \(agent.sizes x agent.layouts x agent.cities\) = 100,000 x 6 x 16"):
        check_run_costs(many, model_config(many))


def test_evaluations_in_other_cities_are_files_of_their_own(compose_cfg):
    """A size-free run evaluated in two cities of one seed, or at other levels, writes three files, none the run's
    own ``eval.json``: nothing evaluated is silently replaced."""
    from uavrl.experiment.evaluating import evaluation_file

    saved = compose_cfg(*TINY, *SET)
    others = [
        ["env.city_seed=7"],
        ["env.city_seed=7", "env.city=highrise", "env.environment=highrise"],
        ["env.city_seed=7", "env.altitudes_m=[30,100]"],
    ]
    names = [evaluation_file(saved, compose_cfg(*TINY, *SET, *other)) for other in others]
    assert len(set(names)) == 3 and "eval.json" not in names
    assert names[0] == "eval-2uav-4x4-urban7.json" and names[1] == "eval-2uav-4x4-highrise7.json"
    assert evaluation_file(saved, compose_cfg(*TINY, *SET)) == "eval.json"
