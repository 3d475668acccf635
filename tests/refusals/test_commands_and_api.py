"""Bad input, from the command line and the Python API: one line from uavrl naming the setting, never a traceback."""

import importlib.util
import os
import subprocess
import sys

import pytest
import torch
from tensordict import TensorDict

from uavrl.envs import UAVSpectrumEnv
from uavrl.experiment.checkpoints import CheckpointError
from uavrl.experiment.saved import load_agent
from uavrl.train import train

# (command and overrides, words the one-line error must contain: the setting as typed); {tmp} is an empty
# directory, {garbage} ... {tensor} unreadable or foreign checkpoint files, {run} a run, {other} another variant
CLI_CASES = [
    ("train env.max_steps=0", "env.max_steps=0 is invalid"),
    ("train agent.episodes=-1", "agent.episodes=-1 is invalid"),
    ("train agent.episodes=0", "agent.episodes=0 is invalid"),
    ("train agent.episodes=2.5", "agent.episodes=2.5 is invalid"),
    ("train agent.episodes=many", "agent.episodes='many' is invalid"),
    ("train agent=dqn agent.iterations=-3", "agent.iterations=-3 is invalid"),
    ("train agent.runs=0", "agent.runs=0 is invalid"),
    ("train train.checkpoint_every=0", "train.checkpoint_every=0 is invalid"),
    ("train train.log_every=0", "train.log_every=0 is invalid"),
    ("train eval.horizon=0", "eval.horizon=0 is invalid"),
    ("train eval.num_starts=0", "eval.num_starts=0 is invalid"),
    ("train eval.every=-1", "eval.every=-1 is invalid"),
    ("train eval.seed=-3", "eval.seed=-3 is invalid"),
    ("train ++eval.gamma=0", "eval.gamma=0 is invalid"),
    ("train seed=-1", "seed=-1 is invalid"),
    ("train seed=9223372036854775808", "seed=9223372036854775808 is invalid"),
    ("train num_threads=0", "num_threads=0 is invalid"),
    ("train device=gpu", "device='gpu' is invalid"),
    ("train progress=maybe", "progress='maybe' is invalid"),
    ("train agent.alpha=0", "agent.alpha=0 is invalid"),
    ("train agent.epsilon=2", "agent.epsilon=2 is invalid"),
    ("train agent.backend=jax", "agent.backend='jax' is invalid"),
    ("train agent.memory_budget=-1", "agent.memory_budget=-1 is invalid"),
    ("train ++agent.method=sarsa", "agent.method='sarsa' is invalid"),
    ("train agent=dqn agent.worlds=0", "agent.worlds=0 is invalid"),
    ("train agent=dqn agent.lr=-0.1", "agent.lr=-0.1 is invalid"),
    ("train agent=dqn agent.mixer=sum", "agent.mixer='sum' is invalid"),
    ("train agent=dqn agent.learning_starts=-1", "agent.learning_starts=-1 is invalid"),
    ("train env.grid=[0,3]", "env.grid=(0, 3) is invalid"),
    ("train env.num_uavs=0", "env.num_uavs=0 is invalid"),
    ("train env.layout=spiral", "env.layout='spiral' is invalid"),
    ("train env.noise=-1", "env.noise=-1 is invalid"),
    ("train env.preset=mine", "env.preset='mine' is invalid"),
    ("train resume={tmp}/nothing", "resume="),
    ("train run_dir={run}", "run_dir="),
    ("train train.episdoes=5", "train.episdoes"),
    ("train agent=sarsa", "agent/sarsa"),
    ("train agent.episodes=[1", "[1"),
    ("evaluate", "checkpoint is not set"),
    ("evaluate checkpoint={tmp}/nothing.pt", "checkpoint="),
    ("evaluate checkpoint={garbage}", "checkpoint="),
    ("evaluate checkpoint={text}", "checkpoint="),
    ("evaluate checkpoint={empty}", "checkpoint="),
    ("evaluate checkpoint={truncated}", "checkpoint="),
    ("evaluate checkpoint={tensor}", "checkpoint="),
    ("evaluate checkpoint={run} eval.num_starts=0", "eval.num_starts=0 is invalid"),
    ("evaluate checkpoint={run} eval.horizon=-2", "eval.horizon=-2 is invalid"),
    ("train scenario=large_20x20", "agent=tabular is invalid with scenario=large_20x20: its agents are 'dqn'"),
    ("train scenario=n6_10x1", "scenario/n6_10x1"),
    ("train scenario=rayleigh scenario.name=x scenario.agents=[dqn,qlearner]", "scenario.agents=['dqn', 'qlearner']"),
    ("train -m agent=random eval.num_starts=1,0", "eval.num_starts=0 is invalid"),
    ("train -m agent=tabular,dqn scenario=large_20x20", "agent=tabular is invalid with scenario=large_20x20"),
    ("train -m seed=0,1 run_dir={tmp}/r", "run_dir is invalid in a sweep"),
    ("train -m seed=0,1 sweep_dir={tmp}/s env.grid=[0,3]", "env.grid="),
    ("reproduce table2 episodes=-5", "episodes=-5 is invalid"),
    ("reproduce table2 runs=0", "runs=0 is invalid"),
    ("reproduce table2 grids=[7]", "grids=[7] is invalid"),
    ("reproduce table2 grids=[]", "grids=[] is invalid"),
    ("reproduce table2 grids=[2] num_uavs=5", "num_uavs=5 is invalid"),
    ("reproduce table2 steps=0", "steps=0 is invalid"),
    ("reproduce table2 seed=-1", "seed=-1 is invalid"),
    ("reproduce table2 eval_starts=0", "eval_starts=0 is invalid"),
    ("reproduce table2 numba_threads=-1", "numba_threads=-1 is invalid"),
    ("reproduce figures grids=[2] figure_grid=6", "figure_grid=6 is invalid"),
    ("reproduce table2 out_dir={other} grids=[2]", "out_dir="),
    ("reproduce table3", "command 'table3'"),
    # what a command would ignore or composing lets through
    ("train checkpoint={run}", "is invalid for python -m uavrl.train, which does not read it"),
    ("train +agent.new_key=1", "agent.new_key=1 is invalid: no such setting"),
    ("train +env.colour=red", "env.colour=red is invalid: no such setting"),
    ("train progress=2", "progress=2 is invalid: it must be true or false"),
    ("train num_threads=1000000", "num_threads=1000000 is invalid"),
    ("train env.layout=random env.grid=[1,1]", "env.grid=(1, 1) is invalid: a 1x1 grid holds 1 to 1 UAVs"),
    ("train -m seed=0,1 sweep_dir={garbage}", "is invalid: it is a file, not a directory"),
    ("evaluate checkpoint={run} agent.alpha=0.5", "agent.alpha=0.5 is invalid for python -m uavrl.evaluate"),
    ("evaluate checkpoint={run} train.log_every=3", "train.log_every=3 is invalid for python -m uavrl.evaluate"),
    ("reproduce table2 +foo=1", "foo=1 is invalid: no such setting"),
    ("reproduce table2 state_includes_tasks=2", "state_includes_tasks=2 is invalid: it must be true or false"),
    ("reproduce table2 grids=[2] out_dir={garbage}", "is a file, not a directory"),
    ("reproduce table2 episdoes=5", "episdoes"),
]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Unreadable and foreign checkpoint files, a run directory, and an output directory of another variant."""
    root = tmp_path_factory.mktemp("files")
    good = root / "good.pt"
    torch.save({"agent": {}, "iteration": 1, "config": {}, "torch_rng": torch.get_rng_state()}, good)
    (root / "garbage.pt").write_bytes(os.urandom(4096))
    (root / "text.pt").write_text("not a checkpoint\n")
    (root / "empty.pt").write_bytes(b"")
    (root / "truncated.pt").write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    torch.save(torch.zeros(3), root / "tensor.pt")
    (root / "run").mkdir()
    (root / "run" / "checkpoint.pt").write_bytes(good.read_bytes())
    (root / "other").mkdir()
    (root / "other" / "variant.json").write_text('{"grids": [3]}\n')
    return {path.stem: str(path) for path in root.iterdir() if path.name != "good.pt"}


def cli_argv(line: str) -> list[str]:
    """``uavrl.<command> [word] progress=false <overrides>`` (a case's own ``progress`` wins)."""
    command, *args = line.split()
    word = [args.pop(0)] if args and "=" not in args[0] else []
    return [f"uavrl.{command}", *word, "progress=false", *args]


@pytest.mark.parametrize("line, words", CLI_CASES, ids=[line for line, _ in CLI_CASES])
def test_command_line_mistakes_are_one_line(line, words, files, tmp_path, command_exit, capsys):
    """Each command as ``python -m`` runs it (here, for speed): a non-zero exit, one line naming the setting."""
    paths = {key.split(".")[0]: value for key, value in files.items()}
    error = command_exit(line.format(tmp=tmp_path, **paths), tmp_path)  # what python prints, with exit status 1
    assert isinstance(error, str) and error.startswith("error: ") and "\n" not in error, error
    assert words.format(tmp=tmp_path, **paths) in error, error
    assert capsys.readouterr() == ("", "")
    assert sorted(p.name for p in tmp_path.iterdir()) == [], "a refused command wrote files"


@pytest.mark.parametrize("line, words", [CLI_CASES[0], CLI_CASES[-3], ("evaluate checkpoint={garbage}", "checkpoint=")])
def test_command_line_mistakes_exit_with_one_line_on_stderr(line, words, files, tmp_path):
    paths = {key.split(".")[0]: value for key, value in files.items()}
    argv = [sys.executable, "-m", *cli_argv(line.format(tmp=tmp_path, **paths))]
    result = subprocess.run(argv, capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert result.returncode == 1 and result.stdout == ""
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("error: "), result.stderr
    assert words.format(**paths) in result.stderr


def test_a_bad_override_is_refused_before_torch_is_imported():
    probe = (
        "import runpy, sys\n"
        "sys.argv = ['train', 'env.max_steps=0']\n"
        "try:\n    runpy.run_module('uavrl.train', run_name='__main__')\n"
        "except SystemExit as exit:\n    print(exit.code)\n"
        "print(sorted(m for m in ('torch', 'tensordict', 'torchrl', 'numba') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.splitlines()
    assert out == ["error: env.max_steps=0 is invalid: an episode needs a whole number of steps >= 1", "[]"]


def policy_writing(shape):
    return lambda td: td.set(("agents", "action"), torch.zeros(shape, dtype=torch.long))


def actions(*shape, batch_size):
    return TensorDict({("agents", "action"): torch.zeros(shape, dtype=torch.long)}, batch_size=batch_size)


POSITIONS = torch.tensor([[[0, 0], [1, 1]], [[2, 2], [0, 1]]])
TASKS = torch.tensor([[0, 1], [1, 0]])

# (call, exception type, words)
API_CASES = [
    (lambda env, compose: UAVSpectrumEnv(device="cuda:7"), ValueError, "device='cuda:7'"),
    (lambda env, compose: UAVSpectrumEnv(device="gpu"), ValueError, "device='gpu'"),
    (lambda env, compose: UAVSpectrumEnv(seed=-1), ValueError, "seed=-1"),
    (lambda env, compose: UAVSpectrumEnv(grid=(0, 3)), ValueError, "grid=(0, 3)"),
    (lambda env, compose: env.set_seed(-5), ValueError, "seed=-5"),
    (lambda env, compose: env.set_seed(2**64), ValueError, f"seed={2**64}"),
    (lambda env, compose: env.rollout(0), ValueError, "max_steps=0"),
    (lambda env, compose: env.rollout(3, policy_writing((2, 3))), ValueError, "('agents', 'action')"),
    (lambda env, compose: env.rollout(3, policy_writing((2,))), ValueError, "('agents', 'action')"),
    (lambda env, compose: env.step(actions(3, 2, batch_size=[3])), ValueError, "('agents', 'action')"),
    (lambda env, compose: env.step(actions(2, 2, batch_size=[])), ValueError, "('agents', 'action')"),
    (lambda env, compose: env.utility(POSITIONS + 5, TASKS), ValueError, "positions"),
    (lambda env, compose: env.utility(POSITIONS - 1, TASKS), ValueError, "positions"),
    (lambda env, compose: env.utility(POSITIONS.float(), TASKS), TypeError, "positions"),
    (lambda env, compose: env.utility(POSITIONS, TASKS + 2), ValueError, "tasks"),
    (lambda env, compose: train(compose("agent.episodes=0")), ValueError, "agent.episodes=0"),
    (lambda env, compose: train(compose("agent=dqn", "agent.updates=0")), ValueError, "agent.updates=0"),
    (lambda env, compose: load_agent(__file__), CheckpointError, "checkpoint="),
]


@pytest.mark.parametrize("call, error, words", API_CASES, ids=[words for _, _, words in API_CASES])
def test_python_api_mistakes_are_one_line(call, error, words, tiny_env, compose_cfg):
    env = tiny_env()
    env.reset()
    with pytest.raises(error) as raised:
        call(env, compose_cfg)
    assert "\n" not in str(raised.value) and words in str(raised.value), str(raised.value)


def test_enough_bad_inputs_are_checked():
    assert len(CLI_CASES) + len(API_CASES) >= 40


WITHOUT_BENCHMARL = [
    (["algorithm=qmix"], "error: algorithm=qmix needs BenchMARL, which is not installed: pip install torch==2.13.0"),
    (["algorithm=vdn", "experiment.max_n_frames=10"], "error: algorithm=vdn experiment.max_n_frames=10 need BenchMARL"),
    ([], 'error: BenchMARL is not installed: pip install torch==2.13.0 -e ".[benchmarl]"'),
    # our own settings are checked first, and named as typed
    (["algorithm=qmix", "env.grid=[0,0]"], "error: env.grid=(0, 0) is invalid"),
    (["algorithm=qmix", "seed=-1"], "error: seed=-1 is invalid"),
    (["env.num_uavs=100000", "env.grid=[1000,1000]"], "error: env.num_uavs=100000 is invalid: the evaluation"),
    (["eval.horizon=100000000000"], "error: eval.horizon=100000000000 is invalid: the evaluation"),
    (["task=uavrl/nope"], "error: task=uavrl/nope is invalid: allowed tasks are"),
    (["run_dir=notes.txt"], "error: run_dir=notes.txt is a file, not a directory"),
]


@pytest.mark.skipif(importlib.util.find_spec("benchmarl") is not None, reason="BenchMARL is installed here")
@pytest.mark.parametrize("arguments, begins", WITHOUT_BENCHMARL, ids=str)
def test_benchmarl_command_without_the_extra_checks_ours_then_says_how_to_install(arguments, begins, tmp_path):
    (tmp_path / "notes.txt").write_text("a user's notes\n")
    done = subprocess.run(
        [sys.executable, "-m", "uavrl.benchmarl", *arguments], capture_output=True, text=True, cwd=tmp_path
    )
    assert done.returncode == 1 and done.stderr.startswith(begins) and done.stderr.count("\n") == 1, done.stderr
