"""The greedy policy of team Q tables in plain torch: its choice rule, and the evaluation of many tables at once.

:class:`~uavrl.agents.tabular.policy.TabularPolicy` (the TorchRL policy) and
:func:`evaluate_tables` choose with the same :func:`greedy_joint_actions` from
the same random numbers, so evaluating the tables here gives the numbers of
:func:`uavrl.agents.evaluation.evaluate` over the TorchRL policies, without TorchRL and
with every table's rollouts stepped together in one world.
"""

from __future__ import annotations

import math

import torch

from uavrl.agents.evaluation import (
    DEFAULT_GAMMA,
    EVAL_SEED,
    NUM_STARTS,
    check_memory,
    check_settings,
    default_horizon,
    evaluation_starts,
    greedy_metrics,
)
from uavrl.envs.config import ModelConfig
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET
from uavrl.envs.physics.grid import decode_joint_actions, joint_action_valid
from uavrl.envs.world import World

OUTPUTS = ("positions", "tasks", "r_pu", "r_se", "task_switches", "moves")  # what the yardstick reads per step


def greedy_joint_actions(q_rows: torch.Tensor, valid: torch.Tensor, uniforms: torch.Tensor) -> torch.Tensor:
    """Index of the greedy joint action of each Q row ``[W, A^N]`` among the ``valid`` ones ``[W, A^N]``.

    Ties are broken uniformly at random: the tied action with the largest of ``uniforms`` ``[W, A^N]``.
    """
    values = q_rows.masked_fill(~valid, -math.inf)
    ties = values == values.amax(-1, keepdim=True)
    return uniforms.masked_fill(~ties, -1.0).argmax(-1)


@torch.no_grad()
def evaluate_tables(
    tables: torch.Tensor,
    cfg: ModelConfig,
    *,
    num_starts: int = NUM_STARTS,
    horizon: int | None = None,
    seed: int = EVAL_SEED,
    device="cpu",
    gamma: float = DEFAULT_GAMMA,
    policy_seed: int = 0,
    memory_budget: int = DEFAULT_MEMORY_BUDGET,
) -> list[dict[str, float]]:
    """:func:`uavrl.agents.evaluation.evaluate` of the greedy policy of each table ``[R, S, A^N]``: one dict per table.

    The same as evaluating ``TabularPolicy(tables[r], cfg, seed=policy_seed)``
    for every ``r`` (same starts, same tie-breaking numbers), with the ``R``
    tables' rollouts stepped together in one world of ``R x num_starts``.
    """
    check_settings(gamma, horizon, num_starts)
    check_memory(cfg, num_starts, horizon or default_horizon(cfg.grid), len(tables), memory_budget)
    world, start, u_star, references, horizon = evaluation_starts(
        cfg, num_starts, horizon, seed, device, gamma, memory_budget
    )
    q = tables.to(world.device)
    R, B, N, A = len(q), num_starts, cfg.num_uavs, cfg.num_joint_actions
    neighbours = world.dynamics.neighbours  # the moves between positions: cells without altitude levels
    C = len(neighbours)
    play = World(world.cfg, R * B, world.device, seed, memory_budget=memory_budget)
    out = play.start_at(world.code.repeat(R, 1))
    table_of = torch.arange(R, device=world.device).repeat_interleave(B)
    joint_actions = decode_joint_actions(N, world.device, cfg.joint_action_base)
    place = C ** torch.arange(N, device=world.device)
    # the valid joint actions of every placement p = sum_i c_i C^i, as in the learner's model tables
    valid = joint_action_valid(torch.arange(C**N, device=world.device)[:, None] // place % C, neighbours, N)
    generator = torch.Generator(device=world.device).manual_seed(policy_seed)
    outputs = OUTPUTS if cfg.num_levels == 1 else (*OUTPUTS, "levels")
    steps = []
    for _ in range(horizon):
        # every table's policy draws the same numbers as TabularPolicy does from its own generator
        uniforms = torch.rand((B, A), generator=generator, device=world.device).repeat(R, 1)
        placement = ((play.code >> 1) * place).sum(-1)
        pick = greedy_joint_actions(q[table_of, out["state_index"]], valid[placement], uniforms)
        out = play.step(joint_actions[pick])[0]
        steps.append({key: out[key] for key in outputs})
    per_table = {key: torch.stack([s[key] for s in steps], 1).unflatten(0, (R, B)) for key in outputs}
    return [
        greedy_metrics(world, start, {key: v[r] for key, v in per_table.items()}, u_star, references, gamma)
        for r in range(R)
    ]
