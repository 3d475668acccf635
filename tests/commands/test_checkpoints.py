"""Checkpoints that survive damage and kills, and TensorBoard curves that stay whole across resumes."""

import os
import random
import shlex

import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.backend.event_processing.plugin_event_accumulator import EventAccumulator as PluginEventAccumulator

import uavrl.agents.tabular as tabular
from uavrl.experiment.checkpoints import CheckpointError
from uavrl.experiment.io import save_text
from uavrl.train import train

SMALL = ["env.grid=[3,3]", "agent.episodes=6", "env.max_steps=100", "agent.runs=2"]
SMALL += ["train.checkpoint_every=2", "eval.num_starts=8", "progress=false"]
CORRUPTIONS = {
    "truncated": lambda data: data[: len(data) // 2],
    "empty": lambda data: b"",
    "random bytes": lambda data: os.urandom(len(data)),
}


@pytest.fixture
def run(compose_cfg, interrupt_at):
    """``run(run_dir, *overrides, killed_at=None)``: train (or resume, when ``run_dir`` holds a checkpoint);
    ``killed_at``: interrupt that train_iteration call."""

    def train_or_resume(run_dir, *overrides, killed_at: int | None = None):
        with interrupt_at(tabular.TabularAgent, killed_at):
            try:
                if (run_dir / "checkpoint.pt").exists() or (run_dir / "checkpoint.prev.pt").exists():
                    train(compose_cfg(*SMALL, *overrides, f"resume={run_dir}"), overrides=[f"resume={run_dir}"])
                else:
                    train(compose_cfg(*SMALL, *overrides, f"run_dir={run_dir}"))
            except KeyboardInterrupt:
                assert killed_at is not None

    return train_or_resume


def load(path):
    return torch.load(path, weights_only=True)


@pytest.mark.parametrize("corruption", CORRUPTIONS)
def test_resume_falls_back_to_the_previous_checkpoint_and_ends_exactly(run, corruption, tmp_path, capsys):
    run(tmp_path / "whole")
    killed = tmp_path / "killed"
    run(killed, killed_at=5)  # checkpoints after iterations 2 (previous) and 4 (newest)
    assert load(killed / "checkpoint.prev.pt")["iteration"] == 2 and load(killed / "checkpoint.pt")["iteration"] == 4
    newest = killed / "checkpoint.pt"
    newest.write_bytes(CORRUPTIONS[corruption](newest.read_bytes()))
    capsys.readouterr()
    run(killed)
    warning = capsys.readouterr().err.strip()
    assert warning.count("\n") == 0 and "checkpoint.pt:" in warning, warning
    assert "resuming from checkpoint.prev.pt, iteration 2" in warning, warning
    assert torch.equal(load(tmp_path / "whole" / "checkpoint.pt")["agent"]["q"], load(newest)["agent"]["q"])
    assert load(killed / "checkpoint.prev.pt")["iteration"] == 4 and load(newest)["iteration"] == 6


def test_no_readable_checkpoint_is_one_line_naming_each_file(run, tmp_path):
    run(tmp_path, killed_at=5)
    (tmp_path / "checkpoint.pt").write_bytes(b"")
    garbage = random.Random(0)
    for _ in range(60):  # some random bytes make pickle's own message span lines
        (tmp_path / "checkpoint.prev.pt").write_bytes(garbage.randbytes(1000))
        with pytest.raises(CheckpointError) as err:
            run(tmp_path)
        message = str(err.value)
        assert "\n" not in message and f"resume={shlex.quote(str(tmp_path))}" in message, message
        assert "checkpoint.pt: empty file" in message and "checkpoint.prev.pt: not a torch file" in message, message


def test_a_damaged_newest_checkpoint_is_replaced_but_the_readable_previous_one_kept(run, tmp_path):
    run(tmp_path, killed_at=5)
    (tmp_path / "checkpoint.pt").write_bytes(b"")
    run(tmp_path, killed_at=3)  # resumes from iteration 2, writes iteration 4 over the damaged file, then dies
    assert load(tmp_path / "checkpoint.pt")["iteration"] == 4
    assert load(tmp_path / "checkpoint.prev.pt")["iteration"] == 2


def test_orphaned_temporary_files_are_removed_at_resume_and_left_alone_by_other_writes(run, tmp_path):
    """Only the run holding the directory's lock removes orphans: a write's temporary file may be another process's
    write in flight."""
    run(tmp_path, killed_at=3)
    orphan = tmp_path / ".checkpoint.pt.k1ll3d.tmp"  # what a kill during torch.save leaves
    orphan.write_bytes(os.urandom(1000))
    run(tmp_path, killed_at=1)  # resumes and dies before any write
    assert not orphan.exists()
    in_flight = tmp_path / ".notes.txt.abc.tmp"
    in_flight.write_text("half")
    save_text("whole", tmp_path / "notes.txt")
    assert in_flight.read_text() == "half" and (tmp_path / "notes.txt").read_text() == "whole"


@pytest.mark.parametrize("kills", [[], [3], [5], [7], [3, 3], [3, 1, 1, 2]], ids=str)
def test_tensorboard_curves_have_one_point_per_logged_step_after_resumes(run, kills, tmp_path):
    for killed_at in kills:
        run(tmp_path, "eval.every=2", killed_at=killed_at)
    run(tmp_path, "eval.every=2")
    events = EventAccumulator(str(tmp_path)).Reload()
    steps = {tag: [e.step for e in events.Scalars(tag)] for tag in events.Tags()["scalars"]}
    assert steps["train/sum_utility"] == [100, 200, 300, 400, 500, 600]
    assert steps["eval/optimality"] == steps["eval/optimal_fraction"] == [200, 400, 600]  # no step-0 point from hparams
    hparams = PluginEventAccumulator(str(tmp_path)).Reload().PluginTagToContent("hparams")
    assert "_hparams_/session_start_info" in hparams
