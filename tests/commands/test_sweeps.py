"""Run directories: unique under concurrent starts; a sweep's job directories named from its overrides and seed."""

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from uavrl.cli import check_sweep, split_sweep_dir, sweep_jobs
from uavrl.experiment.io import claim_dir
from uavrl.experiment.training import hold_run_dir


def test_runs_started_at_once_get_their_own_directories(tmp_path, compose_cfg, monkeypatch):
    """16 threads released together claim and lock runs/<agent>/<env>/<timestamp>[-n]: 16 directories, each claimed
    once."""
    monkeypatch.chdir(tmp_path)
    cfg = compose_cfg("agent=random")
    start, claimed = threading.Barrier(16), []

    def start_a_run():
        start.wait()
        held = hold_run_dir(cfg)
        claimed.append(held.path)
        held.release()

    threads = [threading.Thread(target=start_a_run) for _ in range(16)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(set(claimed)) == 16 and all((tmp_path / path).is_dir() for path in claimed)
    assert {path.parent for path in claimed} == {Path("runs/random/paper")}


def test_processes_started_at_once_get_their_own_directories(tmp_path):
    """The same with real processes (each its own interpreter) released at one instant."""
    release = time.time() + 3.0
    probe = (
        "import sys, time; from uavrl.experiment.io import claim_dir\n"
        f"time.sleep(max(0.0, {release} - time.time()))\n"
        "print(claim_dir(sys.argv[1]))\n"
    )
    processes = [
        subprocess.Popen([sys.executable, "-c", probe, str(tmp_path / "run")], stdout=subprocess.PIPE, text=True)
        for _ in range(4)
    ]
    claimed = [process.communicate(timeout=60)[0].strip() for process in processes]
    assert sorted(claimed) == sorted(str(tmp_path / name) for name in ("run", "run-1", "run-2", "run-3"))


def test_claim_dir_skips_taken_names(tmp_path):
    assert claim_dir(tmp_path / "a") == tmp_path / "a"
    assert claim_dir(tmp_path / "a") == tmp_path / "a-1"
    assert claim_dir(tmp_path / "a") == tmp_path / "a-2"


def test_sweep_jobs_are_named_from_their_overrides_and_seed(tmp_path):
    """Readable (the overrides as typed, sorted), unique within the sweep, and the same for the same overrides."""
    overrides, sweep_dir = split_sweep_dir(
        ["-m", "agent=tabular,dqn", "scenario=paper_6x6", "seed=0,1", "progress=false", f"sweep_dir={tmp_path}/s"]
    )
    assert sweep_dir == tmp_path / "s" and all("sweep_dir" not in arg for arg in overrides)
    from hydra import compose, initialize_config_dir

    from uavrl.config import config_dir

    names = []
    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        for job in sweep_jobs(overrides):
            cfg = compose(config_name="config", overrides=job, return_hydra_config=True)
            names.append(f"{cfg.hydra.job.override_dirname}/seed={cfg.seed}")
    assert names == [
        "agent=tabular,scenario=paper_6x6/seed=0",
        "agent=tabular,scenario=paper_6x6/seed=1",
        "agent=dqn,scenario=paper_6x6/seed=0",
        "agent=dqn,scenario=paper_6x6/seed=1",
    ]


def test_a_sweep_that_would_overwrite_a_job_is_refused(tmp_path):
    (tmp_path / "agent=random" / "seed=1").mkdir(parents=True)
    check_sweep("config", ["agent=random", "seed=0"], tmp_path, None)
    with pytest.raises(FileExistsError, match="agent=random/seed=1 already exists"):
        check_sweep("config", ["agent=random", "seed=0,1"], tmp_path, None)


@pytest.mark.slow
def test_a_sweep_on_the_basic_launcher_writes_one_run_per_job_under_runs(tmp_path, run_sweep, tiny_tabular):
    runs = run_sweep(tmp_path, *tiny_tabular, "seed=0,1")
    (sweep_dir,) = (tmp_path / "runs" / "sweeps").iterdir()
    job = "agent.episodes=2,agent.runs=2,agent=tabular,env.max_steps=20,eval.num_starts=4"
    assert runs == [sweep_dir / job / "seed=0", sweep_dir / job / "seed=1"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]  # no multirun/ or outputs/ beside it
    results = [json.loads((run / "metrics.json").read_text()) for run in runs]
    assert results[0]["eval/optimality"] != results[1]["eval/optimality"]  # the seeds differ
