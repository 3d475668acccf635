"""The greedy policy of a team Q table as a TorchRL policy."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from uavrl.agents.env_check import RunEnvironment
from uavrl.envs.config import ModelConfig
from uavrl.envs.physics.grid import decode_joint_actions, grid_neighbours, joint_action_valid

from ..generators import PolicyGenerator
from .greedy import greedy_joint_actions


class TabularPolicy(TensorDictModuleBase):
    """Greedy valid joint action from a Q table ``[S, 6^N]``, as a TorchRL policy (:mod:`.greedy` in plain torch).

    Reads ``state_index`` and ``positions``; writes ``("agents", "action")``.
    It acts only in environments of ``cfg``'s grid, number of UAVs and layout
    (:mod:`uavrl.agents.env_check`).
    Ties are broken uniformly at random (docs/model.md) from the policy's own
    generator seeded ``seed``, so a rollout is reproducible.

    Args:
        q: the Q table ``[S, 6^N]``, one row per tabular state (``state_index``), one column per joint action.
        cfg: the :class:`~uavrl.envs.ModelConfig` the table was made for.
        seed: seeds the tie-breaking generator.

    Example:
        >>> from uavrl.envs import UAVSpectrumEnv
        >>> env = UAVSpectrumEnv(batch_size=3, grid=(3, 3), num_uavs=2)
        >>> policy = TabularPolicy(torch.zeros(81, 36), env.cfg)
        >>> env.rollout(4, policy)["agents", "action"].shape
        torch.Size([3, 4, 2])
    """

    in_keys = ["state_index", "positions"]
    out_keys = [("agents", "action")]

    def __init__(self, q: torch.Tensor, cfg: ModelConfig, seed: int = 0):
        super().__init__()
        self.cfg = cfg
        self.register_buffer("q", q)
        self.register_buffer("neighbours", grid_neighbours(cfg.grid, q.device))
        self.register_buffer("actions", decode_joint_actions(cfg.num_uavs, q.device))
        self.generator = PolicyGenerator(seed, q.device)
        self.run_env = RunEnvironment(cfg)

    def bind_env(self, env) -> TabularPolicy:
        """Act in ``env``: a one-line ValueError unless it has the table's grid, number of UAVs and layout."""
        self.run_env.check_env(env)
        return self

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        self.run_env.check(td)
        positions = td.get("positions").to(self.q.device)
        cells = positions[..., 1] * self.cfg.grid[0] + positions[..., 0]
        values = self.q[td.get("state_index").squeeze(-1).to(self.q.device)]
        uniforms = torch.rand(values.shape, generator=self.generator, device=self.q.device)
        valid = joint_action_valid(cells, self.neighbours, self.cfg.num_uavs)
        pick = greedy_joint_actions(values, valid, uniforms)
        td.set(("agents", "action"), self.actions[pick].to(td.device or self.q.device))
        return td
