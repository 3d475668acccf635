"""The tabular commands run without TorchRL: the physics is a world layer with no TorchRL import (issue 14)."""

import subprocess
import sys

import pytest

HEAVY = ("torchrl", "tensordict")
# runs a command's module in this process, then prints which of HEAVY it imported
PROBE = """
import runpy, sys
sys.argv = sys.argv[1:]
try:
    runpy.run_module(sys.argv[0], run_name="__main__", alter_sys=True)
finally:
    print("IMPORTED", sorted({m.split(".")[0] for m in sys.modules} & {%s}))
""" % ", ".join(map(repr, HEAVY))


@pytest.mark.parametrize(
    "command",
    [
        ["uavrl.reproduce", "table2", "grids=[2]", "runs=2", "episodes=2", "eval_starts=4", "out_dir={out}"],
        ["uavrl.train", "agent=tabular", "env.grid=[3,3]", "agent.episodes=2", "env.max_steps=50", "run_dir={out}"],
    ],
    ids=["reproduce", "train-tabular"],
)
def test_tabular_commands_import_neither_torchrl_nor_tensordict(command, tmp_path):
    args = [arg.format(out=tmp_path / "out") for arg in command] + ["progress=false"]
    done = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "IMPORTED []" in done.stdout, done.stdout[-500:]


def test_the_probe_sees_torchrl_where_it_is_used(tmp_path):
    """The probe itself: a command that does use TorchRL (the DQN) is reported."""
    args = ["uavrl.train", "agent=dqn", "env.grid=[3,3]", "agent.iterations=1", "agent.worlds=2"]
    args += ["agent.learning_starts=1000", "eval.num_starts=2", "progress=false", f"run_dir={tmp_path / 'out'}"]
    done = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "IMPORTED ['tensordict', 'torchrl']" in done.stdout
