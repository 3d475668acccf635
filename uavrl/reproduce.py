"""Reproduce the paper: ``python -m uavrl.reproduce table2`` and ``python -m uavrl.reproduce figures``.

``table2`` runs the paper's protocol (Table II: 2 UAVs, per grid 10 runs x 200
episodes of 120 to 30,000 steps) with the compiled tabular learner and prints
the table beside the paper's timings, with the final greedy optimality.
``figures`` draws Figs. 3-5 for 6x6 (mean over runs, min-max band) as PNG from
the per-episode data that ``table2`` saved for the same settings (without any,
it runs that grid's protocol first, and writes no table).  Both also write the
curves to TensorBoard.

Overrides (Hydra): ``grids=[6] runs=3 episodes=50 seed=1``;
``state_includes_tasks=true`` learns over the full configuration instead of the
paper's joint location.  Each variant of the protocol writes to its own
directory: ``reproduction/paper`` for the paper's settings, else
``reproduction/<the settings that differ>`` (e.g.
``reproduction/grids-6_runs-3_episodes-50``).  ``out_dir=<dir>`` chooses the
directory; one that holds another variant is refused unless ``overwrite=true``,
which removes the files reproduce wrote there (listed in its ``.uavrl-written.json``) and nothing else: a file of
the same name that reproduce did not write is refused, never overwritten.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
import time
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from uavrl.agents.schema import TabularSchema
from uavrl.cli import run_command
from uavrl.envs.config import make_config
from uavrl.envs.rules import check, shown
from uavrl.experiment.io import (
    EVENTS,
    Manifest,
    make_dirs,
    quoted,
    read_regular_text,
    save_json,
    save_text,
    save_torch,
    special_kind,
)
from uavrl.experiment.runs import share_of_starts
from uavrl.schema import ReproduceSchema
from uavrl.settings import REPRODUCE_SETTINGS, check_reproduce_costs, check_typed

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
# how the model's options are typed on this command line
OPTION_SETTINGS = {"grid": "grids", "max_steps": "steps"}


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


def check_settings(cfg: DictConfig, overrides=None) -> None:
    """Every setting, and that the output directory holds no other variant, before anything heavy is imported
    (``overrides``: the command line's, so a refusal names what was typed)."""
    check(cfg, REPRODUCE_SETTINGS)
    check_typed(cfg, overrides, REPRODUCE_SETTINGS, ReproduceSchema)
    models = []
    for size in cfg.grids:
        if not cfg.steps and size not in PAPER_STEPS:
            reason = f"grid {size}x{size} is not in Table II ({sorted(PAPER_STEPS)}): also give steps=<per episode>"
            raise ValueError(f"grids={shown(list(cfg.grids))} is invalid: {reason}")
        models.append(grid_model(size, cfg))
    check_reproduce_costs(cfg, models, overrides)
    if cfg.command == "figures" and cfg.figure_grid not in cfg.grids:
        raise ValueError(f"figure_grid={cfg.figure_grid} is invalid: it must be one of grids={shown(list(cfg.grids))}")
    out_dir = output_dir(cfg)
    if os.path.lexists(out_dir) and not out_dir.is_dir():
        kind = special_kind(out_dir) or "a file"
        raise NotADirectoryError(f"out_dir={quoted(out_dir)} is {kind}, not a directory: give a new or existing folder")
    if not out_dir.exists():
        return
    manifest = written_here(out_dir)
    saved = saved_variant(out_dir)
    if not cfg.overwrite:
        if saved is not None and saved != variant(cfg):
            mine = variant(cfg)
            changed = [key for key in PROTOCOL if saved.get(key) != mine[key]]
            differences = ", ".join(f"{key}={shown(saved.get(key))} there, {shown(mine[key])} here" for key in changed)
            raise FileExistsError(f"out_dir={quoted(out_dir)} holds another variant ({differences}): {REFUSAL}")
        if saved is None and any(any(out_dir.glob(pattern)) for pattern in OUTPUTS):
            raise FileExistsError(f"out_dir={quoted(out_dir)} holds results of unknown settings: {REFUSAL}")
    manifest.check_writable(planned_files(cfg, out_dir))


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


def run_grid(size: int, cfg: DictConfig, out_dir: Path, manifest: Manifest) -> dict:
    """The protocol on a ``size x size`` grid: per-episode metrics ``[episodes, runs]``, timing, optimality.

    The curves go to TensorBoard (``out_dir/tensorboard/grid<size>x<size>``, replacing those of an earlier
    run of the same variant) and the per-episode metrics to ``out_dir/history_<size>x<size>.pt``.
    """
    import torch

    from uavrl.agents.evaluation import evaluate_agent
    from uavrl.agents.tabular import TabularAgent
    from uavrl.experiment.logger import RunLogger

    steps = steps_per_episode(size, cfg)
    model = grid_model(size, cfg)
    built = time.perf_counter()
    learner = {
        **PAPER_LEARNER,
        "memory_budget": cfg.memory_budget,
        "episodes": int(cfg.episodes),
        "runs": int(cfg.runs),
    }
    settings = OmegaConf.create({"agent": learner})
    agent = TabularAgent(model, settings, "cpu", int(cfg.seed))
    history = {k: torch.empty(int(cfg.episodes), int(cfg.runs), dtype=torch.float64) for k in METRICS}
    # an earlier run's points of this variant (steps from 1 on) are replaced
    log_dir = out_dir / "tensorboard" / f"grid{size}x{size}"
    before = set(log_dir.glob(EVENTS))
    logger = RunLogger(log_dir, resume_step=0)
    manifest.record(*(set(log_dir.glob(EVENTS)) - before))
    started = time.perf_counter()
    for episode in range(int(cfg.episodes)):
        agent.train_iteration()
        per_run = agent.last_episode
        for k in METRICS:
            history[k][episode] = per_run[k]
        logger.log({f"train/{k}": per_run[k].mean().item() for k in METRICS}, (episode + 1) * steps)
    learn_seconds = time.perf_counter() - started
    logger.close()
    record = {"history": history, "grid": size, "steps_per_episode": steps}
    record |= {key: cfg[key] for key in ("num_uavs", "runs", "episodes", "seed", "state_includes_tasks")}
    manifest.record(out_dir / f"history_{size}x{size}.pt")
    save_torch(record, out_dir / f"history_{size}x{size}.pt")
    evaluation = evaluate_agent(agent, model, num_starts=int(cfg.eval_starts))  # mean over runs, the yardstick's too
    return {
        "grid": size,
        "states": model.num_states,
        "q_size": model.num_states * model.num_joint_actions,
        "steps_per_episode": steps,
        "episodes": int(cfg.episodes),
        "runs": int(cfg.runs),
        "setup_seconds": started - built,
        "learn_seconds": learn_seconds,
        "seconds_per_episode": learn_seconds / (int(cfg.episodes) * int(cfg.runs)),
        "team_steps_per_second": int(cfg.episodes) * int(cfg.runs) * steps / learn_seconds,
        "optimality": evaluation["eval/optimality"],
        "optimality_min": evaluation["eval/optimality_min"],
        **{key: evaluation.get(f"eval/{key}") for key in YARDSTICK},
        "history": history,
    }


def table2_markdown(rows: list[dict], wall: float) -> str:
    lines = [
        "| grid | states | Q size | steps/episode | paper s/episode | ours s/episode | speedup | paper total "
        "| ours total | greedy U/U* (min) | return ratio | reach 0.999 U* | step ratio 0.999 |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        paper = PAPER_SECONDS.get(r["grid"])
        ours_total = r["learn_seconds"] + r["setup_seconds"]
        paper_total = paper * r["episodes"] * r["runs"] if paper else None
        speedup = f"{paper / r['seconds_per_episode']:,.0f}x" if paper else "-"
        lines.append(
            f"| {r['grid']}x{r['grid']} | {r['states']:,} | {r['q_size']:,} | {r['steps_per_episode']:,} | "
            f"{paper if paper else '-'} | {r['seconds_per_episode']:.2e} | {speedup} | "
            f"{_duration(paper_total) if paper_total else '-'} | {ours_total:.2f} s | {r['optimality']:.4f} "
            f"({r['optimality_min']:.4f}) | {_number(r.get('return_ratio'), '.3f')} "
            f"| {_number(r.get('reach_999'), '.2f')} | {_number(r.get('step_ratio_999'), '.2f')} |"
        )
    lines.append(
        f"\nWhole table: {wall:.1f} s wall "
        f"({sum(r['episodes'] * r['runs'] * r['steps_per_episode'] for r in rows):,} team steps with learning)."
    )
    return "\n".join(lines) + "\n"


def _number(value, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def _duration(seconds: float) -> str:
    for unit, size in (("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= 2 * size:
            return f"{seconds / size:.1f} {unit}"
    return f"{seconds:.0f} s"


def findings(history: dict, grid: int) -> list[str]:
    """The paper's claims about Figs. 3-5, checked on the first and last 10% of episodes."""
    n = max(1, history["sum_utility"].shape[0] // 10)

    def change(key):
        h = history[key].mean(1)
        return h[:n].mean().item(), h[-n:].mean().item()

    claims = [
        ("sum utility per episode rises", "sum_utility", +1),
        ("task switches fall", "task_switches", -1),
        ("moves fall", "moves", -1),
        ("steps to 90% of U* fall", "steps_to_90", -1),
    ]
    out = []
    for text, key, sign in claims:
        first, last = change(key)
        holds = (last - first) * sign > 0
        out.append(
            f"{grid}x{grid}: {text}: {'holds' if holds else 'does not hold'} (first {n} episodes {first:.4g}, last "
            f"{n} {last:.4g})"
        )
    return out


def yardstick_finding(row: dict) -> str:
    """What the greedy policies achieve against exact optimal control (the yardstick of ``uavrl.agents.evaluation``)."""
    grid = f"{row['grid']}x{row['grid']}"
    if row.get("return_ratio") is None:
        return f"{grid}: against exact optimal control: no exact values for this grid"
    return (
        f"{grid}: against exact optimal control: return ratio {row['return_ratio']:.3f} of the best possible, "
        f"0.999 U* reached from {share_of_starts(row['reach_999'])} of starts"
        + (f" in {row['step_ratio_999']:.2f}x the fewest steps" if row.get("step_ratio_999") is not None else "")
    )


def table2(cfg: DictConfig) -> list[dict]:
    from tqdm import tqdm

    out_dir = output_dir(cfg)
    manifest = claim(out_dir, cfg)
    manifest.record(out_dir / "table2.md", out_dir / "table2.json")
    rows = []
    started = time.perf_counter()
    for size in tqdm([int(g) for g in cfg.grids], desc="Table II", unit="grid", disable=not cfg.progress):
        rows.append(run_grid(size, cfg, out_dir, manifest))
    wall = time.perf_counter() - started
    table = table2_markdown(rows, wall)
    notes = [line for r in rows for line in findings(r["history"], r["grid"]) + [yardstick_finding(r)]]
    print(table)
    print("\n".join(notes))
    save_text(table + "\n" + "\n".join(f"- {n}" for n in notes) + "\n", out_dir / "table2.md")
    save_json(
        [{k: v for k, v in r.items() if k != "history"} | {"wall_seconds_whole_table": wall} for r in rows],
        out_dir / "table2.json",
    )
    print(f"results: {out_dir}")
    return rows


# what run_grid saves beside the per-episode metrics
HISTORY_ENTRIES = ("grid", "steps_per_episode", "num_uavs", "runs", "episodes", "seed", "state_includes_tasks")


def read_history(path: Path, size: int) -> dict:
    """The per-episode metrics that :func:`run_grid` saved to ``path``, read without running anything it holds.

    A damaged file, or one that uavrl did not write, is a one-line ValueError
    naming it and saying what to do.
    """
    import torch

    from uavrl.experiment.checkpoints import CheckpointError, ForeignObjects, read_torch

    again = f"delete it and run this command again (it then runs the {size}x{size} protocol first)"
    shown_path = quoted(path)
    try:
        record = read_torch(path)
    except ForeignObjects as err:
        refused = "it is not a uavrl file, or it was altered; refused, and nothing in it was run"
        raise ValueError(f"{shown_path}: {err}: {refused}; {again}") from None
    except CheckpointError as err:
        raise ValueError(f"{shown_path}: {err}: not a history file uavrl wrote, or a damaged one; {again}") from None
    history = record.get("history") if isinstance(record, dict) else None
    if not isinstance(history, dict):
        raise ValueError(f"{shown_path} is not a history file of this uavrl (no 'history'); {again}")
    missing = [key for key in HISTORY_ENTRIES if key not in record]
    if missing:
        raise ValueError(f"{shown_path} is not a history file of this uavrl (no {', '.join(missing)}); {again}")
    curves = [history.get(key) for key in METRICS]
    if not all(torch.is_tensor(c) and c.dim() == 2 and c.is_floating_point() for c in curves) or (
        len({c.shape for c in curves}) != 1
    ):
        what = f"its history is not the [episodes, runs] curves of {', '.join(METRICS)}"
        raise ValueError(f"{shown_path} is not a history file of this uavrl ({what}); {again}")
    return record


def figures(cfg: DictConfig) -> list[Path]:
    import torch

    from uavrl.experiment.plots import pyplot

    plt = pyplot()
    size = int(cfg.figure_grid)
    out_dir = output_dir(cfg)
    path = out_dir / f"history_{size}x{size}.pt"
    manifest = claim(out_dir, cfg)
    manifest.record(*(out_dir / name for name in FIGURES))
    if not path.exists():
        protocol = f"the {size}x{size} protocol ({cfg.runs} runs x {cfg.episodes} episodes, no table)"
        print(f"no {size}x{size} data in {out_dir}: running {protocol} first", file=sys.stderr)
        run_grid(size, cfg, out_dir, manifest)
    record = read_history(path, size)
    history = record["history"]
    episodes = torch.arange(1, history["sum_utility"].shape[0] + 1)
    state = "location and tasks" if record["state_includes_tasks"] else "joint location (the paper's)"
    episodes_of = f"{record['runs']} runs x {record['episodes']} episodes of {record['steps_per_episode']:,} steps"
    drawn = f"{size}x{size}, {record['num_uavs']} UAVs, {episodes_of}, seed {record['seed']}, state: {state}"

    def band(ax, key, label, color):
        h = history[key]
        ax.plot(episodes, h.mean(1), color=color, label=label)
        ax.fill_between(episodes, h.amin(1), h.amax(1), color=color, alpha=0.2, linewidth=0)

    specs = [
        (
            FIGURES[0],
            "Fig. 3: summation throughput per episode",
            "sum over steps (bit/s/Hz)",
            [
                ("sum_utility", "both networks (U)", "C0"),
                ("sum_r_pu", "primary (R_PU)", "C1"),
                ("sum_r_se", "emergency (R_SE)", "C2"),
            ],
        ),
        (
            FIGURES[1],
            "Fig. 4: task switches and moves per episode",
            "count (all UAVs, all steps)",
            [("task_switches", "task switches", "C3"), ("moves", "moves", "C4")],
        ),
        (
            FIGURES[2],
            "Fig. 5: steps until U first reaches 90% of U*",
            "steps",
            [("steps_to_90", "steps to 90% of U*", "C5")],
        ),
    ]
    written = []
    for name, title, ylabel, curves in specs:
        fig, ax = plt.subplots(figsize=(7, 4.2), dpi=110)
        for key, label, color in curves:
            band(ax, key, label, color)
        ax.set(title=f"{title} (mean over runs, band min-max)\n{drawn}", xlabel="episode", ylabel=ylabel)
        ax.title.set_fontsize(8)
        ax.grid(alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(out_dir / name)
        plt.close(fig)
        written.append(out_dir / name)
    print(f"Figs. 3-5 of {drawn}, from {path}:")
    print("\n".join(str(p) for p in written))
    return written


def reproduce(cfg: DictConfig, overrides=()) -> None:
    """``python -m uavrl.reproduce``: check the settings, then run ``cfg.command``."""
    check_settings(cfg, [o for o in overrides if not o.startswith("command=")] or None)
    import numba  # the heavy modules, once the settings are known to be good
    import torch

    from uavrl.agents.tabular.kernels import use_workqueue_threads

    torch.set_num_threads(int(cfg.num_threads))
    use_workqueue_threads()  # before numba launches its threads
    numba.set_num_threads(min(int(cfg.numba_threads) or numba.config.NUMBA_NUM_THREADS, numba.config.NUMBA_NUM_THREADS))
    (table2 if cfg.command == "table2" else figures)(cfg)


def cli() -> None:
    """``python -m uavrl.reproduce table2|figures [overrides]``: the command word becomes ``command=``."""
    if len(sys.argv) > 1 and "=" not in sys.argv[1] and not sys.argv[1].startswith("-"):
        command = sys.argv.pop(1)
        if command not in COMMANDS:
            raise SystemExit(f"error: unknown command {command!r}: use one of {', '.join(COMMANDS)}")
        sys.argv.append(f"command={command}")
    run_command("reproduce", reproduce, OPTION_SETTINGS)


if __name__ == "__main__":
    cli()
