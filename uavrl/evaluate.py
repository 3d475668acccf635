"""Evaluate a saved agent: ``python -m uavrl.evaluate checkpoint=runs/tabular/paper/<stamp>``.

Rebuilds the agent from the checkpoint's own config, runs the shared greedy
evaluation (``eval.*`` settings may be overridden, e.g. ``eval.num_starts=100``),
prints the metrics as JSON and writes them to ``eval.json`` beside the checkpoint.
"""
from __future__ import annotations

import json
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from uavrl.agents import agent_class
from uavrl.config import config_dir, model_config
from uavrl.evaluation import evaluate_agent
from uavrl.io import save_json
from uavrl.train import CHECKPOINT, eval_settings, resolve_device


def load_agent(path, device="cpu"):
    """``(agent, saved config)`` from a ``checkpoint.pt`` or the run directory holding one."""
    path = Path(path)
    if path.is_dir():
        path = path / CHECKPOINT
    if not path.exists():
        raise FileNotFoundError(f"checkpoint={str(path)!r} does not exist: give a checkpoint.pt or a run directory written by uavrl.train")
    state = torch.load(path, map_location="cpu", weights_only=False)
    cfg = OmegaConf.create(state["config"])
    agent = agent_class(cfg.agent.name)(model_config(cfg), cfg, torch.device(device), int(cfg.seed))
    agent.load_state_dict(state["agent"])
    return agent, cfg


def evaluate_checkpoint(cfg: DictConfig) -> dict[str, float]:
    if not cfg.checkpoint:
        raise ValueError("checkpoint is not set: give checkpoint=<run dir or checkpoint.pt>")
    torch.set_num_threads(int(cfg.num_threads))
    device = resolve_device(cfg.device)
    agent, saved = load_agent(cfg.checkpoint, device)
    metrics = evaluate_agent(agent, model_config(saved), **eval_settings(cfg, device))
    out_dir = Path(cfg.checkpoint) if Path(cfg.checkpoint).is_dir() else Path(cfg.checkpoint).parent
    save_json(metrics, out_dir / "eval.json")
    return metrics


@hydra.main(config_path=config_dir(), config_name="config", version_base=None)
def main(cfg: DictConfig) -> None:
    try:
        print(json.dumps(evaluate_checkpoint(cfg), indent=2, sort_keys=True))
    except (ValueError, FileNotFoundError) as err:
        raise SystemExit(f"error: {err}") from None


if __name__ == "__main__":
    main()
