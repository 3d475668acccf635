"""One evaluation for every agent: the paper's per-episode metrics and greedy optimality.

Training curves (``train/...``) and evaluations (``eval/...``) of all agents are
computed here, so their TensorBoard tags and meanings are identical.

Example:
    >>> from uavrl.envs import make_config
    >>> cfg = make_config("paper", grid=(3, 3), num_uavs=2)
    >>> metrics = evaluate(RandomPolicy(seed=0), cfg, num_starts=4, horizon=5)
    >>> 0 < metrics["eval/optimality"] <= 1
    True
"""
from __future__ import annotations

import torch

from uavrl.envs import ModelConfig, UAVSpectrumEnv

EVAL_SEED = 1_000_003  # far from training seeds: eval worlds (and random layouts) are held out
NINETY_PERCENT = 0.9


def default_horizon(cfg: ModelConfig) -> int:
    """Greedy evaluation length: enough steps to cross the grid twice."""
    return max(20, 2 * (cfg.grid[0] + cfg.grid[1]))


def episode_metrics(r_pu, r_se, task_switches, moves, u_star) -> dict[str, torch.Tensor]:
    """SPEC section 7 per episode.  Inputs ``[W, T]`` for ``W`` episodes of ``T`` steps, ``u_star`` ``[W]``.

    Returns ``[W]`` tensors: the sums over steps of R_PU, R_SE and U (Fig. 3), of
    task switches and moves (Fig. 4), and the number of steps until U first
    reaches 90% of U* (Fig. 5; T if never).
    """
    utility = (r_pu + r_se).double()
    T = utility.shape[-1]
    reached = utility >= NINETY_PERCENT * u_star.double().unsqueeze(-1)
    first = torch.where(reached.any(-1), reached.double().argmax(-1) + 1, torch.full_like(u_star.double(), T))
    return {
        "sum_r_pu": r_pu.double().sum(-1),
        "sum_r_se": r_se.double().sum(-1),
        "sum_utility": utility.sum(-1),
        "task_switches": task_switches.double().sum(-1),
        "moves": moves.double().sum(-1),
        "steps_to_90": first.double(),
    }


@torch.no_grad()
def evaluate(policy, cfg: ModelConfig, *, num_starts: int = 64, horizon: int | None = None, seed: int = EVAL_SEED, device="cpu") -> dict[str, float]:
    """Greedy rollouts of ``policy`` from ``num_starts`` fixed, seeded starts.

    ``policy`` is any TorchRL policy for :class:`UAVSpectrumEnv` (reads the
    observation keys, writes ``("agents", "action")``).  Optimality is the
    utility of the configuration reached after ``horizon`` steps, with
    deterministic channels, over the exact optimum U*.
    """
    horizon = horizon or default_horizon(cfg)
    env = UAVSpectrumEnv(batch_size=num_starts, config=cfg.replace(max_steps=horizon), seed=seed, device=device)
    start = env.reset()
    u_star = env.optimum()[0]
    rollout = env.rollout(horizon, policy, auto_reset=False, tensordict=start, break_when_any_done=False)
    nxt = rollout["next"]
    per_episode = episode_metrics(nxt["r_pu"], nxt["r_se"], nxt["task_switches"], nxt["moves"], u_star)
    final_u = env.utility(nxt["positions"][:, -1], nxt["tasks"][:, -1])[2]
    optimality = final_u / u_star
    out = {f"eval/{k}": v.mean().item() for k, v in per_episode.items()}
    out["eval/optimality"] = optimality.mean().item()
    out["eval/optimality_min"] = optimality.min().item()
    out["eval/optimal_fraction"] = (optimality >= 0.99).double().mean().item()
    return out


class RandomPolicy:
    """Uniform random per-UAV actions among those the ``action_mask`` allows: the baseline policy."""

    def __init__(self, seed: int = 0):
        self.generator = torch.Generator().manual_seed(seed)

    def __call__(self, td):
        mask = td.get(("agents", "action_mask"))
        scores = torch.rand(mask.shape, generator=self.generator).to(mask.device).masked_fill(~mask, -1.0)
        td.set(("agents", "action"), scores.argmax(-1))
        return td


def evaluate_agent(agent, cfg: ModelConfig, **kwargs) -> dict[str, float]:
    """Average :func:`evaluate` over an agent's policies (one per independent run)."""
    results = [evaluate(policy, cfg, **kwargs) for policy in agent.policies()]
    out = {k: sum(r[k] for r in results) / len(results) for k in results[0]}
    out["eval/optimality_min"] = min(r["eval/optimality_min"] for r in results)
    return out
