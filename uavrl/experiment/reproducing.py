"""The reproduce command's body (``python -m uavrl.reproduce``, :mod:`uavrl.reproduce`): the paper's protocol run
with the compiled tabular learner (``table2``: Table II beside the paper's timings, with the final greedy optimality)
and Figs. 3-5 drawn from its per-episode data (``figures``); the protocol's settings and files are
:mod:`uavrl.experiment.protocol`'s."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numba
import torch
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from uavrl.agents.evaluation import evaluate_agent
from uavrl.agents.tabular import TabularAgent
from uavrl.agents.tabular.kernels import use_workqueue_threads
from uavrl.experiment.checkpoints import CheckpointError, ForeignObjects, read_torch
from uavrl.experiment.io import EVENTS, Manifest, quoted, save_json, save_text, save_torch
from uavrl.experiment.logger import RunLogger
from uavrl.experiment.plots import pyplot
from uavrl.experiment.protocol import (
    FIGURES,
    METRICS,
    PAPER_LEARNER,
    PAPER_SECONDS,
    YARDSTICK,
    claim,
    grid_model,
    output_dir,
    steps_per_episode,
)
from uavrl.experiment.runs import share_of_starts


def run_grid(size: int, cfg: DictConfig, out_dir: Path, manifest: Manifest) -> dict:
    """The protocol on a ``size x size`` grid: per-episode metrics ``[episodes, runs]``, timing, optimality.

    The curves go to TensorBoard (``out_dir/tensorboard/grid<size>x<size>``, replacing those of an earlier
    run of the same variant) and the per-episode metrics to ``out_dir/history_<size>x<size>.pt``.
    """
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


def run_reproduction(cfg: DictConfig) -> None:
    """Run ``cfg.command`` (``table2`` or ``figures``), once :func:`uavrl.reproduce.check_settings` passed.

    Args:
        cfg: the composed ``reproduce`` config.
    """
    torch.set_num_threads(int(cfg.num_threads))
    use_workqueue_threads()  # before numba launches its threads
    numba.set_num_threads(min(int(cfg.numba_threads) or numba.config.NUMBA_NUM_THREADS, numba.config.NUMBA_NUM_THREADS))
    (table2 if cfg.command == "table2" else figures)(cfg)
