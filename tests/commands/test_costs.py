"""What a run costs, estimated before the work (uavrl/costs.py): the networks' sizes equal the
networks built, every cost that grows with a setting is refused before anything is built, and a refusal names the
setting as it was typed, with a change that would help."""

import subprocess
import sys
import textwrap

import pytest
from omegaconf import OmegaConf

from uavrl.agents import network_sizes
from uavrl.cli import compose_config
from uavrl.config import RUN_OPTION_SETTINGS
from uavrl.envs import InvalidOption, UAVSpectrumEnv
from uavrl.envs.limits import observation_size, state_size


def parameters(module) -> int:
    return sum(p.numel() for p in module.parameters())


@pytest.mark.parametrize(
    "options",
    [
        dict(grid=(4, 4), num_uavs=2),
        dict(grid=(4, 4), num_uavs=3),
        dict(grid=(4, 4), num_uavs=2, energy="follow_up", base=(-1, 0), recharge_steps=2, num_spares=1),
    ],
    ids=["2 UAVs", "3 UAVs", "energy, recharging, a spare"],
)
def test_the_parameter_counts_are_the_networks_built(options):
    """Each formula of uavrl/costs.py against the network it counts: the team network's both heads, QMIX's mixer
    and the size-free core, at two sizes each."""
    from torchrl.modules import QMixer

    from uavrl.agents.dqn.networks import LocalQNet, TeamQNet
    from uavrl.agents.dqn.setnet import LocalSetQCore, SetQCore

    env = UAVSpectrumEnv(batch_size=1, **options)
    energy, N, A = env.cfg.energy != "none", env.num_uavs, env.num_actions
    assert (observation_size(N, energy), state_size(N, energy)) == (env.observation_size, env.state_size)
    for hidden, depth, heads in ((16, 1, 2), (24, 3, 3)):
        for head in ("factored", "joint"):
            built = parameters(TeamQNet(env, head, hidden, depth))
            assert built == network_sizes.team_parameters(N, A, energy, head, hidden, depth), (head, hidden, depth)
        assert parameters(QMixer((env.state_size,), hidden, N, "cpu")) == network_sizes.qmix_parameters(
            N, energy, hidden
        )
        built = parameters(SetQCore(A, energy, hidden, heads, depth))
        assert built == network_sizes.set_parameters(A, energy, hidden, heads, depth)
        built = parameters(LocalSetQCore(A, energy, hidden, heads, depth))
        assert built == network_sizes.local_set_parameters(A, energy, hidden, depth)
        local = UAVSpectrumEnv(batch_size=1, observation="local", comm_radius=1.0, message_size=heads, **options)
        inputs = network_sizes.local_inputs(local.cfg)
        assert inputs == local.observation_size + N + 4
        built = parameters(LocalQNet(local, hidden, depth))
        counted = network_sizes.team_parameters(
            N, A, energy, "factored", hidden, depth, local=inputs, message_size=heads
        )
        assert built == counted


def refusal(*overrides: str) -> str | None:
    """The one line ``python -m uavrl.train <overrides>`` refuses with (in this process), or None."""
    from uavrl.train import check_settings

    try:
        check_settings(compose_config("config", list(overrides)), list(overrides))
    except InvalidOption as err:
        return err.renamed(RUN_OPTION_SETTINGS)
    except (ValueError, OSError) as err:
        return str(err)
    return None


ENERGY = ("env.energy=rotary_wing", "env.base=[-1,0]")
# (overrides, how the refusal begins, words it holds): costs that grow with a setting, each refused by the setting
# that was typed
COSTS = [
    (["agent=dqn", "agent.batch_size=1000000000"], "agent.batch_size=1000000000 is invalid: a gradient step", ""),
    (["agent=dqn", "agent.updates=1000000000"], "agent.updates=1000000000 is invalid: training", "train.time_budget"),
    (["agent=dqn", "agent.depth=1000000"], "agent.depth=1000000 is invalid: the networks", "lower agent.depth"),
    (["agent=dqn", "agent.hidden=1000000"], "agent.hidden=1000000 is invalid: the networks", "Adam's moments"),
    (
        ["agent=dqn", "agent.network=set", "agent.hidden=1000000", "agent.heads=1000000"],
        "agent.hidden=1000000 is invalid: the networks",
        "agent.heads 1,000,000",
    ),
    (
        ["agent=dqn", "agent.mixer=qmix", "agent.mixing_embed_dim=100000000"],
        "agent.mixing_embed_dim=100000000 is invalid: the networks",
        "lower agent.mixing_embed_dim",
    ),
    (
        ["agent=dqn", *ENERGY, "env.recharge_steps=2", "env.num_spares=1000000"],
        "env.num_spares=1000000 is invalid: the training worlds",
        "lower env.num_spares",
    ),
    (["agent=dqn", "agent.iterations=100000"], "agent.iterations=100000 is invalid: training", "hours of one CPU core"),
    (["agent=dqn", "env.grid=[100000,100000]"], "env.grid=[100000,100000] is invalid: the training worlds", ""),
    (["agent=dqn", "agent.buffer_size=10000000000"], "agent.buffer_size=10000000000 is invalid: the replay", ""),
]


@pytest.mark.parametrize("overrides, begins, words", COSTS, ids=[" ".join(o) for o, _, _ in COSTS])
def test_every_cost_is_refused_before_the_work_by_the_setting_typed(overrides, begins, words):
    line = refusal(*overrides)
    assert line is not None and line.startswith(begins) and words in line and "\n" not in line, line


# (overrides, how the refusal begins, words it must not hold): the setting named is one the user typed
NAMED = [
    ([*ENERGY, "env.battery_wh=1e300"], "env.battery_wh=1e300 is invalid: the evaluation", "eval.horizon=2"),
    ([*ENERGY, "env.circuit_power_w=1e9"], "env.circuit_power_w=1000000000.0 is invalid: a UAV may start", "battery"),
    (["env.energy=follow_up", "env.base=[-100000,0]"], "env.base=[-100000,0] is invalid", "eval.horizon=1"),
    ([*ENERGY, "env.slot_s=1e-300"], "env.slot_s=1e-300 is invalid: a move of one cell", "Overflow"),
    (["agent=dqn", "agent.network=set", "agent.sizes=[[10,3,3]]"], "agent.sizes=[[10,3,3]] is invalid", "env.num"),
    (["agent=dqn", "agent.network=set", "agent.sizes=[[2,100000,100000]]"], "agent.sizes=", "agent.worlds"),
    (["agent=random", "env.grid=[200,200]", "env.num_uavs=200"], "env.grid=[200,200] is invalid", "eval.horizon=800"),
    (["agent=dqn", "env.grid=[100000,100000]"], "env.grid=[100000,100000] is invalid", "lower agent.worlds"),
    (["agent=tabular", "env.grid=[10,10]", "env.num_uavs=4"], "env.num_uavs=4 is invalid: the team Q tables", "TiB"),
    (["env=a2g_urban", "agent=dqn", "agent.hidden=1000000"], "agent.hidden=1000000 is invalid", "env.num_uavs="),
]


@pytest.mark.parametrize("overrides, begins, absent", NAMED, ids=[" ".join(o) for o, _, _ in NAMED])
def test_a_refusal_names_what_was_typed_never_what_follows_from_it(overrides, begins, absent):
    line = refusal(*overrides)
    assert line is not None and line.startswith(begins) and "\n" not in line, line
    assert absent not in line.split(" is invalid")[0], line


def test_a_table_too_large_says_the_dqn_keeps_none():
    line = refusal("agent=tabular", "env.grid=[10,10]", "env.num_uavs=4")
    assert "use agent=dqn, which keeps no table" in line, line


def test_a_setting_chosen_by_a_group_says_which_choice_set_it():
    line = refusal("env=a2g_urban", "agent=tabular")
    assert line.startswith("env.num_uavs=6 (from env=a2g_urban) is invalid: the team Q tables"), line


@pytest.mark.parametrize(
    "overrides, begins",
    [
        (["agent=dqn", "agent.layouts=[random]"], "agent.layouts=[random] is invalid with agent.network='team'"),
        (["agent=dqn", "agent.sizes=[[2,3,3]]"], "agent.sizes=[[2,3,3]] is invalid with agent.network='team'"),
        (["agent=dqn", "agent.network=set", "agent.heads=3"], "agent.heads=3 is invalid with agent.hidden=128"),
        (["agent=dqn", "agent.network=set", "agent.mixer=qmix"], "agent.mixer='qmix' is invalid with agent.network"),
        (["agent=dqn", "agent.network=set", "agent.head=joint"], "agent.head='joint' is invalid with agent.network"),
        (["agent=dqn", "agent.head=joint", "env.num_uavs=5"], "agent.head='joint' is invalid with env.num_uavs=5"),
        (
            ["env=a2g_urban", "env.channel=tr36777_uma", "env.environment=highrise"],
            "env.environment='highrise' is invalid: only env.channel='al_hourani' reads it",
        ),
    ],
    ids=str,
)
def test_settings_that_cannot_go_together_are_refused_with_both_named(overrides, begins):
    line = refusal(*overrides)
    assert line is not None and line.startswith(begins) and "\n" not in line, line


def test_parts_within_the_budget_one_by_one_are_refused_together():
    """The evaluation (137 MB: the exact solver's tables) and the replay buffers (104 MB) each fit 160 MB, but they
    are held at once, with the worlds, the batches and the networks (249 MB in all)."""
    line = refusal("agent=dqn", "agent.buffer_size=4000000", "agent.memory_budget=160000000")
    begins = "agent.buffer_size=4000000 is invalid: 7 parts held at once (the evaluation the largest) needs about 249"
    assert line is not None and line.startswith(begins) and "lower agent.buffer_size" in line, line
    assert refusal("agent=dqn", "agent.buffer_size=4000000", "agent.memory_budget=250000000") is None


def test_what_a_run_within_its_budgets_needs_passes():
    """The budgets' defaults let the shipped scenarios run, and a large grid at a small team (its cost does not grow
    with the area)."""
    assert refusal("agent=dqn", "scenario=large_20x20") is None
    assert refusal("agent=dqn", "scenario=size_free") is None
    assert refusal("agent=dqn", "env.grid=[1000,1000]") is None


@pytest.fixture
def size_free_run(tmp_path):
    """A size-free run's directory as uavrl.train leaves it: its config.yaml and a checkpoint file (never read by
    the checks before torch)."""
    cfg = compose_config("config", ["agent=dqn", "agent.network=set", "agent.mixer=vdn"])
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.to_container(cfg, resolve=True)))
    (tmp_path / "run" / "checkpoint.pt").write_bytes(b"not read before torch")
    return tmp_path / "run"


EVALUATE = [
    (["env.grid=[1000000,1000000]"], "env.grid=[1000000,1000000] is invalid: the evaluation"),
    (["env.grid=[200,200]", "env.num_uavs=200"], "env.grid=[200,200] is invalid: the evaluation"),
    (["env.max_steps=1000000000000"], "env.max_steps=1000000000000 is invalid for an evaluation"),
    (["env.channel=al_hourani"], "checkpoint="),
    (["env.num_uavs=0"], "env.num_uavs=0 is invalid"),
]


def test_zero_shot_refusals_come_before_torch(size_free_run):
    """``python -m uavrl.evaluate`` refuses a zero-shot model it cannot evaluate from the run's config.yaml, and
    the DQN's settings that cannot go together are refused, without importing torch (one process for all)."""
    script = textwrap.dedent(
        f"""
        import sys
        from uavrl.cli import compose_config
        from uavrl.config import RUN_OPTION_SETTINGS
        from uavrl.envs import InvalidOption
        from uavrl.evaluate import check_settings as evaluate_check
        from uavrl.train import check_settings as train_check
        cases = [(evaluate_check, ["checkpoint={size_free_run}", *o]) for o, _ in {EVALUATE!r}]
        cases += [(train_check, ["agent=dqn", "agent.network=set", "agent.heads=3"])]
        cases += [(train_check, ["agent=dqn", "agent.layouts=[random]"])]
        for check, overrides in cases:
            try:
                check(compose_config("config", overrides), overrides=overrides)
                print("accepted")
            except InvalidOption as err:
                print(err.renamed(RUN_OPTION_SETTINGS))
            except ValueError as err:
                print(err)
        print("torch" in sys.modules)
        """
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    *lines, torch_imported = done.stdout.splitlines()
    assert done.returncode == 0 and torch_imported == "False", done.stderr
    for line, (_, begins) in zip(lines, EVALUATE, strict=False):
        assert line.startswith(begins), line
    assert lines[-2].startswith("agent.heads=3 is invalid") and lines[-1].startswith("agent.layouts=[random]")


def test_the_time_estimate_grows_with_every_setting_of_the_work():
    """The DQN's CPU-time estimate doubles (about) with the iterations and grows with the updates, the batch, the
    network and the team, not with the grid's area (at N = 2 the greedy action keeps no occupancy table)."""
    from uavrl.config import model_config
    from uavrl.costs import Factor, dqn_costs

    def hours(*overrides):
        cfg = compose_config("config", ["agent=dqn", *overrides])
        model = model_config(cfg)
        _, _, (seconds,) = dqn_costs(cfg, model, Factor("env.max_steps", model.max_steps))
        return seconds.amount / 3600

    base = hours()
    assert hours("agent.iterations=1000") == pytest.approx(2 * base, rel=0.01)
    for override in ("agent.updates=64", "agent.batch_size=512", "agent.hidden=256", "env.num_uavs=4"):
        assert hours(override) > base, override
    assert hours("env.grid=[1000,1000]") == pytest.approx(base)
