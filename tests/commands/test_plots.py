"""The battery-over-time figure of a mission (uavrl/experiment/missions.py) and ``python -m uavrl.render``
writing it."""

import os
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest
from matplotlib.colors import to_rgba

from uavrl.cli import compose_config
from uavrl.envs import make_config
from uavrl.envs.physics.energy import CHARGING, OUT, RETURNING, SERVING, WAITING
from uavrl.envs.render import STATUS_COLOURS
from uavrl.experiment.missions import battery_figure, mission_events, mission_history
from uavrl.experiment.plots import pyplot, save_figure
from uavrl.experiment.rendering import render_checkpoint
from uavrl.train import train

S, R, C, W, X = SERVING, RETURNING, CHARGING, WAITING, OUT  # X: out
# a hand-made mission of 12 steps, one row per step (the start first), one column per UAV:
# UAV 0 leaves at 4, arrives at 6, is recharged at 9 and waits, enters at 10;
# UAV 1 is a spare that waits until it enters at 4;
# UAV 2 leaves at 6, arrives at 7, is recharged at 10 and enters at once;
# UAV 3 (no recharging) leaves at 2, arrives at 3 and is out
STATUS = np.array(
    [
        [S, W, S, S],  # 0
        [S, W, S, S],
        [S, W, S, R],
        [S, W, S, X],
        [R, S, S, X],  # 4
        [R, S, S, X],
        [C, S, R, X],
        [C, S, C, X],
        [C, S, C, X],  # 8
        [W, S, C, X],
        [S, S, S, X],
        [S, S, S, X],
        [S, S, S, X],  # 12
    ]
)
EXPECTED = {  # UAV -> kind -> steps
    0: {"leaves": [4], "arrives": [6], "recharged": [9], "enters": [10]},
    1: {"leaves": [], "arrives": [], "recharged": [], "enters": [4]},
    2: {"leaves": [6], "arrives": [7], "recharged": [10], "enters": [10]},
    3: {"leaves": [2], "arrives": [3], "recharged": [], "enters": []},
}
# out of service: UAV -> (status, first step, last step)
SPANS = {0: [(R, 4, 5), (C, 6, 8), (W, 9, 9)], 1: [(W, 0, 3)], 2: [(R, 6, 6), (C, 7, 9)], 3: [(R, 2, 2), (X, 3, 12)]}


def hand_made_battery() -> np.ndarray:
    """Batteries of 100 units: -5 a step in service or flying home, kept while charging, full when charged."""
    battery = np.full(STATUS.shape, 100.0)
    for t in range(1, len(STATUS)):
        spending = (STATUS[t - 1] == S) | (STATUS[t - 1] == R)
        charged = (STATUS[t - 1] == C) & (STATUS[t] != C)
        battery[t] = np.where(charged, 100.0, battery[t - 1] - 5 * spending)
    return battery


def test_mission_events_are_the_status_changes_at_their_steps():
    events = mission_events(STATUS)
    for uav, kinds in EXPECTED.items():
        for kind, steps in kinds.items():
            assert [e.step for e in events if e.uav == uav and e.kind == kind] == steps, (uav, kind)
    assert len(events) == sum(len(steps) for kinds in EXPECTED.values() for steps in kinds.values())
    assert [e.step for e in events] == sorted(e.step for e in events)


def test_the_battery_figure_marks_every_event_on_its_uavs_line_and_shades_its_time_away(tmp_path):
    battery = hand_made_battery()
    figure = battery_figure(battery, STATUS, 100.0, num_serving=3, title="hand-made")
    serving_axes, *uav_axes = figure.axes
    assert len(uav_axes) == 4
    assert np.array_equal(serving_axes.lines[0].get_ydata(), (STATUS == S).sum(1))
    for uav, ax in enumerate(uav_axes):
        line = ax.lines[0]
        assert np.allclose(line.get_xdata(), np.arange(13)) and np.allclose(line.get_ydata(), battery[:, uav])
        for kind, steps in EXPECTED[uav].items():
            (marks,) = [mark for mark in ax.lines if mark.get_gid() == kind]
            assert list(marks.get_xdata()) == steps, (uav, kind)
            assert np.allclose(marks.get_ydata(), battery[steps, uav])  # on the line (% of a capacity of 100)
        spans = sorted(
            (patch.get_x(), patch.get_x() + patch.get_width(), patch.get_facecolor()) for patch in ax.patches
        )
        expected = [(first - 0.5, last + 0.5, status) for status, first, last in SPANS[uav]]
        assert [(lo, hi) for lo, hi, _ in spans] == [(lo, hi) for lo, hi, _ in expected], uav
        for (_, _, colour), (_, _, status) in zip(spans, expected, strict=True):
            assert np.allclose(colour[:3], to_rgba(STATUS_COLOURS[status])[:3])
    # recharged at 9: the battery is full from then on (the hand-made rule), and the figure draws it so
    assert uav_axes[0].lines[0].get_ydata()[9] == 100
    path = save_figure(figure, tmp_path / "battery.png")
    assert iio.imread(path).shape[:2] == (int(110 * (1.3 + 0.78 * 5)), 1100)


def test_the_battery_figure_refuses_histories_of_other_shapes():
    with pytest.raises(ValueError, match=r"one shape \[steps \+ 1, UAVs\] over at least one step, not \[13, 4\] and "):
        battery_figure(np.zeros((13, 4)), STATUS[:, :3], 1.0, num_serving=3)
    pyplot().close("all")


PERSISTENT = [
    "agent=oracle", "env.grid=[3,3]", "env.num_uavs=2", "env.energy=rotary_wing", "env.base=[-1,0]",
    "env.battery_wh=0.4", "env.recharge_steps=2", "env.num_spares=1", "eval.num_starts=2", "progress=false",
]  # fmt: skip


def test_the_render_command_writes_the_battery_figure_of_the_runs_mission(tmp_path, compose_cfg, monkeypatch):
    """End to end: a tiny persistent mission's run, rendered: battery.png is the figure of the mission the run's
    policy plays from the evaluation's first start, with its returns and recharges."""
    import uavrl.experiment.missions
    from uavrl.agents.baselines import OraclePolicy

    drawn = []

    def recorded(battery, status, capacity, **kwargs):  # what render hands the figure, checked against the mission
        drawn.append((np.asarray(battery), np.asarray(status), capacity, kwargs["num_serving"]))
        return battery_figure(battery, status, capacity, **kwargs)

    monkeypatch.setattr(uavrl.experiment.missions, "battery_figure", recorded)
    run_dir = train(compose_cfg(*PERSISTENT, f"run_dir={tmp_path / 'run'}"))
    written = render_checkpoint(
        compose_config("config", [f"checkpoint={run_dir}", "eval.video_starts=1", "eval.horizon=30"])
    )
    assert written[-1] == run_dir / "battery.png" and (run_dir / "video.gif") in written
    cfg = make_config("paper", grid=(3, 3), num_uavs=2, energy="rotary_wing", base=(-1, 0), battery_wh=0.4)
    cfg = cfg.replace(recharge_steps=2, num_spares=1)
    seed = int(compose_cfg().eval.seed)
    battery, status = mission_history(OraclePolicy(cfg), cfg, 30, seed)
    kinds = {e.kind for e in mission_events(status)}
    assert {"leaves", "arrives", "recharged", "enters"} <= kinds  # a mission of several lifetimes
    # the oracle's mission from the evaluation's first start, 30 steps, a full battery of 0.4 Wh, 2 serving at once
    ((battery_drawn, status_drawn, capacity, num_serving),) = drawn
    assert np.array_equal(battery_drawn, battery) and np.array_equal(status_drawn, status)
    assert capacity == pytest.approx(0.4 * 3600) and num_serving == 2 and battery.shape == (31, 3)
    assert iio.imread(run_dir / "battery.png").ndim == 3  # a picture was written


@pytest.mark.parametrize("chosen", ["pyplot first", "MPLBACKEND"])
def test_pyplot_keeps_the_backend_the_caller_chose(chosen):
    """A user's own backend survives uavrl's figures; a command alone (no choice made) draws without a display."""
    script = (
        "import matplotlib\n"
        + ("matplotlib.use('svg'); import matplotlib.pyplot\n" if chosen == "pyplot first" else "")
        + "from uavrl.experiment.plots import pyplot\n"
        "pyplot()\n"
        "print(matplotlib.get_backend())\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    if chosen == "MPLBACKEND":
        env["MPLBACKEND"] = "svg"
    chosen_backend = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    assert chosen_backend.stdout.strip() == "svg"
    alone = subprocess.run(
        [sys.executable, "-c", "from uavrl.experiment.plots import pyplot; print(pyplot().get_backend())"],
        env={k: v for k, v in os.environ.items() if k != "MPLBACKEND"},
        capture_output=True,
        text=True,
        check=True,
    )
    assert alone.stdout.strip().lower() == "agg"
