"""The team rewards of docs/model.md (``env.reward``, What the agent is rewarded for), each written once.

``delta`` and ``best_so_far`` (and :func:`team_reward`, which picks one of them and tracks the episode's best) use
arithmetic only, so the environment and the tabular learner's torch loop (batched tensors) and its compiled loops
(numba compiles these same functions for scalars) compute them from the same source; ``log_gap`` is the DQN's
objective and ``env.reward="log_gap"`` for any algorithm, on the mean-channel utility; ``delivered``
(:func:`delivered_reward`) is a mission's data, step by step.  :class:`TeamReward` is the
World's reward part: ``env.reward`` dispatched to these functions, with ``log_gap``'s mean-channel rule.

Example:
    >>> import torch
    >>> delta_reward(torch.tensor(2.0), torch.tensor(1.0), 1.5, 1.0, 1.0, 1.0)
    tensor(0.5000)
    >>> best_so_far_reward(3.0, 2.0), best_so_far_reward(1.0, 2.0)
    (10.0, -1.0)
    >>> team_reward(2.0, 1.0, 1.5, 1.0, 2.5, True, 1.0, 1.0), team_reward(2.0, 1.0, 1.5, 1.0, 2.5, False, 1.0, 1.0)
    ((5.0, 3.0), (0.5, 2.5))
"""

from __future__ import annotations

import torch


def delta_reward(r_pu, r_se, prev_r_pu, prev_r_se, beta1, beta2):
    """Eq. 7: weighted change of both rates.  Works on tensors and on plain floats (numba).

    Args:
        r_pu: R_PU after the step (bit/s/Hz).
        r_se: R_SE after the step.
        prev_r_pu: R_PU before it.
        prev_r_se: R_SE before it.
        beta1: the weight of R_PU's change.
        beta2: the weight of R_SE's change.

    Example:
        >>> delta_reward(2.0, 1.0, 1.5, 1.0, beta1=1.0, beta2=1.0)
        0.5
    """
    return beta1 * (r_pu - prev_r_pu) + beta2 * (r_se - prev_r_se)


def best_so_far_reward(total, best):
    """The authors' reward: ``10 (S - M)`` above the episode's best ``M``, ``S - M`` below, 0 level.

    Written with arithmetic only so it serves tensors and numba-compiled scalars alike.

    Args:
        total: the step's ``S = R_PU + R_SE``.
        best: the episode's best ``M`` before the step (0 at the start).

    Example:
        >>> best_so_far_reward(3.0, 2.5), best_so_far_reward(2.0, 2.5)
        (5.0, -0.5)
    """
    diff = total - best
    return diff * (1 + 9 * (diff > 0))


def episode_best(total, best):
    """``max(total, best)``, as a selection: bit for bit the larger one (rates are finite) on tensors and numba
    scalars alike, where ``best + (total - best)`` could round."""
    return total * (total > best) + best * (total <= best)


def team_reward(r_pu, r_se, prev_r_pu, prev_r_se, best, use_best_so_far, beta1, beta2):
    """The reward of a step to rates ``(r_pu, r_se)`` from ``(prev_r_pu, prev_r_se)``, and the episode's best
    ``R_PU + R_SE`` after it (``best``: before it, 0 at the start; kept as it is for ``delta``).

    ``use_best_so_far`` picks :func:`best_so_far_reward` over :func:`delta_reward` (``env.reward``; ``log_gap``
    is :func:`log_gap_reward`, on tensors only).  Tensors or numba scalars, as those.

    Args:
        r_pu: R_PU after the step.
        r_se: R_SE after the step.
        prev_r_pu: R_PU before it.
        prev_r_se: R_SE before it.
        best: the episode's best ``R_PU + R_SE`` before the step.
        use_best_so_far: the authors' reward (True) or the paper's (False).
        beta1: the weight of R_PU in the delta reward.
        beta2: the weight of R_SE in the delta reward.

    Returns:
        ``(reward, best)``: the step's reward and the episode's best after it.
    """
    if use_best_so_far:
        total = r_pu + r_se
        return best_so_far_reward(total, best), episode_best(total, best)
    return delta_reward(r_pu, r_se, prev_r_pu, prev_r_se, beta1, beta2), best


U_STAR_REWARDS = ("log_gap", "delivered")  # the rewards that read each layout's U* (the World computes it for them)
LOG_GAP_FLOOR = 1e-4  # reward="log_gap": gaps below this fraction of U* count as closed


def log_gap_potential(utility: torch.Tensor, u_star: torch.Tensor, floor: float = LOG_GAP_FLOOR) -> torch.Tensor:
    """``-log(1 - U / U* + floor)`` (the gap to the optimum clamped at 0): ``reward="log_gap"`` is its change over
    a step, so every halving of the gap to U* is worth the same, down to ``floor``.

    Args:
        utility: the utility ``U = R_PU + R_SE`` (bit/s/Hz), any shape.
        u_star: the best utility ``U*``, broadcast against it.
        floor: the smallest gap, a fraction of U*, that counts.
    """
    return -torch.log((1 - utility / u_star).clamp(min=0) + floor)


def log_gap_reward(
    utility: torch.Tensor, prev_utility: torch.Tensor, u_star: torch.Tensor, floor: float = LOG_GAP_FLOOR
) -> torch.Tensor:
    """``reward="log_gap"``: the change of :func:`log_gap_potential` from ``prev_utility`` to ``utility``.

    Args:
        utility: the utility after the step.
        prev_utility: the utility before it.
        u_star: the best utility ``U*``.
        floor: the smallest gap, a fraction of U*, that counts.

    Example:
        >>> log_gap_reward(torch.tensor([1.5]), torch.tensor([1.0]), torch.tensor([2.0]))  # gap 1/2 to 1/4
        tensor([0.6929])
    """
    return log_gap_potential(utility, u_star, floor) - log_gap_potential(prev_utility, u_star, floor)


def delivered_reward(rates: torch.Tensor, u_star: torch.Tensor) -> torch.Tensor:
    """``reward="delivered"``: the data ``(R_PU + R_SE) slot_s`` the step delivered (``rates`` ``[B, 2]``) in units
    of ``U* slot_s``, the most one step can deliver: a mission's rewards add up to its delivered data
    (``eval/delivered_bit_per_hz``) over ``U* slot_s``.

    Args:
        rates: the step's (R_PU, R_SE) ``[B, 2]``.
        u_star: each layout's ``U*`` ``[B]`` or ``[1]``.
    """
    return rates.sum(-1) / u_star


class TeamReward:
    """The reward part: ``env.reward`` for a step of ``B`` worlds, from their rates ``[B, 2]`` (R_PU, R_SE).

    ``random_channel`` is the fading part's ``random`` (:mod:`uavrl.envs.physics.fading`): ``log_gap`` measures the gap
    to ``U*`` as the evaluation does, on the mean channel, so under a random channel it reads the configurations'
    mean-channel rates (``mean_rates()``, asked for only then) instead of the step's draw.

    Args:
        cfg: the model (its ``reward``, ``beta1`` and ``beta2``).
        random_channel: whether the model's fading draws its channels.
    """

    def __init__(self, cfg, random_channel: bool):
        self.kind, self.betas = cfg.reward, (cfg.beta1, cfg.beta2)
        self.reads_mean_channel = cfg.reward == "log_gap" and random_channel

    def __call__(self, rates, prev_rates, best, u_star, mean_rates) -> tuple[torch.Tensor, torch.Tensor]:
        """``(reward [B], best [B])`` of a step from ``prev_rates`` to ``rates``: ``best`` is the episode's best
        ``R_PU + R_SE`` (``best_so_far``'s memory), ``u_star`` ``[B]`` or ``[1]`` each layout's ``U*`` (``log_gap``,
        ``delivered``), ``mean_rates()`` the mean-channel ``(rates, prev_rates)``."""
        if self.kind == "log_gap":
            if self.reads_mean_channel:
                rates, prev_rates = mean_rates()
            return log_gap_reward(rates.sum(-1), prev_rates.sum(-1), u_star), best
        if self.kind == "delivered":
            return delivered_reward(rates, u_star), best
        r_pu, r_se, use_best = rates[:, 0], rates[:, 1], self.kind == "best_so_far"
        return team_reward(r_pu, r_se, prev_rates[:, 0], prev_rates[:, 1], best, use_best, *self.betas)
