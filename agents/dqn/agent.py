"""The DQN agent: one construction and one iteration (an episode in every world, then gradient steps) for both of its
networks, read top to bottom.  What differs between ``agent.network=team`` and ``agent.network=set`` is the network
object, the hooks of :class:`~.builders.QNetwork`: :class:`~.builders.TeamNetwork` and
:class:`~.multisize.SetNetwork`."""

from __future__ import annotations

from functools import partial

import torch
from tensordict import TensorDictBase
from torch import nn

from uavrl.agents.base import Agent
from uavrl.agents.env_check import CheckedPolicy
from uavrl.agents.episodes import episode_metrics
from uavrl.agents.evaluation import evaluate
from uavrl.agents.schema import AGENTS
from uavrl.envs import InvalidOption, ModelConfig, UAVSpectrumEnv
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET, SEED_LIMIT
from uavrl.envs.physics.channel import rates
from uavrl.envs.physics.fading import fading_part
from uavrl.envs.physics.rewards import log_gap_reward
from uavrl.envs.solvers.optimum import MAX_EXCHANGE_UAVS
from uavrl.envs.world import World

from .builders import TeamNetwork, build_collector, build_policies, build_replay_buffer, exploration_schedule
from .curriculum import Curriculum, uniform_sample
from .demonstrations import Demonstrations
from .migration import load_replay_buffer
from .networks import LEVELS, PositionIndex, position_numbers
from .transitions import CompactTransitions, n_step_returns, transition_keys

_ITERATION_STRIDE = 2**24  # world seeds of iteration k: seed * 2^44 + (k + 1) * 2^24 + world, clear of the eval seeds


class _Group:
    """One team (and layout) of the run: its worlds, policies, replay buffer and, once the networks are built, its
    collector (:meth:`start`)."""

    def __init__(self, agent: DQNAgent, env: UAVSpectrumEnv, frames: int):
        a = agent.settings
        self.env, self.cfg, self.grid = env, env.cfg, tuple(env.cfg.grid)
        self.values = agent.network.values(env)
        self.policies = build_policies(env, a, self.values, exploration_schedule(a, frames, agent.device))
        self.greedy, self.exploration = self.policies.greedy, self.policies.exploration
        self.keys = transition_keys(env.world, self.policies.action_keys, int(a.get("n_step", 1)))
        # agent.buffer_size transitions of this team, kept compact; samples of its share of agent.batch_size
        self.transitions = CompactTransitions(env.world, self.policies.action_keys, int(a.get("n_step", 1)))
        self.buffer = build_replay_buffer(a, self.transitions, agent.batch_size)
        self.u_star = None  # a fixed layout's U*, solved once

    def start(self) -> None:
        self.collector = build_collector(self.env, self.policies.explore)
        self.batches = iter(self.collector)

    def optimum(self) -> torch.Tensor:
        if self.u_star is None or self.cfg.layout == "random":
            method = "exchange" if self.cfg.num_uavs <= MAX_EXCHANGE_UAVS else "search"
            self.u_star = self.env.optimum(method=method)[0]
        return self.u_star


class DQNAgent(Agent):
    """The deep agent behind ``python -m uavrl.train agent=dqn`` (contract: :class:`uavrl.agents.base.Agent`).

    ``cfg.agent`` holds the settings (``configs/agent/dqn.yaml``), ``agent.iterations`` the run length.  This class
    trains the per-size network (:class:`~.builders.TeamNetwork`); the size-free one (``agent.network=set``) is
    :class:`~.multisize.SetDQNAgent`, this class with :class:`~.multisize.SetNetwork`, the class
    :func:`uavrl.agents.agent_class` gives for those settings.

    One iteration: an episode in every world of every group (one group per team and layout the network trains on:
    the run's own for the per-size network), then ``agent.updates`` gradient steps, each the sum of one batch's loss
    per group (``agent.batch_size`` split evenly, or by the curriculum).

    Args:
        env_cfg: the run's :class:`~uavrl.envs.ModelConfig` (its ``max_steps`` the episode length).
        cfg: the full Hydra config; the agent reads ``cfg.agent``.
        device: the torch device of the networks, the replay buffer and the training worlds.
        seed: seeds the networks' initial weights and every iteration's worlds.
    """

    Network = TeamNetwork  # what agent.network=team builds (builders.py); SetDQNAgent: SetNetwork

    def __init__(self, env_cfg: ModelConfig, cfg, device, seed: int):
        a = cfg.agent
        AGENTS["dqn"].validate(env_cfg, a)
        network = a.get("network", "team")  # run configs saved before: no setting
        if network != self.Network.name:
            raise ValueError(
                f"agent.network={network!r} is invalid for {type(self).__name__}, the {self.Network.kind} network: "
                "build uavrl.agents.agent_class('dqn', cfg.agent), the class of the settings' agent.network"
            )
        self.env_cfg, self.settings, self.seed = env_cfg, a, int(seed)
        self.device = torch.device(device)
        self.num_iterations = int(a.iterations)
        self.iteration = 0
        torch.manual_seed(self.seed)  # the networks' initial weights; build order matters
        models = self.Network.models(env_cfg, a)
        self.batch_size = max(1, int(a.batch_size) // len(models))
        envs = [self._training_env(model, self._group_seed(0, g)) for g, model in enumerate(models)]
        self.network = self.Network(self, envs[0])
        frames = int(a.worlds) * env_cfg.max_steps * self.num_iterations
        self.groups = [_Group(self, env, frames) for env in envs]
        self.loss = self.network.build_loss(self.groups[0].policies)
        self.optimizer = adam(self.network.parameters(), float(a.lr))
        for group in self.groups:
            group.start()
        # the sample-efficiency levers (off: pure RL): the oracle's demonstrations, a curriculum over the groups
        self.curriculum = Curriculum(a.get("curriculum", "none"), len(self.groups), self.batch_size * len(self.groups))
        self.demonstrations = None  # built at the first gradient step: an evaluation of the checkpoint needs none

    def _training_env(self, cfg: ModelConfig, seed: int) -> UAVSpectrumEnv:
        a = self.settings
        memory_budget = a.get("memory_budget", DEFAULT_MEMORY_BUDGET)  # run directories saved without it
        try:
            return UAVSpectrumEnv(
                batch_size=int(a.worlds), config=cfg, seed=seed, device=self.device, memory_budget=memory_budget
            )
        except InvalidOption as err:  # its worlds and budget are the agent's settings
            names = {"batch_size": "agent.worlds", "memory_budget": "agent.memory_budget"}
            raise InvalidOption(names.get(err.option, err.option), message=err.renamed(names)) from None

    def _world_seed(self, iteration: int) -> int:
        # world seeds are int64: seeds past 2^19 wrap around
        return (self.seed * 2**44 + (iteration + 1) * _ITERATION_STRIDE) % SEED_LIMIT

    def _group_seed(self, iteration: int, group: int) -> int:
        return (self._world_seed(iteration) + group * int(self.settings.worlds)) % SEED_LIMIT

    # the first group's parts: the per-size network's only group
    env = property(lambda self: self.groups[0].env)
    greedy = property(lambda self: self.groups[0].greedy)
    exploration = property(lambda self: self.groups[0].exploration)
    buffer = property(lambda self: self.groups[0].buffer)
    transitions = property(lambda self: self.groups[0].transitions)

    @property
    def env_steps(self) -> int:
        """Team steps collected so far (groups times worlds times steps)."""
        return self.iteration * len(self.groups) * int(self.settings.worlds) * self.env_cfg.max_steps

    def train_iteration(self) -> dict[str, float]:
        """One episode in every world of every group, then ``agent.updates`` gradient steps."""
        a = self.settings
        progress = min(1.0, self.iteration / self.num_iterations)
        for group in self.optimizer.param_groups:  # annealed linearly from agent.lr to agent.lr_end over the run
            group["lr"] = float(a.lr) + (float(a.lr_end) - float(a.lr)) * progress
        if a.get("replay", "uniform") == "prioritized":  # importance weights annealed to full correction
            beta = float(a.priority_beta)
            for group in self.groups:
                group.buffer.sampler.beta = beta + (1.0 - beta) * progress
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
        # this episode's layouts; the exchange method where it runs (its results recorded), the search beyond
        u_star = group.optimum()
        # kept (the properties return copies): the collector's closing reset draws new random layouts before the batch
        # is read; a second clone would copy every world's [C, 2] rows of a shared layout
        layout = (group.env.cell_contributions, group.env.direct)
        utility = partial(mean_utility, group.cfg, layout, numbers=position_numbers(group.env.world))
        batch = next(group.batches)  # [worlds, steps]
        nxt = batch.get("next")
        if self.settings.objective == "log_gap":
            batch.set(("next", "reward"), self._log_gap_reward(batch, u_star, utility))
        batch = group.transitions.with_previous(batch)  # with messages: what they are sent again from
        stored = n_step_returns(batch, int(self.settings.get("n_step", 1)), float(self.settings.gamma))
        group.buffer.extend(stored.reshape(-1).select(*group.keys))
        group.exploration.step(batch.numel())
        # under fading, "reaches 90% of U*" is decided on the configurations' mean-channel utility
        reach_utility = utility(nxt) if fading_part(group.cfg).random else None
        return episode_metrics(
            *(nxt.get(key).squeeze(-1) for key in ("r_pu", "r_se", "task_switches", "moves")), u_star, reach_utility
        )

    def _log_gap_reward(self, batch: TensorDictBase, u_star: torch.Tensor, utility) -> torch.Tensor:
        """``[W, T, 1]`` the change of ``-log(1 - U / U* + agent.gap_floor)`` over each step, mean-channel ``U``.

        The delta reward's action gaps shrink with the distance to the optimum
        (the last 0.1% of U* is worth 0.01 bit/s/Hz), below what the network
        resolves: greedy policies then wander near U*.  On a log scale of the
        gap to U* each halving of the gap is worth the same, down to the floor.
        """
        change = log_gap_reward(
            utility(batch.get("next")), utility(batch), u_star.unsqueeze(-1), float(self.settings.gap_floor)
        )
        return change.unsqueeze(-1).to(batch.get(("next", "reward")).dtype)

    def _update(self) -> torch.Tensor:
        """One gradient step: each group's TD loss on its share of the batch (and DQfD's margin loss on the
        demonstrations among them), summed."""
        a = self.settings
        if self.demonstrations is None and a.get("demonstrations", "none") == "oracle":
            self.demonstrations = Demonstrations(self, self.groups)
        sizes, losses, margins = self.curriculum.batch_sizes(), [], []
        for g, (group, size) in enumerate(zip(self.groups, sizes, strict=True)):
            if self.demonstrations is None:
                batch = group.buffer.sample() if size == self.batch_size else uniform_sample(group.buffer, size)
            else:  # DQfD: the demonstrations' share of the batch gets the TD loss and the margin loss
                demos = self.demonstrations.sample(g, self.demonstrations.demo_size(size))
                batch = torch.cat([uniform_sample(group.buffer, max(1, size - len(demos))), demos])
                margins.append(self.demonstrations.loss(group.values, demos))
            losses.append(self.network.td_loss(batch, group))
            if a.get("replay", "uniform") == "prioritized":
                group.buffer.update_priority(batch.get("index"), batch.get("td_error"))
        self.curriculum.record(torch.stack(losses))
        loss = self.curriculum.total(losses, sizes) + sum(margins)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        nn.utils.clip_grad_norm_(self.network.parameters(), float(a.max_grad_norm), foreach=True)
        self.optimizer.step()
        self.network.update_target()
        return loss.detach()

    def policy_for(self, env_cfg: ModelConfig, run: int = 0) -> CheckedPolicy:
        """The greedy policy (one run: ``run`` 0) in environments of ``env_cfg``: the run's own grid, number of UAVs
        and layout only for the per-size network, any grid and number of UAVs for the size-free one."""
        return self.network.policy_for(env_cfg)

    def policies(self) -> list[CheckedPolicy]:
        """The greedy policy in environments of the run's config (reads the env's keys, writes
        ``("agents", "action")``; :meth:`policy_for` for any other)."""
        return [self.policy_for(self.env_cfg)]

    def evaluate(self, env_cfg, **kwargs) -> list[dict[str, float]]:
        """:func:`uavrl.agents.evaluation.evaluate` of the greedy policy in ``env_cfg`` (``kwargs``: its settings)."""
        return [evaluate(self.policy_for(env_cfg), env_cfg, **kwargs)]

    def state_dict(self) -> dict:
        """Networks with their targets, optimizer, exploration, replay buffer, RNG and progress."""
        per_group = [{"exploration": g.exploration.state_dict(), "buffer": g.buffer.state_dict()} for g in self.groups]
        state = {
            "iteration": self.iteration,
            "loss": self.loss.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            **self.network.experience_state(per_group, self.curriculum),
            "rng": torch.get_rng_state(),
        }
        if self.device.type == "cuda":
            state["cuda_rng"] = torch.cuda.get_rng_state(self.device)
        return state

    def load_state_dict(self, state: dict):
        self.loss.load_state_dict(state["loss"])
        self.optimizer.load_state_dict(state["optimizer"])
        saved_groups = self.network.experience_of(state, self.curriculum)
        for g, (group, saved) in enumerate(zip(self.groups, saved_groups, strict=True)):
            group.exploration.load_state_dict(saved["exploration"])
            # also earlier versions' buffers (.migration): with random layouts those of iteration k are the layouts
            # the group's worlds were reset to
            layouts = partial(self._group_layouts, g) if group.cfg.layout == "random" else None
            frames = group.env.num_worlds * group.cfg.max_steps
            load_replay_buffer(
                group.buffer, group.transitions, saved, group.env.observation_size, self.device, layouts, frames
            )
        self.iteration = int(state["iteration"])
        torch.set_rng_state(state["rng"])
        if "cuda_rng" in state:
            torch.cuda.set_rng_state(state["cuda_rng"], self.device)

    def _group_layouts(self, g: int, iteration: int) -> torch.Tensor:
        """``[W, 4, 3]`` the layouts group ``g``'s worlds were reset to at ``iteration`` (:meth:`_collect`)."""
        group = self.groups[g]
        return reset_layouts(group.cfg, group.env.num_worlds, self.device, self._group_seed(iteration, g))


def mean_utility(
    cfg: ModelConfig, layout: tuple[torch.Tensor, torch.Tensor], td: TensorDictBase, numbers: torch.Tensor | None = None
) -> torch.Tensor:
    """``[W, T]`` mean-channel utility of the configurations of ``td`` (``[W, T]``) in the worlds' ``layout``
    (``(cell_contributions, direct)`` of the env of ``cfg``, the layouts they were played in; with altitude levels
    ``numbers`` ``[L, C]`` turns a UAV's cell and level into the position the contributions are of,
    :func:`~.networks.position_numbers`)."""
    C = layout[0].shape[-2]  # the positions: the cells with one level
    cells = PositionIndex(cfg.grid, numbers)(td.get("positions"), td.get(LEVELS, None))  # C: out of service
    on_grid = layout[0][torch.arange(len(cells), device=cells.device)[:, None, None], cells.clamp(max=C - 1)]
    contributions = on_grid.masked_fill((cells == C).unsqueeze(-1), 0.0)
    r_pu, r_se = rates(contributions, td.get("tasks"), layout[1][:, None], cfg)
    return r_pu + r_se


def adam(parameters: list[torch.nn.Parameter], lr: float) -> torch.optim.Adam:
    """Adam with its fused kernel (one pass over every parameter, CPU and CUDA): about a tenth of a gradient step
    below the per-parameter loop (BENCHMARKS.md, DQN iteration)."""
    return torch.optim.Adam(parameters, lr=lr, fused=True)


def reset_layouts(cfg: ModelConfig, worlds: int, device, seed: int) -> torch.Tensor:
    """``[worlds, 4, 3]`` the layouts ``worlds`` worlds of ``cfg`` seeded ``seed`` are reset to."""
    world = World(cfg, worlds, device, seed)
    world.reset()
    return world.nodes
