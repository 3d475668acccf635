"""Interrupts, concurrent runs, kills and full disks: a run directory loses nothing and resumes exactly.

Signals and kills are sent to real processes where the test is about a process (its exit, its lock, its files);
a signal in the middle of an iteration is sent to this process, from inside ``train_iteration``.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shlex
import signal
import subprocess
import sys
import time

import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.backend.event_processing.event_file_loader import RawEventFileLoader

import uavrl.agents.tabular as tabular
import uavrl.experiment.io
import uavrl.experiment.training
from uavrl.agents.dqn import DQNAgent
from uavrl.cli import typed
from uavrl.experiment.io import quoted
from uavrl.experiment.rundir import HOLDER, Interrupted, RunDirectoryInUse
from uavrl.train import train

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

TABULAR = ["agent=tabular", "env.grid=[3,3]", "agent.episodes=6", "env.max_steps=100", "agent.runs=2"]
DQN = ["agent=dqn", "env.grid=[3,3]", "agent.iterations=6", "env.max_steps=8", "agent.worlds=8", "agent.hidden=16"]
DQN += ["agent.depth=1", "agent.batch_size=32", "agent.buffer_size=100", "agent.updates=2", "agent.learning_starts=16"]
COMMON = ["train.checkpoint_every=2", "eval.num_starts=4", "progress=false"]
# a tabular run of a few seconds that checkpoints every episode: long enough to be signalled or killed mid-way
LONG = ["agent=tabular", "env.grid=[3,3]", "agent.episodes=150", "env.max_steps=2000", "agent.runs=1"]
LONG += ["train.checkpoint_every=1", "eval.num_starts=4", "progress=false", "num_threads=1"]


def final_metrics(run_dir) -> dict:
    """``metrics.json`` without its timings, which no two runs share."""
    metrics = json.loads((run_dir / "metrics.json").read_text())
    return {k: v for k, v in metrics.items() if "seconds" not in k}


def iteration(run_dir, name="checkpoint.pt") -> int:
    return torch.load(run_dir / name, weights_only=False)["iteration"]


def temporary_files(run_dir) -> list[str]:
    return sorted(p.name for p in run_dir.glob(".*.tmp"))


@pytest.fixture
def signal_at(monkeypatch):
    """``with signal_at(AgentClass, n, signum): ...``: ``signum`` is sent to this process at the start of the n-th
    ``train_iteration`` call, which then runs to its end: a Ctrl-C or SIGTERM in the middle of an iteration."""

    @contextlib.contextmanager
    def signalled(agent_class, n: int, signum: int):
        original, calls = agent_class.train_iteration, []

        def signalled_iteration(self):
            calls.append(1)
            if len(calls) == n:
                os.kill(os.getpid(), signum)
            return original(self)

        monkeypatch.setattr(agent_class, "train_iteration", signalled_iteration)
        try:
            yield
        finally:
            monkeypatch.setattr(agent_class, "train_iteration", original)

    return signalled


def resume(compose_cfg, run_dir, *overrides):
    return train(compose_cfg(*overrides, f"resume={run_dir}"), overrides=[f"resume={run_dir}"])


@pytest.mark.parametrize(
    "settings, agent_class, signum",
    [(TABULAR, tabular.TabularAgent, signal.SIGINT), (DQN, DQNAgent, signal.SIGTERM)],
    ids=["tabular-SIGINT", "dqn-SIGTERM"],
)
def test_a_signal_mid_iteration_saves_that_iteration_and_the_resumed_run_ends_exactly(
    settings, agent_class, signum, compose_cfg, signal_at, tmp_path
):
    handlers = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)  # SIGINT is ignored under nohup
    whole = train(compose_cfg(*settings, *COMMON, f"run_dir={tmp_path / 'whole'}"))
    killed = tmp_path / "killed"
    with signal_at(agent_class, 3, signum), pytest.raises(Interrupted) as err:  # between the checkpoints 2 and 4
        train(compose_cfg(*settings, *COMMON, f"run_dir={killed}"))
    assert err.value.signum == signum
    assert err.value.__notes__ == [
        f"checkpoint.pt holds iteration 3 of 6; continue the run with: python -m uavrl.train resume={killed}"
    ]
    assert iteration(killed) == 3 and iteration(killed, "checkpoint.prev.pt") == 2
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == handlers  # the test's again
    resume(compose_cfg, killed, *settings, *COMMON)
    assert final_metrics(killed) == final_metrics(whole)
    a, b = (torch.load(d / "checkpoint.pt", weights_only=False) for d in (whole, killed))
    assert a["final"] == b["final"] and a["agent"].keys() == b["agent"].keys()
    if "q" in a["agent"]:
        assert torch.equal(a["agent"]["q"], b["agent"]["q"])


def test_a_signal_during_the_final_video_keeps_the_training_and_logs_the_evaluation_once(
    compose_cfg, monkeypatch, tmp_path
):
    import uavrl.experiment.video

    settings = [*TABULAR, *COMMON, "eval.video=true", "eval.video_starts=1", "eval.horizon=3"]
    run_dir, drawn = tmp_path / "run", uavrl.experiment.video.comparison_frames

    def signalled(*args, **kwargs):  # a Ctrl-C while the video of the trained policy is drawn
        os.kill(os.getpid(), signal.SIGINT)
        return drawn(*args, **kwargs)

    monkeypatch.setattr(uavrl.experiment.video, "comparison_frames", signalled)
    with pytest.raises(Interrupted) as err:
        train(compose_cfg(*settings, f"run_dir={run_dir}"))
    assert err.value.__notes__ == [
        f"checkpoint.pt holds iteration 6 of 6; continue the run with: python -m uavrl.train resume={run_dir}"
    ]
    monkeypatch.setattr(uavrl.experiment.video, "comparison_frames", drawn)
    resume(compose_cfg, run_dir, *settings)
    events = EventAccumulator(str(run_dir), size_guidance={"scalars": 0, "images": 0})
    events.Reload()
    steps = [event.step for event in events.Scalars("eval/optimality")]
    assert len(steps) == len(set(steps)) == 1 and len(events.Images("eval/video")) == 1


class SignalledFile:
    """A file that receives SIGINT at its third write: a second signal in the middle of torch's zip writer."""

    def __init__(self, file):
        self.file, self.writes = file, 0

    def write(self, data):
        self.writes += 1
        if self.writes == 3:
            os.kill(os.getpid(), signal.SIGINT)
        return self.file.write(data)

    def flush(self):
        self.file.flush()


@pytest.mark.parametrize("during", ["torch.save", "fsync"])
def test_a_second_signal_during_the_checkpoint_write_keeps_the_checkpoints_on_disk(
    during, compose_cfg, signal_at, monkeypatch, tmp_path
):
    whole = train(compose_cfg(*TABULAR, *COMMON, f"run_dir={tmp_path / 'whole'}"))
    killed = tmp_path / "killed"
    save, fsync, writes = torch.save, os.fsync, []

    def second_signal_in_save(obj, file, *args, **kwargs):
        writes.append(1)
        if len(writes) == 2:  # checkpoint 2, then the interrupt's checkpoint 3
            file.file = SignalledFile(file.file)
        return save(obj, file, *args, **kwargs)

    def second_signal_in_fsync(fd):
        fsync(fd)
        writes.append(1)
        if len(writes) == 4:  # config.yaml, the holder, checkpoint 2, then the interrupt's checkpoint 3
            os.kill(os.getpid(), signal.SIGINT)

    if during == "torch.save":
        monkeypatch.setattr(torch, "save", second_signal_in_save)
    else:
        monkeypatch.setattr(uavrl.experiment.io.os, "fsync", second_signal_in_fsync)
    with signal_at(tabular.TabularAgent, 3, signal.SIGTERM), pytest.raises(Interrupted) as err:
        train(compose_cfg(*TABULAR, *COMMON, f"run_dir={killed}"))
    monkeypatch.setattr(uavrl.experiment.io.os, "fsync", fsync)
    monkeypatch.setattr(torch, "save", save)
    assert err.value.signum == signal.SIGINT and "checkpoint.pt holds iteration 2 of 6" in err.value.__notes__[0]
    assert iteration(killed) == 2 and temporary_files(killed) == []
    resume(compose_cfg, killed, *TABULAR, *COMMON)
    assert final_metrics(killed) == final_metrics(whole)


def test_a_second_signal_while_the_run_stops_is_dropped_and_the_report_kept(
    compose_cfg, signal_at, monkeypatch, tmp_path
):
    report = uavrl.experiment.training.interrupted_note

    def second_signal_in_report(*args):
        os.kill(os.getpid(), signal.SIGINT)  # the process is already on its way out
        return report(*args)

    monkeypatch.setattr(uavrl.experiment.training, "interrupted_note", second_signal_in_report)
    with signal_at(tabular.TabularAgent, 3, signal.SIGTERM), pytest.raises(Interrupted) as err:
        train(compose_cfg(*TABULAR, *COMMON, f"run_dir={tmp_path / 'run'}"))
    assert err.value.signum == signal.SIGTERM and "checkpoint.pt holds iteration 3 of 6" in err.value.__notes__[0]


def test_a_signal_before_training_removes_the_run_directory_it_made(compose_cfg, monkeypatch, tmp_path):
    build = tabular.TabularAgent.__init__

    def signalled_build(self, *args):
        os.kill(os.getpid(), signal.SIGINT)
        build(self, *args)

    monkeypatch.setattr(tabular.TabularAgent, "__init__", signalled_build)
    with pytest.raises(Interrupted) as err:
        train(compose_cfg(*TABULAR, *COMMON, f"run_dir={tmp_path / 'new'}"))
    assert err.value.__notes__ == ["stopped before the first checkpoint, nothing saved"]
    assert not (tmp_path / "new").exists()


def test_a_failure_after_start_up_removes_only_a_run_directory_it_made(compose_cfg, monkeypatch, tmp_path):
    def fails(self):
        raise RuntimeError("the first iteration failed")

    monkeypatch.setattr(tabular.TabularAgent, "train_iteration", fails)
    with pytest.raises(RuntimeError):
        train(compose_cfg(*TABULAR, *COMMON, f"run_dir={tmp_path / 'made' / 'here'}"))
    assert not (tmp_path / "made" / "here").exists()
    existing = tmp_path / "existing"
    existing.mkdir()
    (existing / "notes.txt").write_text("mine")
    with pytest.raises(RuntimeError):
        train(compose_cfg(*TABULAR, *COMMON, f"run_dir={existing}"))
    assert (existing / "notes.txt").read_text() == "mine" and not (existing / HOLDER).exists()
    monkeypatch.chdir(tmp_path)  # the default runs/<agent>/<env>/<timestamp>
    with pytest.raises(RuntimeError):
        train(compose_cfg(*TABULAR, *COMMON))
    assert not (tmp_path / "runs").exists()  # nor the folders made for it


def test_a_refused_late_setting_leaves_no_run_directory(tmp_path):
    result = subprocess.run(
        # refused once the agent is built: the DQN's joint head for 5 UAVs
        [sys.executable, "-m", "uavrl.train", "agent=dqn", "agent.head=joint", "env.num_uavs=5", "progress=false"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert result.returncode == 1 and result.stderr.startswith("error: "), result.stderr
    assert result.stderr.strip().count("\n") == 0, result.stderr
    assert "num_uavs=5" in result.stderr and list(tmp_path.iterdir()) == []


def replaced(settings: list[str], overrides) -> list[str]:
    """``settings`` without those ``overrides`` set again (a setting typed twice is refused)."""
    keys = {override.split("=", 1)[0] for override in overrides}
    return [setting for setting in settings if setting.split("=", 1)[0] not in keys]


def start(run_dir, *overrides, cwd=None) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "uavrl.train", *replaced(LONG, overrides), *overrides, f"run_dir='{run_dir}'"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=cwd,
    )


def wait_for(path, process: subprocess.Popen, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, f"no {path} after {timeout} s"
        time.sleep(0.02)


@pytest.fixture(scope="module")
def long_run(tmp_path_factory):
    """The uninterrupted LONG run, for comparison (trained once for the module)."""
    run_dir = tmp_path_factory.mktemp("whole") / "run"
    subprocess.run([sys.executable, "-m", "uavrl.train", *LONG, f"run_dir={run_dir}"], check=True, capture_output=True)
    return run_dir


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signalled_process_prints_a_resume_command_that_pastes_and_ends_exactly(signum, long_run, tmp_path):
    run_dir = tmp_path / "my runs é" / "run"  # a space and a non-ASCII letter: the printed command must paste
    process = start(run_dir)
    wait_for(run_dir / "checkpoint.prev.pt", process)
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signum, stderr
    notice, last = stderr.strip().splitlines()
    assert notice.startswith(f"{signal.Signals(signum).name}: finishing iteration "), stderr
    assert last.startswith("interrupted: checkpoint.pt holds iteration ") and " of 150; " in last, stderr
    command = last.split("continue the run with: ")[1]
    assert command == f"python -m uavrl.train {typed('resume', run_dir)}"
    assert 2 <= iteration(run_dir) < 150 and temporary_files(run_dir) == []
    argv = shlex.split(command)
    subprocess.run([sys.executable, *argv[1:]], check=True, capture_output=True)
    assert final_metrics(run_dir) == final_metrics(long_run)


@pytest.mark.slow
def test_a_second_signal_right_after_the_first_leaves_a_run_that_resumes_exactly(long_run, tmp_path):
    run_dir = tmp_path / "run"
    process = start(run_dir)
    wait_for(run_dir / "checkpoint.prev.pt", process)
    process.send_signal(signal.SIGTERM)
    assert process.stderr.readline().startswith("SIGTERM: finishing iteration ")
    process.send_signal(signal.SIGTERM)  # lands in the iteration's end, the checkpoint's write or after it
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signal.SIGTERM and "continue the run with" in stderr, stderr
    subprocess.run([sys.executable, "-m", "uavrl.train", f"resume={run_dir}"], check=True, capture_output=True)
    assert final_metrics(run_dir) == final_metrics(long_run)
    assert temporary_files(run_dir) == []  # what a cut write left (if anything), the resumed run removed


@pytest.mark.slow
def test_one_process_per_run_directory_and_a_killed_holder_does_not_block(compose_cfg, tmp_path):
    run_dir = tmp_path / "run"
    process = start(run_dir, "agent.episodes=5000")  # killed long before its end
    try:
        wait_for(run_dir / "checkpoint.prev.pt", process)
        holder = (run_dir / HOLDER).read_text().strip()
        assert holder.startswith(f"pid {process.pid} on ")
        with pytest.raises(RunDirectoryInUse) as err:
            train(compose_cfg(*LONG, f"resume={run_dir}"), overrides=[f"resume={run_dir}"])
        assert str(err.value) == (
            f"resume={run_dir} is in use by another uavrl process ({holder}): wait for it to end, or give another "
            "directory"
        )
    finally:
        process.kill()  # kill -9: the operating system releases its lock
        process.wait()
    orphan = run_dir / ".checkpoint.pt.k1ll3d.tmp"
    orphan.write_bytes(b"half a checkpoint")
    with pytest.raises(ValueError, match="differs from the saved run"):  # refused, but it held the directory first
        train(compose_cfg(*LONG, "seed=5", f"resume={run_dir}"), overrides=["seed=5", f"resume={run_dir}"])
    assert not orphan.exists() and not (run_dir / HOLDER).exists()


def test_a_new_run_into_a_directory_another_process_holds_is_refused_at_once(compose_cfg, tmp_path):
    run_dir = tmp_path / "run"
    process = start(run_dir, "agent.episodes=5000", "train.checkpoint_every=5000")  # holds it, saves nothing
    try:
        wait_for(run_dir / HOLDER, process)
        with pytest.raises(RunDirectoryInUse, match=f"^run_dir={run_dir} is in use by another uavrl process \\(pid"):
            train(compose_cfg(*TABULAR, *COMMON, f"run_dir={run_dir}"))
        # refused without waiting for the holder (a lock that waited would return only when it ended); how fast, on an
        # idle machine, is a benchmark's figure (benchmarks/hostile_api.py), not a test's
        assert process.poll() is None
    finally:
        process.kill()
        process.wait()
    train(compose_cfg(*TABULAR, *COMMON, f"run_dir={run_dir}"))  # the killed holder's lock went with it
    assert (run_dir / "metrics.json").exists()


def scalars(run_dir) -> dict[str, list[tuple[int, float]]]:
    events = EventAccumulator(str(run_dir)).Reload()
    return {
        tag: [(e.step, e.value) for e in events.Scalars(tag)]
        for tag in events.Tags()["scalars"]
        if not tag.startswith("time/")  # seconds differ between any two runs
    }


def raw_points(run_dir) -> int:
    """Scalar points in the event files, as a reader that ignores TensorBoard's purges counts them."""
    files = sorted(run_dir.glob("events.out.tfevents.*"))
    return sum(len(event.summary.value) for f in files for event in _events(f) if event.summary.value)


def _events(path):
    from tensorboard.compat.proto import event_pb2

    return [event_pb2.Event.FromString(record) for record in RawEventFileLoader(str(path)).Load()]


@pytest.mark.slow
def test_tensorboard_curves_after_a_kill_and_resume_equal_the_uninterrupted_ones(compose_cfg, long_run, tmp_path):
    run_dir = tmp_path / "run"
    logged_twice = 0
    for kill in range(2):  # killed twice, the second time in the resumed run
        process = start(run_dir, "train.checkpoint_every=10") if kill == 0 else resume_process(run_dir)
        before = iteration(run_dir) if kill else 0
        while not (run_dir / "checkpoint.pt").exists() or iteration(run_dir) < before + 10:
            assert process.poll() is None, process.communicate()
            time.sleep(0.01)
        time.sleep(0.1)  # episodes logged after the checkpoint, which the resumed run logs again
        process.kill()
        process.wait()
        last = iteration(run_dir) * 2000  # the checkpoint's step
        logged_twice += sum(e.step > last for f in run_dir.glob("events.out.tfevents.*") for e in _events(f))
    assert logged_twice > 0  # the kills left points after the checkpoint
    resume(compose_cfg, run_dir, *LONG)
    curves, whole = scalars(run_dir), scalars(long_run)
    assert curves.keys() == whole.keys()
    for tag, points in curves.items():
        steps = [step for step, _ in points]
        assert steps == sorted(set(steps)), tag  # one point per step
        assert points == whole[tag], tag
    assert raw_points(run_dir) == raw_points(long_run)  # also for readers that ignore TensorBoard's purges


def resume_process(run_dir) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "uavrl.train", f"resume={run_dir}", "progress=false"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


class FullDisk:
    def write(self, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def flush(self):
        pass


def test_a_full_disk_during_a_checkpoint_names_the_file_and_keeps_the_checkpoints(compose_cfg, monkeypatch, tmp_path):
    save, calls = torch.save, []

    def disk_fills_at_the_second_checkpoint(obj, file, *args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            file.file = FullDisk()  # the write torch's zip writer makes fails as a full disk's does
        return save(obj, file, *args, **kwargs)

    monkeypatch.setattr(torch, "save", disk_fills_at_the_second_checkpoint)
    with pytest.raises(OSError) as err:
        train(compose_cfg(*TABULAR, *COMMON, f"run_dir={tmp_path}"))
    assert str(err.value) == (
        f"could not write {quoted(tmp_path / 'checkpoint.pt')}: No space left on device; the checkpoints already "
        f"there are unchanged: make room, then continue the run with: python -m uavrl.train resume={tmp_path}"
    )
    assert iteration(tmp_path) == 2 and temporary_files(tmp_path) == []


@pytest.fixture
def small_disk(tmp_path):
    """A 1 MB tmpfs at ``tmp_path / "disk"`` (skips where mounting is not permitted)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(disk)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    yield disk
    subprocess.run(["umount", str(disk)], check=True)


@pytest.mark.slow
def test_a_real_full_disk_names_the_file_and_an_already_full_one_leaves_no_run_directory(small_disk):
    # a DQN whose replay buffer (100,000 compact transitions, ~2.5 MB) does not fit the 1 MB disk
    larger = ["agent.buffer_size=100000", "agent.iterations=4"]
    big = [*replaced(DQN, larger), *larger, *COMMON]
    result = subprocess.run(
        [sys.executable, "-m", "uavrl.train", *big, f"run_dir={small_disk / 'run'}"], capture_output=True, text=True
    )
    assert result.returncode == 1 and result.stderr.count("\n") == 1, result.stderr
    file = small_disk / "run" / "checkpoint.pt"
    assert result.stderr.startswith(f"error: could not write {quoted(file)}: No space left on device"), result.stderr
    assert temporary_files(small_disk / "run") == []
    fd = os.open(small_disk / "filler", os.O_WRONLY | os.O_CREAT)
    with contextlib.suppress(OSError):
        while True:
            os.write(fd, b"\0" * 4096)
    os.close(fd)
    result = subprocess.run(
        [sys.executable, "-m", "uavrl.train", *TABULAR, *COMMON, "run_dir=new"],
        capture_output=True,
        text=True,
        cwd=small_disk,
    )
    assert result.returncode == 1 and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith("error: could not write new/") and "No space left on device" in result.stderr
    assert not (small_disk / "new").exists()


def test_a_resume_refused_for_want_of_a_checkpoint_still_removes_a_killed_write(compose_cfg, tmp_path):
    (tmp_path / "config.yaml").write_text("agent: {name: tabular}\n")
    orphan = tmp_path / ".checkpoint.pt.k1ll3d.tmp"  # a SIGKILL during the first checkpoint's write
    orphan.write_bytes(b"half a checkpoint")
    with pytest.raises(FileNotFoundError, match="no checkpoint.pt"):
        resume(compose_cfg, tmp_path, *TABULAR)
    assert not orphan.exists()


def test_run_dir_that_is_a_file_is_refused_as_a_file(tmp_path, compose_cfg):
    file = tmp_path / "notes.txt"
    file.write_text("mine")
    with pytest.raises(NotADirectoryError, match=f"^run_dir={file} is a file, not a directory: give a directory$"):
        train(compose_cfg(*TABULAR, *COMMON, f"run_dir={file}"))
    assert file.read_text() == "mine"


def test_the_end_of_a_run_prints_commands_that_paste(compose_cfg, tmp_path, capsys):
    run_dir = tmp_path / "a run"
    train(compose_cfg(*TABULAR, *COMMON, f"run_dir={run_dir}"))
    out = capsys.readouterr().out
    assert f"tensorboard --logdir '{run_dir}'" in out
    assert f"evaluate it again: python -m uavrl.evaluate {typed('checkpoint', run_dir)}" in out


def test_a_write_after_one_cut_short_between_its_renames_keeps_both_checkpoints(tmp_path):
    newest, previous = tmp_path / "checkpoint.pt", tmp_path / "checkpoint.prev.pt"
    uavrl.experiment.io.save_torch({"iteration": 1}, newest)
    os.link(newest, previous)  # what a write stopped after keeping the previous checkpoint leaves
    uavrl.experiment.io.save_torch({"iteration": 2}, newest, previous=previous)
    assert iteration(tmp_path) == 2 and iteration(tmp_path, previous.name) == 1
    assert temporary_files(tmp_path) == []
