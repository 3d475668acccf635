"""Exact answers about the model, the yardstick agents are measured against (docs/model.md).

- :mod:`.optimum`: ``U*``, the best utility of deterministic channels (exchange method, branch and bound);
- :mod:`.exact`: exact optimal control, the fewest steps to a good configuration on the configuration graph;
- :mod:`.bounds`: lower bounds on those steps for teams too large for the exact solver;
- :mod:`.mission`: an upper bound on the data a mission delivers under an energy model;
- :mod:`.mission_exact`: the exact optimum of a mission's delivered data (1 or 2 UAVs, small grids).

They read :mod:`uavrl.envs.physics` and no World, TorchRL or agent; this file imports nothing.
"""
