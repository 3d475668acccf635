"""BenchMARL on the UAV task: its task class for :class:`UAVSpectrumEnv`, and the callback that measures its policy.

BenchMARL (``pip install torch==2.13.0 -e ".[benchmarl]"``) runs its own experiments, algorithms, losses and
loggers; this module only tells it what the environment is (:class:`UAVTask`) and evaluates the policy it trains
with the shared evaluation (:class:`YardstickCallback`), so its runs carry the same ``eval/...`` metrics as ours.
The command is ``python -m uavrl.benchmarl`` (:mod:`uavrl.benchmarl`).
"""

from __future__ import annotations

import dataclasses

from benchmarl.environments.common import TaskClass
from benchmarl.experiment.callback import Callback
from torchrl.data import Composite
from torchrl.envs.utils import ExplorationType, set_exploration_type

from uavrl.agents.episodes import TrainingClock
from uavrl.agents.evaluation import evaluate
from uavrl.envs import ModelConfig, UAVSpectrumEnv

GROUP = "agents"


class UAVTask(TaskClass):
    """A BenchMARL task of :class:`UAVSpectrumEnv`; ``config`` holds the fields of a :class:`ModelConfig`.

    One group, ``"agents"``, of the N UAVs; per UAV the ``observation`` and the ``action_mask`` (a UAV's move off
    the grid is masked), the global ``state`` for mixers and critics, one shared team reward at the root. The
    environment is batched, so BenchMARL's ``n_envs_per_worker`` worlds run in one tensor program.

    >>> from uavrl.envs import make_config
    >>> task = UAVTask.from_model_config("tiny", make_config("paper", grid=(3, 3), num_uavs=2, max_steps=5))
    >>> env = task.get_env_fun(num_envs=4, continuous_actions=False, seed=0, device="cpu")()
    >>> task.group_map(env), task.max_steps(env), sorted(task.observation_spec(env)["agents"].keys())
    ({'agents': ['uav_0', 'uav_1']}, 5, ['observation'])
    """

    @classmethod
    def from_model_config(cls, name: str, cfg: ModelConfig) -> UAVTask:
        return cls(name=name, config=dataclasses.asdict(cfg))

    @property
    def model_config(self) -> ModelConfig:
        return ModelConfig(**{**self.config, "grid": tuple(self.config["grid"])})

    def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: int | None, device):
        cfg = self.model_config  # BenchMARL reads the observation, mask, state and reward: no diagnostics carried
        return lambda: UAVSpectrumEnv(batch_size=num_envs, config=cfg, seed=seed, device=device, diagnostics=False)

    def supports_continuous_actions(self) -> bool:
        return False

    def supports_discrete_actions(self) -> bool:
        return True

    def max_steps(self, env) -> int:
        return self.model_config.max_steps

    def has_render(self, env) -> bool:
        return False

    def group_map(self, env) -> dict[str, list[str]]:
        return {GROUP: [f"uav_{i}" for i in range(self.model_config.fleet_size)]}  # spares are agents too

    def _group_entry(self, env, key: str) -> Composite:
        group = env.full_observation_spec_unbatched[GROUP]
        return Composite({GROUP: Composite({key: group[key].clone()}, shape=group.shape)})

    def observation_spec(self, env) -> Composite:
        return self._group_entry(env, "observation")

    def action_mask_spec(self, env) -> Composite:
        return self._group_entry(env, "action_mask")

    def state_spec(self, env) -> Composite:
        return Composite({"state": env.full_observation_spec_unbatched["state"].clone()})

    def info_spec(self, env) -> None:
        return None

    def action_spec(self, env) -> Composite:
        return env.full_action_spec_unbatched.clone()

    @staticmethod
    def env_name() -> str:
        return "uavrl"


class YardstickCallback(Callback):
    """At each of BenchMARL's evaluations, the shared evaluation (:func:`~uavrl.agents.evaluation.evaluate`) of its
    greedy policy, logged with our TensorBoard tags against collected frames, beside the seconds BenchMARL had
    trained by
    then (``time/...``, :class:`~uavrl.agents.episodes.TrainingClock`: our evaluations left out); ``curve`` keeps each
    point.  The TensorBoard writer opens at the first evaluation: BenchMARL pickles its callbacks with the
    experiment's config, and an experiment reloaded to be scored sets them up again, writing nothing.

    Args:
        env_cfg: the model the greedy policy is evaluated in (the task's).
        eval_kwargs: the settings of :func:`~uavrl.agents.evaluation.evaluate` (``num_starts``, ``horizon``, ...).
        open_log: opens the run's TensorBoard events when first called (``functools.partial(RunLogger, run_dir)`` of
            :mod:`uavrl.experiment.logger`): an object with ``log(metrics, step)`` and ``close()``.
    """

    def __init__(self, env_cfg: ModelConfig, eval_kwargs: dict, open_log):
        super().__init__()
        self.env_cfg, self.eval_kwargs, self.open_log = env_cfg, eval_kwargs, open_log
        self.logger = None
        self.curve: list[dict] = []
        self.clock = TrainingClock()

    def log(self, metrics: dict, frames: int) -> None:
        """Write ``metrics`` to the run directory's TensorBoard events, opening them on the first call.

        Args:
            metrics: the scalars by tag (``eval/...``, ``time/...``).
            frames: the frames BenchMARL had collected, the events' step.
        """
        if self.logger is None:
            self.logger = self.open_log()
        self.logger.log(metrics, frames)

    def close(self) -> None:
        """Flush and close the TensorBoard events, if any were written."""
        if self.logger is not None:
            self.logger.close()

    def measure(self) -> dict[str, float]:
        """The shared evaluation of BenchMARL's greedy policy now, and the training seconds so far."""
        trained = self.clock.read()
        with self.clock.paused(), set_exploration_type(ExplorationType.DETERMINISTIC):
            metrics = evaluate(self.experiment.policy, self.env_cfg, **self.eval_kwargs)
        return {**metrics, **trained}

    def on_evaluation_end(self, rollouts) -> None:
        frames, metrics = self.experiment.total_frames, self.measure()
        self.log(metrics, frames)
        self.curve.append({"frames": frames, **metrics})
