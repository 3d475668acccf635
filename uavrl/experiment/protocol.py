"""The paper's protocol as ``python -m uavrl.reproduce`` runs it (:mod:`uavrl.reproduce`), without torch: Table II's
steps and timings, a variant's settings, name and directory, and the files it writes there (claimed, recorded and
checked before anything is written or torch imported)."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from uavrl.agents.schema import TabularSchema
from uavrl.envs.config import make_config
from uavrl.envs.rules import shown
from uavrl.experiment.io import EVENTS, Manifest, make_dirs, quoted, read_regular_text, save_json
from uavrl.schema import ReproduceSchema

# Table II of the paper: steps per episode and seconds per episode (Python, Xeon 3.5 GHz)
PAPER_STEPS = {2: 120, 3: 800, 4: 2000, 5: 5000, 6: 12000, 8: 20000, 10: 30000}
PAPER_SECONDS = {2: 0.102628, 3: 0.762713, 4: 2.425558, 5: 8.757846, 6: 49.007077, 8: 146.936207, 10: 291.176670}
METRICS = ("sum_r_pu", "sum_r_se", "sum_utility", "task_switches", "moves", "steps_to_90")
YARDSTICK = ("return_ratio", "reach_999", "step_ratio_999", "reach_optimum")  # from the shared evaluation
COMMANDS = ("table2", "figures")
# the settings that change the results: one directory per combination
PROTOCOL = ("grids", "num_uavs", "runs", "episodes", "steps", "seed", "state_includes_tasks", "eval_starts")
OUTPUTS = ("variant.json", "table2.md", "table2.json", "history_*.pt", "fig*.png", "tensorboard")
REFUSAL = "give another out_dir, or overwrite=true to replace them"
EXPECTED_VARIANT = (
    "expected the JSON object of settings that reproduce writes there; give another out_dir, or remove it"
)
FIGURES = ("fig3_sum_utility.png", "fig4_switches_moves.png", "fig5_steps_to_90.png")
# the paper's learner (eqs. 9-10): the defaults of agent=tabular, whatever a command line or scenario gives it
PAPER_LEARNER = {
    name: getattr(TabularSchema, name)
    for name in ("name", "method", "alpha", "gamma", "epsilon", "shared_table", "backend")
}


def steps_per_episode(size: int, cfg: DictConfig) -> int:
    return int(cfg.steps or PAPER_STEPS[size])


def grid_model(size: int, cfg: DictConfig):
    """The model of the protocol on a ``size x size`` grid."""
    shape = dict(grid=(size, size), num_uavs=int(cfg.num_uavs), max_steps=steps_per_episode(size, cfg))
    return make_config("paper", **shape, state_includes_tasks=bool(cfg.state_includes_tasks))


def variant(cfg: DictConfig) -> dict:
    return {key: OmegaConf.to_container(cfg[key]) if key == "grids" else cfg[key] for key in PROTOCOL}


def variant_name(cfg: DictConfig) -> str:
    """``paper`` for the paper's settings (the defaults of :class:`~uavrl.schema.ReproduceSchema`), else the
    settings that differ."""
    paper = dataclasses.asdict(ReproduceSchema())
    changed = {key: value for key, value in variant(cfg).items() if value != paper[key]}
    return "_".join(f"{key}-{_in_name(value)}" for key, value in changed.items()) or "paper"


def _in_name(value) -> str:
    return "-".join(map(str, value)) if isinstance(value, list) else shown(value)


def output_dir(cfg: DictConfig) -> Path:
    return Path(cfg.out_dir) if cfg.out_dir else Path("reproduction") / variant_name(cfg)


def planned_files(cfg: DictConfig, out_dir: Path) -> list[Path]:
    """The files of fixed name that ``cfg.command`` writes into ``out_dir`` (TensorBoard's are named as written)."""
    grids = cfg.grids if cfg.command == "table2" else [cfg.figure_grid]
    files = [out_dir / "variant.json", *(out_dir / f"history_{size}x{size}.pt" for size in grids)]
    if cfg.command == "table2":
        return [*files, out_dir / "table2.md", out_dir / "table2.json"]
    return [*files, *(out_dir / name for name in FIGURES)]


def saved_variant(out_dir: Path) -> dict | None:
    """The settings ``out_dir/variant.json`` records, None without one; a ValueError naming it when it is no regular
    file or not the JSON object reproduce writes."""
    record = out_dir / "variant.json"
    if not os.path.lexists(record):
        return None
    try:
        saved = json.loads(read_regular_text(record))
    except json.JSONDecodeError as err:
        raise ValueError(f"{quoted(record)} is not valid JSON ({err}): {EXPECTED_VARIANT}") from None
    except (ValueError, OSError) as err:
        raise ValueError(f"{err}: {EXPECTED_VARIANT}") from None
    if not isinstance(saved, dict):
        raise ValueError(f"{quoted(record)} holds a JSON {type(saved).__name__}: {EXPECTED_VARIANT}")
    return saved


def written_here(out_dir: Path) -> Manifest:
    """The record of the files reproduce wrote into ``out_dir``.  A folder an earlier uavrl wrote (a variant.json
    and no record) is taken to hold reproduce's files under the names reproduce writes, and only those."""
    manifest = Manifest(out_dir, "out_dir")
    if not manifest.files and (out_dir / "variant.json").is_file() and not os.path.lexists(manifest.path):
        names = ("variant.json", "table2.md", "table2.json", "history_*x*.pt", *FIGURES, "tensorboard/grid*/" + EVENTS)
        manifest.files = {manifest._name(found) for name in names for found in out_dir.glob(name) if found.is_file()}
    return manifest


def claim(out_dir: Path, cfg: DictConfig) -> Manifest:
    """Make ``out_dir`` this variant's: with ``overwrite``, the files reproduce wrote for another variant go first
    (only those: a user's own files there stay)."""
    make_dirs(out_dir)
    manifest = written_here(out_dir)
    if cfg.overwrite and saved_variant(out_dir) != variant(cfg):
        manifest.remove_all()
    manifest.check_writable(planned_files(cfg, out_dir))
    record = out_dir / "variant.json"
    manifest.record(record)
    save_json(variant(cfg), record)
    return manifest
