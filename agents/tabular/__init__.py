"""Tabular team Q-learning (the paper's eqs. 9-10), with the Q table as a torch tensor.

One controller learns ``Q[s, j]`` over the joint state ``s`` (docs/model.md, "What the agents see and learn":
the joint location, optionally with tasks) and the joint action
``j = sum_i a_i 6^i``.  Each step it picks an epsilon-greedy *valid* joint
action (every UAV on the grid, cells distinct), ties broken uniformly at random,
and updates ``Q[s, j] <- (1 - alpha) Q[s, j] + alpha (r + gamma max_valid Q[s', .])``.

Speed comes from tabulating the model once.  For deterministic channels the
environment's own functions give, for every configuration, the rates (from
:func:`uavrl.envs.physics.channel.rates`) and, for every joint action, the next cells
(:func:`uavrl.envs.joint_targets`).  A learning step is then a handful of table
lookups, run by one of two interchangeable loops over the same tables and the
same random numbers:

- ``backend="numba"``: a compiled loop on the torch tensors' memory, runs in
  parallel (the paper's 10 iterations side by side on the CPU's cores);
- ``backend="torch"``: the same step batched over runs in torch, on any device.

They give bit-identical Q tables (tests/agents/test_tabular.py).

``R`` independent runs each own a table (the paper's repetitions), or, with
``shared_table``, ``R`` worlds feed one table: every step all worlds read the
table, then each visited ``(s, j)`` moves towards the mean target of the worlds
that visited it (synchronous, so both loops agree exactly).

The package, one job a module, each read top to bottom:

- :mod:`.tables`: the model as lookup tables (:class:`TabularModel`) and the exact table (:func:`exact_q_table`);
- :mod:`.kernels`: the compiled (numba) episode loops and their batched torch twin;
- :mod:`.learner`: :class:`TeamQLearner`, one episode of learning on either backend;
- :mod:`.greedy`: the greedy choice of a table in plain torch, and the evaluation of many tables at once;
- :mod:`.policy`: :class:`TabularPolicy`, the greedy TorchRL policy of a table (imported on first use: TorchRL);
- :mod:`.agent`: :class:`TabularAgent`, the learner behind ``python -m uavrl.train agent=tabular``.

Example:
    >>> from uavrl.envs import make_config
    >>> learner = TeamQLearner(make_config("paper", grid=(3, 3), max_steps=50), runs=2, seed=0)
    >>> metrics = learner.run_episode()
    >>> learner.q.shape, metrics["sum_utility"].shape, bool((metrics["steps_to_90"] <= 50).all())
    (torch.Size([2, 81, 36]), torch.Size([2]), True)
"""

from uavrl.agents.schema import METHODS
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET, table_bytes

from .agent import TabularAgent
from .learner import TeamQLearner
from .tables import TabularModel, exact_q_table

__all__ = [
    "DEFAULT_MEMORY_BUDGET",
    "METHODS",
    "TabularAgent",
    "TabularModel",
    "TabularPolicy",
    "TeamQLearner",
    "exact_q_table",
    "table_bytes",
]


def __getattr__(name):
    if name != "TabularPolicy":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from .policy import TabularPolicy  # tensordict: only where the TorchRL policy is used

    return TabularPolicy
