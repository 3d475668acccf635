"""Schemas of the Hydra configs, registered with Hydra's ConfigStore (standard library, omegaconf and hydra only).

``configs/config.yaml`` starts from :class:`RunSchema`, each ``configs/env/*.yaml``
from :class:`EnvSchema` and each ``configs/agent/*.yaml`` from its agent's
schema, so Hydra refuses an unknown key or a value of the wrong type while it
composes the config (``uavrl.cli`` words the refusal as the rules of
:mod:`uavrl.settings` do); the rules then check the ranges.  Real-valued
settings are typed ``Any``: OmegaConf would turn ``0`` into ``0.0``, and a
refusal names the value as typed.

Example:
    >>> from uavrl.cli import compose_config
    >>> cfg = compose_config("config", ["agent=dqn", "env.grid=[4,4]"])
    >>> type(cfg.agent).__name__, cfg.env.max_steps, cfg.env.layout
    ('DictConfig', 30, None)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

REAL = Any  # a real number as typed (int or float), checked by uavrl.settings or uavrl.envs.ModelConfig


@dataclass
class TrainSchema:
    checkpoint_every: int = 50
    log_every: int = 1
    step_budget: int = 10**10


@dataclass
class EvalSchema:
    num_starts: int = 64
    horizon: Optional[int] = None
    gamma: REAL = 0.9
    seed: int = 1000003
    every: int = 0


@dataclass
class RunEvalSchema(EvalSchema):
    """The evaluation of ``uavrl.train`` and ``uavrl.evaluate``, with a video of the greedy policy beside the oracle
    (``uavrl/video.py``)."""

    video: bool = False
    video_starts: int = 3
    video_fps: int = 4


@dataclass
class EnvSchema:
    """The model's options (:class:`uavrl.envs.ModelConfig`); null keeps the preset's value."""

    name: str = "paper"
    preset: str = "paper"
    grid: list[int] = field(default_factory=lambda: [6, 6])
    num_uavs: int = 2
    max_steps: int = 100
    layout: Optional[str] = None
    cell_size: REAL = None
    altitude: REAL = None
    altitude_m: REAL = None
    channel: Optional[str] = None
    alpha: REAL = None
    g0: REAL = None
    fading: Optional[str] = None
    rician_k_db: REAL = None
    p_pt: REAL = None
    p_s: REAL = None
    p_u: REAL = None
    noise: REAL = None
    environment: Optional[str] = None
    carrier_ghz: REAL = None
    bandwidth_mhz: REAL = None
    noise_figure_db: REAL = None
    p_pt_dbm: REAL = None
    p_s_dbm: REAL = None
    p_u_dbm: REAL = None
    direct_links: Optional[bool] = None
    lease_rule: Optional[bool] = None
    rate_model: Optional[str] = None
    reference_gain: REAL = None
    reward: Optional[str] = None
    beta1: REAL = None
    beta2: REAL = None
    init_tasks: Optional[str] = None
    reset_positions: Optional[str] = None
    state_includes_tasks: Optional[bool] = None


@dataclass
class TabularSchema:
    name: str = "tabular"
    method: str = "q_learning"
    alpha: REAL = 0.1
    gamma: REAL = 0.3
    epsilon: REAL = 0.1
    shared_table: bool = False
    backend: str = "numba"
    memory_budget: REAL = 4 * 2**30
    episodes: int = 200
    runs: int = 10


@dataclass
class DQNSchema:
    name: str = "dqn"
    head: str = "factored"
    mixer: str = "vdn"
    worlds: int = 64
    hidden: int = 128
    depth: int = 2
    mixing_embed_dim: int = 32
    objective: str = "log_gap"
    gap_floor: REAL = 0.0001
    gamma: REAL = 0.7
    lr: REAL = 0.0005
    lr_end: REAL = 0.00005
    batch_size: int = 256
    buffer_size: int = 50000
    updates: int = 32
    learning_starts: int = 2000
    tau: REAL = 0.01
    eps_start: REAL = 1.0
    eps_end: REAL = 0.05
    eps_fraction: REAL = 0.5
    max_grad_norm: REAL = 10.0
    iterations: int = 500
    memory_budget: REAL = 4 * 2**30


@dataclass
class BaselineSchema:
    name: str = "random"
    memory_budget: REAL = 4 * 2**30


@dataclass
class ScenarioSchema:
    """``configs/scenario/<name>.yaml``: a named setting of the environment; its budgets are in ``budget/``."""

    name: str = "paper_6x6"
    agents: list[str] = field(default_factory=lambda: ["tabular", "dqn", "random", "oracle"])  # the agents it runs


@dataclass
class RunSchema:
    """``configs/config.yaml``: the run's settings; ``env`` and ``agent`` come from their groups."""

    seed: int = 0
    device: str = "cpu"
    num_threads: int = 1
    run_dir: Optional[str] = None
    sweep_dir: Optional[str] = None
    resume: Optional[str] = None
    checkpoint: Optional[str] = None
    progress: bool = True
    train: TrainSchema = field(default_factory=TrainSchema)
    eval: RunEvalSchema = field(default_factory=RunEvalSchema)
    env: EnvSchema = field(default_factory=EnvSchema)
    agent: Any = None
    scenario: Optional[ScenarioSchema] = None  # null: env and agent as given; scenario=<name>: configs/scenario/


@dataclass
class BenchmarlTaskSchema:
    name: str = "paper_6x6"


@dataclass
class BenchmarlSchema:
    """``configs/benchmarl.yaml``: our settings, the model's options and the task's name; BenchMARL's own groups
    (``experiment``, ``algorithm``, ``model``, ``critic_model``) bring their schemas from BenchMARL."""

    seed: int = 0
    num_threads: int = 1
    run_dir: Optional[str] = None
    eval: EvalSchema = field(default_factory=EvalSchema)
    env: EnvSchema = field(default_factory=EnvSchema)
    task: BenchmarlTaskSchema = field(default_factory=BenchmarlTaskSchema)
    experiment: Any = None
    algorithm: Any = None
    model: Any = None
    critic_model: Any = None


@dataclass
class ReproduceSchema:
    """``configs/reproduce.yaml``."""

    command: str = "table2"
    grids: list[int] = field(default_factory=lambda: [2, 3, 4, 5, 6, 8, 10])
    num_uavs: int = 2
    runs: int = 10
    episodes: int = 200
    steps: Optional[int] = None
    seed: int = 0
    state_includes_tasks: bool = False
    eval_starts: int = 64
    figure_grid: int = 6
    out_dir: Optional[str] = None
    overwrite: bool = False
    progress: bool = True
    num_threads: int = 1
    numba_threads: int = 0
    memory_budget: REAL = 4 * 2**30
    step_budget: int = 10**10


AGENT_SCHEMAS = {"tabular": TabularSchema, "dqn": DQNSchema, "random": BaselineSchema, "oracle": BaselineSchema}


def register() -> None:
    """Store the schemas in Hydra's ConfigStore (before composing): ``run_schema``, ``reproduce_schema``,
    ``benchmarl_schema``, ``schema/env``, ``schema/scenario``, ``schema/agent/<name>``."""
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance()
    store.store(name="run_schema", node=RunSchema)
    store.store(name="reproduce_schema", node=ReproduceSchema)
    store.store(name="benchmarl_schema", node=BenchmarlSchema)
    store.store(group="schema", name="env", node=EnvSchema)
    store.store(group="schema", name="scenario", node=ScenarioSchema)
    for name, schema in AGENT_SCHEMAS.items():
        store.store(group="schema/agent", name=name, node=schema)
