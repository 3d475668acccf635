"""The factored head's loss: :class:`DoubleQMixerLoss`, TorchRL's ``QMixerLoss`` with double-DQN targets over valid
joint actions (the joint head uses TorchRL's ``DQNLoss(double_dqn=True)``, :func:`.builders.build_loss`).
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.objectives import QMixerLoss

from uavrl.compat import written_into

from .networks import Q_INPUTS


class DoubleQMixerLoss(QMixerLoss):
    """``QMixerLoss`` with double-DQN targets over valid joint actions.

    ``y = r + gamma (1 - terminated) Mix_target(Q_target(s', a'), s')`` where the
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
        # The online parameters are the modules' own (the optimizer steps them in place): called directly, without
        # the parameter swap of to_module.  The target parameters are swapped in.
        net, greedy = (m.module for m in self.local_value_network.module)
        mixer, k, nxt = self.mixer_network.module, self.tensor_keys, td.get("next")

        def team_value(td: TensorDictBase, action: torch.Tensor) -> torch.Tensor:
            chosen = net(*(td.get(key) for key in Q_INPUTS)).gather(-1, action.unsqueeze(-1))
            return mixer(chosen, td.get("state")) if mixer.needs_state else mixer(chosen)

        value = team_value(td, td.get(k.action))
        with torch.no_grad():
            next_values = net(*(nxt.get(key) for key in Q_INPUTS))
            next_action = greedy(
                next_values, nxt.get(("agents", "action_mask")), nxt.get("positions"), nxt.get("tasks")
            )
            with (
                written_into(self.target_local_value_network_params, self.local_value_network),
                written_into(self.target_mixer_network_params, self.mixer_network),
            ):
                next_value = team_value(nxt, next_action)  # the online greedy valid action, valued by the target
            target = nxt.get(k.reward) + self.gamma * (~nxt.get(k.terminated)) * next_value
        return TensorDict({"loss": nn.functional.smooth_l1_loss(value, target)})
