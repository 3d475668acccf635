"""Every setting of the generated settings table (docs/settings.md, ``python -m uavrl.schema``) and every model option
``env.*`` has a bad value here, refused by its command in one line that names the setting as typed; a setting added
to a schema without one fails :func:`test_every_setting_has_a_bad_value`.

The commands' checks run in this process (each as ``python -m`` would run it before torch is imported), so the whole
table costs seconds."""

import re

import pytest
from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from uavrl.cli import compose_config
from uavrl.config import RUN_OPTION_SETTINGS
from uavrl.envs import InvalidOption
from uavrl.envs.config import OPTION_NAMES
from uavrl.schema import settings_markdown

TRAIN = "python -m uavrl.train, python -m uavrl.evaluate"
REPRODUCE = "python -m uavrl.reproduce"
BENCHMARL = "python -m uavrl.benchmarl"
A2G = "env=a2g_urban"  # a physical channel: its options are read
ENERGY = "env.energy=rotary_wing env.base=[-1,0]"

# (the table's section, the setting): the overrides that give it a bad value (the setting's own override last)
BAD = {
    (TRAIN, "seed"): "seed=-1",
    (TRAIN, "device"): "device=gpu",
    (TRAIN, "num_threads"): "num_threads=0",
    (TRAIN, "run_dir"): "run_dir=''",
    (TRAIN, "sweep_dir"): "sweep_dir=''",
    (TRAIN, "resume"): "resume=''",
    (TRAIN, "checkpoint"): "checkpoint=''",
    (TRAIN, "print_json"): "print_json=maybe",
    (TRAIN, "progress"): "progress=maybe",
    (TRAIN, "train.checkpoint_every"): "train.checkpoint_every=0",
    (TRAIN, "train.log_every"): "train.log_every=0",
    (TRAIN, "train.step_budget"): "train.step_budget=0",
    (TRAIN, "train.time_budget"): "train.time_budget=0",
    (TRAIN, "eval.num_starts"): "eval.num_starts=0",
    (TRAIN, "eval.horizon"): "eval.horizon=0",
    (TRAIN, "eval.gamma"): "eval.gamma=0",
    (TRAIN, "eval.seed"): "eval.seed=-1",
    (TRAIN, "eval.every"): "eval.every=-1",
    (TRAIN, "eval.video"): "eval.video=maybe",
    (TRAIN, "eval.video_starts"): "eval.video_starts=0",
    (TRAIN, "eval.video_fps"): "eval.video_fps=0",
    (TRAIN, "eval.lookahead"): "eval.lookahead=-1",
    (TRAIN, "eval.lookahead_width"): "eval.lookahead_width=-2",
    (TRAIN, "scenario"): "scenario=paper_6x6 scenario.agents=[qlearner]",
    ("agent=tabular", "agent.method"): "agent.method=sarsa",
    ("agent=tabular", "agent.alpha"): "agent.alpha=0",
    ("agent=tabular", "agent.gamma"): "agent.gamma=2",
    ("agent=tabular", "agent.epsilon"): "agent.epsilon=-1",
    ("agent=tabular", "agent.shared_table"): "agent.shared_table=maybe",
    ("agent=tabular", "agent.backend"): "agent.backend=jax",
    ("agent=tabular", "agent.memory_budget"): "agent.memory_budget=0",
    ("agent=tabular", "agent.episodes"): "agent.episodes=0",
    ("agent=tabular", "agent.runs"): "agent.runs=0",
    ("agent=dqn", "agent.head"): "agent.head=both",
    ("agent=dqn", "agent.mixer"): "agent.mixer=sum",
    ("agent=dqn", "agent.network"): "agent.network=tree",
    ("agent=dqn", "agent.sizes"): "agent.network=set agent.sizes=[[0,3,3]]",
    ("agent=dqn", "agent.layouts"): "agent.network=set agent.layouts=[spiral]",
    ("agent=dqn", "agent.cities"): "agent.network=set env=a2g_urban env.city=urban agent.cities=[0,0]",
    ("agent=dqn", "agent.heads"): "agent.network=set agent.heads=0",
    ("agent=dqn", "agent.worlds"): "agent.worlds=0",
    ("agent=dqn", "agent.hidden"): "agent.hidden=0",
    ("agent=dqn", "agent.depth"): "agent.depth=0",
    ("agent=dqn", "agent.mixing_embed_dim"): "agent.mixer=qmix agent.mixing_embed_dim=0",
    ("agent=dqn", "agent.objective"): "agent.objective=reward",
    ("agent=dqn", "agent.gap_floor"): "agent.gap_floor=0",
    ("agent=dqn", "agent.gamma"): "agent.gamma=1.5",
    ("agent=dqn", "agent.n_step"): "agent.n_step=0",
    ("agent=dqn", "agent.replay"): "agent.replay=rank",
    ("agent=dqn", "agent.priority_alpha"): "agent.replay=prioritized agent.priority_alpha=0",
    ("agent=dqn", "agent.priority_beta"): "agent.replay=prioritized agent.priority_beta=2",
    ("agent=dqn", "agent.lr"): "agent.lr=0",
    ("agent=dqn", "agent.lr_end"): "agent.lr_end=-1",
    ("agent=dqn", "agent.batch_size"): "agent.batch_size=0",
    ("agent=dqn", "agent.buffer_size"): "agent.buffer_size=0",
    ("agent=dqn", "agent.updates"): "agent.updates=0",
    ("agent=dqn", "agent.learning_starts"): "agent.learning_starts=-1",
    ("agent=dqn", "agent.tau"): "agent.tau=2",
    ("agent=dqn", "agent.eps_start"): "agent.eps_start=2",
    ("agent=dqn", "agent.eps_end"): "agent.eps_end=-0.5",
    ("agent=dqn", "agent.eps_fraction"): "agent.eps_fraction=3",
    ("agent=dqn", "agent.max_grad_norm"): "agent.max_grad_norm=0",
    ("agent=dqn", "agent.iterations"): "agent.iterations=0",
    ("agent=dqn", "agent.memory_budget"): "agent.memory_budget=-5",
    ("agent=dqn", "agent.demonstrations"): "agent.network=set agent.demonstrations=expert",
    ("agent=dqn", "agent.demo_transitions"): "agent.network=set agent.demonstrations=oracle agent.demo_transitions=0",
    ("agent=dqn", "agent.demo_batch_share"): "agent.network=set agent.demonstrations=oracle agent.demo_batch_share=1",
    ("agent=dqn", "agent.margin"): "agent.network=set agent.demonstrations=oracle agent.margin=0",
    ("agent=dqn", "agent.curriculum"): "agent.network=set agent.curriculum=random",
    ("agent=random, agent=oracle, agent=planner", "agent.memory_budget"): "agent.memory_budget=0",
    (REPRODUCE, "command"): "command=table3",
    (REPRODUCE, "grids"): "grids=[0]",
    (REPRODUCE, "num_uavs"): "num_uavs=0",
    (REPRODUCE, "runs"): "runs=0",
    (REPRODUCE, "episodes"): "episodes=0",
    (REPRODUCE, "steps"): "steps=0",
    (REPRODUCE, "seed"): "seed=-1",
    (REPRODUCE, "state_includes_tasks"): "state_includes_tasks=maybe",
    (REPRODUCE, "eval_starts"): "eval_starts=0",
    (REPRODUCE, "figure_grid"): "command=figures figure_grid=7",
    (REPRODUCE, "out_dir"): "out_dir=''",
    (REPRODUCE, "overwrite"): "overwrite=maybe",
    (REPRODUCE, "progress"): "progress=maybe",
    (REPRODUCE, "num_threads"): "num_threads=0",
    (REPRODUCE, "numba_threads"): "numba_threads=-1",
    (REPRODUCE, "memory_budget"): "memory_budget=0",
    (REPRODUCE, "step_budget"): "step_budget=0",
    (BENCHMARL, "seed"): "seed=-1",
    (BENCHMARL, "num_threads"): "num_threads=0",
    (BENCHMARL, "run_dir"): "run_dir=''",
    (BENCHMARL, "eval.num_starts"): "eval.num_starts=0",
    (BENCHMARL, "eval.horizon"): "eval.horizon=0",
    (BENCHMARL, "eval.gamma"): "eval.gamma=0",
    (BENCHMARL, "eval.seed"): "eval.seed=-1",
    (BENCHMARL, "eval.every"): "eval.every=-1",
    (BENCHMARL, "task.name"): "task.name=[1]",
    (BENCHMARL, "memory_budget"): "memory_budget=0",
    (BENCHMARL, "scenario"): "scenario.agents=[qlearner]",
}
# the model's options, as uavrl.train reads them (env.<option>)
BAD_OPTIONS = {
    "grid": "env.grid=[0,3]",
    "num_uavs": "env.num_uavs=0",
    "max_steps": "env.max_steps=0",
    "layout": "env.layout=spiral",
    "cell_size": "env.cell_size=-1",
    "altitude": "env.altitude=-1",
    "altitude_m": "env.altitude_m=-1",
    "altitudes_m": "env.altitudes_m=[100,30]",
    "channel": "env.channel=fibre",
    "alpha": "env.alpha=-1",
    "g0": "env.g0=0",
    "fading": "env.fading=nakagami",
    "rician_k_db": "env.fading=rician env.rician_k_db=inf",
    "p_pt": "env.p_pt=-1",
    "p_s": "env.p_s=0",
    "p_u": "env.p_u=-2",
    "noise": "env.noise=-1",
    "environment": f"{A2G} env.environment=desert",
    "carrier_ghz": f"{A2G} env.carrier_ghz=1000",
    "bandwidth_mhz": f"{A2G} env.bandwidth_mhz=-1",
    "noise_figure_db": f"{A2G} env.noise_figure_db=1000",
    "p_pt_dbm": f"{A2G} env.p_pt_dbm=1000",
    "p_s_dbm": f"{A2G} env.p_s_dbm=-1000",
    "p_u_dbm": f"{A2G} env.p_u_dbm=1000",
    "city": f"{A2G} env.city=atlantis",
    "city_alpha": f"{A2G} env.city=urban env.city_alpha=1",
    "city_beta": f"{A2G} env.city=urban env.city_beta=-500",
    "city_gamma": f"{A2G} env.city=urban env.city_gamma=nan",
    "city_seed": f"{A2G} env.city=urban env.city_seed=-1",
    "los": f"{A2G} env.city=urban env.los=ray_traced",
    "direct_links": "env.direct_links=maybe",
    "lease_rule": "env.lease_rule=maybe",
    "rate_model": "env.rate_model=shannon",
    "reference_gain": "env.reference_gain=-1",
    "reward": "env.reward=money",
    "beta1": "env.beta1=nan",
    "beta2": "env.beta2=inf",
    "init_tasks": "env.init_tasks=both",
    "reset_positions": "env.reset_positions=teleport",
    "state_includes_tasks": "env.state_includes_tasks=maybe",
    "energy": "env.energy=nuclear",
    "base": "env.base=[0,0]",
    "battery_wh": f"{ENERGY} env.battery_wh=-1",
    "battery_init": f"{ENERGY} env.battery_init=empty",
    "recharge_steps": f"{ENERGY} env.recharge_steps=0",
    "num_spares": f"{ENERGY} env.recharge_steps=2 env.num_spares=-1",
    "slot_s": f"{ENERGY} env.slot_s=0",
    "circuit_power_w": f"{ENERGY} env.circuit_power_w=-1",
    "observation": "env.observation=nearby",
    "comm_radius": "env.observation=local env.comm_radius=-1",
    "message_size": "env.observation=local env.message_size=65",
}


def table_settings() -> set[tuple[str, str]]:
    """``(section, setting)`` of every row of the generated table."""
    rows, section = set(), None
    for line in settings_markdown().splitlines():
        if line.startswith("## "):
            section = line[3:]
        elif line.startswith("| `"):
            rows.add((section, re.match(r"\| `([^`]+)`", line).group(1)))
    return rows


def test_every_setting_has_a_bad_value():
    assert table_settings() - set(BAD) == set(), "a setting of docs/settings.md has no bad-input case here"
    assert set(BAD) - table_settings() == set(), "a case here names no setting of docs/settings.md"
    assert set(BAD_OPTIONS) == set(OPTION_NAMES), "a model option has no bad-input case here"


def refused(section: str, overrides: list[str]) -> str | None:
    """The one line the section's command refuses ``overrides`` with, checked as it checks them before torch."""
    from uavrl.reproduce import OPTION_SETTINGS
    from uavrl.reproduce import check_settings as check_reproduce
    from uavrl.settings import BENCHMARL_SETTINGS
    from uavrl.train import check_settings as check_train

    try:
        if section == BENCHMARL:  # BenchMARL's own groups need BenchMARL: uavrl's settings against their rules
            from uavrl.envs.rules import check
            from uavrl.schema import BenchmarlSchema

            cfg = OmegaConf.merge(OmegaConf.structured(BenchmarlSchema), OmegaConf.from_dotlist(overrides))
            check(cfg, BENCHMARL_SETTINGS)
        elif section == REPRODUCE:
            check_reproduce(compose_config("reproduce", overrides), overrides)
        else:
            agent = [] if section == TRAIN else [section.split(",")[0]]
            check_train(compose_config("config", [*agent, *overrides]), [*agent, *overrides])
    except SystemExit as err:
        return str(err).removeprefix("error: ")
    except InvalidOption as err:
        return err.renamed(OPTION_SETTINGS if section == REPRODUCE else RUN_OPTION_SETTINGS)
    except (ValueError, OSError, OmegaConfBaseException) as err:
        return " ".join(str(err).split())
    return None


CASES = [(section, name, text.split()) for (section, name), text in BAD.items()]
CASES += [(TRAIN, f"env.{name}", text.split()) for name, text in BAD_OPTIONS.items()]


@pytest.mark.parametrize("section, name, overrides", CASES, ids=[f"{s}: {' '.join(o)}" for s, _, o in CASES])
def test_each_bad_value_is_refused_naming_its_setting(section, name, overrides, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a command that wrongly accepted would write here, not in the checkout
    line = refused(section, overrides)
    assert line is not None, f"{' '.join(overrides)} was accepted"
    assert "\n" not in line and "Traceback" not in line, line
    assert name in line, f"the refusal does not name {name}: {line}"


# every setting read only where a sibling setting allows (its schema's read_if): a value other than its default, the
# overrides that leave it unread and the sibling's value the refusal names, and the overrides that make it read
SET = "agent.network=set agent.mixer=vdn"
UNREAD = {
    "eval.lookahead_width": ("3", "", "eval.lookahead=0", "eval.lookahead=1"),
    "agent.heads": ("2", "", "agent.network='team'", SET),
    "agent.demo_transitions": ("80", SET, "agent.demonstrations='none'", f"{SET} agent.demonstrations=oracle"),
    "agent.demo_batch_share": ("0.5", "", "agent.demonstrations='none'", f"{SET} agent.demonstrations=oracle"),
    "agent.margin": ("2", "", "agent.demonstrations='none'", f"{SET} agent.demonstrations=oracle"),
    "agent.mixing_embed_dim": ("8", "", "agent.mixer='vdn'", "agent.mixer=qmix"),
    "agent.gap_floor": ("0.01", "agent.objective=delta", "agent.objective='delta'", "agent.objective=log_gap"),
    "agent.priority_alpha": ("0.5", "", "agent.replay='uniform'", "agent.replay=prioritized"),
    "agent.priority_beta": ("0.5", "", "agent.replay='uniform'", "agent.replay=prioritized"),
}


def read_only_where() -> dict:
    """``{setting: its Rule}`` of the commands' settings read only where another allows (``read_if``)."""
    from uavrl.settings import AGENT_SETTINGS, RUN_SETTINGS

    tables = [RUN_SETTINGS, *AGENT_SETTINGS.values()]
    return {name: rule for table in tables for name, rule in table.items() if rule.reader is not None}


def test_every_setting_read_only_where_another_allows_has_a_case():
    assert set(read_only_where()) == set(UNREAD)


@pytest.mark.parametrize("name", sorted(UNREAD))
def test_a_setting_nothing_reads_is_refused_naming_what_reads_it(name, tmp_path, monkeypatch):
    """Changed from its default where its sibling leaves it unread: refused in one line naming the sibling's value
    that reads it; where that value is given, accepted."""
    monkeypatch.chdir(tmp_path)
    value, unread, sibling, reads = UNREAD[name]
    rule, section = read_only_where()[name], name.rpartition(".")[0]
    agent = [] if name.startswith("eval.") else ["agent=dqn"]
    line = refused(TRAIN, [*agent, *unread.split(), f"{name}={value}"])
    assert line == f"{name}={value} is invalid: only {section}.{rule.reader.words} reads it, not {sibling}"
    assert refused(TRAIN, [*agent, *reads.split(), f"{name}={value}"]) is None


def test_an_agent_built_in_python_refuses_an_unread_setting_as_the_command_line_does(compose_cfg):
    from uavrl.agents.dqn import DQNAgent
    from uavrl.config import model_config

    cfg = compose_cfg("agent=dqn", "agent.priority_alpha=0.5")
    with pytest.raises(ValueError) as raised:
        DQNAgent(model_config(cfg), cfg, "cpu", 0)
    assert str(raised.value) == (
        "agent.priority_alpha=0.5 is invalid: only agent.replay='prioritized' reads it, not agent.replay='uniform'"
    )
