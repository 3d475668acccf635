"""The DQN agent: one iteration (an episode in every world, then gradient steps), read top to bottom."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torch import nn

from uavrl.agents.base import Agent
from uavrl.agents.env_check import CheckedPolicy
from uavrl.agents.schema import AGENTS
from uavrl.envs import ModelConfig, UAVSpectrumEnv
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET
from uavrl.envs.physics.channel import rates
from uavrl.envs.physics.fading import fading_part
from uavrl.envs.physics.grid import cells_or_away
from uavrl.envs.physics.rewards import log_gap_reward
from uavrl.envs.solvers.optimum import MAX_EXCHANGE_UAVS
from uavrl.envs.world import World
from uavrl.evaluation import episode_metrics

from .builders import (
    TargetUpdate,
    build_collector,
    build_loss,
    build_policies,
    build_q_network,
    build_replay_buffer,
    exploration_schedule,
)
from .migration import load_replay_buffer
from .transitions import CompactTransitions, n_step_returns, transition_keys

_ITERATION_STRIDE = 2**24  # world seeds of iteration k: seed * 2^44 + (k + 1) * 2^24 + world, clear of the eval seeds
_SEED_MODULUS = 2**63  # world seeds are int64: seeds past 2^19 wrap around


class DQNAgent(Agent):
    """The deep agent behind ``python -m uavrl.train agent=dqn`` (contract: :class:`uavrl.agents.base.Agent`).

    ``cfg.agent`` holds the settings (``configs/agent/dqn.yaml``), ``agent.iterations`` the run length.  The
    size-free network (``agent.network=set``) is :class:`~.multisize.SetDQNAgent`, the class
    :func:`uavrl.agents.agent_class` gives for those settings.

    Args:
        env_cfg: the run's :class:`~uavrl.envs.ModelConfig` (its ``max_steps`` the episode length).
        cfg: the full Hydra config; the agent reads ``cfg.agent``.
        device: the torch device of the networks, the replay buffer and the training worlds.
        seed: seeds the networks' initial weights and every iteration's worlds.
    """

    def __init__(self, env_cfg: ModelConfig, cfg, device, seed: int):
        a = cfg.agent
        AGENTS["dqn"].validate(env_cfg, a)
        if a.get("network", "team") != "team":  # run configs saved before: no setting
            raise ValueError(
                f"agent.network={a.network!r} is invalid for DQNAgent, the per-size network: build "
                "uavrl.agents.agent_class('dqn', cfg.agent), SetDQNAgent for agent.network='set'"
            )
        self.env_cfg, self.settings, self.seed = env_cfg, a, int(seed)
        self.device = torch.device(device)
        self.num_iterations = int(a.iterations)
        self.iteration = 0
        torch.manual_seed(self.seed)  # the networks' initial weights; build order matters
        self.env = UAVSpectrumEnv(
            batch_size=int(a.worlds),
            config=env_cfg,
            seed=self._world_seed(0),
            device=self.device,
            memory_budget=a.get("memory_budget", DEFAULT_MEMORY_BUDGET),  # run directories saved without it
        )
        q = build_q_network(self.env, a)
        frames = int(a.worlds) * env_cfg.max_steps * self.num_iterations
        policies = build_policies(self.env, a, q, exploration_schedule(a, frames, self.device))
        self.greedy, self.exploration = policies.greedy, policies.exploration
        self.loss = build_loss(self.env, a, policies)
        self.optimizer = adam(list(self.loss.parameters()), float(a.lr))
        self.target_update = TargetUpdate(self.loss, tau=float(a.tau))
        self.transitions = CompactTransitions(self.env.world, policies.action_keys)  # what the buffer keeps of each
        self.buffer = build_replay_buffer(a, self.transitions)
        self._keys = transition_keys(self.env.world, policies.action_keys, int(a.get("n_step", 1)))
        self.collector = build_collector(self.env, policies.explore)
        self._batches = iter(self.collector)

    def _world_seed(self, iteration: int) -> int:
        return (self.seed * 2**44 + (iteration + 1) * _ITERATION_STRIDE) % _SEED_MODULUS

    @property
    def env_steps(self) -> int:
        """Team steps collected so far (worlds times steps)."""
        return self.iteration * int(self.settings.worlds) * self.env_cfg.max_steps

    def train_iteration(self) -> dict[str, float]:
        """One episode in every world, then ``agent.updates`` gradient steps."""
        self.collector.set_seed(self._world_seed(self.iteration), static_seed=True)
        self.collector.reset()
        progress = min(1.0, self.iteration / self.num_iterations)
        for group in self.optimizer.param_groups:  # annealed linearly from agent.lr to agent.lr_end over the run
            group["lr"] = float(self.settings.lr) + (float(self.settings.lr_end) - float(self.settings.lr)) * progress
        if self.settings.get("replay", "uniform") == "prioritized":  # importance weights annealed to full correction
            beta = float(self.settings.priority_beta)
            self.buffer.sampler.beta = beta + (1.0 - beta) * progress
        # this episode's layouts; the exchange method where it runs (its results recorded), the search beyond
        u_star = self.env.optimum(method="exchange" if self.env_cfg.num_uavs <= MAX_EXCHANGE_UAVS else "search")[0]
        # kept (the properties return copies): the collector's closing reset draws new random layouts before the batch
        # is read; a second clone would copy every world's [C, 2] rows of a shared layout
        layout = (self.env.cell_contributions, self.env.direct)
        batch = next(self._batches)  # [worlds, steps]

        def mean_utility(td: TensorDictBase) -> torch.Tensor:
            """``[W, T]`` mean-channel utility of the batch's configurations in the layouts they were played in."""
            C = self.env_cfg.num_cells
            cells = cells_or_away(td.get("positions"), self.env_cfg.grid)  # C: out of service, adds nothing
            on_grid = layout[0][torch.arange(len(cells), device=cells.device)[:, None, None], cells.clamp(max=C - 1)]
            contributions = on_grid.masked_fill((cells == C).unsqueeze(-1), 0.0)
            r_pu, r_se = rates(contributions, td.get("tasks"), layout[1][:, None], self.env_cfg)
            return r_pu + r_se

        if self.settings.objective == "log_gap":
            batch.set(("next", "reward"), self._log_gap_reward(batch, u_star, mean_utility))
        stored = n_step_returns(batch, int(self.settings.get("n_step", 1)), float(self.settings.gamma))
        self.buffer.extend(stored.reshape(-1).select(*self._keys))
        losses = (
            [self._update() for _ in range(int(self.settings.updates))]
            if len(self.buffer) >= int(self.settings.learning_starts)
            else []
        )
        self.exploration.step(batch.numel())
        self.iteration += 1
        nxt = batch.get("next")
        # under fading, "reaches 90% of U*" is decided on the configurations' mean-channel utility
        reach_utility = mean_utility(nxt) if fading_part(self.env_cfg).random else None
        per_world = episode_metrics(
            *(nxt.get(key).squeeze(-1) for key in ("r_pu", "r_se", "task_switches", "moves")), u_star, reach_utility
        )
        out = {f"train/{k}": v.mean().item() for k, v in per_world.items()}
        out["train/epsilon"] = self.exploration.eps.item()
        if losses:
            out["train/loss"] = torch.stack(losses).mean().item()
        return out

    def _log_gap_reward(self, batch: TensorDictBase, u_star: torch.Tensor, mean_utility) -> torch.Tensor:
        """``[W, T, 1]`` the change of ``-log(1 - U / U* + agent.gap_floor)`` over each step, mean-channel ``U``.

        The delta reward's action gaps shrink with the distance to the optimum
        (the last 0.1% of U* is worth 0.01 bit/s/Hz), below what the network
        resolves: greedy policies then wander near U*.  On a log scale of the
        gap to U* each halving of the gap is worth the same, down to the floor.
        """
        change = log_gap_reward(
            mean_utility(batch.get("next")), mean_utility(batch), u_star.unsqueeze(-1), float(self.settings.gap_floor)
        )
        return change.unsqueeze(-1).to(batch.get(("next", "reward")).dtype)

    def _update(self) -> torch.Tensor:
        batch = self.buffer.sample()
        loss = self.loss(batch)["loss"]
        if self.settings.get("replay", "uniform") == "prioritized":
            self.buffer.update_priority(batch.get("index"), batch.get("td_error"))
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        nn.utils.clip_grad_norm_(self.loss.parameters(), float(self.settings.max_grad_norm), foreach=True)
        self.optimizer.step()
        self.target_update.step()
        return loss.detach()

    def _layouts_of(self, iteration: int) -> torch.Tensor:
        """``[W, 4, 3]`` the layouts iteration ``iteration``'s worlds were reset to (:meth:`train_iteration`)."""
        return reset_layouts(self.env_cfg, int(self.settings.worlds), self.device, self._world_seed(iteration))

    def policies(self) -> list[CheckedPolicy]:
        """The greedy policy: reads the env's keys, writes ``("agents", "action")``, in environments of the run's grid,
        number of UAVs and layout only."""
        return [CheckedPolicy(self.greedy, self.env_cfg)]

    def state_dict(self) -> dict:
        """Networks with their targets, optimizer, exploration, replay buffer, RNG and progress."""
        state = {
            "iteration": self.iteration,
            "loss": self.loss.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            **self._experience_state(),
            "rng": torch.get_rng_state(),
        }
        if self.device.type == "cuda":
            state["cuda_rng"] = torch.cuda.get_rng_state(self.device)
        return state

    def load_state_dict(self, state: dict):
        self.loss.load_state_dict(state["loss"])
        self.optimizer.load_state_dict(state["optimizer"])
        self._load_experience(state)
        self.iteration = int(state["iteration"])
        torch.set_rng_state(state["rng"])
        if "cuda_rng" in state:
            torch.cuda.set_rng_state(state["cuda_rng"], self.device)

    def _experience_state(self) -> dict:
        """``"exploration"`` and ``"buffer"`` (storage, write cursor and count, sampler) of the state."""
        return {"exploration": self.exploration.state_dict(), "buffer": self.buffer.state_dict()}

    def _load_experience(self, state: dict) -> None:
        self.exploration.load_state_dict(state["exploration"])
        self._load_buffer(self.buffer, self.transitions, state, self.env, self._layouts_of)

    def _load_buffer(self, buffer, transitions: CompactTransitions, state: dict, env: UAVSpectrumEnv, layouts_of):
        """``buffer`` (of ``env``'s transitions) from ``state["buffer"]``, also earlier versions' (:mod:`.migration`):
        with random layouts those of iteration ``k`` are ``layouts_of(k)``, what its worlds were reset to."""
        layouts = layouts_of if env.cfg.layout == "random" else None
        frames = env.num_worlds * env.cfg.max_steps
        load_replay_buffer(buffer, transitions, state, env.observation_size, self.device, layouts, frames)


def adam(parameters: list[torch.nn.Parameter], lr: float) -> torch.optim.Adam:
    """Adam with its fused kernel (one pass over every parameter, CPU and CUDA): about a tenth of a gradient step
    below the per-parameter loop (BENCHMARKS.md, DQN iteration)."""
    return torch.optim.Adam(parameters, lr=lr, fused=True)


def reset_layouts(cfg: ModelConfig, worlds: int, device, seed: int) -> torch.Tensor:
    """``[worlds, 4, 3]`` the layouts ``worlds`` worlds of ``cfg`` seeded ``seed`` are reset to."""
    world = World(cfg, worlds, device, seed)
    world.reset()
    return world.nodes
