"""A mission's batteries over time (its figure drawn with :mod:`uavrl.experiment.plots`).

:func:`battery_figure` draws a mission under
an energy model (docs/model.md, Energy and lifetime) from its per-step
batteries and statuses: one strip per UAV with its battery in % of the
capacity against the step, the steps it spends out of service shaded in its
status' colour (the rendered frames' colours: returning, charging, waiting,
out), and the events marked where they happen: it leaves service (on its
reserve or on ``return``), arrives at the base, is recharged, enters service
(a spare's first entry too); a strip on top counts the UAVs serving.
:func:`mission_history` plays a policy from the evaluation's first start
(world 0 of a batch seeded ``eval.seed``) and records them; ``python -m
uavrl.render <run>`` writes ``battery.png`` of the run's greedy policy so.

Example:
    >>> import numpy as np
    >>> from uavrl.envs.physics.energy import CHARGING, RETURNING, SERVING, WAITING
    >>> status = np.array([[SERVING, WAITING], [RETURNING, SERVING], [CHARGING, SERVING], [SERVING, SERVING]])
    >>> [(e.step, e.uav, e.kind) for e in mission_events(status)]
    [(1, 0, 'leaves'), (1, 1, 'enters'), (2, 0, 'arrives'), (3, 0, 'recharged'), (3, 0, 'enters')]
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from uavrl.agents.evaluation import mission_rollout
from uavrl.envs.env import UAVSpectrumEnv
from uavrl.envs.limits import evaluation_horizon
from uavrl.envs.physics.energy import CHARGING, OUT, RETURNING, SERVING, WAITING
from uavrl.envs.render import STATUS_COLOURS, STATUS_NAMES
from uavrl.experiment.plots import pyplot, save_figure

# the events of a UAV's mission: (its status before, its statuses after), marker, colour, legend
EVENT_STYLES = {
    "leaves": ("v", "#c0392b", "leaves service"),
    "arrives": ("s", "#6a3d9a", "arrives at the base"),
    "recharged": ("^", "#0e8a9a", "recharged"),
    "enters": ("o", "#1f4e9c", "enters service"),
}


@dataclass(frozen=True)
class MissionEvent:
    """UAV ``uav`` ``kind`` (a key of :data:`EVENT_STYLES`) at step ``step`` (the step that changed its status)."""

    step: int
    uav: int
    kind: str


def mission_events(status: np.ndarray) -> list[MissionEvent]:
    """The events of a mission from its statuses ``[T + 1, N]`` (the start, then after every step), in step order:
    a serving UAV that leaves (returning, or out at once), a returning one that arrives (charging, or out), a charging
    one recharged (waiting, or serving at once where a place is free), and one that enters service.

    Args:
        status: the statuses ``[T + 1, N]`` of :mod:`uavrl.envs.physics.energy` (``SERVING`` 0, ``RETURNING`` 1,
            ``OUT`` 2, ``CHARGING`` 3, ``WAITING`` 4).
    """
    before, after = np.asarray(status[:-1]), np.asarray(status[1:])
    kinds = {
        "leaves": (before == SERVING) & ((after == RETURNING) | (after == OUT)),
        "arrives": (before == RETURNING) & ((after == CHARGING) | (after == OUT)),
        "recharged": (before == CHARGING) & ((after == WAITING) | (after == SERVING)),
        "enters": ((before == WAITING) | (before == CHARGING)) & (after == SERVING),  # charged and straight back in
    }
    events = [MissionEvent(int(t) + 1, int(i), kind) for kind, where in kinds.items() for t, i in np.argwhere(where)]
    return sorted(events, key=lambda e: (e.step, e.uav, list(EVENT_STYLES).index(e.kind)))


def _runs(values: np.ndarray):
    """``(value, first, last)`` of each run of equal values of a 1-D array."""
    edges = np.flatnonzero(np.diff(values)) + 1
    starts, ends = np.r_[0, edges], np.r_[edges, len(values)] - 1
    return [(values[s], int(s), int(e)) for s, e in zip(starts, ends, strict=True)]


def battery_figure(battery: np.ndarray, status: np.ndarray, capacity: float, *, num_serving: int, title: str = ""):
    """The matplotlib figure of a mission's batteries ``[T + 1, N]`` (the model's units; ``capacity`` a full battery)
    and statuses ``[T + 1, N]`` (:mod:`uavrl.envs.physics.energy`'s), the start then every step (module doc): the top
    axes count the UAVs serving (``num_serving`` at most at once, ``env.num_uavs``), then one axes per UAV, its events
    drawn as one line of markers per kind whose ``gid`` is the kind (a key of :data:`EVENT_STYLES`).

    Args:
        battery: the batteries ``[T + 1, N]`` (J for ``rotary_wing``, the follow-up's units for ``follow_up``).
        status: the statuses ``[T + 1, N]``.
        capacity: a full battery, in the batteries' units.
        num_serving: the most UAVs in service at once.
        title: the figure's title.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    battery, status = np.asarray(battery, dtype=float), np.asarray(status)
    if battery.ndim != 2 or battery.shape != status.shape or len(battery) < 2:
        raise ValueError(
            f"battery_figure needs batteries and statuses of one shape [steps + 1, UAVs] over at least one step, "
            f"not {list(battery.shape)} and {list(status.shape)}"
        )
    T, N = battery.shape[0] - 1, battery.shape[1]
    steps, percent = np.arange(T + 1), 100 * battery / capacity
    figure, axes = pyplot().subplots(
        N + 1, 1, sharex=True, figsize=(10, 1.3 + 0.78 * (N + 1)), gridspec_kw={"height_ratios": [1.2] + [1] * N}
    )
    serving = (status == SERVING).sum(1)
    axes[0].step(steps, serving, where="mid", color="black", lw=1.2)
    axes[0].axhline(num_serving, color="0.5", ls=":", lw=1)
    axes[0].set_ylim(-0.3, status.shape[1] + 0.3)
    axes[0].set_yticks(sorted({0, num_serving}))
    axes[0].set_ylabel("serving", rotation=0, ha="right", va="center", fontsize=9)
    events = mission_events(status)
    for i, ax in enumerate(axes[1:]):
        for value, first, last in _runs(status[:, i]):
            if value != SERVING:  # out of service from the step it left to the step it is back
                ax.axvspan(first - 0.5, last + 0.5, color=STATUS_COLOURS[int(value)], alpha=0.22, lw=0)
        ax.plot(steps, percent[:, i], color=f"C{i % 10}", lw=1.4)
        for kind, (marker, colour, _) in EVENT_STYLES.items():
            at = [e.step for e in events if e.uav == i and e.kind == kind]
            size = 4.5 if kind == "enters" else 7  # over a recharge at the same step
            ax.plot(at, percent[at, i], marker, color=colour, ms=size, mec="white", mew=0.6, zorder=3, gid=kind)
        ax.set_ylim(-8, 112)
        ax.set_yticks([0, 50, 100])
        ax.tick_params(labelsize=8)
        ax.set_ylabel(f"UAV {i}", rotation=0, ha="right", va="center", fontsize=9)
        ax.grid(axis="y", color="0.9", lw=0.6)
    axes[-1].set_xlim(-0.5, T + 0.5)
    axes[-1].set_xlabel("step")
    handles = [Line2D([], [], ls="", marker=m, color=c, label=label) for m, c, label in EVENT_STYLES.values()]
    drawn = sorted({int(v) for v in np.unique(status)} - {SERVING})
    handles += [Patch(color=STATUS_COLOURS[v], alpha=0.35, label=STATUS_NAMES[v]) for v in drawn]
    axes[0].legend(handles=handles, ncol=len(handles), loc="lower center", bbox_to_anchor=(0.5, 1.02), fontsize=8,
                   frameon=False, handletextpad=0.3, columnspacing=1.2)  # fmt: skip
    figure.suptitle(
        f"{title}\nbattery (% of capacity) per UAV" if title else "battery (% of capacity) per UAV", fontsize=10
    )
    return figure


def mission_history(policy, cfg, horizon: int, seed: int, device="cpu") -> tuple[np.ndarray, np.ndarray]:
    """``(battery, status)`` ``[horizon + 1, N]`` of the mission ``policy`` (a TorchRL policy) plays from the
    evaluation's first start (world 0 of ``eval.seed=seed``) under ``cfg`` (an energy model) for ``horizon`` steps:
    the start, then after every step.

    Args:
        policy: a TorchRL policy of the model.
        cfg: the model, with an energy model.
        horizon: the mission's steps.
        seed: the evaluation's seed, whose first start is played.
        device: the torch device of the mission's world.
    """

    env = UAVSpectrumEnv(batch_size=1, config=cfg.replace(max_steps=horizon), seed=seed, device=device)
    start = env.reset()
    if hasattr(policy, "bind_env"):
        policy.bind_env(env)
    battery, status = [env.world.battery[0]], [env.world.status[0]]

    def record(env):
        battery.append(env.world.battery[0])
        status.append(env.world.status[0])

    with torch.no_grad():
        mission_rollout(env, policy, start, horizon, after_step=record)
    return torch.stack(battery).cpu().numpy(), torch.stack(status).cpu().numpy()


def mission_figure(policy, cfg, path: Path, *, horizon: int | None, seed: int, device="cpu", label="policy") -> Path:
    """``path`` written: :func:`battery_figure` of the mission ``policy`` plays from the evaluation's first start for
    ``horizon`` steps (None: the evaluation's, the whole mission) under ``cfg`` (an energy model); ``label`` names
    the policy in the title.

    Args:
        policy: a TorchRL policy of the model (``uavrl.load_policy`` returns one for a saved run).
        cfg: the model, with an energy model.
        path: the PNG file to write.
        horizon: the mission's steps; None: the evaluation's.
        seed: the evaluation's seed (``eval.seed``), whose first start is played.
        device: the torch device of the mission's world.
        label: the policy's name in the title.
    """

    horizon = horizon or evaluation_horizon(cfg)
    battery, status = mission_history(policy, cfg, horizon, seed, device)
    (L1, L2), spares = cfg.grid, f" + {cfg.num_spares} spares" if cfg.num_spares else ""
    size = f", {cfg.battery_wh:g} Wh" if cfg.energy == "rotary_wing" else ""
    recharge = "no recharging" if cfg.recharge_steps is None else f"recharged in {cfg.recharge_steps} steps"
    title = (
        f"{label} from the evaluation's first start (eval.seed={seed})\n"
        f"energy {cfg.energy}{size}, base {list(cfg.base)}, {L1}x{L2}, {cfg.num_uavs} serving{spares}, {recharge}"
    )
    figure = battery_figure(battery, status, cfg.step_energies.capacity, num_serving=cfg.num_uavs, title=title)
    return save_figure(figure, path)
