"""The training command: run directory contents, resume, evaluation of a checkpoint, errors."""

import json
import os
import subprocess
import sys

import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

import uavrl.agents.tabular as tabular
from uavrl.experiment.evaluating import evaluate_checkpoint
from uavrl.train import train

SMALL = [
    "env.grid=[3,3]",
    "agent.episodes=6",
    "env.max_steps=100",
    "agent.runs=2",
    "train.checkpoint_every=2",
    "eval.num_starts=8",
    "progress=false",
]


def test_run_directory_has_everything(tmp_path, compose_cfg, episode_tags):
    make_cfg = compose_cfg
    run_dir = train(make_cfg(*SMALL, f"run_dir={tmp_path / 'run'}"))
    assert {"checkpoint.pt", "config.yaml", "metrics.json"} <= {p.name for p in run_dir.iterdir()}
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert 0 < metrics["eval/optimality"] <= 1 and metrics["env_steps"] == 600
    events = EventAccumulator(str(run_dir)).Reload()
    tags = set(events.Tags()["scalars"])
    assert episode_tags <= tags
    assert len(events.Scalars("train/sum_utility")) == 6


def test_periodic_evaluations_come_with_the_training_time_they_leave_out(tmp_path, compose_cfg, monkeypatch):
    """eval.every: each evaluation is logged with time/train_seconds and time/train_cpu_seconds, which grow by the
    training between evaluations and leave the evaluations out (here made to take 0.3 s each)."""
    import time

    import uavrl.agents.evaluation

    evaluate_agent = uavrl.agents.evaluation.evaluate_agent

    def slow_evaluation(*args, **kwargs):
        time.sleep(0.3)
        return evaluate_agent(*args, **kwargs)

    monkeypatch.setattr(uavrl.agents.evaluation, "evaluate_agent", slow_evaluation)
    run_dir = train(compose_cfg(*SMALL, "eval.every=2", f"run_dir={tmp_path / 'run'}"))
    events = EventAccumulator(str(run_dir)).Reload()
    wall = [e.value for e in events.Scalars("time/train_seconds")]
    cpu = [e.value for e in events.Scalars("time/train_cpu_seconds")]
    assert [e.step for e in events.Scalars("time/train_seconds")] == [200, 400, 600]  # iterations 2, 4 and the end
    assert wall == sorted(wall) and cpu == sorted(cpu) and 0 < cpu[0]
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["train_seconds"] == pytest.approx(wall[-1])
    assert metrics["train_cpu_seconds"] == pytest.approx(cpu[-1])
    assert metrics["total_seconds"] - metrics["train_seconds"] >= 0.6  # the two periodic evaluations' sleeps


def test_resume_after_a_kill_equals_an_uninterrupted_run(tmp_path, compose_cfg, interrupt_at):
    make_cfg = compose_cfg
    whole = train(make_cfg(*SMALL, f"run_dir={tmp_path / 'whole'}"))
    with interrupt_at(tabular.TabularAgent, 5), pytest.raises(KeyboardInterrupt):
        train(make_cfg(*SMALL, f"run_dir={tmp_path / 'killed'}"))
    assert torch.load(tmp_path / "killed" / "checkpoint.pt", weights_only=False)["iteration"] == 4
    train(make_cfg(*SMALL, f"resume={tmp_path / 'killed'}"), overrides=[f"resume={tmp_path / 'killed'}"])
    a = torch.load(whole / "checkpoint.pt", weights_only=False)["agent"]["q"]
    b = torch.load(tmp_path / "killed" / "checkpoint.pt", weights_only=False)["agent"]["q"]
    assert torch.equal(a, b)


def test_resume_refuses_conflicting_overrides(tmp_path, compose_cfg):
    make_cfg = compose_cfg
    train(make_cfg(*SMALL, f"run_dir={tmp_path / 'r'}"))
    with pytest.raises(ValueError, match="differs from the saved run"):
        train(make_cfg(*SMALL, "seed=3", f"resume={tmp_path / 'r'}"), overrides=["seed=3", f"resume={tmp_path / 'r'}"])
    with pytest.raises(FileNotFoundError, match="nothing does not exist"):
        train(make_cfg(*SMALL, f"resume={tmp_path / 'nothing'}"))


def test_evaluate_a_checkpoint(tmp_path, compose_cfg):
    make_cfg = compose_cfg
    run_dir = train(make_cfg(*SMALL, f"run_dir={tmp_path / 'r'}"))
    metrics = evaluate_checkpoint(make_cfg(f"checkpoint={run_dir}", "eval.num_starts=8"))
    saved = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["eval/optimality"] == pytest.approx(saved["eval/optimality"])
    assert json.loads((run_dir / "eval.json").read_text()) == metrics


def test_the_evaluate_command_prints_a_summary_and_json_on_request(tmp_path, compose_cfg, capsys):
    """``python -m uavrl.evaluate``: the run's agent and model, the headline metrics, the yardstick and where the
    file went, in words; ``print_json=true``: the metrics as JSON, as in the file."""
    from uavrl.evaluate import print_evaluation

    run_dir = train(compose_cfg(*SMALL, f"run_dir={tmp_path / 'r'}"))
    capsys.readouterr()
    print_evaluation(compose_cfg(f"checkpoint={run_dir}", "eval.num_starts=8"), [])
    lines = capsys.readouterr().out.splitlines()
    assert (
        lines[0] == f"evaluated tabular of the paper run {run_dir} on: 3x3 grid, 2 UAVs, layout 'line', channel 'paper'"
    )
    assert lines[1].startswith("optimality ") and lines[2].startswith("yardstick: return ratio ")
    assert lines[3].startswith(f"metrics: {run_dir / 'eval.json'} (all ") and len(lines) == 4
    print_evaluation(compose_cfg(f"checkpoint={run_dir}", "eval.num_starts=8", "print_json=true"), [])
    assert json.loads(capsys.readouterr().out) == json.loads((run_dir / "eval.json").read_text())


def test_a_baseline_says_it_does_not_train(tmp_path, compose_cfg, capsys):
    from uavrl.evaluate import print_evaluation

    run_dir = train(compose_cfg("agent=random", "env.grid=[3,3]", "eval.num_starts=4", f"run_dir={tmp_path / 'r'}"))
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("evaluated the random baseline (no training) on paper (3x3 grid, 2 UAVs, layout 'line'")
    assert "iterations" not in first and "trained" not in first
    print_evaluation(compose_cfg(f"checkpoint={run_dir}", "eval.num_starts=4"), [])
    assert capsys.readouterr().out.startswith(f"evaluated the random baseline (no training) of the paper run {run_dir}")


@pytest.mark.parametrize(
    "override, message",
    [
        ("env.grid=[0,3]", "grid=(0, 3) is invalid"),
        ("env.layout=spiral", "layout='spiral' is invalid"),
        ("env.num_uavs=5 env.grid=[10,10]", "env.num_uavs=5 is invalid: the team Q tables on 10x10"),
        ("device=cuda:7", "device='cuda:7' is not available"),
        ("agent.epsilon=2", "epsilon=2 is invalid"),
        ("train.steps_per_episode=50", "train.steps_per_episode is now env.max_steps: write env.max_steps=50"),
    ],
)
def test_bad_overrides_fail_with_one_line(override, message, tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "uavrl.train", *override.split(), "progress=false", f"run_dir={tmp_path}"],
        capture_output=True,
        text=True,
    )
    assert result.returncode != 0
    assert message in result.stderr
    assert result.stderr.strip().count("\n") == 0, result.stderr


@pytest.mark.slow  # two whole training commands
def test_the_train_command_keeps_torchrls_info_lines_out_unless_asked(tmp_path):
    """TorchRL logs each replay buffer it allocates at INFO; the commands lower that to WARNING, and a user's
    ``RL_LOGGING_LEVEL`` still wins."""
    argv = [sys.executable, "-m", "uavrl.train", "agent=dqn", "env.grid=[3,3]", "env.max_steps=4", "agent.worlds=2"]
    argv += ["agent.iterations=1", "agent.hidden=8", "eval.num_starts=2", "progress=false"]
    outputs = {}
    for level in (None, "INFO"):
        env = {k: v for k, v in os.environ.items() if k != "RL_LOGGING_LEVEL"} | (
            {"RL_LOGGING_LEVEL": level} if level else {}
        )
        result = subprocess.run([*argv, f"run_dir={tmp_path / str(level)}"], capture_output=True, text=True, env=env)
        assert result.returncode == 0, result.stderr[-2000:]
        outputs[level] = result.stdout + result.stderr
    assert "Initialized LazyTensorStorage" not in outputs[None]
    assert "Initialized LazyTensorStorage" in outputs["INFO"]
