"""The factored head's mixers and loss: :class:`VDNMix` and :class:`QMix` (the team value of the UAVs' chosen values),
and :class:`DoubleQMixerLoss`, double-DQN targets over valid joint actions through one of them (the joint head uses
TorchRL's ``DQNLoss(double_dqn=True)``, :func:`.builders.build_loss`).
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase, TensorDictParams
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.objectives import LossModule

from .transitions import STEPS


class VDNMix(nn.Module):
    """VDN (Sunehag et al. 2018): the team value ``[*, 1]`` is the sum of the chosen per-UAV values ``[*, N, 1]``
    (TorchRL's ``VDNMixer``'s function); no parameters."""

    def forward(self, chosen: torch.Tensor, state: torch.Tensor = None, params: TensorDictBase = None) -> torch.Tensor:
        return chosen.sum(dim=-2)


class QMix(nn.Module):
    """QMIX (Rashid et al. 2018): a team value ``[*, 1]`` monotonic in the chosen per-UAV values ``[*, N, 1]``, mixed
    by weights and biases that hypernetworks compute from the state ``[*, S]``.

    The layers, their names, their creation order (so their initial weights) and the arithmetic are those of
    TorchRL's ``QMixer``; :meth:`forward` also takes the parameters as an argument (``params``: the structure of
    ``TensorDict.from_module(self)``, the target copy in the loss) so no parameter is ever swapped in.

    Example:
        >>> mix = QMix(state_dim=5, embed_dim=4, n_agents=3, device="cpu")
        >>> mix(torch.zeros(2, 3, 1), torch.zeros(2, 5)).shape
        torch.Size([2, 1])
    """

    def __init__(self, state_dim: int, embed_dim: int, n_agents: int, device):
        super().__init__()
        self.state_dim, self.embed_dim, self.n_agents = state_dim, embed_dim, n_agents
        self.hyper_w_1 = nn.Linear(state_dim, embed_dim * n_agents, device=device)
        self.hyper_w_final = nn.Linear(state_dim, embed_dim, device=device)
        self.hyper_b_1 = nn.Linear(state_dim, embed_dim, device=device)  # the hidden layer's state-dependent bias
        self.V = nn.Sequential(  # the state value, in place of the last layer's bias
            nn.Linear(state_dim, embed_dim, device=device), nn.ReLU(), nn.Linear(embed_dim, 1, device=device)
        )

    def forward(self, chosen: torch.Tensor, state: torch.Tensor, params: TensorDictBase = None) -> torch.Tensor:
        def layer(name: str, x: torch.Tensor) -> torch.Tensor:  # "V.0": the first layer of the state value V
            if params is None:
                own = self.get_submodule(name)
                return nn.functional.linear(x, own.weight, own.bias)
            path = tuple(name.split("."))
            return nn.functional.linear(x, params.get((*path, "weight")), params.get((*path, "bias")))

        state = state.reshape(-1, self.state_dim)
        w1 = layer("hyper_w_1", state).abs().view(-1, self.n_agents, self.embed_dim)
        b1 = layer("hyper_b_1", state).view(-1, 1, self.embed_dim)
        hidden = nn.functional.elu(torch.bmm(chosen.reshape(-1, 1, self.n_agents), w1) + b1)  # [-1, 1, embed_dim]
        w_final = layer("hyper_w_final", state).abs().view(-1, self.embed_dim, 1)
        v = layer("V.2", torch.relu(layer("V.0", state))).view(-1, 1, 1)
        return (torch.bmm(hidden, w_final) + v).view(*chosen.shape[:-2], 1)


class DoubleQMixerLoss(LossModule):
    """The factored head's double-DQN loss with a mixer, a TorchRL ``LossModule`` with target copies of the value
    network's and the mixer's parameters (what :class:`~.builders.TargetUpdate` soft-updates).

    ``y = r + gamma^n (1 - terminated) Mix_target(Q_target(s', a'), s')`` (``n``: the transition's
    ``"steps_to_next_obs"``, 1 without n-step returns) where the
    online network's :class:`ValidGreedy` picks ``a'``; the loss is the Huber
    distance to ``Mix(Q(s, a), s)``.

    Args:
        greedy: the value network followed by its :class:`ValidGreedy` (``Policies.value_network`` of
            :func:`build_policies`); the loss keeps a target copy of its parameters.
        mixer: :class:`VDNMix` or :class:`QMix` as a module writing the team value (:func:`build_mixer`).
        gamma: the discount of the targets.
    """

    local_value_network: TensorDictSequential
    local_value_network_params: TensorDictParams
    target_local_value_network_params: TensorDictParams
    mixer_network: TensorDictModule
    mixer_network_params: TensorDictParams
    target_mixer_network_params: TensorDictParams

    def __init__(self, greedy: TensorDictSequential, mixer: TensorDictModule, gamma: float):
        super().__init__()
        # the names TorchRL's QMixerLoss gives them: the checkpoints' keys
        self.convert_to_functional(greedy, "local_value_network", create_target_params=True)
        self.convert_to_functional(mixer, "mixer_network", create_target_params=True)
        self.gamma = gamma

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        # Parameters are read, never swapped into the modules: the online ones are the modules' own (the optimizer
        # steps them in place), the target ones are handed to the network and the mixer as arguments.
        q, choose = self.local_value_network.module[:2]  # then, with messages, what the UAVs send
        net, greedy = q.module, choose.module
        inputs = getattr(net, "loss_keys", q.in_keys)  # Q_INPUTS (and the levels); LocalQNet's: with the messages
        mixer, nxt = self.mixer_network.module, td.get("next")
        # the successors' online pass stays apart from the states': one pass over both costs ~10% more a gradient
        # step on CPU, its backward running over the successors' rows too (BENCHMARKS.md, DQN iteration)
        chosen = net(*(td.get(key) for key in inputs)).gather(-1, td.get(("agents", "action")).unsqueeze(-1))
        value = mixer(chosen, td.get("state"))
        with torch.no_grad():
            after = net(*(nxt.get(key) for key in inputs))
            next_action = greedy(after, *(nxt.get(key) for key in choose.in_keys[1:]))  # mask, positions, tasks...
            target_values = net(*(nxt.get(key) for key in inputs), params=self._target_net)
            chosen = target_values.gather(-1, next_action.unsqueeze(-1))  # the online greedy action, target-valued
            next_value = mixer(chosen, nxt.get("state"), self.target_mixer_network_params.get("module"))
            target = nxt.get("reward") + discount(td, self.gamma) * (~nxt.get("terminated")) * next_value
        # prioritized replay (agents/dqn/priorities.py): the TD errors for the priorities, as TorchRL's DQNLoss writes
        # them into the batch, and each transition's importance weight
        td.set("td_error", (value - target).detach().abs().squeeze(-1))
        weight = td.get("priority_weight", None)
        if weight is None:
            return TensorDict({"loss": nn.functional.smooth_l1_loss(value, target)})
        huber = nn.functional.smooth_l1_loss(value, target, reduction="none").squeeze(-1)
        return TensorDict({"loss": (weight * huber).mean()})

    @property
    def _target_net(self) -> TensorDictBase:
        """The target copy of :class:`~.networks.TeamQNet`'s parameters (the first module of the greedy policy)."""
        return self.target_local_value_network_params.get(("module", "0", "module"))


def discount(td: TensorDictBase, gamma: float) -> torch.Tensor | float:
    """``gamma`` to the power of the steps the transitions' rewards sum (``[B, 1]``), or ``gamma`` for one step."""
    steps = td.get(STEPS, None)
    return gamma if steps is None else gamma ** steps.unsqueeze(-1).to(td.get(("next", "reward")).dtype)
