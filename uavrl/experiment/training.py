"""The training command's body (``python -m uavrl.train``, :mod:`uavrl.train`): a run in its held directory.

:func:`run_training` takes a run whose settings :func:`uavrl.train.check_settings` passed: it holds the run
directory, trains (:class:`Training`, step by step), evaluates, writes ``metrics.json`` and prints the summary.
Each run writes ``runs/<agent>/<env>/<timestamp>/``: TensorBoard events, the resolved ``config.yaml``,
``checkpoint.pt`` (atomic, every ``train.checkpoint_every`` iterations and at the end; the one it replaces is kept as
``checkpoint.prev.pt``) and ``metrics.json``; ``resume=<run dir>`` continues a killed run from its newest readable
checkpoint (:mod:`uavrl.experiment.rundir`).
"""

from __future__ import annotations

import random
import sys
import time
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from uavrl.agents import agent_class
from uavrl.agents import evaluation as shared_evaluation  # evaluate_agent looked up at each call, as before
from uavrl.agents.episodes import TrainingClock
from uavrl.agents.lookahead_rules import lookahead_settings
from uavrl.config import model_config, saved_config
from uavrl.envs.world import resolve_device
from uavrl.experiment.checkpoints import (
    CheckpointError,
    CheckpointWriter,
    check_resumable,
    checkpoint_files,
    restore_agent,
    run_directory,
)
from uavrl.experiment.io import WriteError, quoted, save_json, save_text
from uavrl.experiment.logger import RunLogger
from uavrl.experiment.rundir import Interrupted, Interrupts, RunDirectory, hold, path_argument, resume_command
from uavrl.experiment.runs import (
    BASELINE_AGENTS,
    agent_label,
    agent_words,
    already_a_run,
    claim_run_dir,
    eval_settings,
    flat_hparams,
    is_size_free,
    model_words,
    optimality_line,
    size_free_teams,
    yardstick_line,
)
from uavrl.experiment.saved import load_run_checkpoint, saved_agent
from uavrl.settings import (
    check_run,
)

# settings a resumed run may change; everything else must match the saved run
RESUMABLE_OVERRIDES = ("resume", "progress", "num_threads", "run_dir")


def seed_everything(seed: int) -> None:

    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


def hold_run_dir(cfg: DictConfig) -> RunDirectory:
    """The run directory, locked (:mod:`uavrl.experiment.rundir`): ``resume``'s, ``run_dir`` if given (a sweep job
    gets one from ``uavrl.cli``), else a new ``runs/<agent>/<env>/<timestamp>`` (``<agent>``:
    :func:`uavrl.experiment.runs.agent_label`, ``dqn-set`` for a size-free network)."""
    if cfg.resume:
        return hold(run_directory(cfg.resume, "resume"), "resume")
    refusal = already_a_run(cfg.run_dir) if cfg.run_dir else ""
    return claim_run_dir(cfg.run_dir, agent_label(cfg), cfg.env.name, checkpoint_files, refusal)


def resumed_config(cfg: DictConfig, overrides) -> tuple[DictConfig, dict, Path, bool]:
    """The saved config and newest readable checkpoint of ``cfg.resume`` (a run directory or its ``checkpoint.pt``),
    that checkpoint's file, and whether it is the newest file.

    Explicit overrides must agree with the saved run.
    """
    run_dir = run_directory(cfg.resume, "resume")
    checkpoint, file, skipped = load_run_checkpoint(run_dir, "resume")
    if skipped:
        iteration = checkpoint["iteration"]
        print(f"warning: {'; '.join(skipped)}: resuming from {file.name}, iteration {iteration}", file=sys.stderr)
    check_resumable(checkpoint, file)
    try:
        saved = saved_config(checkpoint["config"], quoted(file))
    except ValueError as err:
        raise CheckpointError(str(err)) from None
    for override in overrides:
        key = override.split("=", 1)[0].lstrip("+~")
        if key.split(".")[0] in RESUMABLE_OVERRIDES:
            continue
        if OmegaConf.select(saved, key) != OmegaConf.select(cfg, key):
            raise ValueError(
                f"resume: {override!r} differs from the saved run ({key}={OmegaConf.select(saved, key)}); resume "
                "continues the saved config"
            )
    for key in RESUMABLE_OVERRIDES:
        saved[key] = cfg[key]
    saved.resume = saved.run_dir = str(run_dir)
    check_run(saved)
    return saved, checkpoint, file, not skipped


def run_training(cfg: DictConfig, overrides=()) -> Path:
    """Run training as configured, once :func:`uavrl.train.check_settings` passed; returns the run directory.

    The run directory is locked for the whole run; SIGINT and SIGTERM end the
    run with a checkpoint at the end of the iteration (:mod:`uavrl.experiment.rundir`); a
    run that fails before it saved anything removes the directory it made.

    Args:
        cfg: the run's composed config (``uavrl/configs/config.yaml`` with the overrides).
        overrides: the command line's overrides (a resumed run checks them against its saved config).

    Returns:
        The run directory.
    """
    held = hold_run_dir(cfg)
    try:
        with Interrupts(notify=lambda line: tqdm.write(line, file=sys.stderr)) as interrupts:
            cfg, env_cfg, result = run(cfg, overrides, held.path, interrupts)
    except Interrupted as err:
        if not getattr(err, "__notes__", None):  # before the first iteration
            err.add_note(
                f"the run is as it was; continue it with: {resume_command(held.path)}"
                if cfg.resume
                else "stopped before the first checkpoint, nothing saved"
            )
        held.discard()
        raise
    except BaseException:
        held.discard()
        raise
    held.release()
    print(summary(cfg, env_cfg, result, held.path))
    return held.path


def run(cfg: DictConfig, overrides, run_dir: Path, interrupts: Interrupts) -> tuple[DictConfig, object, dict]:
    """Train in the held ``run_dir``: the resumed or new run's config, its model config and ``metrics.json``."""
    training = Training(run_dir, interrupts)
    training.configure(cfg, overrides)
    training.build_agent()
    training.restore()
    training.open_run_files()
    result = training.train_and_evaluate()
    return training.cfg, training.env_cfg, result


class Training:
    """One run in its held directory, step by step (:func:`run` takes the steps in order).

    The heavy modules are imported by the steps, once the settings are known to be good.
    """

    def __init__(self, run_dir: Path, interrupts: Interrupts):
        self.run_dir, self.interrupts = run_dir, interrupts

    def configure(self, cfg: DictConfig, overrides) -> None:
        """The resumed run's saved config and checkpoint (or the new run's config), threads, device and seeds."""

        self.checkpoint, self.checkpoint_file, self.newest_is_readable = None, None, True
        if cfg.resume:
            cfg, self.checkpoint, self.checkpoint_file, self.newest_is_readable = resumed_config(cfg, overrides)
        torch.set_num_threads(int(cfg.num_threads))
        self.cfg, self.device = cfg, resolve_device(cfg.device)
        self.env_cfg = model_config(cfg)
        seed_everything(int(cfg.seed))

    def build_agent(self) -> None:
        """A new agent, or one built as the checkpoint's run built it."""

        cfg = self.cfg
        if self.checkpoint is None:
            self.agent = agent_class(cfg.agent.name, cfg.agent)(self.env_cfg, cfg, self.device, int(cfg.seed))
        else:
            self.agent = saved_agent(cfg, self.env_cfg, self.device, self.checkpoint_file)

    def restore(self) -> None:
        """The checkpoint's agent state, RNG and iteration (a new run starts at 0)."""

        self.start = self.saved = 0
        if self.checkpoint is not None:
            restore_agent(self.agent, self.checkpoint, self.checkpoint_file, self.cfg.agent.name)
            torch.set_rng_state(self.checkpoint["torch_rng"])
            self.start = self.saved = int(self.checkpoint["iteration"])

    def open_run_files(self) -> None:
        """``config.yaml``, the logger and the checkpoint writer."""

        self.resolved = OmegaConf.to_container(self.cfg, resolve=True)
        save_text(OmegaConf.to_yaml(self.resolved), self.run_dir / "config.yaml")
        # points after the checkpoint's step (any, for a new run) are replaced; those up to it stay
        with self.interrupts.shielded():
            resume_step = self.agent.env_steps if self.checkpoint is not None else 0
            self.logger = RunLogger(self.run_dir, resume_step=resume_step)
        self.checkpoints = CheckpointWriter(self.run_dir, self.newest_is_readable)
        self.eval_kwargs = eval_settings(self.cfg, self.device)
        if self.cfg.eval.get("lookahead", 0):  # the lookahead's keywords, where eval.lookahead asks for one
            self.eval_kwargs.update(lookahead_settings(self.cfg))

    def train_and_evaluate(self) -> dict:
        """The iterations, then the final evaluation; writes ``metrics.json`` and returns it.

        An interrupt or a full disk leaves the newest checkpoint and the command that continues the run.
        """

        cfg, agent, interrupts = self.cfg, self.agent, self.interrupts
        started = time.perf_counter()
        clock = TrainingClock()
        with interrupts.shielded():
            bar = tqdm(
                initial=self.start,
                total=agent.num_iterations,
                disable=not cfg.progress,
                desc=f"{agent_label(cfg)} {cfg.env.name}",
                unit="it",
                dynamic_ncols=True,
            )
        try:
            self.train_loop(bar, clock)
            trained = clock.read()
            final = self.evaluate_and_save(trained)
            with interrupts.shielded():
                self.logger.hparams(flat_hparams(cfg), ("eval/optimality", "eval/optimal_fraction"))
        except Interrupted as err:
            resumed = self.checkpoint is not None
            err.add_note(interrupted_note(self.run_dir, self.saved, agent.num_iterations, resumed))
            raise
        except WriteError as err:
            if self.saved == 0:  # nothing to continue from
                raise
            raise OSError(
                f"{err}; the checkpoints already there are unchanged: make room, then continue the run with: "
                f"{resume_command(self.run_dir)}"
            ) from None
        finally:
            with interrupts.shielded(act_after=False):
                bar.close()
                self.logger.close()
        result = {
            "agent": cfg.agent.name,
            "env": cfg.env.name,
            "env_steps": agent.env_steps,
            "iterations": agent.num_iterations,
            "train_seconds": trained["time/train_seconds"],  # the periodic evaluations left out, as for BenchMARL's
            "train_cpu_seconds": trained["time/train_cpu_seconds"],
            "total_seconds": time.perf_counter() - started,
            **final,
        }
        save_json(result, self.run_dir / "metrics.json")
        return result

    def train_loop(self, bar, clock) -> None:
        """The iterations left, each logged, evaluated and checkpointed as the run's settings ask."""

        cfg, agent, interrupts, env_cfg = self.cfg, self.agent, self.interrupts, self.env_cfg
        every = int(cfg.train.checkpoint_every)
        # a first signal waits for the iteration's end, where a checkpoint resumes exactly
        with interrupts.deferred():
            for done in range(self.start + 1, agent.num_iterations + 1):
                interrupts.working_on = f"iteration {done} of {agent.num_iterations}"
                metrics = agent.train_iteration()
                if done % int(cfg.train.log_every) == 0 or done == agent.num_iterations:
                    with interrupts.shielded():
                        self.logger.log(metrics, agent.env_steps)
                        if "train/sum_utility" in metrics:  # the episode's mean utility U = R_PU + R_SE per step
                            per_step = metrics["train/sum_utility"] / env_cfg.max_steps
                            bar.set_postfix({"utility/step": f"{per_step:.4g}"}, refresh=False)
                if cfg.eval.every and done % int(cfg.eval.every) == 0 and done < agent.num_iterations:
                    trained = clock.read()  # before the evaluation, which the clock leaves out
                    with clock.paused():
                        evaluation = shared_evaluation.evaluate_agent(agent, env_cfg, **self.eval_kwargs)
                    self.log_evaluation({**evaluation, **trained}, self.video_frames())
                if done % every == 0 and done < agent.num_iterations:
                    self.save_checkpoint(done)
                with interrupts.shielded():
                    bar.update()
                if interrupts.received:
                    if self.saved != done:
                        self.save_checkpoint(done)
                    raise interrupts.stop(interrupts.received)

    def evaluate_and_save(self, trained: dict) -> dict:
        """The final evaluation, logged and saved with the final checkpoint (a run resumed after it: the saved one)."""

        if self.checkpoint is not None and "final" in self.checkpoint:  # resumed after the final checkpoint
            return self.checkpoint["final"]
        iterations = self.agent.num_iterations
        trained_rng = torch.get_rng_state()
        try:
            final = shared_evaluation.evaluate_agent(self.agent, self.env_cfg, **self.eval_kwargs)
            frames = self.video_frames()
        except Interrupted:  # the training is whole: kept, and the resumed run evaluates it
            if self.saved != iterations:
                self.save_checkpoint(iterations, torch_rng=trained_rng)
            raise
        with self.interrupts.shielded():  # logged and saved as one: a resumed run neither logs it again nor loses it
            self.log_evaluation({**final, **trained}, frames)
            self.save_checkpoint(iterations, final)
        return final

    def save_checkpoint(self, iteration: int, final: dict | None = None, torch_rng=None) -> None:

        state = {
            "agent": self.agent.state_dict(),
            "iteration": iteration,
            "config": self.resolved,
            "torch_rng": torch.get_rng_state() if torch_rng is None else torch_rng,
        }
        self.checkpoints.save(state if final is None else {**state, "final": final})
        self.saved = iteration

    def video_frames(self):
        """The greedy policy beside the oracle, where ``eval.video`` asks (a run saved before has no setting)."""

        cfg = self.cfg
        if not cfg.eval.get("video", False):
            return None
        from uavrl.experiment import video  # TorchRL (the oracle's rollouts): a tabular run without one imports none

        policy = self.agent.policies()[0]
        return video.comparison_frames(
            policy, self.env_cfg, label=cfg.agent.name, **video.video_settings(cfg, self.device)
        )

    def log_evaluation(self, metrics: dict, frames) -> None:
        with self.interrupts.shielded():
            self.logger.log(metrics, self.agent.env_steps)
            if frames is not None:
                self.logger.video("eval/video", frames, self.agent.env_steps, int(self.cfg.eval.video_fps))


def interrupted_note(run_dir: Path, saved: int, iterations: int, resumed: bool) -> str:
    """What an interrupted run left, and the command that continues it."""
    if saved == 0 and not resumed:
        return "stopped before the first checkpoint, nothing saved"
    return f"checkpoint.pt holds iteration {saved} of {iterations}; continue the run with: {resume_command(run_dir)}"


def summary(cfg: DictConfig, env_cfg, result: dict, run_dir: Path) -> str:
    """The end of a run in words: what was trained (a baseline: evaluated, it has nothing to learn; a size-free
    network: the teams it trained on), what the numbers mean, where the run is, how to look at it."""
    seconds = f"{result['total_seconds']:.1f} s"
    if cfg.agent.name in BASELINE_AGENTS:
        lines = [f"evaluated {agent_words(cfg)} on {cfg.env.name} ({model_words(env_cfg)}) in {seconds}"]
    elif is_size_free(cfg):
        lines = [
            f"trained {agent_words(cfg)} on {cfg.env.name}: {result['iterations']} iterations in {seconds}",
            f"size-free: trained on {size_free_teams(cfg, env_cfg)}; its own evaluation: {model_words(env_cfg)}",
        ]
    else:
        trained = f"{cfg.agent.name} on {cfg.env.name} ({model_words(env_cfg)})"
        lines = [f"trained {trained}: {result['iterations']} iterations in {seconds}"]
    return "\n".join(
        [
            *lines,
            optimality_line(cfg, result, cfg.agent.name),
            yardstick_line(cfg, result),
            f"run directory: {run_dir} (config.yaml, checkpoint.pt, metrics.json, TensorBoard events)",
            f"look at it: tensorboard --logdir {quoted(run_dir)}   "
            f"evaluate it again: python -m uavrl.evaluate {path_argument('checkpoint', run_dir)}",
        ]
    )
