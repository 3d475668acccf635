"""The benchmark's tasks and suites: a scenario, the starts it is scored from, and how a score is normalised.

A task (:class:`Task`) is a model (a scenario of ``configs/scenario/``, optionally resized for the zero-shot suite)
plus its evaluation protocol: ``num_starts`` greedy rollouts of ``horizon`` steps (the scenario's evaluation
horizon: ``max(20, 2 (L1 + L2))``, or the whole mission under an energy model) from held-out starts, measured
as :mod:`uavrl.agents.evaluation` measures every policy.  Start ``b`` of a task is the world whose random stream is
seeded
``task.seed + b``; every task's seeds lie in ``[2^62, 2^63)``, where no training command draws a world (a test
proves it: :func:`training_seed_bound`), and apart from ``eval.seed``, which checkpoints may have been selected on.

Each start gets a raw value and a normalised score (docs/leaderboard.md):

- without an energy model the raw value is the discounted gain ``J = sum_t gamma^(t-1) (U_t - U_{t-1})`` of
  docs/yardstick.md; with one it is the data the mission delivers (bit/Hz, mean channels).
- ``score = (value - random) / (reference - random)`` per start, where ``random`` is the uniform random policy's
  (seed 0) value from that start and ``reference`` the task's reference there: the exact best return ``V*_H`` or the
  exact mission optimum where the exact solvers fit, else the best planner (the oracle; under an energy model the
  energy-aware planner), whose distance to the certified bounds (U*, the fewest steps or their lower bound, the
  mission's upper bound) each results file records.  So 0 is random, 1 is exact optimal control or the planner, on
  every start (one where random comes close to the reference is divided by a floor: :func:`.run.normalised`).

Example:
    >>> [task.name for task in SUITES["energy"]]
    ['energy_4x4', 'energy_6x6', 'persistent_10x10']
    >>> TASKS["zs_n50_50x50"].options
    (('grid', (50, 50)), ('num_uavs', 50), ('layout', 'line'))
"""

from __future__ import annotations

import dataclasses
import hashlib
import json

from uavrl.envs._moved import moved_names
from uavrl.envs.config import HELD_OUT_CITY_SEEDS
from uavrl.envs.errors import InvalidOption, InvalidType
from uavrl.envs.rules import at_least, shown

SEED_BASE = 2**62  # the held-out starts' streams: seeds [2^62, 2^63); no training command draws one there
TASK_SEED_STRIDE = 2**24  # each task's starts: seeds task.seed .. task.seed + num_starts - 1
NUM_STARTS = 32
GAMMA = 0.9


@dataclasses.dataclass(frozen=True)
class Task:
    """A benchmark task (module doc): the model, its starts and its protocol.

    ``name`` is the task's name in a suite and a results file; ``scenario`` names a scenario of
    ``configs/scenario/`` (its model and evaluation horizon), ``options`` the model options changed from it
    (``grid``, ``num_uavs``, ``layout``: the zero-shot suite's teams), ``seed`` the stream of start 0,
    ``num_starts`` the starts (one greedy rollout each), ``gamma`` the yardstick's discount and ``about`` one line
    for the tables.
    """

    name: str
    scenario: str
    seed: int
    options: tuple = ()
    num_starts: int = NUM_STARTS
    gamma: float = GAMMA
    about: str = ""

    def spec(self) -> dict:
        """The task as JSON: what its references and every results file are keyed by."""
        out = dataclasses.asdict(self)
        out["options"] = {key: list(value) if isinstance(value, tuple) else value for key, value in self.options}
        return out

    def digest(self) -> str:
        """A content hash of :meth:`spec` (sha256, hex)."""
        return hashlib.sha256(json.dumps(self.spec(), sort_keys=True).encode()).hexdigest()


def _task(index: int, name: str, scenario: str, about: str, **options) -> Task:
    return Task(
        name=name,
        scenario=scenario,
        seed=SEED_BASE + index * TASK_SEED_STRIDE,
        options=tuple(options.items()),
        about=about,
    )


def _zero_shot(index: int, num_uavs: int, side: int, layout: str) -> Task:
    suffix = "" if layout == "line" else f"_{layout}"
    return _task(
        index,
        f"zs_n{num_uavs}_{side}x{side}{suffix}",
        "paper_6x6",
        f"the paper's model, N = {num_uavs} on {side}x{side}, layout {layout!r}",
        grid=(side, side),
        num_uavs=num_uavs,
        layout=layout,
    )


def _held_out_city(index: int, environment: str, num_uavs: int) -> Task:
    """A city no training run lays out (``city_seed`` from :data:`~uavrl.envs.config.HELD_OUT_CITY_SEEDS`, fixed by
    the task's index) of an ITU-R P.1410 environment, on ``city_urban_10x10``'s model (N = 6) or
    ``city_dense_20x20``'s (N = 10); S and E at 200 m where the high-rise city's roofs reach 100 m."""
    scenario, side = ("city_urban_10x10", 10) if num_uavs == 6 else ("city_dense_20x20", 20)
    high = {"altitude_m": 200.0} if environment == "highrise" else {}
    return _task(
        index,
        f"city_{environment}_n{num_uavs}",
        scenario,
        f"N = {num_uavs} on {side}x{side} in a held-out {environment.replace('_', '-')} city, altitude levels",
        city=environment,
        environment=environment,
        city_seed=HELD_OUT_CITY_SEEDS + index,
        **high,
    )


def _decentralised(index: int, num_uavs: int, side: int, radius: float | None, message_size: int = 0) -> Task:
    """``n6_10x10`` (N = 6) or ``large_20x20`` (N = 10) with local observations within ``radius`` cells (None: every
    UAV and node heard), and messages of ``message_size`` numbers."""
    shown = ("full" if radius is None else f"r{radius:g}") + (f"_m{message_size}" if message_size else "")
    heard = "every UAV and node" if radius is None else f"within {radius:g} cell{'' if radius == 1 else 's'}"
    messages = {"message_size": message_size} if message_size else {}
    return _task(
        index,
        f"dec_n{num_uavs}_{side}x{side}_{shown}",
        "n6_10x10" if num_uavs == 6 else "large_20x20",
        f"N = {num_uavs} on {side}x{side}, each UAV observing {heard}"
        + (f", messages of {message_size}" if message_size else ""),
        observation="local",
        comm_radius=radius,
        **messages,
    )


COMM_RADII = (0.0, 1.0, 2.0, 4.0, None)  # the decentralised suite's radii in cells (None: full)
CITY_ENVIRONMENTS = ("suburban", "urban", "dense_urban", "highrise")
# the index fixes a task's seeds: a new task takes a new index, an old one keeps its own
_ALL = [
    _task(0, "paper_6x6", "paper_6x6", "the paper's 6x6 grid with 2 UAVs"),
    _task(1, "reference_code", "reference_code", "the authors' published code's model, 6x6 with 2 UAVs"),
    _task(2, "n6_10x10", "n6_10x10", "6 UAVs on 10x10"),
    _task(3, "large_20x20", "large_20x20", "10 UAVs on 20x20"),
    _task(4, "random_layouts", "random_layouts", "6 UAVs on 10x10, a new layout of the nodes per start"),
    _task(5, "rayleigh", "rayleigh", "the paper's 6x6 under Rayleigh fading"),
    _task(6, "a2g_urban", "a2g_urban", "6 UAVs on 10x10, the urban air-to-ground channel"),
    _task(7, "energy_4x4", "energy_4x4", "2 UAVs with 1.2 Wh batteries on 4x4: the exact mission optimum"),
    _task(8, "energy_6x6", "energy_6x6", "2 UAVs with 5 Wh batteries on 6x6, no recharge"),
    _task(9, "persistent_10x10", "persistent_10x10", "6 UAVs and 2 spares recharging, a 500-step mission"),
    _zero_shot(10, 2, 6, "line"),
    _zero_shot(11, 6, 10, "line"),
    _zero_shot(12, 10, 20, "line"),
    _zero_shot(13, 20, 30, "line"),
    _zero_shot(14, 50, 50, "line"),
    _zero_shot(15, 6, 10, "random"),
    _zero_shot(16, 10, 20, "random"),
    # smoke-sized: the tests and the documentation's runnable examples
    _task(17, "tiny_3x3", "paper_6x6", "2 UAVs on 3x3 (smoke-sized)", grid=(3, 3), num_uavs=2),
    _task(18, "tiny_energy", "energy_4x4", "energy_4x4 on 3x3 (smoke-sized)", grid=(3, 3)),
    *(_held_out_city(19 + k, environment, 6) for k, environment in enumerate(CITY_ENVIRONMENTS)),
    *(_held_out_city(23 + k, environment, 10) for k, environment in enumerate(CITY_ENVIRONMENTS)),
    *(_decentralised(27 + k, 6, 10, radius) for k, radius in enumerate(COMM_RADII)),
    *(_decentralised(32 + k, 10, 20, radius) for k, radius in enumerate(COMM_RADII)),
    _decentralised(37, 6, 10, 2.0, message_size=4),
    _decentralised(38, 10, 20, 2.0, message_size=4),
]
TASKS = {task.name: task for task in _ALL}
SUITES = {
    "paper": [TASKS[name] for name in ("paper_6x6", "reference_code")],
    "core": [TASKS[name] for name in ("n6_10x10", "large_20x20", "random_layouts", "rayleigh", "a2g_urban")],
    "energy": [TASKS[name] for name in ("energy_4x4", "energy_6x6", "persistent_10x10")],
    "zero_shot": [task for task in _ALL if task.name.startswith("zs_")],
    "city": [task for task in _ALL if task.name.startswith("city_")],
    "decentralised": [task for task in _ALL if task.name.startswith("dec_")],
    "tiny": [TASKS["tiny_3x3"], TASKS["tiny_energy"]],
}
SUITES_TEXT = ", ".join(SUITES)
# uavrl 0.2's model() and horizon() of a task are uavrl.bench.run's (they compose the scenario with Hydra):
# deprecated aliases
__getattr__ = moved_names(__name__, "uavrl.bench.run")


# what training cost, as a submission states it: score_suite's budget= and the command line's budget.<key>=
BUDGET = {"env_steps": at_least(0, whole_only=True), "cpu_seconds": at_least(0), "gpu_seconds": at_least(0)}


def check_budget(budget) -> dict:
    """A submission's training budget (:data:`BUDGET`; ``None``: none stated) with ``env_steps`` as an int, or a
    one-line ValueError naming ``budget.<key>`` for an unknown key or a value that breaks its rule.  Text (the
    command line's ``budget.<key>=<text>``) is read as a number first and shown as typed."""
    if budget is None:
        return {}
    if not isinstance(budget, dict):
        raise InvalidType(
            "budget", message=f"budget={budget!r} is invalid: give a dict of {', '.join(BUDGET)}, or None"
        )
    checked = {}
    for key, value in budget.items():
        if key not in BUDGET:
            raise InvalidOption(
                f"budget.{key}",
                message=f"budget.{key}={value} is invalid: unknown key; a budget states {', '.join(BUDGET)}",
            )
        number = value
        if isinstance(value, str):
            try:
                number = float(value)
            except ValueError:
                pass
        if not BUDGET[key].accepts(number):
            typed = value if isinstance(value, str) else shown(value)
            raise InvalidOption(f"budget.{key}", message=f"budget.{key}={typed} is invalid: {BUDGET[key].allowed}")
        checked[key] = int(number) if key == "env_steps" else float(number)
    return checked


def training_seed_bound(max_training_seed: int, step_budget: int) -> int:
    """An upper bound on the world seeds a training command draws with ``seed < max_training_seed`` and at most
    ``step_budget`` team steps (``train.step_budget``): the DQN's iteration ``k`` seeds its worlds ``seed * 2^44 +
    (k + 1) * 2^24 + world`` (agents/dqn/agent.py), the tabular learner's episode ``e`` of run ``r`` the world
    ``seed + e R + r``, BenchMARL's and the adapters' worlds ``seed + world``: every one below the bound, at least
    one step per iteration or episode, and fewer than 2^24 worlds."""
    return max_training_seed * 2**44 + (step_budget + 1) * 2**24 + max_training_seed + step_budget
