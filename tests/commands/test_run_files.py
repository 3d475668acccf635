"""Run directories from anyone: nothing in them runs, damaged or foreign files get one line, policies stay in their
run's environment.

Each table row is one case: a command line (run as ``python -m`` runs it, in this process for speed), a call of
``uavrl.load_policy``, or a policy in an environment.  The code-execution rows read a file whose pickle calls
``os.system("touch <marker>")`` and assert that no marker appears.
"""

import json
import os
import pickle
import random
import shlex
import shutil
import subprocess
import sys

import pytest
import torch
from hydra import compose, initialize_config_dir

import uavrl
from uavrl.agents.env_check import FULL_CHECKS
from uavrl.config import config_dir
from uavrl.envs import UAVSpectrumEnv
from uavrl.experiment.checkpoints import CheckpointError
from uavrl.experiment.protocol import variant
from uavrl.experiment.saved import load_agent
from uavrl.train import train

TINY = ["env.grid=[3,3]", "env.max_steps=10", "eval.num_starts=2", "progress=false"]
AGENTS = {
    "tabular": ["agent=tabular", "agent.episodes=2", "agent.runs=2", "train.checkpoint_every=1"],
    "dqn": ["agent=dqn", "agent.iterations=2", "agent.worlds=2", "agent.buffer_size=50", "agent.learning_starts=8"],
    "oracle": ["agent=oracle"],
    "random": ["agent=random"],
}
REPRODUCE = ["grids=[2]", "runs=1", "episodes=2", "figure_grid=2", "eval_starts=2"]
REFUSED = "not a uavrl file, or it was altered; refused, and nothing in it was run"


class Payload:
    """What a hostile file holds: unpickling it runs a shell command."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {shlex.quote(str(self.marker))}",)


def compose_config(name: str, overrides: list[str]):
    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        return compose(config_name=name, overrides=overrides)


def changed(root, name: str, base, change) -> str:
    """A copy of the run ``base`` whose ``checkpoint.pt`` went through ``change(state)``, without its previous one."""
    run_dir = root / name
    shutil.copytree(base, run_dir)
    state = torch.load(run_dir / "checkpoint.pt", weights_only=True)
    change(state)
    torch.save(state, run_dir / "checkpoint.pt")
    (run_dir / "checkpoint.prev.pt").unlink(missing_ok=True)
    return str(run_dir)


def benchmarl_run(root, marker) -> str:
    """A run directory as ``python -m uavrl.benchmarl`` lays it out; BenchMARL's own pickles are hostile here."""
    run_dir = root / "benchmarl_run"
    experiment = run_dir / "mappo_tiny_mlp__0a1b2c3d_26_12_01-10_00_00"
    (experiment / "checkpoints").mkdir(parents=True)
    (experiment / "config.pkl").write_bytes(pickle.dumps(Payload(marker)))
    torch.save({"payload": Payload(marker)}, experiment / "checkpoints" / "checkpoint_600.pt")
    (run_dir / "config.yaml").write_text("algorithm: {}\nexperiment: {}\n")
    (run_dir / "metrics.json").write_text('{"agent": "benchmarl_mappo"}\n')
    return str(run_dir)


def reproduction(root, name: str, write) -> str:
    """An output directory of ``python -m uavrl.reproduce`` for REPRODUCE, its 2x2 history written by ``write``."""
    out_dir = root / name
    out_dir.mkdir()
    (out_dir / "variant.json").write_text(json.dumps(variant(compose_config("reproduce", REPRODUCE))))
    write(out_dir / "history_2x2.pt")
    return str(out_dir)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A finished run directory of each agent (3x3 grid, 2 UAVs, layout 'line')."""
    root = tmp_path_factory.mktemp("runs")
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return {
            name: train(compose_config("config", [*TINY, *o, f"run_dir={root / name}"])) for name, o in AGENTS.items()
        }
    finally:
        torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def files(runs, tmp_path_factory):
    """Run directories and reproductions that are hostile, damaged or foreign; ``marker``: what a payload creates."""
    root = tmp_path_factory.mktemp("files")
    marker = root / "marker"
    tabular = runs["tabular"]
    out = {"marker": str(marker), "tabular": str(tabular)}

    def payload(state):
        state["extra"] = Payload(marker)

    out["payload"] = changed(root, "payload", tabular, payload)
    shutil.copy(tabular / "checkpoint.prev.pt", root / "payload")  # readable, but a hostile newest is not skipped
    out["no_agent"] = changed(root, "no_agent", tabular, lambda s: s["config"].pop("agent"))
    out["agent_list"] = changed(root, "agent_list", tabular, lambda s: s.update(agent=[1, 2]))
    out["agent_text"] = changed(root, "agent_text", tabular, lambda s: s.update(agent={"q": "abc", "episode": 1}))
    out["dqn_no_hidden"] = changed(root, "dqn_no_hidden", runs["dqn"], lambda s: s["config"]["agent"].pop("hidden"))
    out["no_rng"] = changed(root, "no_rng", tabular, lambda s: s.pop("torch_rng"))
    out["seed_abc"] = changed(root, "seed_abc", tabular, lambda s: s["config"].update(seed="abc"))
    out["interpolation"] = changed(
        root, "interpolation", tabular, lambda s: s["config"]["env"].update(name="${oc.env:HOME}")
    )
    out["benchmarl"] = benchmarl_run(root, marker)
    out["prev_only"] = str(root / "prev_only")
    shutil.copytree(tabular, root / "prev_only")
    (root / "prev_only" / "checkpoint.pt").unlink()
    out["repro_payload"] = reproduction(root, "repro_payload", lambda p: torch.save({"history": Payload(marker)}, p))
    out["repro_garbage"] = reproduction(
        root, "repro_garbage", lambda p: p.write_bytes(random.Random(0).randbytes(2000))
    )
    out["repro_pickle"] = reproduction(root, "repro_pickle", lambda p: p.write_bytes(pickle.dumps({"history": 1})))
    out["repro_eof"] = reproduction(
        root, "repro_eof", lambda p: p.write_bytes(_legacy_torch_file({"history": {"a": torch.zeros(9)}})[:40])
    )
    out["repro_zip_cut"] = reproduction(
        root, "repro_zip_cut", lambda p: p.write_bytes(_torch_file({"history": torch.zeros(99)})[:300])
    )
    out["repro_no_history"] = reproduction(root, "repro_no_history", lambda p: torch.save({"grid": 2}, p))
    out["repro_empty"] = reproduction(root, "repro_empty", lambda p: p.write_bytes(b""))
    return out


def _torch_file(obj) -> bytes:
    import io

    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


def _legacy_torch_file(obj) -> bytes:
    import io

    buffer = io.BytesIO()
    torch.save(obj, buffer, _use_new_zipfile_serialization=False)
    return buffer.getvalue()


def quoted(path) -> str:
    return shlex.quote(str(path))


# (command line, words the one-line error must contain); {name} is files[name], {q_name} the same path shell-quoted
CLI_CASES = [
    ("evaluate checkpoint={payload}", "(posix.system): it is " + REFUSED),
    ("train resume={payload}", "(posix.system): it is " + REFUSED),
    ("reproduce figures {reproduce} out_dir={repro_payload}", "(posix.system): it is " + REFUSED),
    ("evaluate checkpoint={no_agent}", "checkpoint.pt: its config has no agent section"),
    ("train resume={no_agent}", "checkpoint.pt: its config has no agent section"),
    ("evaluate checkpoint={agent_list}", "its agent is a list, not a dict"),
    ("evaluate checkpoint={agent_text}", "checkpoint.pt: its agent state does not fit a tabular agent"),
    ("train resume={agent_text}", "checkpoint.pt: its agent state does not fit a tabular agent"),
    ("evaluate checkpoint={dqn_no_hidden}", "checkpoint.pt: its saved config does not fit a dqn agent"),
    ("train resume={dqn_no_hidden}", "checkpoint.pt: its saved config does not fit a dqn agent"),
    ("train resume={no_rng}", "checkpoint.pt cannot be resumed: it holds no torch random state (torch_rng: none)"),
    ("evaluate checkpoint={seed_abc}", "checkpoint.pt: in its saved config, seed='abc' is invalid"),
    ("train resume={seed_abc}", "checkpoint.pt: in its saved config, seed='abc' is invalid"),
    ("evaluate checkpoint={interpolation}", "env.name='${{oc.env:HOME}}' is an interpolation"),
    ("evaluate checkpoint={benchmarl}", "checkpoint={q_benchmarl} is a BenchMARL run"),
    ("train resume={benchmarl}", "resume={q_benchmarl} is a BenchMARL run"),
    ("train resume={tabular}/checkpoint.prev.pt", "resume={q_tabular}/checkpoint.prev.pt is invalid: give the run dir"),
    ("reproduce figures {reproduce} out_dir={repro_garbage}", "history_2x2.pt: not a torch file (UnpicklingError"),
    ("reproduce figures {reproduce} out_dir={repro_pickle}", "history_2x2.pt: not a torch file (UnpicklingError"),
    ("reproduce figures {reproduce} out_dir={repro_eof}", "history_2x2.pt: truncated or damaged (EOFError)"),
    ("reproduce figures {reproduce} out_dir={repro_zip_cut}", "history_2x2.pt: truncated or damaged"),
    ("reproduce figures {reproduce} out_dir={repro_no_history}", "history_2x2.pt is not a history file of this uavrl"),
    ("reproduce figures {reproduce} out_dir={repro_empty}", "history_2x2.pt: empty file"),
    # render reads the run as evaluate does, and names it as typed: a bare directory is checkpoint=
    ("render {payload}", "checkpoint={q_payload}: " + "{q_payload}/checkpoint.pt: it holds objects"),
    ("render checkpoint={agent_list}", "checkpoint={q_agent_list}: no readable checkpoint"),
    ("render {benchmarl}", "checkpoint={q_benchmarl} is a BenchMARL run"),
]


def fill(text: str, files: dict) -> str:
    paths = {**files, **{f"q_{k}": quoted(v) for k, v in files.items()}, "reproduce": " ".join(REPRODUCE)}
    return text.format(**paths)


def cli_argv(line: str) -> list[str]:
    """``uavrl.<command> [word] progress=false <overrides>``."""
    command, *args = line.split()
    word = [args.pop(0)] if args and "=" not in args[0] else []
    return [f"uavrl.{command}", *word, "progress=false", *args]


@pytest.mark.parametrize("line, words", CLI_CASES, ids=[line for line, _ in CLI_CASES])
def test_run_files_that_are_hostile_damaged_or_foreign_are_refused_in_one_line(
    line, words, files, tmp_path, command_exit, capsys
):
    error = command_exit(fill(line, files), tmp_path)  # what the interpreter prints, with exit status 1
    assert isinstance(error, str) and error.startswith("error: ") and "\n" not in error, error
    assert fill(words, files) in error, error
    assert capsys.readouterr().out == ""
    assert not os.path.exists(files["marker"]), "a file's code ran"
    assert sorted(p.name for p in tmp_path.iterdir()) == [], "a refused command wrote files"


@pytest.mark.parametrize(
    "line",
    [
        "evaluate checkpoint={payload}",
        "train resume={payload}",
        "reproduce figures {reproduce} out_dir={repro_payload}",
    ],
)
def test_a_hostile_file_runs_nothing_under_python_m(line, files, tmp_path):
    argv = [sys.executable, "-m", *cli_argv(fill(line, files))]
    result = subprocess.run(argv, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert result.returncode == 1 and result.stdout == "", result
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("error: "), result.stderr
    assert "(posix.system)" in result.stderr and REFUSED in result.stderr
    assert not os.path.exists(files["marker"])


# (run directory, exception, words): uavrl.load_policy(files[run directory])
API_CASES = [
    ("payload", CheckpointError, "(posix.system): it is " + REFUSED),
    ("no_agent", CheckpointError, "its config has no agent section"),
    ("agent_list", CheckpointError, "its agent is a list, not a dict"),
    ("agent_text", CheckpointError, "its agent state does not fit a tabular agent"),
    ("seed_abc", CheckpointError, "in its saved config, seed='abc' is invalid"),
    ("benchmarl", FileNotFoundError, "run_dir={q_benchmarl} is a BenchMARL run"),
]


@pytest.mark.parametrize("run_dir, error, words", API_CASES, ids=[run for run, _, _ in API_CASES])
def test_load_policy_refuses_hostile_damaged_or_foreign_runs_in_one_line(run_dir, error, words, files):
    with pytest.raises(error) as raised:
        uavrl.load_policy(files[run_dir])
    assert "\n" not in str(raised.value) and fill(words, files) in str(raised.value), str(raised.value)
    assert not os.path.exists(files["marker"])


def test_a_benchmarl_run_is_explained_with_its_checkpoint_and_results(files):
    with pytest.raises(FileNotFoundError) as raised:
        load_agent(files["benchmarl"])
    message = str(raised.value)
    assert "uavrl reads only its own checkpoint.pt" in message and "metrics.json" in message
    assert "checkpoint_600.pt" in message and "Experiment.reload_from_file(" in message
    assert "only for runs you trust" in message and not os.path.exists(files["marker"])


def test_a_missing_newest_checkpoint_is_said_with_the_file_and_iteration_used(files, runs, tmp_path, capsys):
    prev_only = files["prev_only"]
    iteration = torch.load(runs["tabular"] / "checkpoint.prev.pt", weights_only=True)["iteration"]
    used = (
        f"checkpoint.pt: missing: using {quoted(os.path.join(prev_only, 'checkpoint.prev.pt'))} (iteration {iteration})"
    )
    with pytest.warns(UserWarning) as warned:
        uavrl.load_policy(prev_only)
    assert [str(w.message) for w in warned] == [used]
    from uavrl.experiment.evaluating import evaluate_checkpoint

    evaluate_checkpoint(compose_config("config", [f"checkpoint={prev_only}", *TINY]))
    assert capsys.readouterr().err.strip() == f"warning: {used}"
    resumed = tmp_path / "resumed"
    shutil.copytree(prev_only, resumed)
    train(compose_config("config", [*TINY, f"resume={resumed}"]), overrides=[f"resume={resumed}"])
    warning = capsys.readouterr().err.strip()
    assert warning == f"warning: checkpoint.pt: missing: resuming from checkpoint.prev.pt, iteration {iteration}"


def test_resume_of_a_checkpoint_file_continues_its_run_directory(runs, tmp_path):
    run_dir = tmp_path / "run"
    shutil.copytree(runs["tabular"], run_dir)
    (run_dir / "checkpoint.pt").rename(run_dir / "final.pt")
    (run_dir / "checkpoint.prev.pt").rename(run_dir / "checkpoint.pt")  # the iteration before the last
    given = f"resume={run_dir / 'checkpoint.pt'}"
    assert train(compose_config("config", [*TINY, given]), overrides=[given]) == run_dir
    state, final = (torch.load(run_dir / name, weights_only=True) for name in ("checkpoint.pt", "final.pt"))
    assert state["iteration"] == final["iteration"] and torch.equal(state["agent"]["q"], final["agent"]["q"])


def test_saved_settings_of_earlier_versions_still_load(runs, tmp_path):
    """``uavrl.config.MOVED``: a checkpoint whose config has ``train.episodes`` evaluates as one with
    ``agent.episodes``."""
    old = changed(
        tmp_path,
        "old",
        runs["tabular"],
        lambda s: s["config"]["train"].update(episodes=s["config"]["agent"].pop("episodes")),
    )
    agent, cfg, fallback = load_agent(old)
    assert cfg.agent.episodes == 2 and "episodes" not in cfg.train and fallback is None


@pytest.mark.parametrize("name", AGENTS)
def test_every_agent_checkpoint_loads_with_weights_only_and_its_policy_pickles(name, runs):
    state = torch.load(runs[name] / "checkpoint.pt", weights_only=True)
    assert state["iteration"] == (0 if name in ("oracle", "random") else 2)
    policy, env_cfg = uavrl.load_policy(runs[name])
    copy = pickle.loads(pickle.dumps(policy))  # before either acts: the same generator states
    actions = [
        UAVSpectrumEnv(batch_size=4, config=env_cfg, seed=3).rollout(6, p)["agents", "action"] for p in (policy, copy)
    ]
    assert torch.equal(*actions)


def test_a_dqn_checkpoint_of_an_earlier_version_loads_its_replay_buffer(runs, tmp_path):
    """Before its buffer's own state_dict, a DQN checkpoint held the filled slots as a TensorDict and the write count:
    read through a stand-in that rebuilds a plain TensorDict, and nothing else."""
    agent, _, _ = load_agent(runs["dqn"])
    stored = agent.buffer[: len(agent.buffer)]
    old = changed(
        tmp_path,
        "old_dqn",
        runs["dqn"],
        lambda s: s["agent"].update(buffer=stored, buffer_writes=agent.buffer.write_count),
    )
    restored, _, _ = load_agent(old)
    assert len(restored.buffer) == len(agent.buffer)
    assert (restored.buffer[: len(agent.buffer)] == stored).all()


MISMATCHES = {
    "a 4x4 grid": dict(grid=(4, 4)),
    "a 2x3 grid": dict(grid=(2, 3)),
    "3 UAVs": dict(num_uavs=3),
    "layout 'random'": dict(layout="random"),
}
POLICY_CASES = [(agent, env) for agent in AGENTS for env in MISMATCHES]


@pytest.mark.parametrize("agent, env", POLICY_CASES, ids=[f"{a} in {e}" for a, e in POLICY_CASES])
def test_a_policy_refuses_an_environment_unlike_its_run(agent, env, runs):
    """Bound to the environment (as the evaluation does) or handed its tensordicts (``env.rollout(T, policy)``)."""
    policy, env_cfg = uavrl.load_policy(runs[agent])
    other = UAVSpectrumEnv(batch_size=1, config=env_cfg.replace(**MISMATCHES[env]), seed=0)
    with pytest.raises(ValueError) as bound:
        policy.bind_env(other)
    with pytest.raises(ValueError) as acted:
        other.rollout(FULL_CHECKS + 2, uavrl.load_policy(runs[agent])[0])
    for message in (str(bound.value), str(acted.value)):
        assert "\n" not in message and "this policy acts in its run's environment (a 3x3 grid, 2 UAVs" in message
    assert f"the environment has {env}" in str(bound.value)
