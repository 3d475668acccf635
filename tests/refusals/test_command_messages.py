"""Paths as the shell passes them (spaces, letters beyond ASCII, quotes), values Hydra's grammar cannot read, and the
advice of a refusal: each command's messages say what to type, and what they print pastes back."""

import shlex
from pathlib import Path

import pytest
import torch
from hydra.core.override_parser.overrides_parser import OverridesParser

from uavrl.cli import hydra_quoted, readable, split_sweep_dir, sweep_dir_override, typed
from uavrl.envs import make_config
from uavrl.experiment.training import summary

ODD = "my runs/ünï (copy) #1 ~x 'q'"  # a directory name Hydra cannot read unquoted; {odd} below is tmp/ODD

# (command line as argv, the one-line error); {tmp} is an empty directory, {odd} a path below it with ODD's name,
# {run} a run directory (a checkpoint.pt) named ODD, {variant} an output directory of another variant named ODD
CASES = [
    (["train", "env.layout=ünï"], "error: env.layout='ünï' is invalid: allowed values are 'line', 'random', 'ref"),
    (["train", "env.layout='ünï'"], "error: env.layout='ünï' is invalid: allowed values are 'line', 'random', 'ref"),
    (
        ["train", "agent=dqn", "agent.mixer=a#b"],
        "error: agent.mixer='a#b' is invalid: allowed mixers are 'vdn', 'qmix'",
    ),
    (["train", "agent.episodes=ünï"], "error: agent.episodes='ünï' is invalid: it must be a whole number"),
    (["train", "ünï=3"], "error: ünï=3 cannot be read: token recognition error at: 'ü' (type setting=value, e.g."),
    (["train", "agent.episodes=[1"], "error: agent.episodes=[1 cannot be read: no viable alternative at input '[1'"),
    (
        ["train", "scenario.agents=[dqn]"],
        "error: scenario.agents=[dqn] is invalid: no scenario is chosen; choose one first, e.g. scenario=paper_6x6",
    ),
    (["train", "env.fading=rician", "env.rician_k_db=x"], "error: env.rician_k_db='x' is invalid: it must be a finite"),
    (["train", "resume={odd}"], "error: resume={odd_quoted} does not exist"),
    (["train", "resume='{tmp}/my runs/ünï'"], "error: resume='{tmp}/my runs/ünï' does not exist"),
    (["train", "run_dir={run}"], "error: run_dir={run_quoted} already holds a run"),
    (
        ["train", "resume={run}", "agent.iterations=100"],
        "error: Could not override 'agent.iterations': Key 'iterations' not in 'TabularSchema' (resume= continues the "
        "saved run with its own settings: give resume=<run dir> alone)",
    ),
    (["train", "-m", "seed=0,1", "sweep_dir={odd}", "env.grid=[0,3]"], "error: env.grid=(0, 3) is invalid"),
    (["train", "-m", "sweep_dir=a,b", "seed=0,1"], "error: sweep_dir=a,b is invalid: give one sweep_dir"),
    (["evaluate", "checkpoint={odd}"], "error: checkpoint={odd_quoted} does not exist"),
    (["evaluate", "checkpoint={tmp}/my runs/x"], "error: checkpoint='{tmp}/my runs/x' does not exist"),
    (["evaluate", "checkpoint=/tmp/ünï"], "error: checkpoint='/tmp/ünï' does not exist"),
    (
        ["reproduce", "table2", "grids=[2]", "runs=100000000"],
        "error: runs=100000000 is invalid: the team Q tables on 2x2 (16 states x 36 joint actions each",
    ),
    (
        ["reproduce", "figures", "grids=[2]", "figure_grid=2", "runs=100000000", "memory_budget=2e9"],
        "error: runs=100000000 is invalid: the team Q tables on 2x2",
    ),
    (["reproduce", "table2", "memory_budget=0"], "error: memory_budget=0 is invalid: it must be positive"),
    (
        ["reproduce", "table2", "grids=[2]", "out_dir={variant}"],
        "error: out_dir={variant_quoted} holds another variant",
    ),
    (["reproduce", "table2", "episodes=ünï"], "error: episodes='ünï' is invalid: it must be a whole number"),
]


@pytest.fixture
def paths(tmp_path_factory):
    root = tmp_path_factory.mktemp("paths")
    run = root / "runs" / ODD
    run.mkdir(parents=True)
    torch.save({"agent": {}, "iteration": 1, "config": {}, "torch_rng": torch.get_rng_state()}, run / "checkpoint.pt")
    variant = root / "out" / ODD
    variant.mkdir(parents=True)
    (variant / "variant.json").write_text('{"grids": [3]}\n')
    return {"run": str(run), "variant": str(variant)}


@pytest.mark.parametrize("argv, expected", CASES, ids=[" ".join(argv) for argv, _ in CASES])
def test_each_command_reads_paths_as_given_and_says_what_to_type(argv, expected, paths, tmp_path, command_exit):
    values = {"tmp": tmp_path, "odd": str(tmp_path / ODD), "odd_quoted": shlex.quote(str(tmp_path / ODD))}
    values |= paths | {"run_quoted": shlex.quote(paths["run"]), "variant_quoted": shlex.quote(paths["variant"])}
    error = command_exit([arg.format(**values) for arg in argv], tmp_path)
    assert isinstance(error, str) and "\n" not in error, error
    assert error.startswith(expected.format(**values)), error
    assert "agent.memory_budget" not in error
    assert sorted(p.name for p in tmp_path.iterdir()) == [], "a refused command wrote files"


PATHS = ["/tmp/plain", "/tmp/my runs/x", "/tmp/ünï", "/tmp/a'b", "/tmp/a,b", "/tmp/a\\", "/tmp/(1) [2] #3 ~4 =5", ODD]


@pytest.mark.parametrize("path", PATHS)
def test_a_printed_override_pastes_back_as_the_path(path):
    """What uavrl prints to type (``typed``), split as a POSIX shell splits it and read as the command line reads
    it, sets the setting to the path itself."""
    (word,) = shlex.split(typed("checkpoint", path))
    (override,) = readable([word])
    assert OverridesParser.create().parse_override(override).value() == path
    assert OverridesParser.create().parse_override(f"checkpoint={hydra_quoted(path)}").value() == path


@pytest.mark.parametrize("path", [path for path in PATHS if "," not in path])  # a,b typed unquoted: a sweep
def test_a_sweep_dir_is_read_as_the_path(path, tmp_path):
    """``sweep_dir`` as typed (quoted for Hydra by the command line), then as uavrl passes it on to Hydra."""
    given = str(tmp_path / path.lstrip("/"))
    rest, sweep_dir = split_sweep_dir(readable(["seed=0,1", f"sweep_dir={given}"]))
    assert rest == ["seed=0,1"] and sweep_dir == Path(given)
    assert OverridesParser.create().parse_override(sweep_dir_override(sweep_dir)).value() == given


def test_the_end_of_run_lines_paste(compose_cfg, tmp_path):
    run_dir = tmp_path / ODD
    cfg = compose_cfg("agent=random")
    result = {"eval/optimality": 1.0, "eval/optimality_min": 1.0, "eval/optimal_fraction": 1.0}
    result |= {"iterations": 1, "total_seconds": 1.0, "eval/return_ratio": 1.0, "eval/reach_999": 1.0}
    env_cfg = make_config("paper")
    last = summary(cfg, env_cfg, result, run_dir).splitlines()[-1]
    board, again = last.split("   ")
    assert shlex.split(board) == ["look", "at", "it:", "tensorboard", "--logdir", str(run_dir)]
    *command, word = shlex.split(again)
    assert command == ["evaluate", "it", "again:", "python", "-m", "uavrl.evaluate"]
    assert OverridesParser.create().parse_override(readable([word])[0]).value() == str(run_dir)


def test_reproduce_checks_its_memory_budget_before_any_work(monkeypatch, tmp_path, compose_cfg):
    """A budget too small for one 2x2 table is refused before any file is written, naming reproduce's setting."""
    monkeypatch.chdir(tmp_path)
    from uavrl.reproduce import check_settings

    cfg = compose_cfg("grids=[2]", "runs=1", "memory_budget=1000", config_name="reproduce")
    with pytest.raises(
        ValueError, match=r"^num_uavs=2 is invalid: the team Q tables on 2x2 .* over memory_budget=1000: lower num_uavs"
    ):
        check_settings(cfg)
    check_settings(compose_cfg("grids=[2]", "runs=1", config_name="reproduce"))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "fraction, shown", [(1.0, "100%"), (199 / 200, "99.5%"), (0.9999, "99.9%"), (63 / 64, "98.4%"), (0.29, "29%")]
)
def test_a_share_of_starts_never_rounds_a_miss_up_to_all(fraction, shown):
    """199 of 200 starts is 99.5%, not 100%: the summary's shares round down to 0.1%."""
    from uavrl.experiment.runs import share_of_starts, yardstick_line

    assert share_of_starts(fraction) == shown
    assert yardstick_line(None, {"eval/reach_999": fraction}) == f"yardstick: 0.999 U* reached from {shown} of starts"


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("train seed=1 seed=2", "error: seed=1 seed=2 is invalid: seed is given 2 times: give it once"),
        (
            "evaluate checkpoint=a checkpoint=b",
            "error: checkpoint=a checkpoint=b is invalid: checkpoint is given 2 times: give it once",
        ),
        (
            "train env.grid=[4,4] +env.grid=[5,5] env.grid=[6,6]",
            "error: env.grid=[4,4] +env.grid=[5,5] env.grid=[6,6] is invalid: env.grid is given 3 times: give it once",
        ),
    ],
)
def test_a_setting_typed_twice_is_refused_not_the_last_kept(line, expected, tmp_path, command_exit):
    assert command_exit(line, tmp_path) == expected
    assert not any(tmp_path.iterdir())
