"""A run directory's files are accepted only as that run's own.

Another run's checkpoint copied or linked into a run directory (another agent, network, model or seed than its
``config.yaml`` records), a ``config.yaml`` edited to another run, a link out of the directory or a file of a run that
is a directory or a FIFO: ``train resume=``, ``evaluate`` and ``render`` refuse each in one line naming the file,
before anything is written, and every file of the run is byte for byte as it was.  The commands run in this process
(``command_exit``, tests/conftest.py).
"""

from __future__ import annotations

import hashlib
import json
import os
import shlex
import shutil
from pathlib import Path

import pytest
import torch
import yaml

from uavrl.experiment.checkpoints import NotThisRun
from uavrl.experiment.saved import load_run_checkpoint

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

TINY = ["env.grid=[3,3]", "env.max_steps=10", "eval.num_starts=2", "progress=false", "train.checkpoint_every=1"]
TABULAR = ["agent=tabular", "agent.episodes=2", "agent.runs=2"]
DQN = ["agent=dqn", "agent.iterations=2", "agent.worlds=2", "agent.hidden=16", "agent.updates=1"]
DQN += ["agent.learning_starts=0", "agent.batch_size=8"]
RUNS = {
    "tabular": TABULAR,
    "seed1": [*TABULAR, "seed=1"],
    "grid4": [*TABULAR, "env.grid=[4,4]"],
    "dqn": DQN,
    "dqn_set": [*DQN, "agent.network=set"],
}
COMMANDS = {
    "resume": "train resume={run}",
    "evaluate": "evaluate checkpoint={run} eval.horizon=3",
    "render": "render {run} eval.horizon=3 eval.video_starts=1",
}


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """Finished tiny runs, each with both checkpoints (one every iteration)."""
    from uavrl.cli import compose_config
    from uavrl.train import train

    root = tmp_path_factory.mktemp("runs")
    return {name: train(compose_config("config", [*TINY, *o, f"run_dir={root / name}"])) for name, o in RUNS.items()}


def files_of(run: Path) -> dict[str, str]:
    """Every entry under ``run`` (hidden ones too): a file's SHA-256, a link's target, a FIFO or folder as such."""
    found = {}
    for path in sorted(run.rglob("*")):
        name = path.relative_to(run).as_posix()
        if path.is_symlink():
            found[name] = f"link to {os.readlink(path)}"
        elif path.is_file():
            found[name] = hashlib.sha256(path.read_bytes()).hexdigest()
        else:
            found[name] = "folder" if path.is_dir() else "special"
    return found


def copy_of(runs, name: str, where: Path) -> Path:
    run = where / f"copy of {name}"  # a space: the messages quote paths
    shutil.copytree(runs[name], run, symlinks=True)
    return run


def replace(path: Path, by) -> None:
    """``path`` replaced by a copy of the file ``by``, a symbolic link (``("link", target)``) or a FIFO."""
    path.unlink(missing_ok=True)
    if by == "fifo":
        os.mkfifo(path)
    elif isinstance(by, tuple):
        path.symlink_to(by[1])
    else:
        shutil.copyfile(by, path)


def edited_config(run: Path, **settings) -> None:
    """``config.yaml`` with ``settings`` (``agent__name="dqn"``: agent.name) changed, as a user's editor saves it."""
    saved = yaml.safe_load((run / "config.yaml").read_text())
    for key, value in settings.items():
        *sections, name = key.split("__")
        place = saved
        for section in sections:
            place = place[section]
        place[name] = value
    (run / "config.yaml").write_text(yaml.safe_dump(saved))


def refused(command_exit, command: str, run: Path, cwd: Path) -> str:
    """The one error line of ``command`` on ``run``; every file of the run unchanged by it."""
    before = files_of(run)
    error = command_exit([word.format(run=run) for word in COMMANDS[command].split()], cwd)
    assert isinstance(error, str) and error.startswith("error: ") and "\n" not in error, error
    assert files_of(run) == before, "a refused command changed the run's files"
    assert list(cwd.iterdir()) == [], "a refused command wrote files"
    return error


def q(path) -> str:
    return shlex.quote(str(path))


def setting(command: str) -> str:
    return "resume" if command == "resume" else "checkpoint"


# (case, how the run directory is made from the runs, the words of the refusal; {run}: the run directory quoted)
FOREIGN = {
    "a tabular checkpoint copied into a dqn run": (
        lambda runs, run: replace(run / "checkpoint.pt", runs["tabular"] / "checkpoint.pt"),
        "dqn",
        "checkpoint.pt is a tabular run's checkpoint (agent=tabular), but {config} is a dqn run's "
        "(agent=dqn): it belongs to another run; refused, nothing written",
    ),
    "a tabular checkpoint in a dqn run without its config.yaml": (
        lambda runs, run: (
            replace(run / "checkpoint.pt", runs["tabular"] / "checkpoint.pt"),
            (run / "config.yaml").unlink(),
        ),
        "dqn",
        "checkpoint.pt is a tabular run's checkpoint (agent=tabular), but {metrics} is a dqn run's (agent=dqn)",
    ),
    "a size-free network's checkpoint in a team network's run": (
        lambda runs, run: replace(run / "checkpoint.pt", runs["dqn_set"] / "checkpoint.pt"),
        "dqn",
        "checkpoint.pt is a dqn-set run's checkpoint (agent.network=set), but {config} is a dqn run's "
        "(agent.network=team)",
    ),
    "another seed's checkpoint": (
        lambda runs, run: replace(run / "checkpoint.pt", runs["seed1"] / "checkpoint.pt"),
        "tabular",
        "checkpoint.pt is another run's checkpoint (seed=1), but {config} has seed=0",
    ),
    "another grid's checkpoint": (
        lambda runs, run: replace(run / "checkpoint.pt", runs["grid4"] / "checkpoint.pt"),
        "tabular",
        "checkpoint.pt is another run's checkpoint (env.grid=[4, 4]), but {config} has env.grid=[3, 3]",
    ),
    "a config.yaml edited to another seed": (
        lambda runs, run: edited_config(run, seed=7),
        "tabular",
        "checkpoint.pt is another run's checkpoint (seed=0), but {config} has seed=7",
    ),
    "another run's previous checkpoint behind a damaged newest one": (
        lambda runs, run: (
            replace(run / "checkpoint.prev.pt", runs["seed1"] / "checkpoint.prev.pt"),
            (run / "checkpoint.pt").write_bytes(b""),
        ),
        "tabular",
        "checkpoint.prev.pt (after checkpoint.pt: empty file) is another run's checkpoint (seed=1), but "
        "{config} has seed=0",
    ),
    "a link to another run's checkpoint": (
        lambda runs, run: replace(run / "checkpoint.pt", ("link", runs["tabular"] / "checkpoint.pt")),
        "dqn",
        "checkpoint.pt is a symbolic link to {tabular_checkpoint}, outside the run directory: a run's checkpoints "
        "are files of its own; refused",
    ),
    "a checkpoint that links to itself": (
        lambda runs, run: (
            replace(run / "checkpoint.pt", ("link", run / "checkpoint.pt")),
            (run / "checkpoint.prev.pt").unlink(),
        ),
        "tabular",
        "checkpoint.pt is a symbolic link that leads nowhere (a loop, or its target is gone)",
    ),
    "a config.yaml that links to another run's": (
        lambda runs, run: replace(run / "config.yaml", ("link", runs["seed1"] / "config.yaml")),
        "tabular",
        "{config} is not readable as the run's config (a symbolic link to {seed1_config}, outside the "
        "run directory); no checkpoint there can be told to be that run's: restore it, or move it away",
    ),
    "a config.yaml that is a list": (
        lambda runs, run: (run / "config.yaml").write_text("- seed: 0\n"),
        "tabular",
        "{config} is not readable as the run's config (it holds a list, not a mapping of settings)",
    ),
}


@pytest.mark.parametrize("command", ["resume", "evaluate"])
@pytest.mark.parametrize("case", FOREIGN)
def test_a_file_that_is_not_the_runs_own_is_refused_before_anything_is_written(
    case, command, runs, tmp_path, command_exit
):
    make, base, words = FOREIGN[case]
    run = copy_of(runs, base, tmp_path / "runs")
    make(runs, run)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    error = refused(command_exit, command, run, cwd)
    paths = {
        "tabular_checkpoint": q(runs["tabular"] / "checkpoint.pt"),
        "seed1_config": q(runs["seed1"] / "config.yaml"),
    }
    assert error.startswith(f"error: {setting(command)}={q(run)}: "), error
    assert words.format(config=q(run / "config.yaml"), metrics=q(run / "metrics.json"), **paths) in error, error


def test_the_tabular_checkpoint_in_a_dqn_run_is_refused_by_render_and_load_run_checkpoint(runs, tmp_path, command_exit):
    run = copy_of(runs, "dqn", tmp_path / "runs")
    replace(run / "checkpoint.pt", runs["tabular"] / "checkpoint.pt")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    assert "checkpoint.pt is a tabular run's checkpoint (agent=tabular)" in refused(command_exit, "render", run, cwd)
    with pytest.raises(NotThisRun, match=r"^run_dir=.*: checkpoint.pt is a tabular run's checkpoint"):
        load_run_checkpoint(run, "run_dir")
    # given as the file, it is refused as the directory's all the same (an evaluation writes beside it)
    with pytest.raises(NotThisRun, match=r"checkpoint.pt is a tabular run's checkpoint"):
        load_run_checkpoint(run / "checkpoint.pt", "checkpoint")


def test_a_config_yaml_edited_to_another_agent_is_refused_by_each_command(runs, tmp_path, command_exit):
    run = copy_of(runs, "tabular", tmp_path / "runs")
    edited_config(run, agent__name="dqn")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    resumed = refused(command_exit, "resume", run, cwd)
    assert f"checkpoint.pt is a tabular run's checkpoint (agent=tabular), but {q(run / 'config.yaml')} is a dqn" in (
        resumed
    )
    # the evaluation's cost, estimated from config.yaml before torch, cannot be: its agent section is the tabular's
    evaluated = refused(command_exit, "evaluate", run, cwd)
    assert f"{q(run / 'config.yaml')}: its saved config does not fit a dqn agent" in evaluated, evaluated


@pytest.mark.parametrize(
    ("name", "kind", "words"),
    [
        ("metrics.json", "folder", "metrics.json is a directory, not a regular file"),
        ("checkpoint.pt", "folder", "checkpoint.pt is a directory, not a regular file"),
        ("config.yaml", "fifo", "config.yaml is a FIFO, not a regular file"),
        ("events.out.tfevents.1.host.1.0", "fifo", "events.out.tfevents.1.host.1.0 is a FIFO, not a regular file"),
        ("checkpoint.prev.pt", "device", "checkpoint.prev.pt is a character device, not a regular file"),
    ],
)
def test_a_resumed_runs_file_that_is_no_regular_file_is_refused_before_the_run_starts(
    name, kind, words, runs, tmp_path, command_exit
):
    """Without the check, a folder named metrics.json failed the run's last write after config.yaml and the events
    were rewritten, and a FIFO among the events blocked the resume for ever."""
    run = copy_of(runs, "tabular", tmp_path / "runs")
    if kind == "folder":
        (run / name).unlink()
        (run / name).mkdir()
    else:
        replace(run / name, "fifo" if kind == "fifo" else ("link", "/dev/null"))
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    error = refused(command_exit, "resume", run, cwd)
    assert error == f"error: resume={q(run)}: {words}, and the run reads it back or writes it anew: move it away"


def test_a_copy_of_a_run_and_a_link_inside_it_are_the_runs_own(runs, tmp_path, capsys):
    """The ownership check leaves out where a run was made (``run_dir``): a copied run evaluates, and so does one
    whose checkpoint.pt links to its own previous one."""
    from uavrl.cli import compose_config
    from uavrl.experiment.evaluating import evaluate_checkpoint

    run = copy_of(runs, "tabular", tmp_path)
    replace(run / "checkpoint.pt", ("link", "checkpoint.prev.pt"))
    evaluate_checkpoint(compose_config("config", [f"checkpoint={run}", "eval.horizon=3"]))
    assert json.loads((run / "eval.json").read_text())["eval/optimality"] >= 0
    # an older version's config (a setting it lacks, one since moved) is still the same run's
    state = torch.load(runs["tabular"] / "checkpoint.pt", weights_only=True)
    state["config"]["train"]["episodes"] = state["config"]["agent"].pop("episodes")
    del state["config"]["env"]["num_spares"]
    torch.save(state, run / "checkpoint.pt.new")
    os.replace(run / "checkpoint.pt.new", run / "checkpoint.pt")
    assert load_run_checkpoint(run, "checkpoint")[1] == run / "checkpoint.pt"
    # without config.yaml, a size-free run is its metrics.json's dqn run
    size_free = copy_of(runs, "dqn_set", tmp_path)
    (size_free / "config.yaml").unlink()
    assert load_run_checkpoint(size_free, "checkpoint")[1] == size_free / "checkpoint.pt"


def test_render_of_two_runs_is_one_line(runs, tmp_path, command_exit):
    first, second = runs["tabular"], runs["seed1"]
    before = files_of(first), files_of(second)
    error = command_exit(["render", str(first), str(second), "eval.video_starts=1"], tmp_path)
    assert error.startswith(
        f"error: checkpoint='{first}' checkpoint='{second}' is invalid: render watches one run, "
    ), error
    assert "2 were given: give one (each in turn: for run in" in error and "\n" not in error
    assert (files_of(first), files_of(second)) == before


@pytest.mark.parametrize("value", [float("nan"), float("inf"), None])
def test_report_over_runs_without_a_finite_metric_writes_its_tables_without_a_figure(value, runs, tmp_path):
    """Each metric NaN, infinite or null: reported as missing (``-``), and the metrics figure, which has nothing to
    draw, is left out (it divided by zero)."""
    from uavrl.experiment.reporting import METRICS, report

    study = tmp_path / "study"
    for name in ("tabular", "seed1"):
        run = copy_of(runs, name, study)
        metrics = json.loads((run / "metrics.json").read_text())
        (run / "metrics.json").write_text(json.dumps({k: value if k in METRICS else v for k, v in metrics.items()}))
    text = report([study], study, resamples=20).read_text()
    assert "No metric to plot: each is NaN, infinite or null in these runs' metrics.json." in text
    assert "| tabular | **2 (0, 1) < 3** | " + " | ".join(["-"] * len(METRICS)) + " |" in text, text
    assert not list(study.glob("*_metrics.png")) and "_metrics.png" not in text
