"""The DQN with a size-free network (``agent.network=set``), trained over several team sizes and grids at once.

``agent.sizes`` lists the teams ``[N, L1, L2]`` one run trains on (``[]``: the run's ``env.num_uavs`` and
``env.grid`` only), each in every layout of ``agent.layouts`` (``[]``: ``env.layout``); every other model option is
the run's (channel, energy model, ...).  Each team and layout is a group
with its own ``agent.worlds`` worlds, collector, exploration and replay buffer; one core
(:class:`~.setnet.SetQCore`) acts in all of them.  One iteration: an episode in every world of every group, then
``agent.updates`` gradient steps, each the sum of one batch's loss per group (``agent.batch_size`` split evenly).
The checkpoint holds one core: :meth:`SetDQNAgent.policy_for` acts with it in an environment of any size, so
``python -m uavrl.evaluate checkpoint=<run> env.grid=[30,30] env.num_uavs=20`` evaluates it zero-shot.

Example:
    >>> from hydra import compose, initialize_config_dir
    >>> from uavrl.config import config_dir, model_config
    >>> with initialize_config_dir(config_dir=config_dir(), version_base=None):
    ...     sizes = "agent.sizes=[[2,4,4],[3,5,5]]"
    ...     cfg = compose("config", overrides=["agent=dqn", "agent.network=set", sizes, "agent.worlds=2"])
    >>> agent = SetDQNAgent(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    >>> agent.train_iteration()["train/epsilon"] < 1.0, agent.env_steps  # 2 sizes x 2 worlds x 30 steps
    (True, 120)
"""

from __future__ import annotations

from functools import partial

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torch import nn

from uavrl.agents.env_check import CheckedPolicy
from uavrl.agents.schema import AGENTS, network_refusal, training_models  # noqa: F401 (uavrl.load_policy's)
from uavrl.envs import ModelConfig, UAVSpectrumEnv
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET
from uavrl.envs.physics.channel import rates
from uavrl.envs.physics.fading import fading_part
from uavrl.envs.physics.grid import cells_or_away
from uavrl.envs.physics.rewards import log_gap_reward
from uavrl.envs.solvers.optimum import MAX_EXCHANGE_UAVS
from uavrl.evaluation import episode_metrics

from .agent import _SEED_MODULUS, DQNAgent, adam, reset_layouts
from .builders import build_collector, build_policies, build_replay_buffer, exploration_schedule
from .curriculum import Curriculum, uniform_sample
from .demonstrations import Demonstrations
from .networks import Q_INPUTS
from .setnet import SetDoubleQLoss, SetQCore, SetQNet
from .transitions import CompactTransitions, n_step_returns, transition_keys


class _Group:
    """One team size of the run: its worlds, policies, collector and replay buffer."""

    def __init__(self, agent: SetDQNAgent, cfg: ModelConfig, seed: int, frames: int):
        a = agent.settings
        self.cfg, self.grid = cfg, tuple(cfg.grid)
        self.env = UAVSpectrumEnv(
            batch_size=int(a.worlds),
            config=cfg,
            seed=seed,
            device=agent.device,
            memory_budget=a.get("memory_budget", DEFAULT_MEMORY_BUDGET),
        )
        values = TensorDictModule(
            SetQNet(agent.core, self.grid), in_keys=list(Q_INPUTS), out_keys=[("agents", "action_value")]
        )
        policies = build_policies(self.env, a, values, exploration_schedule(a, frames, agent.device))
        self.greedy, self.exploration = policies.greedy, policies.exploration
        self.keys = transition_keys(self.env.world, policies.action_keys, int(a.get("n_step", 1)))
        # agent.buffer_size transitions of this size, kept compact; samples of its share of agent.batch_size
        self.transitions = CompactTransitions(self.env.world, policies.action_keys)
        self.buffer = build_replay_buffer(a, self.transitions, agent.batch_size)
        self.collector = build_collector(self.env, policies.explore)
        self.batches = iter(self.collector)
        self.u_star = None  # a fixed layout's U*, solved once

    def optimum(self) -> torch.Tensor:
        if self.u_star is None or self.cfg.layout == "random":
            method = "exchange" if self.cfg.num_uavs <= MAX_EXCHANGE_UAVS else "search"
            self.u_star = self.env.optimum(method=method)[0]
        return self.u_star


class SetDQNAgent(DQNAgent):
    """:class:`DQNAgent` with a size-free network (``agent.network=set``, module doc), the class
    :func:`uavrl.agents.agent_class` gives for those settings.  The greedy rule (:class:`~.networks.ValidGreedy`),
    the double-DQN targets, the objective and the ``train/...`` tags are the factored DQN's; the tags are means over
    the sizes' worlds."""

    def __init__(self, env_cfg: ModelConfig, cfg, device, seed: int):
        a = cfg.agent
        AGENTS["dqn"].validate(env_cfg, a)  # the size-free network's checks too (agents/schema.py)
        if a.get("network", "team") != "set":
            raise ValueError(
                f"agent.network={a.get('network', 'team')!r} is invalid for SetDQNAgent: use agent.network=set"
            )
        self.env_cfg, self.settings, self.seed = env_cfg, a, int(seed)
        self.device = torch.device(device)
        self.num_iterations = int(a.iterations)
        self.iteration = 0
        torch.manual_seed(self.seed)  # the core's initial weights
        energy = env_cfg.energy != "none"
        self.core = SetQCore(env_cfg.num_actions, energy, int(a.hidden), int(a.heads), int(a.depth)).to(self.device)
        self.loss = SetDoubleQLoss(self.core, a.mixer, float(a.gamma), env_cfg.num_actions)
        self.optimizer = adam(list(self.core.parameters()), float(a.lr))
        frames = int(a.worlds) * env_cfg.max_steps * self.num_iterations
        models = training_models(env_cfg, a)
        self.batch_size = max(1, int(a.batch_size) // len(models))
        self.groups = [_Group(self, model, self._group_seed(0, g), frames) for g, model in enumerate(models)]
        # the sample-efficiency levers (off: pure RL): the oracle's demonstrations, a curriculum over the groups
        self.curriculum = Curriculum(a.get("curriculum", "none"), len(self.groups), self.batch_size * len(self.groups))
        self.demonstrations = None  # built at the first gradient step: an evaluation of the checkpoint needs none

    def _group_seed(self, iteration: int, group: int) -> int:
        return (self._world_seed(iteration) + group * int(self.settings.worlds)) % _SEED_MODULUS

    @property
    def env_steps(self) -> int:
        """Team steps collected so far (sizes times worlds times steps)."""
        return self.iteration * len(self.groups) * int(self.settings.worlds) * self.env_cfg.max_steps

    def train_iteration(self) -> dict[str, float]:
        """One episode in every world of every size, then ``agent.updates`` gradient steps."""
        a = self.settings
        for group in self.optimizer.param_groups:  # annealed linearly from agent.lr to agent.lr_end over the run
            group["lr"] = float(a.lr) + (float(a.lr_end) - float(a.lr)) * min(1.0, self.iteration / self.num_iterations)
        per_world = [self._collect(g, group) for g, group in enumerate(self.groups)]
        learning = all(len(group.buffer) >= int(a.learning_starts) for group in self.groups)
        losses = [self._update() for _ in range(int(a.updates))] if learning else []
        self.iteration += 1
        out = {f"train/{k}": torch.cat([w[k] for w in per_world]).mean().item() for k in per_world[0]}
        out["train/epsilon"] = self.groups[0].exploration.eps.item()
        if losses:
            out["train/loss"] = torch.stack(losses).mean().item()
        return out

    def _collect(self, g: int, group: _Group) -> dict[str, torch.Tensor]:
        """One episode in every world of ``group`` into its buffer; the episodes' metrics ``[worlds]``."""
        group.collector.set_seed(self._group_seed(self.iteration, g), static_seed=True)
        group.collector.reset()
        u_star = group.optimum()
        env, cfg = group.env, group.cfg
        # kept (the properties return copies): the collector's closing reset draws new random layouts before the batch
        # is read; a second clone would copy every world's [C, 2] rows of a shared layout
        layout = (env.cell_contributions, env.direct)
        batch = next(group.batches)  # [worlds, steps]

        def mean_utility(td: TensorDictBase) -> torch.Tensor:
            """``[W, T]`` mean-channel utility of the batch's configurations in the layouts they were played in."""
            C = cfg.num_cells
            cells = cells_or_away(td.get("positions"), cfg.grid)  # C: out of service, adds nothing
            on_grid = layout[0][torch.arange(len(cells), device=cells.device)[:, None, None], cells.clamp(max=C - 1)]
            contributions = on_grid.masked_fill((cells == C).unsqueeze(-1), 0.0)
            r_pu, r_se = rates(contributions, td.get("tasks"), layout[1][:, None], cfg)
            return r_pu + r_se

        nxt = batch.get("next")
        if self.settings.objective == "log_gap":
            change = log_gap_reward(
                mean_utility(nxt), mean_utility(batch), u_star.unsqueeze(-1), float(self.settings.gap_floor)
            )
            batch.set(("next", "reward"), change.unsqueeze(-1).to(nxt.get("reward").dtype))
        stored = n_step_returns(batch, int(self.settings.get("n_step", 1)), float(self.settings.gamma))
        group.buffer.extend(stored.reshape(-1).select(*group.keys))
        group.exploration.step(batch.numel())
        reach_utility = mean_utility(nxt) if fading_part(cfg).random else None
        return episode_metrics(
            *(nxt.get(key).squeeze(-1) for key in ("r_pu", "r_se", "task_switches", "moves")), u_star, reach_utility
        )

    def _update(self) -> torch.Tensor:
        if self.demonstrations is None and self.settings.get("demonstrations", "none") == "oracle":
            self.demonstrations = Demonstrations(self, self.groups)
        sizes, losses, margins = self.curriculum.batch_sizes(), [], []
        for g, (group, size) in enumerate(zip(self.groups, sizes, strict=True)):
            if self.demonstrations is None:
                batch = group.buffer.sample() if size == self.batch_size else uniform_sample(group.buffer, size)
            else:  # DQfD: the demonstrations' share of the batch gets the TD loss and the margin loss
                demos = self.demonstrations.sample(g, self.demonstrations.demo_size(size))
                batch = torch.cat([uniform_sample(group.buffer, max(1, size - len(demos))), demos])
                margins.append(self.demonstrations.loss(self.core, demos, group.grid))
            losses.append(self.loss(batch, group.grid)["loss"])
        self.curriculum.record(torch.stack(losses))
        loss = self.curriculum.total(losses, sizes) + sum(margins)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        nn.utils.clip_grad_norm_(self.core.parameters(), float(self.settings.max_grad_norm), foreach=True)
        self.optimizer.step()
        self.loss.update_target(float(self.settings.tau))
        return loss.detach()

    def policy_for(self, env_cfg: ModelConfig, run: int = 0) -> CheckedPolicy:
        """The greedy policy (one run: ``run`` 0) in environments of ``env_cfg``: any grid and number of UAVs of the
        run's model (a one-line ValueError for another model: other observations, or actions)."""
        if (env_cfg.energy != "none") != self.core.energy or env_cfg.num_actions != self.env_cfg.num_actions:
            raise ValueError(
                f"env.energy={env_cfg.energy!r} is invalid for this network, trained with "
                f"env.energy={self.env_cfg.energy!r}: its inputs and actions differ"
            )
        env = UAVSpectrumEnv(batch_size=1, config=env_cfg, device=self.device)
        values = TensorDictModule(
            SetQNet(self.core, env_cfg.grid), in_keys=list(Q_INPUTS), out_keys=[("agents", "action_value")]
        )
        frames = exploration_schedule(self.settings, 1, self.device)
        return CheckedPolicy(build_policies(env, self.settings, values, frames).greedy, env_cfg)

    def policies(self) -> list[CheckedPolicy]:
        """The greedy policy in environments of the run's config (:meth:`policy_for` for any other size)."""
        return [self.policy_for(self.env_cfg)]

    def evaluate(self, env_cfg, **kwargs) -> list[dict[str, float]]:
        """:func:`uavrl.evaluation.evaluate` of the greedy policy in ``env_cfg``, of any size."""
        from uavrl.evaluation import evaluate

        return [evaluate(self.policy_for(env_cfg), env_cfg, **kwargs)]

    def _experience_state(self) -> dict:
        """Every size's ``"exploration"`` and ``"buffer"``, in the order of the groups."""
        return {
            "exploration": [group.exploration.state_dict() for group in self.groups],
            "buffer": [group.buffer.state_dict() for group in self.groups],
            "curriculum": self.curriculum.state_dict(),
        }

    def _load_experience(self, state: dict) -> None:
        if len(state["buffer"]) != len(self.groups):
            raise ValueError(f"the state holds {len(state['buffer'])} team sizes, the agent {len(self.groups)}")
        if "curriculum" in state:  # checkpoints saved before the curriculum: none
            self.curriculum.load_state_dict(state["curriculum"])
        for g, group in enumerate(self.groups):
            group.exploration.load_state_dict(state["exploration"][g])
            layouts_of = partial(self._group_layouts, g)
            self._load_buffer(group.buffer, group.transitions, {"buffer": state["buffer"][g]}, group.env, layouts_of)

    def _group_layouts(self, g: int, iteration: int) -> torch.Tensor:
        """``[W, 4, 3]`` the layouts group ``g``'s worlds were reset to at ``iteration`` (:meth:`_collect`)."""
        group = self.groups[g]
        return reset_layouts(group.cfg, group.env.num_worlds, self.device, self._group_seed(iteration, g))
