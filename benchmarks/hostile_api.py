"""Hostile input to the Python API, the adapters and the commands' file handling, each case measured in a process.

    python benchmarks/hostile_api.py [--group old|new|cities|all] [--jobs 2] [--timeout S] [--only SURFACE] [--json P]

About a hundred cases on ``load_policy``, ``UAVSpectrumEnv`` (construction, ``reset``, ``step``, ``to``,
``rollout``), the Gymnasium and PettingZoo adapters, ``uavrl.agents.evaluation.evaluate`` and the files that
``reproduce``,
``evaluate`` and ``train`` read and write (the ``old`` group); the ``new`` group holds about a hundred more on the
benchmark in Python (``uavrl.bench.run.score_suite``, its cache, ``uavrl.bench.results.read``, ``save`` and
``markdown``), the leaderboard's page (every string of a results file escaped), ``load_experiment`` (where the
``[benchmarl]`` extra is missing, BenchMARL's names are stand-ins that raise ``BenchmarlStandIn``: the cases still
show how the run directory is read before BenchMARL is reached) and rollouts with no end; the ``cities`` group the
cities of buildings and the altitude levels (the options, the World's queries, the city functions, the adapters).
Each runs in its own process, forked from one that imported torch and
uavrl once (address space capped at ``--memory-gib``, killed after ``--timeout`` seconds, by default 16 GiB and
300 s for the old group, 6 GiB and 60 s for the new; the commands' cases start
``python -m uavrl.<command>`` from there), and is classified as:

- ``typed``: refused by a one-line error of uavrl's own (``InvalidOption``, ``InvalidType``, ``CheckpointError``, ...;
  ``ValueError``/``TypeError`` subclasses) that names the argument;
- ``one line``: refused in one line that names the argument, of Python's own type (``FileNotFoundError``,
  ``FileExistsError``; ``RuntimeError`` for a step before any reset) or as a command's ``error:`` line;
- ``honoured``: accepted, and the case checked that it did what was asked (a seed that seeds, a file written beside);
- ``traceback``: a foreign exception, a message of several lines or one that does not name the argument;
- ``hang``, ``OOM``, ``silent accept`` (accepted and ignored or wrong), ``data loss`` (a user's file gone or changed).

The first run trains a tiny baseline run (3x3, the random agent) that the cases read (for the new group also scores
the random policy on the tiny suite's first task: a results file and a filled cache); cases that change files work on
copies.  Prints one line per case as it ends, then the table of counts per group and surface and the median time to a
refusal per group.  Needs the [gym] extra for the adapters' cases and the [bench] extra for the new group.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

CLASSES = ("typed", "one line", "honoured", "traceback", "hang", "OOM", "silent accept", "data loss")

# run in every case's process before the case: the names the cases use
PRELUDE = """
import json, os, re, shutil, subprocess, sys
from pathlib import Path
import numpy as np
import torch
from tensordict import TensorDict
import uavrl
from uavrl import load_policy
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.agents.evaluation import evaluate

RUN = Path(os.environ["HOSTILE_RUN"])
CFG = make_config("paper", grid=(3, 3), num_uavs=2)
OUTCOME = None

def env(**options):
    return UAVSpectrumEnv(batch_size=2, grid=(3, 3), num_uavs=2, **options)

def stepped(tensordict, environment=None):
    environment = environment or env()
    environment.reset()
    return environment.step(tensordict)

def action(a, device=None):
    return TensorDict({"agents": TensorDict({"action": a}, batch_size=[2], device=device)}, [2], device=device)

def fresh_run():
    return Path(shutil.copytree(RUN, TMP / "run"))

def policy():
    return load_policy(RUN)[0]

def gym(**kw):
    from uavrl.envs.adapters.gym_env import UAVSpectrumGymEnv
    return UAVSpectrumGymEnv(grid=(3, 3), **kw)

def vector(n=2, **kw):
    from uavrl.envs.adapters.gym_env import UAVSpectrumVectorEnv
    return UAVSpectrumVectorEnv(n, grid=(3, 3), **kw)

def parallel(**kw):
    from uavrl.envs.adapters.pettingzoo_env import UAVSpectrumParallelEnv
    return UAVSpectrumParallelEnv(grid=(3, 3), **kw)

def command(*args, progress=True):
    '''python -m uavrl.<args>, in TMP: its exit status and what it printed to stderr.'''
    argv = [sys.executable, "-m", *args, *(["progress=false"] if progress else [])]
    done = subprocess.run(argv, cwd=TMP, capture_output=True, text=True)
    global COMMAND
    COMMAND = {"rc": done.returncode, "stderr": done.stderr[-3000:]}
    return done.returncode

def user_files(folder, names=("notes.txt", "fig_mine.png", "tensorboard/notes.txt")):
    '''A user's files in ``folder``; returns a check that they are all still there, unchanged.'''
    for name in names:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text("mine: " + name)
    return lambda: all((folder / n).is_file() and (folder / n).read_bytes() == b"mine: " + n.encode() for n in names)

def kept(check):
    global OUTCOME
    if OUTCOME is None and not check():
        OUTCOME = "data loss"

def verdict(ok):
    global OUTCOME
    if OUTCOME is None:  # a data loss found first stays one
        OUTCOME = "honoured" if ok else "silent accept"

SMALL = ["grids=[2]", "runs=1", "episodes=2", "eval_starts=4"]
EVAL = ["eval.num_starts=2", "eval.horizon=6"]

# the new group's names: our results file and the references' cache it filled, made once (main), read by the cases
RESULTS = Path(os.environ.get("HOSTILE_RESULTS", "no-results"))
CACHE = Path(os.environ.get("HOSTILE_CACHE", "no-cache"))
MARKER = "<!-- generated by python -m uavrl.bench leaderboard: edit above this line only -->"

def ours():
    return json.loads(RESULTS.read_text())

def written(results, name="r.json"):
    '''``results`` as the file TMP/name (NaN written as JSON's NaN).'''
    path = TMP / name
    path.write_text(results if isinstance(results, str) else json.dumps(results))
    return path

def sparse(path):
    '''A 20 GB sparse file at ``path``.'''
    with open(path, "wb") as handle:
        handle.truncate(20 * 2**30)
    return path

def cache(change=None):
    '''This case's copy of the filled cache; ``change(entry path)`` damages its entry.'''
    copy = Path(shutil.copytree(CACHE, TMP / "cache"))
    if change:
        change(next(copy.glob("*.json")))
    return copy

def resigned(change):
    '''A cache entry whose payload ``change`` alters, its checksum recomputed as anyone can.'''
    def damage(entry):
        import hashlib
        stored = json.loads(entry.read_text())
        change(stored["payload"])
        stored["sha256"] = hashlib.sha256(json.dumps(stored["payload"], sort_keys=True).encode()).hexdigest()
        entry.write_text(json.dumps(stored))
    return damage

def replaced(make):
    '''A cache entry replaced by what ``make(path)`` puts there (a FIFO, a link).'''
    def damage(entry):
        entry.unlink()
        make(entry)
    return damage

def random_factory(env):
    from uavrl.agents.baselines import RandomPolicy
    return RandomPolicy(seed=0)

def score(factory=random_factory, **options):
    '''score_suite on the tiny suite's first task with this case's copy of the cache, ``options`` changed.'''
    from uavrl.bench.run import score_suite
    options = {"name": "hostile", "tasks": ["tiny_3x3"], **options}
    if "cache_dir" not in options:
        options["cache_dir"] = cache()
    return score_suite(options.pop("suite", "tiny"), factory, **options)

def recomputed(directory):
    '''score_suite over a damaged cache ``directory``: honoured when it says, in one warning, that it recomputed the
    damaged entry and rewrote it (the cache is the benchmark's own derived data: docs/leaderboard.md).'''
    import contextlib, io, re
    said = io.StringIO()
    with contextlib.redirect_stderr(said):
        score(cache_dir=directory)
    warning = r"^warning: the references' cache entry .* is damaged \\(.*\\): recomputed and rewritten$"
    verdict(bool(re.match(warning, said.getvalue().strip())))

def in_code(page, text):
    '''``text`` shows in ``page`` only inside inline code spans (where Markdown makes no markup of it).'''
    import re
    spans = [m.group(2) for m in re.finditer(r"(`+)(.+?)\\1", page)]
    return page.count(text) == sum(span.count(text) for span in spans)

def acting(function):
    '''A factory of the TorchRL policy ``action = function(action_mask)``.'''
    from tensordict.nn import TensorDictModule
    return lambda env: TensorDictModule(function, in_keys=[("agents", "action_mask")], out_keys=[("agents", "action")])

PAPER = Path(uavrl.__file__).resolve().parents[1] / "benchmarks/results/leaderboard/paper-benchmarl-mappo.json"

def full(**submission):
    '''A committed full-protocol results file of suite paper (the kind the leaderboard shows), its submission
    changed.'''
    results = json.loads(PAPER.read_text())
    results["submission"].update(submission)
    return results

def page_kept(results, check):
    '''python -m uavrl.bench leaderboard over ``results``: honoured when it refuses the file or its page passes
    ``check(page text)``.'''
    folder = TMP / "lb"
    folder.mkdir()
    (folder / "hostile.json").write_text(json.dumps(results))
    if command("uavrl.bench", "leaderboard", f"results={folder}", f"out={TMP / 'page.md'}", progress=False) == 0:
        verdict(check((TMP / "page.md").read_text()))

def saved_beside(name, user_names):
    '''results.save(ours, TMP/name) beside a user's files ``user_names``: data loss when one changed.'''
    from uavrl.bench.results import save
    ok = user_files(TMP, user_names)
    save(ours(), TMP / name)
    kept(ok)
    verdict(True)

class BenchmarlStandIn(Exception):
    '''Raised where a load_experiment case reaches BenchMARL itself, which is not installed here.'''

def load_experiment(run_dir):
    '''uavrl.experiment.benchmarl.load_experiment; without the [benchmarl] extra BenchMARL's names are stand-ins that
    raise BenchmarlStandIn, so a case still shows how the run directory is read before BenchMARL is reached.'''
    import importlib.util, types
    if importlib.util.find_spec("benchmarl") is None and "benchmarl" not in sys.modules:
        def reached(*args, **kwargs):
            raise BenchmarlStandIn("the case reached BenchMARL (a stand-in here: the [benchmarl] extra is missing)")
        names = ("benchmarl", "benchmarl.environments", "benchmarl.environments.common", "benchmarl.experiment",
                 "benchmarl.experiment.callback", "benchmarl.hydra_config")
        modules = {name: types.ModuleType(name) for name in names}
        modules["benchmarl.environments.common"].TaskClass = type("TaskClass", (), {})
        modules["benchmarl.experiment.callback"].Callback = type("Callback", (), {})
        modules["benchmarl.experiment"].Experiment = reached
        for loader in ("experiment", "algorithm", "model"):
            setattr(modules["benchmarl.hydra_config"], f"load_{loader}_config_from_hydra", reached)
        sys.modules.update(modules)
    from uavrl.experiment.benchmarl import load_experiment as load
    return load(run_dir)

def benchmarl_run(metrics=None, config=None):
    '''A directory shaped as a python -m uavrl.benchmarl run: metrics.json, config.yaml, one checkpoint.'''
    run = TMP / "bm"
    (run / "mappo_x" / "checkpoints").mkdir(parents=True)
    torch.save({}, run / "mappo_x" / "checkpoints" / "checkpoint_600.pt")
    (run / "metrics.json").write_text(metrics if metrics is not None else json.dumps({"agent": "benchmarl_mappo"}))
    (run / "config.yaml").write_text(config if config is not None else "task:\\n  name: paper_6x6\\n")
    return run
"""

# (surface, what is typed, the argument the refusal must name, the case's code)
CASES = [
    # ------------------------------------------------------------------ load_policy
    ("load_policy", "run_dir=b'bytes'", "run_dir", "load_policy(bytes(RUN))"),
    ("load_policy", "run_dir=['run']", "run_dir", "load_policy([str(RUN)])"),
    ("load_policy", "run_dir='' (the working directory)", "run_dir", "os.chdir(TMP); load_policy('')"),
    ("load_policy", "run_dir=a folder with no checkpoint", "run_dir", "load_policy(TMP)"),
    ("load_policy", "run_dir=the run's config.yaml", "run_dir", "load_policy(RUN / 'config.yaml')"),
    ("load_policy", "checkpoint.pt a directory", "checkpoint.pt",
     "r = fresh_run(); (r / 'checkpoint.pt').unlink(); (r / 'checkpoint.pt').mkdir(); load_policy(r)"),
    ("load_policy", "checkpoint.pt -> /dev/zero", "checkpoint.pt",
     "r = fresh_run(); (r / 'checkpoint.pt').unlink(); (r / 'checkpoint.pt').symlink_to('/dev/zero'); load_policy(r)"),
    ("load_policy", "run_dir=a FIFO checkpoint.pt given as the file", "checkpoint.pt",
     "os.mkfifo(TMP / 'checkpoint.pt'); load_policy(TMP / 'checkpoint.pt')"),
    ("load_policy", "checkpoint.pt of 0 bytes", "checkpoint.pt",
     "r = fresh_run(); (r / 'checkpoint.pt').write_bytes(b''); load_policy(r)"),
    ("load_policy", "checkpoint.pt of random bytes", "checkpoint.pt",
     "r = fresh_run(); (r / 'checkpoint.pt').write_bytes(os.urandom(4096)); load_policy(r)"),
    ("load_policy", "checkpoint.pt holding a list", "checkpoint.pt",
     "r = fresh_run(); torch.save([1, 2], r / 'checkpoint.pt'); load_policy(r)"),
    ("load_policy", "checkpoint.pt whose agent is a str", "checkpoint.pt",
     "r = fresh_run(); s = torch.load(r / 'checkpoint.pt', weights_only=False); s['agent'] = 'x'; "
     "torch.save(s, r / 'checkpoint.pt'); load_policy(r)"),
    ("load_policy", "checkpoint.pt whose config names agent 'nope'", "checkpoint.pt",
     "r = fresh_run(); s = torch.load(r / 'checkpoint.pt', weights_only=False); s['config']['agent']['name'] = 'nope'; "
     "torch.save(s, r / 'checkpoint.pt'); load_policy(r)"),
    ("load_policy", "device=torch.device('meta')", "device", "load_policy(RUN, device=torch.device('meta'))"),
    ("load_policy", "device=None", "device", "load_policy(RUN, device=None)"),
    ("load_policy", "device='cuda:-1'", "device", "load_policy(RUN, device='cuda:-1')"),
    ("load_policy", "device=[0]", "device", "load_policy(RUN, device=[0])"),
    ("load_policy", "run=0.0", "run", "load_policy(RUN, run=0.0)"),
    ("load_policy", "run=10**30", "run", "load_policy(RUN, run=10**30)"),
    ("load_policy", "run=np.int64(0) (honoured)", "run",
     "p, c = load_policy(RUN, run=np.int64(0)); verdict(c.grid == (3, 3))"),
    ("load_policy", "env_config=4x4 for a baseline of 3x3", "env_config",
     "load_policy(RUN, env_config=make_config('paper', grid=(4, 4)))"),
    ("load_policy", "env_config=ModelConfig (the class)", "env_config",
     "from uavrl.envs import ModelConfig; load_policy(RUN, env_config=ModelConfig)"),
    ("load_policy", "env_config=(3, 3)", "env_config", "load_policy(RUN, env_config=(3, 3))"),
    # ------------------------------------------------------------------ UAVSpectrumEnv: construction
    ("UAVSpectrumEnv", "batch_size=0", "batch_size", "UAVSpectrumEnv(batch_size=0)"),
    ("UAVSpectrumEnv", "batch_size=-1", "batch_size", "UAVSpectrumEnv(batch_size=-1)"),
    ("UAVSpectrumEnv", "batch_size=(2, 2)", "batch_size", "UAVSpectrumEnv(batch_size=(2, 2))"),
    ("UAVSpectrumEnv", "batch_size='4'", "batch_size", "UAVSpectrumEnv(batch_size='4')"),
    ("UAVSpectrumEnv", "grid=(3,)", "grid", "UAVSpectrumEnv(grid=(3,))"),
    ("UAVSpectrumEnv", "grid='3x3'", "grid", "UAVSpectrumEnv(grid='3x3')"),
    ("UAVSpectrumEnv", "grid=(3.5, 3)", "grid", "UAVSpectrumEnv(grid=(3.5, 3))"),
    ("UAVSpectrumEnv", "grid=(0, 3)", "grid", "UAVSpectrumEnv(grid=(0, 3))"),
    ("UAVSpectrumEnv", "num_uavs=0", "num_uavs", "UAVSpectrumEnv(num_uavs=0)"),
    ("UAVSpectrumEnv", "num_uavs=10 on 3x3", "num_uavs", "UAVSpectrumEnv(grid=(3, 3), num_uavs=10)"),
    ("UAVSpectrumEnv", "num_uavs='2'", "num_uavs", "UAVSpectrumEnv(num_uavs='2')"),
    ("UAVSpectrumEnv", "max_steps=0", "max_steps", "UAVSpectrumEnv(max_steps=0)"),
    ("UAVSpectrumEnv", "max_steps=2.5", "max_steps", "UAVSpectrumEnv(max_steps=2.5)"),
    ("UAVSpectrumEnv", "preset='nope'", "preset", "UAVSpectrumEnv(preset='nope')"),
    ("UAVSpectrumEnv", "preset=None", "preset", "UAVSpectrumEnv(preset=None)"),
    ("UAVSpectrumEnv", "seed=1.5", "seed", "UAVSpectrumEnv(seed=1.5)"),
    ("UAVSpectrumEnv", "seed=2**64", "seed", "UAVSpectrumEnv(seed=2**64)"),
    ("UAVSpectrumEnv", "device=torch.device('meta')", "device", "UAVSpectrumEnv(device=torch.device('meta'))"),
    ("UAVSpectrumEnv", "memory_budget=-1", "memory_budget", "UAVSpectrumEnv(memory_budget=-1)"),
    ("UAVSpectrumEnv", "memory_budget='1GB'", "memory_budget", "UAVSpectrumEnv(memory_budget='1GB')"),
    ("UAVSpectrumEnv", "layout='circle'", "layout", "UAVSpectrumEnv(layout='circle')"),
    ("UAVSpectrumEnv", "fading='nakagami'", "fading", "UAVSpectrumEnv(fading='nakagami')"),
    ("UAVSpectrumEnv", "p_u=nan", "p_u", "UAVSpectrumEnv(p_u=float('nan'))"),
    ("UAVSpectrumEnv", "channel=3", "channel", "UAVSpectrumEnv(channel=3)"),
    ("UAVSpectrumEnv", "config= with grid=(4, 4)", "grid", "UAVSpectrumEnv(config=CFG, grid=(4, 4))"),
    ("UAVSpectrumEnv", "config= with max_steps=7", "max_steps", "UAVSpectrumEnv(config=CFG, max_steps=7)"),
    ("UAVSpectrumEnv", "diagnostics=None", "diagnostics", "UAVSpectrumEnv(diagnostics=None)"),
    ("UAVSpectrumEnv", "agent_rewards='true'", "agent_rewards", "UAVSpectrumEnv(agent_rewards='true')"),
    # ------------------------------------------------------------------ UAVSpectrumEnv: reset, step, to, rollout
    ("reset/step/to", "reset(seed=-5)", "seed", "env().reset(seed=-5)"),
    ("reset/step/to", "reset(seed=True)", "seed", "env().reset(seed=True)"),
    ("reset/step/to", "reset(seed=3) twice (honoured)", "seed",
     "e = env(); a = e.reset(seed=3)['positions']; e.rollout(3); "
     "verdict(torch.equal(a, e.reset(seed=3)['positions']))"),
    ("reset/step/to", "reset(tensordict=5)", "tensordict", "env().reset(5)"),
    ("reset/step/to", "reset '_reset' of floats", "_reset",
     "env().reset(TensorDict(_reset=torch.ones(2), batch_size=[2]))"),
    ("reset/step/to", "reset '_reset' on meta", "_reset",
     "env().reset(TensorDict(_reset=torch.ones(2, dtype=torch.bool, device='meta'), batch_size=[2]))"),
    ("reset/step/to", "reset(options={})", "options", "env().reset(options={})"),
    ("reset/step/to", "reset(max_steps=5)", "max_steps", "env().reset(max_steps=5)"),
    ("reset/step/to", "step before reset", "reset", "env().step(action(torch.zeros(2, 2, dtype=torch.long)))"),
    ("reset/step/to", "action int32 (honoured)", "action",
     "td = stepped(action(torch.ones(2, 2, dtype=torch.int32))); verdict(td['next', 'positions'].shape == (2, 2, 2))"),
    ("reset/step/to", "action uint8 255", "action", "stepped(action(torch.full((2, 2), 255, dtype=torch.uint8)))"),
    ("reset/step/to", "action [2, 2, 1]", "action", "stepped(action(torch.zeros(2, 2, 1, dtype=torch.long)))"),
    ("reset/step/to", "action [2]", "action", "stepped(action(torch.zeros(2, dtype=torch.long)))"),
    ("reset/step/to", "action complex", "action", "stepped(action(torch.zeros(2, 2, dtype=torch.complex64)))"),
    ("reset/step/to", "action nan", "action", "stepped(action(torch.full((2, 2), float('nan'))))"),
    ("reset/step/to", "action a non-tensor", "action",
     "td = TensorDict({'agents': TensorDict({}, [2])}, [2]); td['agents'].set_non_tensor('action', 'up'); stepped(td)"),
    ("reset/step/to", "step(td of batch [])", "tensordict", "stepped(TensorDict({}, []))"),
    ("reset/step/to", "step(td of batch [3])", "tensordict", "stepped(TensorDict({}, [3]))"),
    ("reset/step/to", "step(None)", "tensordict", "stepped(None)"),
    ("reset/step/to", "to(None)", "device", "env().to(None)"),
    ("reset/step/to", "to(123)", "device", "env().to(123)"),
    ("reset/step/to", "to('cpu:0') (honoured)", "device", "verdict(env().to('cpu:0').device.type == 'cpu')"),
    ("reset/step/to", "rollout(0)", "max_steps", "env().rollout(0)"),
    ("reset/step/to", "rollout(2.5)", "max_steps", "env().rollout(2.5)"),
    ("reset/step/to", "optimum(method='nope')", "method", "env().optimum(method='nope')"),
    ("reset/step/to", "render(env_index=5)", "env_index", "e = env(); e.reset(); e.render(env_index=5)"),
    ("reset/step/to", "render(mode='human')", "mode", "e = env(); e.reset(); e.render(mode='human')"),
    # ------------------------------------------------------------------ adapters
    ("adapters", "Gymnasium step before reset", "reset", "gym().step([0, 0])"),
    ("adapters", "Gymnasium step('01')", "action", "g = gym(); g.reset(); g.step('01')"),
    ("adapters", "Gymnasium step(None)", "action", "g = gym(); g.reset(); g.step(None)"),
    ("adapters", "Gymnasium step(uint64 [1, 1]) (honoured)", "action",
     "g = gym(); g.reset(); out = g.step(np.array([1, 1], dtype=np.uint64)); verdict(len(out) == 5)"),
    ("adapters", "Gymnasium reset(seed=-1)", "seed", "gym().reset(seed=-1)"),
    ("adapters", "Gymnasium reset(seed=1.0)", "seed", "gym().reset(seed=1.0)"),
    ("adapters", "Gymnasium num_uavs=20 on 3x3", "num_uavs", "gym(num_uavs=20)"),
    ("adapters", "Gymnasium render_mode='rgb_array_list'", "render_mode", "gym(render_mode='rgb_array_list')"),
    ("adapters", "Gymnasium config= with grid=(4, 4)", "grid",
     "from uavrl.envs.adapters.gym_env import UAVSpectrumGymEnv; UAVSpectrumGymEnv(grid=(4, 4), config=CFG)"),
    ("adapters", "vector num_envs=0", "num_envs", "vector(0)"),
    ("adapters", "vector num_envs=2.0", "num_envs", "vector(2.0)"),
    ("adapters", "vector step([2, 2, 1])", "actions", "v = vector(); v.reset(); v.step(np.zeros((2, 2, 1), int))"),
    ("adapters", "vector reset(seed=[1, 2])", "seed", "vector().reset(seed=[1, 2])"),
    ("adapters", "vector reset(options={'reset_mask': ...})", "options",
     "vector().reset(options={'reset_mask': np.ones(2, bool)})"),
    ("adapters", "PettingZoo step with 'up'", "actions",
     "p = parallel(); p.reset(); p.step({'uav_0': 'up', 'uav_1': 0})"),
    ("adapters", "PettingZoo step before reset", "reset", "parallel().step({'uav_0': 0, 'uav_1': 0})"),
    ("adapters", "PettingZoo observation_space('uav_9')", "agent", "parallel().observation_space('uav_9')"),
    ("adapters", "PettingZoo action_space(0)", "agent", "parallel().action_space(0)"),
    ("adapters", "PettingZoo reset(seed='x')", "seed", "parallel().reset(seed='x')"),
    ("adapters", "PettingZoo step(None)", "actions", "p = parallel(); p.reset(); p.step(None)"),
    # ------------------------------------------------------------------ evaluate
    ("evaluate()", "num_starts=10**9", "num_starts", "evaluate(policy(), CFG, num_starts=10**9)"),
    ("evaluate()", "horizon=0", "horizon", "evaluate(policy(), CFG, horizon=0)"),
    ("evaluate()", "gamma=nan", "gamma", "evaluate(policy(), CFG, gamma=float('nan'))"),
    ("evaluate()", "memory_budget=0", "memory_budget", "evaluate(policy(), CFG, memory_budget=0)"),
    ("evaluate()", "memory_budget='x'", "memory_budget", "evaluate(policy(), CFG, memory_budget='x')"),
    ("evaluate()", "a policy that writes no action", "action", "evaluate(lambda td: td, CFG, num_starts=2)"),
    ("evaluate()", "a 3x3 policy on 4x4", "grid", "evaluate(policy(), make_config('paper', grid=(4, 4)))"),
    ("evaluate()", "seed=2**63", "seed", "evaluate(policy(), CFG, seed=2**63)"),
    ("evaluate()", "device=None", "device", "evaluate(policy(), CFG, device=None)"),
    ("evaluate()", "cfg='paper'", "cfg", "evaluate(policy(), 'paper')"),
    # ------------------------------------------------------------------ files the commands read and write
    ("files", "reproduce: variant.json -> /dev/zero", "variant.json",
     "o = TMP / 'o'; o.mkdir(); (o / 'variant.json').symlink_to('/dev/zero'); "
     "command('uavrl.reproduce', 'table2', *SMALL, f'out_dir={o}')"),
    ("files", "reproduce: variant.json {}", "out_dir",
     "o = TMP / 'o'; o.mkdir(); (o / 'variant.json').write_text('{}'); "
     "command('uavrl.reproduce', 'table2', *SMALL, f'out_dir={o}')"),
    ("files", "reproduce overwrite: a record naming ../victim", "uavrl-written",
     "o = TMP / 'o'; o.mkdir(); v = TMP / 'victim'; v.write_text('mine: victim'); "
     "(o / '.uavrl-written.json').write_text(json.dumps(['../victim'])); "
     "command('uavrl.reproduce', 'table2', *SMALL, f'out_dir={o}', 'overwrite=true'); "
     "kept(lambda: v.read_text() == 'mine: victim')"),
    ("files", "reproduce overwrite: tensorboard/ a link to a user's folder", "out_dir",
     "o = TMP / 'o'; o.mkdir(); u = TMP / 'users'; ok = user_files(u, ('grid2x2/x',)); "
     "(o / 'tensorboard').symlink_to(u); "
     "(o / '.uavrl-written.json').write_text(json.dumps(['tensorboard/grid2x2/x'])); "
     "rc = command('uavrl.reproduce', 'table2', *SMALL, f'out_dir={o}', 'overwrite=true'); kept(ok); verdict(rc == 0)"),
    ("files", "reproduce figures: a FIFO history_2x2.pt", "history_2x2.pt",
     "o = TMP / 'o'; command('uavrl.reproduce', 'table2', *SMALL, f'out_dir={o}'); (o / 'history_2x2.pt').unlink(); "
     "os.mkfifo(o / 'history_2x2.pt'); command('uavrl.reproduce', 'figures', *SMALL, 'figure_grid=2', f'out_dir={o}')"),
    ("files", "reproduce: a FIFO .uavrl-written.json", "uavrl-written",
     "o = TMP / 'o'; o.mkdir(); os.mkfifo(o / '.uavrl-written.json'); (o / 'variant.json').write_text('{}'); "
     "command('uavrl.reproduce', 'table2', *SMALL, f'out_dir={o}', 'overwrite=true')"),
    ("files", "reproduce overwrite into a run (honoured: its files kept)", "out_dir",
     "r = fresh_run(); ok = user_files(r); "
     "before = {p.name: p.read_bytes() for p in r.iterdir() if p.is_file() and not p.name.startswith('.')}; "
     "rc = command('uavrl.reproduce', 'table2', *SMALL, f'out_dir={r}', 'overwrite=true'); "
     "kept(lambda: ok() and all((r / n).read_bytes() == b for n, b in before.items())); verdict(rc == 0)"),
    ("files", "evaluate: eval.json a directory (honoured: beside it)", "checkpoint",
     "r = fresh_run(); (r / 'eval.json').mkdir(); rc = command('uavrl.evaluate', f'checkpoint={r}', *EVAL); "
     "verdict(rc == 0 and (r / 'eval-2.json').is_file())"),
    ("files", "evaluate: a damaged .uavrl-evaluations.json (honoured)", "checkpoint",
     "r = fresh_run(); (r / 'eval.json').write_text('mine: eval.json'); "
     "(r / '.uavrl-evaluations.json').write_text('['); rc = command('uavrl.evaluate', f'checkpoint={r}', *EVAL); "
     "kept(lambda: (r / 'eval.json').read_text() == 'mine: eval.json'); verdict(rc == 0)"),
    ("files", "evaluate: eval.json a link to a user's file", "checkpoint",
     "r = fresh_run(); u = TMP / 'mine.json'; u.write_text('mine: json'); (r / 'eval.json').symlink_to(u); "
     "rc = command('uavrl.evaluate', f'checkpoint={r}', *EVAL); kept(lambda: u.read_text() == 'mine: json'); "
     "verdict(rc == 0)"),
    ("files", "evaluate twice, other seeds (honoured: both kept)", "checkpoint",
     "r = fresh_run(); command('uavrl.evaluate', f'checkpoint={r}', *EVAL); first = (r / 'eval.json').read_text(); "
     "command('uavrl.evaluate', f'checkpoint={r}', *EVAL, 'eval.seed=9'); "
     "kept(lambda: (r / 'eval.json').read_text() == first); verdict((r / 'eval-2.json').is_file())"),
    ("files", "evaluate: checkpoint.pt -> /dev/zero", "checkpoint",
     "r = fresh_run(); (r / 'checkpoint.pt').unlink(); (r / 'checkpoint.pt').symlink_to('/dev/zero'); "
     "command('uavrl.evaluate', f'checkpoint={r}', *EVAL)"),
    ("files", "evaluate: only a FIFO checkpoint.prev.pt", "checkpoint",
     "r = fresh_run(); (r / 'checkpoint.pt').unlink(); os.mkfifo(r / 'checkpoint.prev.pt'); "
     "command('uavrl.evaluate', f'checkpoint={r}', *EVAL)"),
    ("files", "evaluate: checkpoint= a socket", "checkpoint",
     "import socket; s = socket.socket(socket.AF_UNIX); s.bind(str(TMP / 'sock')); "
     "command('uavrl.evaluate', f'checkpoint={TMP / \"sock\"}', *EVAL)"),
    ("files", "train: run_dir a FIFO", "run_dir",
     "os.mkfifo(TMP / 'f'); command('uavrl.train', 'agent=random', f'run_dir={TMP / \"f\"}', *EVAL)"),
    ("files", "train: run_dir holding a user's metrics.json", "run_dir",
     "d = TMP / 'd'; ok = user_files(d, ('metrics.json',)); "
     "command('uavrl.train', 'agent=random', 'env.grid=[3,3]', f'run_dir={d}', *EVAL); kept(ok)"),
    ("files", "train: run_dir holding a user's config.yaml", "run_dir",
     "d = TMP / 'd'; ok = user_files(d, ('config.yaml',)); "
     "command('uavrl.train', 'agent=random', 'env.grid=[3,3]', f'run_dir={d}', *EVAL); kept(ok)"),
    ("files", "train: resume= a run whose .uavrl.lock.holder is a FIFO (honoured)", "resume",
     "r = fresh_run(); os.mkfifo(r / '.uavrl.lock.holder'); rc = command('uavrl.train', f'resume={r}'); "
     "verdict(rc == 0 and not os.path.lexists(r / '.uavrl.lock.holder'))"),
]  # fmt: skip

# the new group: the benchmark in Python (score_suite, results.read/save/markdown), the leaderboard's page,
# load_experiment, and a rollout with no end
NEW_CASES = [
    # ------------------------------------------------------------------ score_suite: the policy factory
    ("score_suite", "policy_factory returning None", "policy", "score(lambda env: None)"),
    ("score_suite", "policy_factory returning 'random'", "policy", "score(lambda env: 'random')"),
    ("score_suite", "policy_factory returning []", "policy", "score(lambda env: [])"),
    ("score_suite", "policy_factory='oracle'", "policy_factory", "score('oracle')"),
    ("score_suite", "policy_factory=None", "policy_factory", "score(None)"),
    ("score_suite", "a policy playing only masked actions", "action",
     "score(acting(lambda mask: (~mask).long().argmax(-1)))"),
    ("score_suite", "a policy writing actions 2.7", "action",
     "score(acting(lambda mask: torch.full(mask.shape[:-1], 2.7)))"),
    ("score_suite", "a policy writing action 7", "action",
     "score(acting(lambda mask: torch.full(mask.shape[:-1], 7, dtype=torch.long)))"),
    ("score_suite", "a policy writing actions of shape [B]", "action",
     "score(acting(lambda mask: torch.zeros(mask.shape[0], dtype=torch.long)))"),
    # ------------------------------------------------------------------ score_suite: its other arguments
    ("score_suite", "suite='TINY'", "suite", "score(suite='TINY')"),
    ("score_suite", "suite=None", "suite", "score(suite=None)"),
    ("score_suite", "suite=['tiny']", "suite", "score(suite=['tiny'])"),
    ("score_suite", "name=None", "name", "score(name=None)"),
    ("score_suite", "name=''", "name", "score(name='')"),
    ("score_suite", "name=5", "name", "score(name=5)"),
    ("score_suite", "name='a\\nb'", "name", "score(name='a\\nb')"),
    ("score_suite", "budget={'env_steps': -5, 'cpu_seconds': nan}", "budget",
     "score(budget={'env_steps': -5, 'cpu_seconds': float('nan')})"),
    ("score_suite", "budget={'env_steps': 2.7}", "budget", "score(budget={'env_steps': 2.7})"),
    ("score_suite", "budget={'steps': 100}", "budget", "score(budget={'steps': 100})"),
    ("score_suite", "budget='1000'", "budget", "score(budget='1000')"),
    ("score_suite", "budget={'env_steps': True}", "budget", "score(budget={'env_steps': True})"),
    ("score_suite", "budget={'gpu_seconds': inf}", "budget", "score(budget={'gpu_seconds': float('inf')})"),
    ("score_suite", "tasks=[]", "tasks", "score(tasks=[])"),
    ("score_suite", "tasks='tiny_3x3'", "tasks", "score(tasks='tiny_3x3')"),
    ("score_suite", "tasks=['tiny_3x3', 'tiny_3x3']", "tasks", "score(tasks=['tiny_3x3', 'tiny_3x3'])"),
    ("score_suite", "tasks=['paper_6x6'] (another suite's)", "tasks", "score(tasks=['paper_6x6'])"),
    ("score_suite", "progress='yes'", "progress", "score(progress='yes')"),
    ("score_suite", "train_command=123", "train_command", "score(train_command=123)"),
    ("score_suite", "source=None", "source", "score(source=None)"),
    # ------------------------------------------------------------------ score_suite: the references' cache
    ("score_suite", "cache_dir=a file", "cache_dir", "(TMP / 'f').write_text('x'); score(cache_dir=TMP / 'f')"),
    ("score_suite", "cache_dir=''", "cache_dir", "score(cache_dir='')"),
    ("score_suite", "cache_dir=123", "cache_dir", "score(cache_dir=123)"),
    ("score_suite", "cache entry a FIFO", "cache", "recomputed(cache(replaced(os.mkfifo)))"),
    ("score_suite", "cache entry -> /dev/zero", "cache",
     "recomputed(cache(replaced(lambda p: p.symlink_to('/dev/zero'))))"),
    ("score_suite", "cache entry a 20 GB sparse file", "cache", "recomputed(cache(replaced(sparse)))"),
    ("score_suite", "cache entry re-signed: reference values of text", "cache",
     "recomputed(cache(resigned(lambda p: p['reference'].update(values=['x'] * 32))))"),
    ("score_suite", "cache entry re-signed: random values a dict", "cache",
     "recomputed(cache(resigned(lambda p: p['baselines']['random'].update(values={'a': 1}))))"),
    ("score_suite", "cache entry re-signed: reference NaN", "cache",
     "recomputed(cache(resigned(lambda p: p['reference'].update(values=[float('nan')] * 32))))"),
    ("score_suite", "cache entry re-signed: starts of another dtype", "cache",
     "recomputed(cache(resigned(lambda p: p['starts']['best_return'].update(dtype='__class__'))))"),
    ("score_suite", "cache entry re-signed: payload a list", "cache",
     "recomputed(cache(resigned(lambda p: p.clear())))"),
    # ------------------------------------------------------------------ results.read
    ("results.read", "a FIFO", "r.json", "from uavrl.bench.results import read; os.mkfifo(TMP / 'r.json'); "
     "read(TMP / 'r.json')"),
    ("results.read", "a link to /dev/zero", "r.json",
     "from uavrl.bench.results import read; (TMP / 'r.json').symlink_to('/dev/zero'); read(TMP / 'r.json')"),
    ("results.read", "a 20 GB sparse file", "r.json",
     "from uavrl.bench.results import read; read(sparse(TMP / 'r.json'))"),
    ("results.read", "a directory", "tmp", "from uavrl.bench.results import read; read(TMP)"),
    ("results.read", "path=None", "path", "from uavrl.bench.results import read; read(None)"),
    ("results.read", "nested 100,000 deep", "r.json",
     "from uavrl.bench.results import read; read(written('{\"format\": \"uavrl-bench-results\", \"version\": 1, "
     "\"tasks\": ' + '[' * 100000 + ']' * 100000 + '}'))"),
    ("results.read", "format and version, no suite", "suite",
     "from uavrl.bench.results import read; r = ours(); r.pop('suite'); read(written(r))"),
    ("results.read", "version true", "version",
     "from uavrl.bench.results import read; r = ours(); r['version'] = True; read(written(r))"),
    ("results.read", "an IQM of NaN", "iqm",
     "from uavrl.bench.results import read; r = ours(); r['aggregate']['iqm'] = float('nan'); read(written(r))"),
    ("results.read", "tasks a string", "tasks",
     "from uavrl.bench.results import read; r = ours(); r['tasks'] = 'tiny_3x3'; read(written(r))"),
    ("results.read", "an unknown suite", "suite",
     "from uavrl.bench.results import read; r = ours(); r['suite'] = 'nope'; read(written(r))"),
    ("results.read", "a run's metrics.json", "metrics.json",
     "from uavrl.bench.results import read; read(RUN / 'metrics.json')"),
    # ------------------------------------------------------------------ results.save
    ("results.save", "report.json beside a user's report.md", "report", "saved_beside('report.json', ('report.md',))"),
    ("results.save", "report.json beside a user's report.png", "report",
     "saved_beside('report.json', ('report.png',))"),
    ("results.save", "a user's notes.md", "notes.md", "saved_beside('notes.md', ('notes.md',))"),
    ("results.save", "a run's metrics.json", "metrics.json",
     "from uavrl.bench.results import save; r = fresh_run(); before = (r / 'metrics.json').read_bytes(); "
     "save(ours(), r / 'metrics.json'); kept(lambda: (r / 'metrics.json').read_bytes() == before); verdict(True)"),
    ("results.save", "a run's config.yaml", "config.yaml",
     "from uavrl.bench.results import save; r = fresh_run(); before = (r / 'config.yaml').read_bytes(); "
     "save(ours(), r / 'config.yaml'); kept(lambda: (r / 'config.yaml').read_bytes() == before); verdict(True)"),
    ("results.save", "path=a directory", "path", "from uavrl.bench.results import save; save(ours(), TMP)"),
    ("results.save", "path=None", "path", "from uavrl.bench.results import save; save(ours(), None)"),
    ("results.save", "results={}", "results", "from uavrl.bench.results import save; save({}, TMP / 'r.json')"),
    ("results.save", "results=None", "results", "from uavrl.bench.results import save; save(None, TMP / 'r.json')"),
    # ------------------------------------------------------------------ results.markdown: every string escaped
    ("results.markdown", "results={}", "results", "from uavrl.bench.results import markdown; markdown({})"),
    ("results.markdown", "results=None", "results", "from uavrl.bench.results import markdown; markdown(None)"),
    ("results.markdown", "a mean score of text", "mean_score",
     "from uavrl.bench.results import markdown; r = ours(); r['tasks'][0]['mean_score'] = 'high'; markdown(r)"),
    ("results.markdown", "a mean score of NaN", "mean_score",
     "from uavrl.bench.results import markdown; r = ours(); r['tasks'][0]['mean_score'] = float('nan'); markdown(r)"),
    ("results.markdown", "name '</td><script>' (honoured: escaped)", "name",
     "from uavrl.bench.results import markdown; r = ours(); "
     "r['submission']['name'] = '</td><script>alert(1)</script>'; verdict('<script>' not in markdown(r))"),
    ("results.markdown", "name with a newline and '# heading' (honoured: escaped)", "name",
     "from uavrl.bench.results import markdown; r = ours(); r['submission']['name'] = 'x\\n# heading'; "
     "verdict('\\n# heading' not in markdown(r))"),
    ("results.markdown", "source with a backtick and <img> (honoured: escaped)", "source",
     "from uavrl.bench.results import markdown; r = ours(); "
     "r['submission']['source'] = 'x` <img src=x onerror=alert(1)> `'; verdict(in_code(markdown(r), '<img'))"),
    ("results.markdown", "task name '| x |' (honoured: escaped)", "task",
     "from uavrl.bench.results import markdown; r = ours(); r['tasks'][0]['task'] = 'a | 9.999 | b'; "
     "verdict('| a | 9.999 | b |' not in markdown(r))"),
    # ------------------------------------------------------------------ the leaderboard's page: every string escaped
    ("leaderboard page", "name '</td><script>' (honoured: escaped or refused)", "name",
     "page_kept(full(name='</td><script>alert(1)</script>'), lambda page: '<script>' not in page)"),
    ("leaderboard page", "name with '\\n# heading' (honoured: escaped or refused)", "name",
     "page_kept(full(name='x\\n# heading'), lambda page: '\\n# heading' not in page)"),
    ("leaderboard page", "name '[click](javascript:...)' (honoured: escaped or refused)", "name",
     "page_kept(full(name='[click](javascript:alert(1))'), "
     "lambda page: re.search(r'(?<!\\\\)\\]\\(javascript:', page) is None)"),
    ("leaderboard page", "name 'a | b | c' (honoured: escaped or refused)", "name",
     "page_kept(full(name='a | b | c'), lambda page: '| a | b | c |' not in page)"),
    ("leaderboard page", "train_command with a backtick and <img> (honoured: escaped or refused)", "train_command",
     "page_kept(full(train_command='x` <img src=x onerror=alert(1)> `'), lambda page: in_code(page, '<img'))"),
    ("leaderboard page", "source holding the page's marker (honoured: escaped or refused)", "source",
     "page_kept(full(source=MARKER), "  # the generated part starts at the marker's own line, whatever the page shows
     "lambda page: page.index(MARKER) == page.index(chr(10) + MARKER + chr(10)) + 1)"),
    ("leaderboard page", "torch version '2.13\\n\\n# pwned' (honoured: escaped or refused)", "environment",
     "r = full(); r['environment']['torch'] = '2.13\\n\\n# pwned'; "
     "page_kept(r, lambda page: '\\n# pwned' not in page)"),
    ("leaderboard page", "cpus '<b>2</b>' (honoured: escaped or refused)", "environment",
     "r = full(); r['environment']['cpus'] = '<b>2</b>'; page_kept(r, lambda page: '<b>' not in page)"),
    ("leaderboard page", "budget env_steps '1e3' (honoured: refused or shown right)", "budget",
     "page_kept(full(budget={'env_steps': '1e3'}), lambda page: '1,000 env steps' in page)"),
    # ------------------------------------------------------------------ load_experiment
    ("load_experiment", "run_dir=None", "run_dir", "load_experiment(None)"),
    ("load_experiment", "run_dir=123", "run_dir", "load_experiment(123)"),
    ("load_experiment", "run_dir=''", "run_dir", "os.chdir(TMP); load_experiment('')"),
    ("load_experiment", "run_dir=missing", "run_dir", "load_experiment(TMP / 'nothing')"),
    ("load_experiment", "run_dir=a file", "run_dir", "(TMP / 'f').write_text('x'); load_experiment(TMP / 'f')"),
    ("load_experiment", "run_dir=a FIFO", "run_dir", "os.mkfifo(TMP / 'f'); load_experiment(TMP / 'f')"),
    ("load_experiment", "run_dir=a uavrl.train run", "run_dir", "load_experiment(RUN)"),
    ("load_experiment", "metrics.json -> /dev/zero", "run_dir",
     "r = benchmarl_run(); (r / 'metrics.json').unlink(); (r / 'metrics.json').symlink_to('/dev/zero'); "
     "load_experiment(r)"),
    ("load_experiment", "metrics.json a FIFO", "run_dir",
     "r = benchmarl_run(); (r / 'metrics.json').unlink(); os.mkfifo(r / 'metrics.json'); load_experiment(r)"),
    ("load_experiment", "config.yaml a 20 GB sparse file", "run_dir",
     "r = benchmarl_run(); sparse(r / 'config.yaml'); load_experiment(r)"),
    ("load_experiment", "config.yaml with !!python/object/apply", "run_dir",
     "load_experiment(benchmarl_run(config='task: !!python/object/apply:os.system [\"touch pwned\"]\\n'))"),
    ("load_experiment", "config.yaml nested 100,000 deep", "run_dir",
     "load_experiment(benchmarl_run(config='task: ' + '[' * 100000 + ']' * 100000 + '\\n'))"),
    ("load_experiment", "metrics.json agent 'benchmarl_nope'", "run_dir",
     "load_experiment(benchmarl_run(metrics=json.dumps({'agent': 'benchmarl_nope'})))"),
    ("load_experiment", "config.yaml task '../../etc/passwd'", "run_dir",
     "load_experiment(benchmarl_run(config='task:\\n  name: ../../etc/passwd\\n'))"),
    ("load_experiment", "metrics.json agent a list", "run_dir",
     "load_experiment(benchmarl_run(metrics=json.dumps({'agent': ['benchmarl_mappo']})))"),
    # ------------------------------------------------------------------ a rollout with no end
    ("reset/step/to", "rollout(10**12, break_when_any_done=False)", "max_steps",
     "env().rollout(10**12, break_when_any_done=False)"),
    ("reset/step/to", "rollout(5, policy='random')", "policy", "env().rollout(5, policy='random')"),
]  # fmt: skip
A2G = "preset='a2g_urban', grid=(4, 4), num_uavs=2"  # a physical channel: the cities' and levels' options are read
CITY_CASES = [
    # ------------------------------------------------------------------ cities of buildings and altitude levels
    ("cities", "city='urban' under the paper's channel", "city", "make_config('paper', city='urban')"),
    ("cities", "city=['urban']", "city", f"UAVSpectrumEnv({A2G}, city=['urban'])"),
    ("cities", "city_seed=-1", "city_seed", f"UAVSpectrumEnv({A2G}, city='urban', city_seed=-1)"),
    ("cities", "city_seed=2**63", "city_seed", f"UAVSpectrumEnv({A2G}, city='urban', city_seed=2**63)"),
    ("cities", "city_seed=np.int64(3) without a city", "city_seed", f"UAVSpectrumEnv({A2G}, city_seed=np.int64(3))"),
    ("cities", "city_alpha=nan", "city_alpha", f"UAVSpectrumEnv({A2G}, city='urban', city_alpha=float('nan'))"),
    ("cities", "city_beta=1e12", "city_beta", f"UAVSpectrumEnv({A2G}, city='urban', city_beta=1e12)"),
    ("cities", "los=True", "los", f"UAVSpectrumEnv({A2G}, city='urban', los=True)"),
    ("cities", "UAVs inside the high-rise city's buildings", "altitude_m",
     "UAVSpectrumEnv(preset='a2g_urban', city='highrise', environment='highrise')"),
    ("cities", "altitudes_m='300'", "altitudes_m", f"UAVSpectrumEnv({A2G}, altitudes_m='300')"),
    ("cities", "altitudes_m=[30, nan]", "altitudes_m", f"UAVSpectrumEnv({A2G}, altitudes_m=[30, float('nan')])"),
    ("cities", "altitudes_m=torch.tensor([30., 100.])", "altitudes_m",
     f"UAVSpectrumEnv({A2G}, altitudes_m=torch.tensor([30.0, 100.0]))"),
    ("cities", "altitudes_m={30, 100} (a set)", "altitudes_m", f"UAVSpectrumEnv({A2G}, altitudes_m={{30, 100}})"),
    ("cities", "altitudes_m with recharging", "recharge_steps",
     "UAVSpectrumEnv(grid=(4, 4), altitudes_m=[30, 100], energy='follow_up', base=(-1, 0), recharge_steps=3)"),
    ("cities", "action 8 at levels", "action",
     f"e = UAVSpectrumEnv({A2G}, altitudes_m=[30, 100]); td = e.reset(); "
     "td['agents', 'action'] = torch.full((1, 2), 8); e.step(td)"),
    ("cities", "utility of (x, y) at levels", "positions",
     f"e = UAVSpectrumEnv({A2G}, altitudes_m=[30, 100]); e.reset(); "
     "e.world.utility(torch.zeros(1, 2, 2, dtype=torch.long), torch.zeros(1, 2, dtype=torch.long))"),
    ("cities", "utility at level 5 of 2", "positions",
     f"e = UAVSpectrumEnv({A2G}, altitudes_m=[30, 100]); e.reset(); "
     "e.world.utility(torch.tensor([[[0, 0, 5], [1, 0, 0]]]), torch.zeros(1, 2, dtype=torch.long))"),
    ("cities", "a policy of one altitude in an env of levels", "env",
     "p = load_policy(RUN)[0]; p.bind_env(UAVSpectrumEnv(preset='a2g_urban', grid=(3, 3), num_uavs=2, "
     "altitudes_m=[30, 100]))"),
    ("cities", "generate_city over 1e9 m", "beta",
     "from uavrl.envs.physics.city import generate_city; generate_city(0.3, 500, 15, 1e9, 1e9)"),
    ("cities", "line_of_sight of a NaN point", "a",
     "from uavrl.envs.physics.city import generate_city, line_of_sight; "
     "line_of_sight(generate_city(0.3, 500, 15, 500, 500), [[float('nan'), 0, 0]], [[0, 0, 0]])"),
    ("cities", "gym env: action 9 at levels", "action",
     "import uavrl.envs.gym_env as g; e = g.UAVSpectrumGymEnv(preset='a2g_urban', grid=(4, 4), num_uavs=2, "
     "altitudes_m=[30, 100]); e.reset(seed=0); e.step(np.array([9, 0]))"),
]  # fmt: skip
GROUPS = {"old": CASES, "new": NEW_CASES, "cities": CITY_CASES}
TIMEOUTS = {"old": 300, "new": 60, "cities": 60}  # seconds before a case counts as a hang, unless --timeout
MEMORY_GIB = {"old": 16, "new": 6, "cities": 6}  # each case's address space, unless --memory-gib


def classify(report: dict | None, names: str, timed_out: bool, returncode: int) -> tuple[str, str]:
    """``(class, what was seen)`` of one case."""
    if timed_out:
        return "hang", "killed after the timeout"
    if report is None:
        return ("OOM" if returncode < 0 else "traceback"), f"exit status {returncode}, no report"
    if report["raised"] == "MemoryError":
        return "OOM", "MemoryError"
    if report["raised"] is not None:
        message = report["message"]
        line = " ".join(message.split())[:160]
        one_line = "\n" not in message.strip() and names.lower() in message.lower()
        if one_line and report["own"] and {"ValueError", "TypeError"} & set(report["kinds"]):
            return "typed", f"{report['raised']}: {line}"
        if one_line and report["raised"] in (
            "FileNotFoundError",
            "FileExistsError",
            "NotADirectoryError",
            "RuntimeError",
        ):
            return "one line", f"{report['raised']}: {line}"
        return "traceback", f"{report['raised']}: {line}"
    outcome, command = report["outcome"], report["command"]
    if outcome in ("data loss", "honoured", "silent accept"):
        return outcome, command["stderr"].strip().splitlines()[-1][:160] if command and command["stderr"] else ""
    if command is not None:
        stderr = command["stderr"].strip()
        if command["rc"] == 0:
            return "silent accept", "exit status 0"
        if "Traceback" in stderr or stderr.count("\n") > 0 or names.lower() not in stderr.lower():
            return "traceback", " ".join(stderr.split())[-160:]
        return "one line", stderr[:160]
    return "silent accept", "no error"


def case_process(code: str, base: dict, tmp: str, memory_gib: float, conn) -> None:
    """One case, in a process forked from the one that imported the prelude: its report sent through ``conn``."""
    import resource

    limit = int(memory_gib * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    os.chdir(tmp)
    namespace = base  # this process's copy: the prelude's helpers read TMP, COMMAND and OUTCOME from it
    namespace.update(TMP=Path(tmp), COMMAND=None, OUTCOME=None)
    try:
        exec(compile(textwrap.dedent(code), "case", "exec"), namespace)
        report = {"raised": None, "outcome": namespace.get("OUTCOME"), "command": namespace.get("COMMAND")}
    except MemoryError:
        report = {"raised": "MemoryError"}
    except BaseException as err:
        own = any(kind.__module__.split(".")[0] == "uavrl" for kind in type(err).__mro__)
        kinds = [kind.__name__ for kind in type(err).__mro__]
        report = {"raised": type(err).__name__, "own": own, "kinds": kinds, "message": str(err)}
    conn.send(report)
    conn.close()


def run_cases(cases, base: dict, args) -> list[dict]:
    """Every case in its own forked process, ``args.jobs`` at a time, each killed after ``args.timeout`` s; the
    results in the order of ``cases``, each printed as it ends."""
    context = multiprocessing.get_context("fork")  # the prelude's imports, done once, shared by every case
    waiting, running, results = list(enumerate(cases)), [], {}
    while waiting or running:
        while waiting and len(running) < args.jobs:
            index, case = waiting.pop(0)
            tmp = tempfile.mkdtemp(prefix="hostile-")
            receive, send = context.Pipe(duplex=False)
            memory = args.memory_gib or MEMORY_GIB[case[4]]
            process = context.Process(target=case_process, args=(case[3], base, tmp, memory, send))
            process.start()
            send.close()
            running.append((index, case, process, receive, tmp, time.perf_counter()))
        time.sleep(0.05)
        for entry in list(running):
            index, case, process, receive, tmp, started = entry
            report = receive.recv() if receive.poll() else None
            timed_out = time.perf_counter() - started > (args.timeout or TIMEOUTS[case[4]])
            if report is None and process.is_alive() and not timed_out:
                continue
            if report is None and process.is_alive():
                process.kill()
            process.join()
            running.remove(entry)
            shutil.rmtree(tmp, ignore_errors=True)
            kind, seen = classify(report, case[2], timed_out and report is None, process.exitcode or 0)
            surface, typed = case[0], case[1]
            seconds = round(time.perf_counter() - started, 2)
            results[index] = {
                "group": case[4],
                "surface": surface,
                "case": typed,
                "class": kind,
                "seen": seen,
                "seconds": seconds,
            }
            print(f"{kind:>13}  {case[4]:<3} {surface:<16} {typed:<55} {seen}", flush=True)
    return [results[index] for index in range(len(cases))]


def make_run(directory: Path) -> Path:
    run_dir = directory / "run"
    settings = ["agent=random", "env.grid=[3,3]", "eval.num_starts=2", "progress=false", f"run_dir={run_dir}"]
    subprocess.run([sys.executable, "-m", "uavrl.train", *settings], check=True, capture_output=True)
    return run_dir


def make_results(directory: Path) -> tuple[Path, Path]:
    """The new group's fixtures: the random policy scored on the tiny suite's first task (``(results file, the
    references' cache it filled)``)."""
    results, cache = directory / "ours.json", directory / "cache"
    settings = ["tiny", "agent=random", "tasks=[tiny_3x3]", f"cache_dir={cache}", f"out={results}"]
    subprocess.run([sys.executable, "-m", "uavrl.bench", *settings], check=True, capture_output=True)
    return results, cache


def table(results: list[dict]) -> str:
    """The counts per class: a row per group and surface, then a total per group."""
    header = "| group | surface | cases | " + " | ".join(CLASSES) + " |"
    rows = [header, "|" + "---|" * (len(CLASSES) + 3)]
    for group in dict.fromkeys(r["group"] for r in results):
        surfaces = list(dict.fromkeys(r["surface"] for r in results if r["group"] == group))
        for surface in [*surfaces, "all"]:
            chosen = [r for r in results if r["group"] == group and surface in ("all", r["surface"])]
            cells = [str(sum(1 for r in chosen if r["class"] == c)) for c in CLASSES]
            name = f"**{surface}**" if surface == "all" else surface
            rows.append(f"| {group} | {name} | {len(chosen)} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--group", choices=("old", "new", "cities", "all"), default="all", help="which cases (module doc)"
    )
    parser.add_argument("--jobs", type=int, default=2, help="cases run at once")
    parser.add_argument("--timeout", type=float, help="seconds before a case counts as a hang (default per group)")
    parser.add_argument("--memory-gib", type=float, help="address space of each case's process (default per group)")
    parser.add_argument("--only", help="run the cases of this surface only")
    parser.add_argument("--json", type=Path, help="also write the results here")
    args = parser.parse_args()
    cases = [
        (*case, group)
        for group, listed in GROUPS.items()
        if args.group in ("all", group)
        for case in listed
        if args.only in (None, case[0])
    ]
    with tempfile.TemporaryDirectory(prefix="hostile-run-") as tmp:
        run_dir = make_run(Path(tmp))
        os.environ["HOSTILE_RUN"] = str(run_dir)
        if any(case[4] == "new" for case in cases):
            results_file, cache_dir = make_results(Path(tmp))
            os.environ.update(HOSTILE_RESULTS=str(results_file), HOSTILE_CACHE=str(cache_dir))
        base = {"__name__": "hostile_case"}
        exec(compile(PRELUDE, "prelude", "exec"), base)
        results = run_cases(cases, base, args)
    print(f"\n{len(results)} cases")
    for group in dict.fromkeys(r["group"] for r in results):
        seconds = sorted(r["seconds"] for r in results if r["group"] == group and r["class"] in ("typed", "one line"))
        if seconds:
            print(f"{group}: median time to a refusal {seconds[len(seconds) // 2]:.1f} s (in the forked process)")
    print()
    print(table(results))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
