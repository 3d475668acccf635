"""The factored head's loss: :class:`DoubleQMixerLoss`, TorchRL's ``QMixerLoss`` with double-DQN targets over valid
joint actions (the joint head uses TorchRL's ``DQNLoss(double_dqn=True)``, :func:`.builders.build_loss`).
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.objectives import QMixerLoss

from .networks import Q_INPUTS
from .transitions import STEPS


class DoubleQMixerLoss(QMixerLoss):
    """``QMixerLoss`` with double-DQN targets over valid joint actions.

    ``y = r + gamma^n (1 - terminated) Mix_target(Q_target(s', a'), s')`` (``n``: the transition's
    ``"steps_to_next_obs"``, 1 without n-step returns) where the
    online network's :class:`ValidGreedy` picks ``a'``; the loss is the Huber
    distance to ``Mix(Q(s, a), s)``.

    Args:
        greedy: the value network followed by its :class:`ValidGreedy` (``Policies.value_network`` of
            :func:`build_policies`); the loss keeps a target copy of its parameters.
        mixer: the module that mixes the UAVs' chosen values into the team value (:func:`build_mixer`).
        action_spec: the per-UAV action spec ``[N]`` (``Policies.action_spec``).
        gamma: the discount of the targets.
    """

    def __init__(self, greedy: TensorDictSequential, mixer: TensorDictModule, action_spec, gamma: float):
        super().__init__(greedy, mixer, action_space=action_spec, loss_function="smooth_l1")
        self.gamma = gamma

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        # Parameters are read, never swapped into the modules: the online ones are the modules' own (the optimizer
        # steps them in place), the target ones are handed to the network and the mixer as arguments.
        net, greedy = (m.module for m in self.local_value_network.module)
        mixer, k, nxt = self.mixer_network.module, self.tensor_keys, td.get("next")
        # the successors' online pass stays apart from the states': one pass over both costs ~10% more a gradient
        # step on CPU, its backward running over the successors' rows too (BENCHMARKS.md, DQN iteration)
        value = _mixed(
            mixer, net(*(td.get(key) for key in Q_INPUTS)).gather(-1, td.get(k.action).unsqueeze(-1)), td.get("state")
        )
        with torch.no_grad():
            after = net(*(nxt.get(key) for key in Q_INPUTS))
            next_action = greedy(after, nxt.get(("agents", "action_mask")), nxt.get("positions"), nxt.get("tasks"))
            target_values = net(*(nxt.get(key) for key in Q_INPUTS), params=self._target_net)
            chosen = target_values.gather(-1, next_action.unsqueeze(-1))  # the online greedy action, target-valued
            next_value = _mixed(mixer, chosen, nxt.get("state"), self.target_mixer_network_params.get("module"))
            target = nxt.get(k.reward) + discount(td, self.gamma) * (~nxt.get(k.terminated)) * next_value
        # prioritized replay (agents/dqn/priorities.py): the TD errors for the priorities, as TorchRL's DQNLoss writes
        # them into the batch, and each transition's importance weight
        td.set(k.priority, (value - target).detach().abs().squeeze(-1))
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


def _mixed(mixer: nn.Module, chosen: torch.Tensor, state: torch.Tensor, params: TensorDictBase = None) -> torch.Tensor:
    """``[*, 1]`` the team value of the chosen per-UAV values ``[*, N, 1]``: VDN's sum, or QMIX's monotonic mix with
    the mixer's own parameters or ``params`` (TorchRL's ``QMixer.mix``, here with parameters as arguments)."""
    if not mixer.needs_state:
        return mixer(chosen)
    if params is None:
        return mixer(chosen, state)

    def layer(name: str, x: torch.Tensor) -> torch.Tensor:  # "V.0": the first layer of the state value V
        return nn.functional.linear(x, params.get((*name.split("."), "weight")), params.get((*name.split("."), "bias")))

    state = state.reshape(-1, mixer.state_dim)
    w1 = layer("hyper_w_1", state).abs().view(-1, mixer.n_agents, mixer.embed_dim)
    hidden = nn.functional.elu(
        torch.bmm(chosen.reshape(-1, 1, mixer.n_agents), w1) + layer("hyper_b_1", state)[:, None]
    )
    w_final = layer("hyper_w_final", state).abs().view(-1, mixer.embed_dim, 1)
    v = layer("V.2", torch.relu(layer("V.0", state))).view(-1, 1, 1)
    return (torch.bmm(hidden, w_final) + v).view(*chosen.shape[:-2], 1)
