"""The size-free DQN (agent.network=set): permutation invariance, one set of parameters on any size, training over
several sizes with an exact resume, zero-shot evaluation and the one-line refusals."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from uavrl import load_policy
from uavrl.agents import agent_class
from uavrl.agents.dqn import DQNAgent
from uavrl.agents.dqn.multisize import SetDQNAgent
from uavrl.agents.dqn.setnet import Q_INPUTS, SetQCore, SetQNet
from uavrl.config import model_config
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.world import World
from uavrl.experiment.evaluating import evaluate_checkpoint
from uavrl.train import train

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

SIZES = "agent.sizes=[[2,3,3],[3,4,4]]"
TINY = [
    "agent=dqn",
    "agent.network=set",
    "agent.mixer=mean",
    SIZES,
    "agent.worlds=4",
    "agent.hidden=16",
    "agent.heads=2",
    "agent.depth=1",
    "agent.batch_size=32",
    "agent.buffer_size=500",
    "agent.updates=2",
    "agent.learning_starts=40",
    "agent.iterations=4",
    "env.max_steps=6",
    "eval.num_starts=4",
    "progress=false",
]


@pytest.fixture
def set_cfg(compose_cfg):
    return lambda *overrides: compose_cfg(*TINY, *overrides)


def values_at(core, cfg, code):
    """The core's values ``[1, N, A]`` for the configuration ``code`` ``[1, N]`` of a world of ``cfg``."""
    world = World(cfg, 1)
    world.reset()
    out = world.start_at(code)
    return SetQNet(core, cfg.grid)(out["observation"], out["positions"], out["state"])


@pytest.mark.parametrize("energy", [{}, {"energy": "rotary_wing", "base": [-1, 0]}])
def test_permuting_the_uavs_permutes_their_values(energy):
    cfg = make_config("paper", grid=(5, 4), num_uavs=5, **energy)
    torch.manual_seed(0)
    core = SetQCore(cfg.num_actions, bool(energy), hidden=16, heads=4, depth=2)
    code = torch.tensor([[2 * 3 + 1, 2 * 7, 2 * 12 + 1, 2 * 18, 2 * 0 + 1]])
    perm = torch.tensor([3, 0, 4, 1, 2])
    values = values_at(core, cfg, code)
    assert torch.allclose(values_at(core, cfg, code[:, perm]), values[:, perm], atol=1e-6)
    assert not torch.allclose(values[:, 0], values[:, 1])  # the UAVs' values differ: the test can fail


def test_the_network_reads_the_batteries():
    cfg = make_config("paper", grid=(4, 4), num_uavs=3, energy="rotary_wing", base=[-1, 0])
    torch.manual_seed(0)
    net = SetQNet(SetQCore(cfg.num_actions, True, hidden=16, heads=2, depth=1), cfg.grid)
    td = UAVSpectrumEnv(batch_size=1, config=cfg).reset()
    inputs = [td[k].clone() for k in Q_INPUTS]
    start = 13 + 3 * 2  # own (13), the others' (x, y, task), then its battery (envs/world/observations.py)
    drained = inputs[0].clone()
    drained[..., start] = 0.1
    assert not torch.allclose(net(*inputs), net(drained, *inputs[1:]))


def test_one_set_of_parameters_acts_on_small_and_large_teams(set_cfg):
    cfg = set_cfg()
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), 0)
    assert isinstance(agent, SetDQNAgent)
    for grid, n in (((6, 6), 2), ((50, 50), 50)):
        env_cfg = make_config("paper", grid=grid, num_uavs=n)
        policy = agent.policy_for(env_cfg)
        assert set(policy.policy.parameters()) == set(agent.core.parameters())
        env = UAVSpectrumEnv(batch_size=2, config=env_cfg)
        rollout = env.rollout(3, policy.bind_env(env))  # the env refuses invalid joint actions
        positions = rollout["next", "positions"]
        assert positions.shape == (2, 3, n, 2)
        cells = positions[..., 1] * grid[0] + positions[..., 0]
        assert (cells.sort(-1).values.diff(dim=-1) > 0).all()  # distinct cells after every step


def test_training_over_sizes_resumes_exactly(tmp_path, set_cfg, interrupt_at):
    run = ["train.checkpoint_every=2"]
    whole = train(set_cfg(*run, f"run_dir={tmp_path / 'whole'}"))
    with interrupt_at(SetDQNAgent, 4), pytest.raises(KeyboardInterrupt):
        train(set_cfg(*run, f"run_dir={tmp_path / 'killed'}"))
    train(set_cfg(*run, f"resume={tmp_path / 'killed'}"), overrides=[f"resume={tmp_path / 'killed'}"])
    a, b = (torch.load(d / "checkpoint.pt", weights_only=True)["agent"] for d in (whole, tmp_path / "killed"))
    assert a["loss"].keys() == b["loss"].keys() and len(a["buffer"]) == 2
    assert all(torch.equal(a["loss"][k], b["loss"][k]) for k in a["loss"])
    assert json.loads((whole / "metrics.json").read_text())["eval/optimality"] == pytest.approx(
        json.loads((tmp_path / "killed" / "metrics.json").read_text())["eval/optimality"], abs=0
    )


def test_a_size_free_run_is_filed_and_summarised_as_size_free(tmp_path, set_cfg, monkeypatch, capsys):
    """``runs/dqn-set/<env>/<stamp>``, apart from the per-size DQN's ``runs/dqn/``, and a summary naming the teams and
    layouts it trained on."""
    monkeypatch.chdir(tmp_path)
    run_dir = train(set_cfg("agent.iterations=2", "agent.layouts=[line,random]"))
    assert run_dir.parent == Path("runs/dqn-set/paper")
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("trained dqn with a size-free network (agent.network=set) on paper: 2 iterations in ")
    assert lines[1] == (
        "size-free: trained on 2 teams (N = 2 on 3x3, N = 3 on 4x4) in layouts 'line', 'random'; its own evaluation: "
        "6x6 grid, 2 UAVs, layout 'line', channel 'paper'"
    )


def test_a_size_free_checkpoint_is_evaluated_zero_shot_on_other_sizes(tmp_path, set_cfg, compose_cfg):
    run_dir = train(set_cfg(f"run_dir={tmp_path / 'set'}", "agent.iterations=2"))
    other = ["env.grid=[7,5]", "env.num_uavs=6", "env.layout=random"]
    metrics = evaluate_checkpoint(compose_cfg(f"checkpoint={run_dir}", "eval.num_starts=4", *other), other)
    assert json.loads((run_dir / "eval-6uav-7x5-random.json").read_text()) == metrics
    policy, env_cfg = load_policy(run_dir, env_config=make_config("paper", grid=(4, 9), num_uavs=3))
    env = UAVSpectrumEnv(batch_size=2, config=env_cfg)
    assert env.rollout(2, policy.bind_env(env))["next", "positions"].shape == (2, 2, 3, 2)
    with pytest.raises(ValueError, match="only env.grid, env.num_uavs, env.layout may differ"):
        evaluate_checkpoint(compose_cfg(f"checkpoint={run_dir}", "env.channel=al_hourani"), ["env.channel=al_hourani"])


def test_the_evaluate_command_runs_zero_shot_and_refuses_a_per_size_network(tmp_path, set_cfg, compose_cfg):
    """End to end through ``python -m uavrl.evaluate``."""
    size_free = train(set_cfg(f"run_dir={tmp_path / 'set'}", "agent.iterations=2"))
    team = train(
        compose_cfg(
            *TINY,
            "agent.network=team",
            "agent.heads=4",
            "agent.mixer=vdn",
            "agent.sizes=[]",
            "agent.iterations=2",
            "env.grid=[3,3]",
            f"run_dir={tmp_path / 'team'}",
        )
    )
    command = [sys.executable, "-m", "uavrl.evaluate", "eval.num_starts=4", "env.grid=[9,9]", "env.num_uavs=5"]
    done = subprocess.run([*command, f"checkpoint={size_free}"], capture_output=True, text=True, check=True)
    lines = done.stdout.splitlines()
    assert lines[:2] == [
        f"evaluated dqn with a size-free network (agent.network=set) of the paper run {size_free} on: 9x9 grid, 5 "
        "UAVs, layout 'line', channel 'paper'",
        "zero-shot: trained on 2 teams (N = 2 on 3x3, N = 3 on 4x4) in layout 'line', evaluated on N = 5 on 9x9 in "
        "layout 'line'",
    ]
    assert lines[-1].startswith(f"metrics: {size_free / 'eval-5uav-9x9.json'} (all ")
    as_json = subprocess.run([*command, "print_json=true", f"checkpoint={size_free}"], capture_output=True, text=True)
    assert json.loads(as_json.stdout) == json.loads((size_free / "eval-5uav-9x9.json").read_text())
    refused = subprocess.run([*command, f"checkpoint={team}"], capture_output=True, text=True)
    assert refused.returncode == 1 and refused.stdout == ""
    assert refused.stderr.splitlines() == [
        f"error: checkpoint={team}: env.grid, env.num_uavs given: its dqn policy (agent.network=team) acts only in "
        "its run's model (3x3 grid, 2 UAVs, layout 'line'); only a size-free network (agent=dqn agent.network=set) "
        "acts on any size"
    ]
    with pytest.raises(ValueError, match="is invalid: its dqn policy"):
        load_policy(team, env_config=make_config("paper", grid=(4, 4), num_uavs=3))


@pytest.mark.parametrize(
    "overrides, message",
    [
        (
            ["agent.network=team", "agent.heads=4", "agent.sizes=[]"],
            "agent.mixer='mean' is invalid with agent.network='team'",
        ),
        (
            ["agent.network=team", "agent.heads=4", "agent.mixer=vdn"],
            "agent.sizes=[[2,3,3],[3,4,4]] is invalid with agent.network",
        ),
        (["agent.mixer=qmix"], "agent.mixer='qmix' is invalid with agent.network='set'"),
        (["agent.head=joint"], "agent.head='joint' is invalid with agent.network='set'"),
        (["agent.replay=prioritized"], "agent.replay='prioritized' is invalid with agent.network='set'"),
        (["agent.heads=3"], "agent.heads=3 is invalid with agent.hidden=16: the heads split the hidden units"),
        (["agent.sizes=[[10,3,3]]"], "agent.sizes=[[10,3,3]] is invalid: its team [10, 3, 3] has 10 UAVs for the 9"),
        (["agent.sizes=[[2,3]]"], "agent.sizes=[[2, 3]] is invalid: give a list of teams [num_uavs, L1, L2]"),
        (["agent.layouts=[grid]"], "agent.layouts=['grid'] is invalid: give a list among line, random"),
        (["agent.network=tree"], "agent.network='tree' is invalid: allowed networks are 'team', 'set'"),
    ],
)
def test_bad_set_settings_are_refused_in_one_line(set_cfg, overrides, message):
    cfg = set_cfg(*overrides)
    with pytest.raises(ValueError, match=None) as err:
        agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), 0)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_the_registry_picks_the_network_and_each_class_refuses_the_other(set_cfg):
    """agent=dqn is one name with two classes: the settings choose, and neither class turns into the other."""
    cfg = set_cfg()
    assert agent_class("dqn", cfg.agent) is SetDQNAgent
    assert agent_class("dqn", set_cfg("agent.network=team", "agent.heads=4", "agent.mixer=vdn").agent) is DQNAgent
    assert agent_class("dqn") is DQNAgent
    with pytest.raises(ValueError, match="agent.network='set' is invalid for DQNAgent, the per-size network"):
        DQNAgent(model_config(cfg), cfg, torch.device("cpu"), 0)
    team = set_cfg("agent.network=team", "agent.heads=4", "agent.mixer=vdn", "agent.sizes=[]")
    with pytest.raises(ValueError, match="agent.network='team' is invalid for SetDQNAgent"):
        SetDQNAgent(model_config(team), team, torch.device("cpu"), 0)


def test_the_cost_check_counts_every_team_and_layout_of_a_size_free_run(tmp_path, compose_cfg):
    """Each group of agent.sizes x agent.layouts has its own worlds, batch and buffer: a team that alone fits but
    with the others does not is refused by the command in one line, before any file is written."""
    from uavrl.costs import check_run_costs

    base = ["agent=dqn", "agent.network=set", "agent.mixer=mean", "agent.worlds=128", "agent.memory_budget=400000000"]
    base += ["agent.batch_size=32", "agent.iterations=20"]  # a gradient step and the run's time within the budgets
    one, both = "agent.sizes=[[30,40,40]]", "agent.sizes=[[30,40,40],[30,40,40]]"
    fits, over = compose_cfg(*base, one), compose_cfg(*base, both)
    check_run_costs(fits, model_config(fits))
    # one group: 374 MB in all (the evaluation 137, the batch 106, a gradient step 108); two: each group's worlds,
    # batch and buffer again, 495 MB
    with pytest.raises(ValueError, match=r"agent.sizes=.* is invalid: 7 parts held at once .* needs about 495,"):
        check_run_costs(over, model_config(over))
    done = subprocess.run(
        [sys.executable, "-m", "uavrl.train", *base, both, f"run_dir={tmp_path / 'run'}"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 1 and done.stdout == "" and len(done.stderr.splitlines()) == 1
    assert "7 parts held at once" in done.stderr and not (tmp_path / "run").exists()
