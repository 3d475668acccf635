"""Learning from the oracle's demonstrations (``agent.demonstrations=oracle``): DQfD (Hester et al., "Deep
Q-learning from Demonstrations", AAAI 2018) for the size-free DQN.

At the first gradient step the oracle planner (:class:`~uavrl.agents.baselines.OraclePolicy`, which knows U*'s
configurations) plays episodes of ``env.max_steps`` steps from random starts in every team and layout of the run
(``agent.sizes`` x ``agent.layouts``); ``agent.demo_transitions`` of its transitions, split evenly over the teams, are
kept for the whole run beside the agent's own replay (never overwritten), with the rewards of the agent's objective.
Every gradient step then draws ``agent.demo_batch_share`` of each team's batch from its demonstrations: they get the
double-DQN TD loss like the rest, and DQfD's large-margin supervised loss

``J_E = Mix_i [ max_b (Q_i(s, b) + m [b != a_E,i]) - Q_i(s, a_E,i) ]``

over the actions ``b`` each UAV's mask allows (``m``: ``agent.margin``; ``Mix``: the team value's sum or mean,
``agent.mixer``), which pushes the oracle's action of every UAV at least ``m`` above its others.  The supervised loss
is kept, not annealed, as DQfD keeps it.  The demonstrations are rebuilt from the seed when a run resumes (the
oracle is deterministic), so a checkpoint does not hold them.

Example:
    >>> values = torch.tensor([[[1.0, 0.0, 0.5]]])  # one state, one UAV, three actions
    >>> allowed = torch.ones(1, 1, 3, dtype=torch.bool)
    >>> margin_loss(values, torch.tensor([[2]]), allowed, margin=0.8, mixer="vdn")  # max(1 + 0.8, 0.5) - 0.5
    tensor(1.3000)
"""

from __future__ import annotations

import math

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torchrl.data import TensorDictReplayBuffer
from torchrl.envs.utils import step_mdp

from uavrl.agents.baselines import OraclePolicy
from uavrl.agents.references import placements
from uavrl.envs import ModelConfig, UAVSpectrumEnv
from uavrl.envs.limits import SEED_LIMIT
from uavrl.envs.physics.rewards import log_gap_reward
from uavrl.envs.solvers.optimum import MAX_EXCHANGE_UAVS

from .builders import ZeroedStorage
from .curriculum import uniform_sample
from .setnet import team_value
from .transitions import n_step_returns

_DEMO_SEED_OFFSET = 2**43  # demonstration worlds: seed * 2^44 + 2^43 + group * 2^20, clear of the training iterations'


def margin_loss(
    values: torch.Tensor, expert: torch.Tensor, allowed: torch.Tensor, margin: float, mixer: str
) -> torch.Tensor:
    """DQfD's large-margin loss (module doc), the mean over the batch: ``values`` ``[B, N, A]`` per-UAV values,
    ``expert`` ``[B, N]`` the demonstrated actions, ``allowed`` ``[B, N, A]`` the actions' masks."""
    penalty = torch.full_like(values, margin).scatter(-1, expert.unsqueeze(-1), 0.0)
    best = (values + penalty).masked_fill(~allowed, -math.inf).max(-1).values  # [B, N]
    chosen = values.gather(-1, expert.unsqueeze(-1)).squeeze(-1)
    return team_value((best - chosen).unsqueeze(-1), mixer).mean()


@torch.no_grad()
def oracle_transitions(
    cfg: ModelConfig, worlds: int, seed: int, objective: str, gap_floor: float, n_step: int = 1, gamma: float = 1.0
) -> TensorDictBase:
    """``[worlds * cfg.max_steps]`` the oracle's transitions from ``worlds`` random starts of ``cfg`` (seeded by
    ``seed``), one episode each, with the rewards of ``objective`` (``log_gap``: the change of
    ``-log(1 - U / U* + gap_floor)``, mean channels; ``delta``: the env's), as ``n_step`` returns discounted by
    ``gamma`` (:func:`~.transitions.n_step_returns`)."""
    env = UAVSpectrumEnv(batch_size=worlds, config=cfg, seed=seed)
    oracle = OraclePolicy(cfg)
    td = env.reset()
    u_star = env.optimum(method="exchange" if cfg.num_uavs <= MAX_EXCHANGE_UAVS else "search")[0]
    frames = []
    for _ in range(cfg.max_steps):  # no reset in between: every world keeps its layout for the whole episode
        frames.append(env.step(oracle(td)))
        td = step_mdp(frames[-1], keep_other=True, exclude_action=False)
    batch = torch.stack(frames, 1)  # [worlds, steps]
    if objective == "log_gap":
        now, after = (env.world.utility(placements(step), step["tasks"])[2] for step in (batch, batch["next"]))
        change = log_gap_reward(after, now, u_star.unsqueeze(-1), gap_floor)
        batch.set(("next", "reward"), change.unsqueeze(-1).to(batch.get(("next", "reward")).dtype))
    return n_step_returns(batch, n_step, gamma).reshape(-1)


class Demonstrations:
    """The oracle's transitions of every team of a :class:`~.agent.DQNAgent` (its ``groups``; the size-free
    network's levers, :class:`~.multisize.SetDQNAgent`), and the margin loss on them (module doc)."""

    def __init__(self, agent, groups: list):
        a = agent.settings
        self.share, self.margin, self.mixer = float(a.demo_batch_share), float(a.margin), a.mixer
        per_group = max(1, int(a.demo_transitions) // len(groups))
        self.buffers = []
        for g, group in enumerate(groups):
            cfg = group.cfg
            worlds = max(1, math.ceil(per_group / cfg.max_steps))
            seed = (agent.seed * 2**44 + _DEMO_SEED_OFFSET + g * 2**20) % SEED_LIMIT
            found = oracle_transitions(
                cfg, worlds, seed, a.objective, float(a.gap_floor), int(a.get("n_step", 1)), float(a.gamma)
            )[:per_group]
            storage = ZeroedStorage(per_group, device=group.transitions.world.device)
            buffer = TensorDictReplayBuffer(storage=storage, transform=group.transitions)
            buffer.extend(found.select(*group.keys))
            self.buffers.append(buffer)

    def demo_size(self, batch_size: int) -> int:
        """How many of a team's ``batch_size`` transitions per gradient step are demonstrations (at least one)."""
        return max(1, round(self.share * batch_size))

    def sample(self, g: int, size: int) -> TensorDictBase:
        """``size`` of team ``g``'s demonstrations, uniformly (full transitions)."""
        return uniform_sample(self.buffers[g], size)

    def loss(self, net: TensorDictModule, demos: TensorDictBase) -> torch.Tensor:
        """The margin loss of the values of ``net`` (the module acting in the team's worlds, around a
        :class:`~.setnet.SetQNet`) on ``demos``."""
        values = net.module(*(demos.get(k) for k in net.in_keys))
        expert, allowed = demos.get(("agents", "action")), demos.get(("agents", "action_mask"))
        return margin_loss(values, expert, allowed, self.margin, self.mixer)
