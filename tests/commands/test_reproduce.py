"""The reproduction commands on a tiny subset: table, findings, figures, TensorBoard."""

import contextlib
import json
import subprocess
import sys

import pytest
from PIL import Image
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from uavrl.reproduce import reproduce


def run_reproduce(command: str, tmp_path, *overrides: str) -> subprocess.CompletedProcess:
    """``python -m uavrl.reproduce <command>`` at a tiny budget (4 evaluation starts, no progress bar) into tmp_path."""
    settings = ["eval_starts=4", "progress=false", f"out_dir={tmp_path}", *overrides]
    return subprocess.run(
        [sys.executable, "-m", "uavrl.reproduce", command, *settings], capture_output=True, text=True, check=True
    )


def test_table2_and_figures_subset(tmp_path):
    common = ["grids=[2,3]", "runs=2", "episodes=4", "figure_grid=3"]
    table = run_reproduce("table2", tmp_path, *common)
    assert "| 2x2 | 16 | 576 | 120 |" in table.stdout and "| 3x3 | 81 | 2,916 | 800 |" in table.stdout
    assert "sum utility per episode rises" in table.stdout
    assert (
        "| return ratio | reach 0.999 U* | step ratio 0.999 |" in table.stdout
        and "against exact optimal control: return ratio" in table.stdout
    )
    rows = json.loads((tmp_path / "table2.json").read_text())
    assert [r["grid"] for r in rows] == [2, 3] and all(0 < r["optimality"] <= 1 for r in rows)
    assert list((tmp_path / "tensorboard" / "grid3x3").glob("events.out.tfevents.*"))
    run_reproduce("figures", tmp_path, *common)
    for name in ("fig3_sum_utility.png", "fig4_switches_moves.png", "fig5_steps_to_90.png"):
        with Image.open(tmp_path / name) as image:
            assert image.size[0] > 300


def test_unknown_command_and_grid_fail_clearly(tmp_path):
    bad = subprocess.run([sys.executable, "-m", "uavrl.reproduce", "table3"], capture_output=True, text=True)
    assert bad.returncode != 0 and "unknown command 'table3'" in bad.stderr
    bad = subprocess.run(
        [sys.executable, "-m", "uavrl.reproduce", "table2", "grids=[7]", "progress=false", f"out_dir={tmp_path}"],
        capture_output=True,
        text=True,
    )
    assert bad.returncode != 0 and "grid 7x7 is not in Table II" in bad.stderr


def test_state_with_tasks_widens_the_table(tmp_path):
    table = run_reproduce("table2", tmp_path, "grids=[2]", "runs=1", "episodes=2", "state_includes_tasks=true")
    assert "| 2x2 | 64 | 2,304 | 120 |" in table.stdout


@pytest.fixture
def reproduce_in(compose_cfg):
    """``reproduce_in(directory, *overrides)``: ``python -m uavrl.reproduce <overrides>`` in ``directory``, in this
    process (its learner is compiled)."""

    def run(directory, *overrides):
        cfg = compose_cfg(*overrides, "progress=false", config_name="reproduce")
        with contextlib.chdir(directory):
            reproduce(cfg)

    return run


def test_variants_do_not_overwrite_each_other(reproduce_in, tmp_path):
    tiny = ["grids=[2]", "episodes=2", "eval_starts=4"]
    for runs in (1, 2, 1):  # the last run repeats the first variant: its results are replaced, the other's stay
        reproduce_in(tmp_path, "command=table2", *tiny, f"runs={runs}")
    one, two = (tmp_path / "reproduction" / f"grids-2_runs-{runs}_episodes-2_eval_starts-4" for runs in (1, 2))
    assert [r["runs"] for r in json.loads((one / "table2.json").read_text())] == [1]
    assert [r["runs"] for r in json.loads((two / "table2.json").read_text())] == [2]
    assert len(EventAccumulator(str(one / "tensorboard" / "grid2x2")).Reload().Scalars("train/sum_utility")) == 2
    with pytest.raises(FileExistsError, match=r"out_dir=.* holds another variant \(runs=1 there, 3 here\)"):
        reproduce_in(tmp_path, "command=table2", *tiny, "runs=3", f"out_dir={one}")
    reproduce_in(tmp_path, "command=table2", "grids=[3]", *tiny[1:], f"out_dir={one}", "overwrite=true")
    assert sorted(p.name for p in one.glob("history_*.pt")) == ["history_3x3.pt"]


def test_figures_say_what_they_draw_and_write_no_table(reproduce_in, tmp_path, capsys):
    overrides = ["grids=[2]", "figure_grid=2", "runs=1", "episodes=3", f"out_dir={tmp_path}"]
    reproduce_in(tmp_path, "command=figures", *overrides)
    out, err = capsys.readouterr()
    assert "running the 2x2 protocol (1 runs x 3 episodes, no table) first" in err
    assert "Figs. 3-5 of 2x2, 2 UAVs, 1 runs x 3 episodes of 120 steps, seed 0, state: joint location" in out
    assert not (tmp_path / "table2.md").exists() and (tmp_path / "fig3_sum_utility.png").exists()
