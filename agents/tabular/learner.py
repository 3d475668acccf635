"""Team Q-learning over the model tables: :class:`TeamQLearner`, one episode at a time, on either backend."""

from __future__ import annotations

import math

import torch

from uavrl.agents.episodes import EPISODE_METRICS, NINETY_PERCENT, episode_start, episode_step
from uavrl.agents.schema import START_BLOCK, TabularSchema
from uavrl.envs import ModelConfig
from uavrl.envs.limits import SEED_LIMIT, table_bytes
from uavrl.envs.physics import streams
from uavrl.envs.physics.rewards import team_reward
from uavrl.envs.rules import refuse, rule_of
from uavrl.envs.world import World

from .kernels import _choose_batched, _episode_per_run, _episode_shared, use_workqueue_threads
from .tables import TabularModel, table_place

_LEARNER_STREAM = 1 << 20  # the purpose of the learner's draws in the random streams (the world's are small numbers)


class TeamQLearner:
    """Team Q-learning over ``runs`` worlds of ``cfg`` (episode length ``cfg.max_steps``).

    Args:
        cfg: the model.
        runs: independent runs (each its own table), or worlds feeding one table with ``shared_table``.
        seed: seeds the episode starts (drawn by the env's reset) and the learner's random numbers.
        alpha, gamma, epsilon: eq. 9-10 constants.
        backend: ``"numba"`` (CPU) or ``"torch"`` (any device).
        memory_budget: refuse tables larger than this many bytes.

    The defaults and the rules of these settings are ``agent=tabular``'s (:class:`~uavrl.agents.schema.TabularSchema`):
    the paper's learner.
    """

    def __init__(
        self,
        cfg: ModelConfig,
        runs: int = 1,
        seed: int = 0,
        alpha=TabularSchema.alpha,
        gamma=TabularSchema.gamma,
        epsilon=TabularSchema.epsilon,
        shared_table=TabularSchema.shared_table,
        backend=TabularSchema.backend,
        device="cpu",
        memory_budget=TabularSchema.memory_budget,
    ):
        settings = dict(runs=runs, alpha=alpha, gamma=gamma, epsilon=epsilon, backend=backend)
        for name, value in settings.items():
            refuse(name, value, rule_of(TabularSchema, name))
        if backend == "numba" and torch.device(device).type != "cpu":
            raise ValueError(f"backend='numba' runs on the CPU, not device={device!r}: use backend='torch' there")
        if cfg.reward in ("log_gap", "delivered"):
            raise ValueError(
                f"env.reward={cfg.reward!r} is invalid for agent=tabular: its table learns the paper's reward 'delta' "
                f"or the authors' 'best_so_far'; {cfg.reward} is for agent=dqn and BenchMARL's algorithms"
            )
        num_tables = 1 if shared_table else int(runs)
        if not cfg.has_state_index:
            raise ValueError(
                f"the team Q table of {cfg.num_uavs} UAVs on {table_place(cfg)} has {cfg.num_states:.3g} "
                "states: no int64 state index exists; use agent=dqn, which scales further"
            )
        need = table_bytes(cfg, num_tables)
        if need > memory_budget:
            raise ValueError(
                f"the team Q table of {cfg.num_uavs} UAVs on {table_place(cfg)} would need {need:,} bytes "
                f"({need / 2**30:.3g} GiB) with the model tables, over the memory budget of {int(memory_budget):,} "
                "bytes; raise agent.memory_budget or use agent=dqn, which scales further"
            )
        self.cfg, self.runs, self.seed = cfg, int(runs), int(seed)
        self.alpha, self.gamma, self.epsilon = float(alpha), float(gamma), float(epsilon)
        self.shared_table, self.backend, self.device = bool(shared_table), backend, torch.device(device)
        self.memory_budget = memory_budget
        self.model = TabularModel(cfg, self.device)
        self.q = torch.zeros(num_tables, cfg.num_states, cfg.num_joint_actions, dtype=torch.float64, device=self.device)
        self.episode = 0
        self._configuration = None  # end of the last episode, for reset_positions="keep"
        self._start_block, self._block_starts = -1, None
        self._run_keys = streams.world_keys(self.seed, self.runs, self.device)  # run r: the stream of world seed + r

    def _episode_starts(self) -> torch.Tensor:
        """``[R]`` start configurations: run ``r``'s episode ``e`` starts where the world's (the env's) reset puts
        world ``seed + e R + r``; drawn for blocks of episodes in one batched reset."""
        if self.cfg.reset_positions == "keep" and self._configuration is not None:
            return self._configuration.clone()
        block, offset = divmod(self.episode, START_BLOCK)
        if block != self._start_block:
            worlds = START_BLOCK * self.runs
            first_world = (self.seed + block * worlds) % SEED_LIMIT  # world seeds are int64
            start = World(self.cfg, worlds, self.device, first_world, memory_budget=self.memory_budget).reset()
            ids = self.model.configuration_ids(start["positions"], start["tasks"], start.get("levels"))
            self._block_starts = ids.view(START_BLOCK, self.runs)
            self._start_block = block
        return self._block_starts[offset]

    def _stream_heads(self) -> torch.Tensor:
        """``[R]`` this episode's random stream of each run (:func:`uavrl.envs.physics.streams.stream_heads`): step
        ``t`` draws its lane ``t``.  Run ``r`` has the stream key of world ``seed + r``, the episode is the counter: a
        pure function of (seed, episode, run)."""
        episode = torch.full((self.runs,), self.episode, dtype=torch.long, device=self.device)
        return streams.stream_heads(self._run_keys, episode, _LEARNER_STREAM)

    def run_episode(self) -> dict[str, torch.Tensor]:
        """Learn for one episode; returns each run's episode metrics ``[R]`` (the keys of
        :data:`~uavrl.agents.episodes.EPISODE_METRICS`, summed step by step by
        :func:`~uavrl.agents.episodes.episode_step`)."""
        k0 = self._episode_starts()
        heads = self._stream_heads()
        metrics = (self._episode_numba if self.backend == "numba" else self._episode_torch)(k0, heads)
        self.episode += 1
        return dict(zip(EPISODE_METRICS, metrics, strict=True))

    def _learning_constants(self) -> tuple:
        cfg, u90 = self.cfg, NINETY_PERCENT * self.model.u_star
        return (self.alpha, self.gamma, self.epsilon, cfg.beta1, cfg.beta2, cfg.reward == "best_so_far", u90)

    def _episode_numba(self, k0, heads) -> tuple[torch.Tensor, ...]:
        k = k0.numpy().copy()
        metrics = torch.empty(self.runs, len(EPISODE_METRICS), dtype=torch.float64)
        kernel = _episode_shared if self.shared_table else _episode_per_run
        use_workqueue_threads()
        kernel(
            self.q.numpy(),
            k,
            heads.numpy(),
            self.cfg.max_steps,
            self.model.kernel_tables,
            self._learning_constants(),
            metrics.numpy(),
        )
        self._configuration = torch.from_numpy(k)
        return metrics.unbind(-1)

    def _episode_torch(self, k0, heads) -> tuple[torch.Tensor, ...]:
        m, cfg, q = self.model, self.cfg, self.q
        R, T, T2, A = self.runs, cfg.max_steps, m.num_task_codes, cfg.num_joint_actions
        tables = (
            torch.zeros(R, dtype=torch.long, device=self.device)
            if self.shared_table
            else torch.arange(R, device=self.device)
        )
        k = k0.to(self.device)
        lanes = torch.arange(T, device=self.device)
        u = streams.lane_bits(heads.unsqueeze(-1), lanes).double() * streams.UNIFORM_SCALE  # the kernel's uniforms
        prev = m.rates[k]
        best = torch.zeros(R, dtype=torch.float64, device=self.device)
        metrics = episode_start(torch.zeros_like(best), T)
        u90 = self._learning_constants()[-1]
        for step in range(T):
            p, t = k // T2, k % T2
            s = m.row[k]
            j = _choose_batched(q[tables, s], m.valid[p], u[:, step], self.epsilon)
            p2, t2 = m.next_cells[p, j].long(), m.next_tasks[t, j].long()
            k2 = p2 * T2 + t2
            r_pu, r_se = m.rates[k2].unbind(-1)
            reward, best = team_reward(
                r_pu, r_se, prev[:, 0], prev[:, 1], best, cfg.reward == "best_so_far", cfg.beta1, cfg.beta2
            )
            prev = m.rates[k2]
            next_q = q[tables, m.row[k2]].masked_fill(~m.valid[p2], -math.inf).amax(-1)
            target = reward + self.gamma * next_q
            if self.shared_table:
                flat = s * A + j
                total = torch.zeros(q[0].numel(), dtype=torch.float64, device=self.device).index_add_(0, flat, target)
                count = torch.zeros(q[0].numel(), dtype=torch.float64, device=self.device).index_add_(
                    0, flat, torch.ones_like(target)
                )
                q0 = q[0].view(-1)
                q0[flat] = (1 - self.alpha) * q0[flat] + self.alpha * (total[flat] / count[flat])
            else:
                q[tables, s, j] = (1 - self.alpha) * q[tables, s, j] + self.alpha * target
            metrics = episode_step(
                metrics, step + 1, r_pu, r_se, m.switches[t, j].double(), m.moves[p, j].double(), u90
            )
            k = k2
        self._configuration = k
        return metrics

    # checkpoints
    def state_dict(self) -> dict:
        return {
            "q": self.q.cpu(),
            "episode": self.episode,
            "configuration": None if self._configuration is None else self._configuration.cpu(),
        }

    def load_state_dict(self, state: dict):
        if state["q"].shape != self.q.shape:
            raise ValueError(
                f"checkpoint Q table has shape {tuple(state['q'].shape)}, this learner needs {tuple(self.q.shape)}: "
                "same env and agent settings are required"
            )
        self.q.copy_(state["q"])
        self.episode = int(state["episode"])
        self._configuration = None if state["configuration"] is None else state["configuration"].to(self.device)
