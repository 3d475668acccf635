"""Train an agent: ``python -m uavrl.train agent=tabular env=paper env.grid=[6,6] train.episodes=200``.

Each run writes ``runs/<agent>/<env>/<timestamp>/``: TensorBoard events, the
resolved ``config.yaml``, ``checkpoint.pt`` (atomic, every
``train.checkpoint_every`` iterations and at the end) and ``metrics.json`` with
the final evaluation.  ``resume=<run dir>`` continues a killed run from its
checkpoint with the run's saved config; with the same seed it ends exactly as
an uninterrupted run would.
"""
from __future__ import annotations

import random
import time
from datetime import datetime
from pathlib import Path

import hydra
import numpy as np
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from uavrl.agents import agent_class
from uavrl.config import config_dir, flat_hparams, model_config
from uavrl.evaluation import check_settings as check_eval_settings
from uavrl.evaluation import evaluate_agent
from uavrl.io import save_json, save_text, save_torch
from uavrl.logger import RunLogger

CHECKPOINT = "checkpoint.pt"
# settings a resumed run may change; everything else must match the saved run
RESUMABLE_OVERRIDES = ("resume", "progress", "num_threads", "run_dir")


def resolve_device(name: str) -> torch.device:
    try:
        device = torch.device(name)
    except RuntimeError:
        raise ValueError(f"device={name!r} is invalid: use 'cpu', 'cuda' or 'cuda:<index>'") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device={name!r} is not available: this torch has no usable CUDA (see the README for a CUDA build)")
    return device


def eval_settings(cfg: DictConfig, device) -> dict:
    """Keyword arguments of :func:`uavrl.evaluation.evaluate` from ``cfg.eval``."""
    return dict(num_starts=cfg.eval.num_starts, horizon=cfg.eval.horizon, seed=int(cfg.eval.seed), device=device, gamma=cfg.eval.gamma)


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


def new_run_dir(cfg: DictConfig) -> Path:
    if cfg.run_dir:
        return Path(cfg.run_dir)
    base = Path("runs") / cfg.agent.name / cfg.env.name / datetime.now().strftime("%Y%m%d-%H%M%S")
    run_dir, n = base, 1
    while run_dir.exists():
        run_dir, n = base.with_name(f"{base.name}-{n}"), n + 1
    return run_dir


def resumed_config(cfg: DictConfig, overrides) -> tuple[DictConfig, dict]:
    """The saved config and checkpoint of ``cfg.resume``; explicit overrides must agree with the saved run."""
    run_dir = Path(cfg.resume)
    path = run_dir / CHECKPOINT
    if not path.exists():
        raise FileNotFoundError(f"resume={cfg.resume!r}: no {CHECKPOINT} in that directory (give a run directory written by uavrl.train)")
    checkpoint = torch.load(path, weights_only=False)
    saved = OmegaConf.create(checkpoint["config"])
    for override in overrides:
        key = override.split("=", 1)[0].lstrip("+~")
        if key.split(".")[0] in RESUMABLE_OVERRIDES:
            continue
        if OmegaConf.select(saved, key) != OmegaConf.select(cfg, key):
            raise ValueError(f"resume: {override!r} differs from the saved run ({key}={OmegaConf.select(saved, key)}); resume continues the saved config")
    for key in RESUMABLE_OVERRIDES:
        saved[key] = cfg[key]
    saved.run_dir = str(run_dir)
    return saved, checkpoint


def train(cfg: DictConfig, overrides=()) -> Path:
    """Run training as configured; returns the run directory."""
    check_eval_settings(cfg.eval.gamma, cfg.eval.horizon, cfg.eval.num_starts)
    checkpoint = None
    if cfg.resume:
        cfg, checkpoint = resumed_config(cfg, overrides)
    torch.set_num_threads(int(cfg.num_threads))
    device = resolve_device(cfg.device)
    env_cfg = model_config(cfg)
    seed_everything(int(cfg.seed))
    agent = agent_class(cfg.agent.name)(env_cfg, cfg, device, int(cfg.seed))
    run_dir = new_run_dir(cfg)
    start = 0
    if checkpoint is not None:
        agent.load_state_dict(checkpoint["agent"])
        torch.set_rng_state(checkpoint["torch_rng"])
        start = int(checkpoint["iteration"])
    resolved = OmegaConf.to_container(cfg, resolve=True)
    save_text(OmegaConf.to_yaml(resolved), run_dir / "config.yaml")
    logger = RunLogger(run_dir, purge_step=agent.env_steps if checkpoint is not None else None)

    def save_checkpoint(iteration: int) -> None:
        state = {"agent": agent.state_dict(), "iteration": iteration, "config": resolved, "torch_rng": torch.get_rng_state()}
        save_torch(state, run_dir / CHECKPOINT)

    every = int(cfg.train.checkpoint_every)
    eval_kwargs = eval_settings(cfg, device)
    started = time.perf_counter()
    bar = tqdm(range(start, agent.num_iterations), initial=start, total=agent.num_iterations, disable=not cfg.progress, desc=f"{cfg.agent.name} {cfg.env.name}", unit="it", dynamic_ncols=True)
    for iteration in bar:
        metrics = agent.train_iteration()
        done = iteration + 1
        if done % int(cfg.train.log_every) == 0 or done == agent.num_iterations:
            logger.log(metrics, agent.env_steps)
            if "train/sum_utility" in metrics:
                bar.set_postfix(utility=f"{metrics['train/sum_utility']:.4g}", refresh=False)
        if cfg.eval.every and done % int(cfg.eval.every) == 0 and done < agent.num_iterations:
            logger.log(evaluate_agent(agent, env_cfg, **eval_kwargs), agent.env_steps)
        if done % every == 0 or done == agent.num_iterations:
            save_checkpoint(done)
    if start == agent.num_iterations:
        save_checkpoint(start)
    train_seconds = time.perf_counter() - started
    final = evaluate_agent(agent, env_cfg, **eval_kwargs)
    logger.log(final, agent.env_steps)
    logger.hparams(flat_hparams(cfg), {k: v for k, v in final.items() if k in ("eval/optimality", "eval/optimal_fraction")})
    logger.close()
    result = {
        "agent": cfg.agent.name,
        "env": cfg.env.name,
        "env_steps": agent.env_steps,
        "iterations": agent.num_iterations,
        "train_seconds": train_seconds,
        "total_seconds": time.perf_counter() - started,
        **final,
    }
    save_json(result, run_dir / "metrics.json")
    print(f"optimality {final['eval/optimality']:.4f} (min {final['eval/optimality_min']:.4f}) in {result['total_seconds']:.1f} s")
    print(run_dir)
    return run_dir


@hydra.main(config_path=config_dir(), config_name="config", version_base=None)
def main(cfg: DictConfig) -> None:
    try:
        train(cfg, HydraConfig.get().overrides.task)
    except (ValueError, FileNotFoundError) as err:
        raise SystemExit(f"error: {err}") from None


if __name__ == "__main__":
    main()
