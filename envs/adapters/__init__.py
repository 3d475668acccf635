"""The model outside TorchRL (``pip install -e ".[gym]"``): adapters over the same batched
:class:`~uavrl.envs.World`, with its physics, seeds and masks.

- :mod:`.gym_env`: Gymnasium's team ``Env`` and ``VectorEnv`` (importing it registers ``uavrl/UAVSpectrum-v0``),
  and ``TeamActionPolicy``, their users' policies as TorchRL policies for the evaluation;
- :mod:`.pettingzoo_env`: PettingZoo's ``ParallelEnv``, one agent per UAV.

This file imports nothing, so ``uavrl.envs`` never needs Gymnasium or PettingZoo.
"""
