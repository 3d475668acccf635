"""The reproduction commands on a tiny subset: table, findings, figures, TensorBoard."""
import json
import subprocess
import sys

from PIL import Image


def test_table2_and_figures_subset(tmp_path):
    common = ["grids=[2,3]", "runs=2", "episodes=4", "eval_starts=4", "progress=false", f"out_dir={tmp_path}", "figure_grid=3"]
    table = subprocess.run([sys.executable, "-m", "uavrl.reproduce", "table2", *common], capture_output=True, text=True, check=True)
    assert "| 2x2 | 16 | 576 | 120 |" in table.stdout and "| 3x3 | 81 | 2,916 | 800 |" in table.stdout
    assert "sum utility per episode rises" in table.stdout
    rows = json.loads((tmp_path / "table2.json").read_text())
    assert [r["grid"] for r in rows] == [2, 3] and all(0 < r["optimality"] <= 1 for r in rows)
    assert list((tmp_path / "tensorboard" / "grid3x3").glob("events.out.tfevents.*"))
    subprocess.run([sys.executable, "-m", "uavrl.reproduce", "figures", *common], capture_output=True, text=True, check=True)
    for name in ("fig3_sum_utility.png", "fig4_switches_moves.png", "fig5_steps_to_90.png"):
        with Image.open(tmp_path / name) as image:
            assert image.size[0] > 300


def test_unknown_command_and_grid_fail_clearly(tmp_path):
    bad = subprocess.run([sys.executable, "-m", "uavrl.reproduce", "table3"], capture_output=True, text=True)
    assert bad.returncode != 0 and "unknown command 'table3'" in bad.stderr
    bad = subprocess.run([sys.executable, "-m", "uavrl.reproduce", "table2", "grids=[7]", "progress=false", f"out_dir={tmp_path}"], capture_output=True, text=True)
    assert bad.returncode != 0 and "grid 7x7 is not in Table II" in bad.stderr


def test_state_with_tasks_widens_the_table(tmp_path):
    args = ["grids=[2]", "runs=1", "episodes=2", "eval_starts=4", "progress=false", f"out_dir={tmp_path}", "state_includes_tasks=true"]
    table = subprocess.run([sys.executable, "-m", "uavrl.reproduce", "table2", *args], capture_output=True, text=True, check=True)
    assert "| 2x2 | 64 | 2,304 | 120 |" in table.stdout
