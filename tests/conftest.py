"""Fixtures shared by the test files: the Hydra config as the commands compose it, tiny environments, a killed run."""

from __future__ import annotations

import contextlib
import importlib.util
import runpy
import subprocess
import sys

import pytest
from hydra import compose, initialize_config_dir

from uavrl.config import config_dir

_EPISODE_TAGS = {
    "train/sum_utility",
    "train/sum_r_pu",
    "train/sum_r_se",
    "train/task_switches",
    "train/moves",
    "train/steps_to_90",
    "eval/optimality",
}


def _compose(*overrides: str, config_name: str = "config"):
    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        return compose(config_name=config_name, overrides=list(overrides))


@pytest.fixture
def compose_cfg():
    """``compose_cfg(*overrides, config_name="config")``: the config ``python -m uavrl.train`` would run with."""
    return _compose


@pytest.fixture
def episode_tags():
    """The per-episode TensorBoard scalars every agent writes (``uavrl.agents.episodes.episode_metrics``) and
    ``eval/optimality``."""
    return set(_EPISODE_TAGS)


@pytest.fixture
def one_thread():
    """One torch thread for the test: small tensors run fastest so, and two threads crawl on a busy 2-core machine."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture
def tiny_env():
    """``tiny_env(batch_size=2, **options)``: a :class:`~uavrl.envs.UAVSpectrumEnv` of 2 UAVs on a 3x3 grid."""
    from uavrl.envs import UAVSpectrumEnv

    def make(batch_size: int = 2, **options):
        return UAVSpectrumEnv(batch_size=batch_size, **{"grid": (3, 3), "num_uavs": 2, **options})

    return make


@pytest.fixture
def interrupt_at(monkeypatch):
    """``with interrupt_at(AgentClass, n): ...``: the n-th ``train_iteration`` call raises KeyboardInterrupt.

    As a kill does, it leaves what the last periodic checkpoint saved (a real
    Ctrl-C saves the iteration it interrupts: ``tests/commands/test_interrupts.py``). A
    run killed this way and resumed must end exactly as the uninterrupted run.
    """

    @contextlib.contextmanager
    def interrupted(agent_class, n: int | None):
        original, calls = agent_class.train_iteration, []

        def dies(self):
            calls.append(1)
            if len(calls) == n:
                raise KeyboardInterrupt
            return original(self)

        monkeypatch.setattr(agent_class, "train_iteration", dies)
        try:
            yield
        finally:
            monkeypatch.setattr(agent_class, "train_iteration", original)

    return interrupted


RAY_START_TIMEOUT = "The current node timed out during startup"


@pytest.fixture
def command_exit(monkeypatch):
    """``run(line, cwd)``: the command ``python -m uavrl.<command> [word] progress=false <overrides>`` run in this
    process (for speed) from ``cwd``; returns its exit code (the one error line of a refusal).  ``line`` is a string
    or a list of words; a first argument with no ``=`` that is no flag is the command's word (``reproduce table2``,
    ``render <run dir>``)."""

    def run(line, cwd) -> object:
        command, *args = line.split() if isinstance(line, str) else line
        word = [args.pop(0)] if args and "=" not in args[0] and not args[0].startswith("-") else []
        module = f"uavrl.{command}"
        monkeypatch.chdir(cwd)
        quiet = [] if any(arg.startswith("progress=") for arg in args) else ["progress=false"]  # typed once
        monkeypatch.setattr(sys, "argv", [module, *word, *quiet, *args])
        with pytest.raises(SystemExit) as exit:
            runpy.run_path(importlib.util.find_spec(module).origin, run_name="__main__")
        return exit.value.code

    return run


@pytest.fixture
def hand_built():
    """``hand_built(cfg, codes, battery)``: a :class:`~uavrl.envs.world.World` of one world of ``cfg`` (an energy
    model) started at the configuration ``codes`` (``2 cell + task`` per UAV) with its batteries set by hand."""
    import torch

    from uavrl.envs.world import World

    def build(cfg, codes, battery):
        world = World(cfg, 1)
        world.start_at(torch.tensor([codes]))
        world._s.battery = torch.tensor([battery], dtype=torch.float64)
        return world

    return build


@pytest.fixture(scope="session")
def run_sweep():
    """``run_sweep(directory, *overrides)``: ``python -m uavrl.train -m progress=false <overrides>`` run in
    ``directory``; the run directories it holds then (those with a ``metrics.json``), sorted."""

    def run(directory, *overrides, timeout=600):
        argv = [sys.executable, "-m", "uavrl.train", "-m", "progress=false", *overrides]
        result = subprocess.run(argv, cwd=directory, capture_output=True, text=True, timeout=timeout)
        if RAY_START_TIMEOUT in result.stderr:  # before any job ran: Ray waits a fixed 30 s, too short under load
            result = subprocess.run(argv, cwd=directory, capture_output=True, text=True, timeout=timeout)
        assert result.returncode == 0, result.stderr[-3000:]
        return sorted(path.parent for path in directory.rglob("metrics.json"))

    return run


@pytest.fixture(scope="session")
def tiny_tabular():
    """Overrides of a tabular run of a second or two (a sweep's job in the sweep tests)."""
    return ["agent=tabular", "agent.episodes=2", "env.max_steps=20", "agent.runs=2", "eval.num_starts=4"]


@pytest.fixture
def bench_refusal_before_torch():
    """``run(args)``: ``python -m uavrl.bench <args>`` in a fresh interpreter; its one-line ValueError, and whether
    torch was imported before it (the benchmark checks its settings without torch)."""
    return _bench_refusal


def _bench_refusal(args: list[str]) -> tuple[str, bool]:
    code = (
        "import sys; from uavrl.bench.__main__ import main\n"
        f"try:\n    main({args!r})\nexcept ValueError as err:\n    print(err)\n"
        "print('torch' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    line, torch_loaded = out.strip().splitlines()
    return line, torch_loaded == "True"
