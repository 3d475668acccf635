"""The greedy policy of a team Q table as a TorchRL policy."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from uavrl.agents.env_check import RunEnvironment
from uavrl.envs.config import ModelConfig
from uavrl.envs.physics.grid import decode_joint_actions, joint_action_valid
from uavrl.envs.physics.positions import model_positions

from ..generators import PolicyGenerator
from .greedy import greedy_joint_actions
from .tables import position_indices


class TabularPolicy(TensorDictModuleBase):
    """Greedy valid joint action from a Q table ``[S, A^N]``, as a TorchRL policy (:mod:`.greedy` in plain torch).

    Reads ``state_index`` and ``positions`` (and ``levels`` with altitude levels); writes ``("agents", "action")``.
    It acts only in environments of ``cfg``'s model (grid, number of UAVs, layout, altitude levels, city)
    (:mod:`uavrl.agents.env_check`).
    Ties are broken uniformly at random (docs/model.md) from the policy's own
    generator seeded ``seed``, so a rollout is reproducible.

    Args:
        q: the Q table ``[S, A^N]``, one row per tabular state (``state_index``), one column per joint action.
        cfg: the :class:`~uavrl.envs.ModelConfig` the table was made for.
        seed: seeds the tie-breaking generator.

    Example:
        >>> from uavrl.envs import UAVSpectrumEnv
        >>> env = UAVSpectrumEnv(batch_size=3, grid=(3, 3), num_uavs=2)
        >>> policy = TabularPolicy(torch.zeros(81, 36), env.cfg)
        >>> env.rollout(4, policy)["agents", "action"].shape
        torch.Size([3, 4, 2])
    """

    out_keys = [("agents", "action")]

    def __init__(self, q: torch.Tensor, cfg: ModelConfig, seed: int = 0):
        super().__init__()
        self.cfg = cfg
        self.in_keys = ["state_index", "positions", *(["levels"] if cfg.num_levels > 1 else [])]
        positions = model_positions(cfg, q.device)
        self.register_buffer("q", q)
        self.register_buffer("neighbours", positions.neighbours)
        self.register_buffer("position_number", positions.number)
        self.register_buffer("actions", decode_joint_actions(cfg.num_uavs, q.device, cfg.joint_action_base))
        self.generator = PolicyGenerator(seed, q.device)
        self.run_env = RunEnvironment(cfg)

    def bind_env(self, env) -> TabularPolicy:
        """Act in ``env``: a one-line ValueError unless it has the table's model (:mod:`uavrl.agents.env_check`)."""
        self.run_env.check_env(env)
        return self

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        self.run_env.check(td)
        levels = td.get("levels").to(self.q.device) if self.cfg.num_levels > 1 else None
        cells = position_indices(self.cfg, self.position_number, td.get("positions").to(self.q.device), levels)
        values = self.q[td.get("state_index").squeeze(-1).to(self.q.device)]
        uniforms = torch.rand(values.shape, generator=self.generator, device=self.q.device)
        valid = joint_action_valid(cells, self.neighbours, self.cfg.num_uavs)
        pick = greedy_joint_actions(values, valid, uniforms)
        td.set(("agents", "action"), self.actions[pick].to(td.device or self.q.device))
        return td
