"""Hostile command lines against every command, each run as a whole process, and what each one got.

    python benchmarks/hostile_cli.py [--group old|new|cities|local|all] [--timeout 60] [--jobs 2] [--only WORD]
        [--out X.json]

Every case is a mistake a user could type (sizes that cannot fit, settings that cannot go together, values of the
wrong kind, paths that are no run, options a part does not read), on ``uavrl.train``, ``uavrl.evaluate``,
``uavrl.render``, ``uavrl.reproduce``, ``uavrl.report``, ``uavrl.benchmarl`` and ``uavrl.schema`` (the ``old``
group); the ``new`` group holds the benchmark (``uavrl.bench``: its suites and settings, results files, the
references' cache, ``compare``, ``leaderboard``, ``list``), the DQN's and the evaluation's newer options (n-step
returns, prioritized replay, the curriculum, demonstrations, the lookahead), large grids and run directories holding
another run's checkpoint; the ``cities`` group the cities of buildings, the altitude levels, ``agent.cities`` and
the ``city`` suite; the ``local`` group the local observations, the communication radius, messages and the
``decentralised`` suite.  The script first makes its own fixtures in a temporary directory (a tabular run and a
size-free DQN run, trained for a few seconds; a text file, a FIFO, a directory with no run; a sentinel ``notes.txt``
in each; for the new group also a team DQN run, copies of it holding the tabular run's checkpoint, a results file of
ours and malformed ones, caches with damaged or re-signed entries, links to ``/dev/zero``, 20 GB sparse files, a
read-only directory and a user's ``notes.md``, ``thesis.md`` and ``thesis.png``), then runs each case from there with
a wall-clock timeout (the new group's cases also under an address-space cap, ``--memory-gib``) and classifies it:

- ``refused``: exit status 1 and one line ``error: ...`` naming a setting the case typed (for ``report``, its flag
  or path);
- ``refused, names another``: one line, but none of what was typed;
- ``traceback``, ``hang`` (past the timeout), ``out of memory`` (killed, or ``MemoryError``);
- ``honoured``: exit status 0 where going on is the documented answer, saying so (:data:`HONOURED`: a damaged
  cache entry recomputed with a warning, a label that looks like a path);
- ``accepted``: exit status 0 (a silent accept: every case here is a mistake);
- ``data loss``: a sentinel file or a run's files changed or gone (every fixture file is hashed before and after
  each case, and put back when changed; with ``--jobs`` above 1 a loss is charged to the case that ends first: rerun
  it with ``--jobs 1 --only <word>`` to pin it).

For ``uavrl.bench`` a refusal may name any word typed: a setting's key, the suite, a path (a file inside a directory
typed counts, its path starting with the directory's).  It prints each case's class as it ends (to stderr), then
a table of the counts per group, the cases that were not refused cleanly, and the median wall and CPU seconds of a
refusal per group (CPU: user + system of the process, which the load of other processes does not inflate).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import resource
import shlex
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

TINY_DQN = (
    "agent.iterations=2 agent.worlds=2 agent.hidden=16 agent.updates=1 agent.learning_starts=0 agent.batch_size=8"
)
E = "env.energy=rotary_wing env.base=[-1,0]"
F = "env.energy=follow_up env.base=[-1,0]"
A2G = "env=a2g_urban agent=dqn"

# (command, arguments): {set} a size-free DQN run, {tab} a tabular run, {file} a text file, {fifo} a FIFO,
# {empty} a directory with no run, {zero} a directory whose checkpoint.pt is empty, {tmp} the fixtures' directory
CASES = [
    # ---------------------------------------------------------------- train: sizes and costs
    ("train", "agent=dqn agent.hidden=100000000"),
    ("train", "agent=dqn agent.depth=100000"),
    ("train", "agent=dqn agent.batch_size=100000000"),
    ("train", "agent=dqn agent.updates=100000000"),
    ("train", "agent=dqn agent.iterations=100000000"),
    ("train", "agent=dqn agent.network=set agent.heads=1000000 agent.hidden=1000000"),
    ("train", "agent=dqn agent.mixer=qmix agent.mixing_embed_dim=1000000000"),
    ("train", "agent=dqn agent.network=set agent.sizes=[[3,1000000,1000000]]"),
    ("train", "agent=dqn env.grid=[3000,3000]"),
    ("train", "agent=dqn env.grid=[300,300] agent.worlds=1000000"),
    ("train", "agent=dqn env.num_uavs=500 env.grid=[30,30]"),
    ("train", f"agent=dqn {F} env.recharge_steps=1 env.num_spares=100000"),
    ("train", "agent=dqn agent.buffer_size=100000000000"),
    ("train", "agent=dqn agent.worlds=10000000"),
    ("train", "agent=dqn env.max_steps=100000000"),
    ("train", "agent=tabular env.grid=[30,30] env.num_uavs=3"),
    ("train", "agent=tabular agent.runs=1000000000"),
    ("train", "agent=tabular agent.episodes=100000000000"),
    ("train", "agent=tabular agent.method=value_iteration env.grid=[50,50] env.num_uavs=3"),
    ("train", "agent=random eval.num_starts=100000000000"),
    ("train", "agent=random eval.horizon=100000000000"),
    ("train", "agent=oracle env.grid=[2000,2000]"),
    ("train", "agent=random eval.video=true eval.video_starts=1000000"),
    ("train", "agent=random eval.video=true eval.horizon=100000000"),
    ("train", "agent=random env.num_uavs=300 env.grid=[20,20]"),
    ("train", "agent=planner env.grid=[100000,100000]"),
    # ---------------------------------------------------------------- train: settings that cannot go together
    ("train", "agent=dqn agent.head=joint env.num_uavs=6 env.grid=[10,10]"),
    ("train", f"agent=dqn agent.head=joint {F}"),
    ("train", "agent=dqn agent.network=set agent.sizes=[[1000,10,10]]"),
    ("train", "agent=dqn agent.network=set agent.layouts=[line,spiral]"),
    ("train", "agent=dqn agent.network=set agent.heads=7"),
    ("train", "agent=dqn agent.network=set agent.mixer=qmix"),
    ("train", "agent=dqn agent.layouts=[line]"),
    ("train", "agent=dqn agent.sizes=[[2,6,6]]"),
    ("train", "agent=dqn agent.mixer=mean"),
    ("train", "scenario=large_20x20 agent=tabular"),
    ("train", "scenario=n6_10x10 scenario.agents=[]"),
    ("train", "env.fading=los_nlos"),
    ("train", "env.fading=rayleigh env.rician_k_db=3"),
    ("train", "env=a2g_urban env.channel=tr36777_umi env.environment=suburban agent=dqn"),
    ("train", f"{A2G} env.channel=tr36777_rma env.carrier_ghz=100"),
    ("train", f"{A2G} env.altitude_m=1000000"),
    ("train", f"{A2G} env.p_u=5"),
    ("train", "env.channel=al_hourani env.g0=2 agent=dqn"),
    ("train", "env.rate_model=reference_code env.direct_links=true"),
    ("train", "env.base=[-1,0]"),
    ("train", "env.num_spares=2"),
    ("train", "env.battery_wh=50"),
    # ---------------------------------------------------------------- train: energy numbers
    ("train", f"{E} env.battery_wh=1e200"),
    ("train", f"{E} env.slot_s=1e-200"),
    ("train", f"{E} env.slot_s=1e200"),
    ("train", f"{E} env.circuit_power_w=1e12"),
    ("train", f"{E} env.cell_size=1e12"),
    ("train", "env.energy=follow_up env.base=[-1000000,0]"),
    ("train", "env.energy=follow_up env.base=[1,1]"),
    ("train", f"{F} env.recharge_steps=-4"),
    ("train", f"{F} env.num_spares=3"),
    ("train", f"{E} env.battery_init=half"),
    ("train", f"{F} env.reset_positions=keep"),
    # ---------------------------------------------------------------- train: numbers and kinds
    ("train", "env.cell_size=1e-320"),
    ("train", "env.altitude=1e308"),
    ("train", "env.beta1=1e300"),
    ("train", "env.beta2=-1e39"),
    ("train", "env.grid=[2,2,2]"),
    ("train", "env.grid=[-3,3]"),
    ("train", "env.num_uavs=1e3"),
    ("train", "env.layout=random env.grid=[1,1]"),
    ("train", "agent.alpha=nan"),
    ("train", "agent.gamma=inf"),
    ("train", "agent.epsilon=[0.1]"),
    ("train", "eval.gamma=-0.0"),
    ("train", "seed=18446744073709551616"),
    ("train", "seed=1.5"),
    ("train", "device=cuda:x"),
    ("train", "num_threads=1000000"),
    ("train", "train.checkpoint_every=-1"),
    ("train", "train.log_every=1e9"),
    ("train", "train.step_budget=1e30"),
    ("train", "train.time_budget=-1"),
    ("train", "train.time_budget=nan"),
    ("train", "agent=dqn agent.lr=inf"),
    ("train", "agent=dqn agent.tau=-0.5"),
    ("train", "agent=dqn agent.eps_fraction=nan"),
    ("train", "agent=dqn agent.objective=log_gap agent.gap_floor=-1"),
    ("train", "env.init_tasks=[sensing]"),
    # ---------------------------------------------------------------- train: paths and overrides
    ("train", "run_dir={file}"),
    ("train", "run_dir={fifo}"),
    ("train", "resume={tab} agent.episodes=5"),
    ("train", "resume={tmp}/nothing"),
    ("train", "resume={file}"),
    ("train", "resume={fifo}"),
    ("train", "resume={zero}"),
    ("train", "-m seed=0,1 sweep_dir={file}"),
    ("train", "+agent.new_key=1"),
    ("train", "agent="),
    ("train", "env=nonexistent"),
    ("train", "print_json=2"),
    ("train", "agent.episodes=${{oc.env:HOME}}"),
    ("train", "agent.episodes=${{agent.runs}}0000000000000"),
    # ---------------------------------------------------------------- evaluate
    ("evaluate", "checkpoint={set} env.grid=[2000000,2000000]"),
    ("evaluate", "checkpoint={set} env.num_uavs=100000 env.grid=[1000,1000]"),
    ("evaluate", "checkpoint={set} env.max_steps=5"),
    ("evaluate", "checkpoint={set} env.fading=rayleigh"),
    ("evaluate", f"checkpoint={{set}} {F}"),
    ("evaluate", "checkpoint={set} env.layout=spiral"),
    ("evaluate", "checkpoint={set} env.grid=[0,0]"),
    ("evaluate", "checkpoint={set} env.num_uavs=37"),
    ("evaluate", "checkpoint={tab} env.num_uavs=3"),
    ("evaluate", "checkpoint={tab} env.layout=random"),
    ("evaluate", "checkpoint={set} eval.num_starts=10000000000"),
    ("evaluate", "checkpoint={set} eval.horizon=10000000000"),
    ("evaluate", "checkpoint={set} eval.video=true eval.video_starts=10000000"),
    ("evaluate", "checkpoint={set} eval.video=true eval.video_fps=0"),
    ("evaluate", "checkpoint={set} agent.memory_budget=10"),
    ("evaluate", "checkpoint={fifo}"),
    ("evaluate", "checkpoint={empty}"),
    ("evaluate", "checkpoint={file}"),
    ("evaluate", "checkpoint={zero}"),
    ("evaluate", "checkpoint={set} device=tpu"),
    ("evaluate", "checkpoint={set} print_json=maybe"),
    ("evaluate", "checkpoint=''"),
    ("evaluate", "checkpoint={set} eval.gamma=2"),
    ("evaluate", "checkpoint={set} eval.seed=-5"),
    ("evaluate", "checkpoint={set} num_threads=-1"),
    ("evaluate", "checkpoint={set} env.grid=[6,6,6]"),
    ("evaluate", "checkpoint={set} env.channel=tr36777_uma"),
    ("evaluate", "checkpoint={set} env.num_uavs=2.5"),
    ("evaluate", "checkpoint={tmp}/nothing/checkpoint.pt"),
    ("evaluate", "checkpoint={set} +env.colour=red"),
    ("evaluate", "checkpoint={set} env.grid=[40,40] eval.horizon=1000000000"),
    ("evaluate", "checkpoint={set} env.num_uavs=0"),
    ("evaluate", "checkpoint={set} env.grid=[100000,100000] env.num_uavs=2"),
    # ---------------------------------------------------------------- render
    ("render", "{set} eval.video_starts=100000000"),
    ("render", "{set} eval.horizon=1000000000"),
    ("render", "{set} eval.video_fps=-1"),
    ("render", "{fifo}"),
    ("render", "{file}"),
    ("render", "{tmp}/nothing"),
    ("render", "{set} agent.memory_budget=1"),
    ("render", "checkpoint=''"),
    ("render", "{set} eval.video_starts=0"),
    ("render", "{set} device=cuda:abc"),
    ("render", "{tab} eval.num_starts=100000000000"),
    ("render", "{set} eval.seed=1e30"),
    ("render", "{set} num_threads=0"),
    ("render", "{zero}"),
    ("render", "{empty}"),
    # ---------------------------------------------------------------- reproduce
    ("reproduce", "table2 grids=[3000] steps=10"),
    ("reproduce", "table2 grids=[2] num_uavs=5"),
    ("reproduce", "table2 grids=[2] runs=1000000000"),
    ("reproduce", "table2 grids=[100] steps=100"),
    ("reproduce", "table2 episodes=1000000000000"),
    ("reproduce", "table2 eval_starts=100000000000"),
    ("reproduce", "figures figure_grid=3 grids=[2]"),
    ("reproduce", "table2 steps=-1"),
    ("reproduce", "table2 grids=2"),
    ("reproduce", "table2 grids=[2.5]"),
    ("reproduce", "table2 memory_budget=nan"),
    ("reproduce", "table2 step_budget=1.5"),
    ("reproduce", "table2 out_dir={file}"),
    ("reproduce", "table2 out_dir={fifo}"),
    ("reproduce", "table2 num_threads=0"),
    ("reproduce", "table4"),
    ("reproduce", "table2 seed=-7"),
    ("reproduce", "table2 state_includes_tasks=2"),
    ("reproduce", "figures figure_grid=0"),
    ("reproduce", "table2 +foo=1"),
    ("reproduce", "table2 grids=[]"),
    ("reproduce", "table2 progress=often"),
    ("reproduce", "table2 grids=[2] num_uavs=3 steps=10000000000000"),
    ("reproduce", "table2 grids=[10] num_uavs=3"),
    ("reproduce", "table2 memory_budget=-1e9"),
    # ---------------------------------------------------------------- report
    ("report", "{tmp}/nothing"),
    ("report", "{file}"),
    ("report", "{fifo}"),
    ("report", "{empty}"),
    ("report", "{tab} --resamples=-1"),
    ("report", "{tab} --resamples=1000000000000"),
    ("report", "{tab} --out={file}"),
    ("report", "{tab} --seed=-1"),
    ("report", "{tab} --resamples=0"),
    ("report", "{tab} --resamples=ten"),
    # ---------------------------------------------------------------- benchmarl
    ("benchmarl", "algorithm=nope"),
    ("benchmarl", "eval.num_starts=0"),
    ("benchmarl", "env.grid=[0,0]"),
    ("benchmarl", "seed=-1"),
    ("benchmarl", "run_dir={file}"),
    ("benchmarl", "task.name=[1]"),
    ("benchmarl", "env.num_uavs=100000 env.grid=[1000,1000]"),
    ("benchmarl", "eval.horizon=100000000000"),
    # ---------------------------------------------------------------- schema
    ("schema", "--settings"),
    ("schema", "agent=dqn"),
    ("schema", "docs/settings.md"),
]

# the new group: the benchmark, the DQN's and the evaluation's newer options, large grids and swapped run
# directories.  Placeholders as above, and: {dqn} a team DQN run, {res} a results file of ours (res/ a folder of
# damaged ones), {cache} the references' cache it filled (cache-* damaged copies), {lb} folders of results files for
# the leaderboard, {zerolink} a link to /dev/zero, {sparse} a 20 GB sparse file, {ro} a read-only directory,
# {fifo_bench} and {fifo_leaderboard} FIFOs of their own, {swap*} copies of {dqn} holding the tabular run's
# checkpoint.pt (copied, linked, as checkpoint.prev.pt beside a damaged checkpoint.pt; {swapset}: {tab} holding the
# size-free run's), one per command; {swapmetrics_report}: {dqn} holding the tabular run's metrics.json
T = f"{TINY_DQN} eval.num_starts=2"
S = f"agent=dqn agent.network=set {TINY_DQN} eval.num_starts=2"
B = "tiny agent=random tasks=[tiny_3x3] cache_dir={cache}"  # a quick, valid benchmark run: the cases add one mistake
NEW_CASES = [
    # ---------------------------------------------------------------- bench: the suite and the policy
    ("bench", "tiyn agent=random"),
    ("bench", "TINY agent=random"),
    ("bench", "tiny_3x3 agent=random"),
    ("bench", "tiny agent=random,oracle"),
    ("bench", "tiny agent=random checkpoint={set}"),
    ("bench", "tiny agent=dqn"),
    ("bench", "tiny agent=Random"),
    ("bench", "tiny agent="),
    ("bench", "tiny checkpoint="),
    ("bench", "tiny checkpoint={fifo}"),
    ("bench", "tiny checkpoint={file}"),
    ("bench", "tiny checkpoint={zero}"),
    ("bench", "tiny checkpoint={empty}"),
    ("bench", "tiny checkpoint={tmp}/nothing"),
    ("bench", "tiny checkpoint={zerolink}"),
    ("bench", "tiny checkpoint={sparse}"),
    ("bench", "tiny checkpoint={res}"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] extra"),
    ("bench", "tiny agent=random --out=x.json"),
    ("bench", "tiny agent=random seed=1"),
    ("bench", "tiny agent=random device=cuda"),
    ("bench", "tiny agent=random eval.num_starts=1000000000"),
    # ---------------------------------------------------------------- bench: budget, threads, tasks, name
    ("bench", B + " budget.env_steps=-5"),
    ("bench", B + " budget.env_steps=2.7"),
    ("bench", B + " budget.env_steps=1e400"),
    ("bench", B + " budget.env_steps="),
    ("bench", B + " budget.cpu_seconds=nan"),
    ("bench", B + " budget.cpu_seconds=-inf"),
    ("bench", B + " budget.gpu_seconds=-1"),
    ("bench", B + " budget.gpu_seconds=1e309"),
    ("bench", B + " budget.wall_seconds=5"),
    ("bench", B + " budget.env_steps=5 budget.env_steps=6"),
    ("bench", B + " num_threads=5000"),
    ("bench", B + " num_threads=0"),
    ("bench", B + " num_threads=1_000_000"),
    ("bench", "tiny agent=random cache_dir={cache} tasks=[]"),
    ("bench", "tiny agent=random cache_dir={cache} tasks=[paper_6x6]"),
    ("bench", "tiny agent=random cache_dir={cache} tasks=[tiny_3x3,tiny_3x3]"),
    ("bench", "tiny agent=random cache_dir={cache} tasks=[tiny_3x3,nope]"),
    ("bench", "tiny agent=random cache_dir={cache} tasks=[[tiny_3x3]]"),
    ("bench", B + " name="),
    ("bench", B + " name=a name=b"),
    ("bench", B + " name=../../escape out={tmp}/escape.json"),
    # ---------------------------------------------------------------- bench: where the results go
    ("bench", B + " out="),
    ("bench", B + " out={file}"),
    ("bench", B + " out={tmp}/thesis.json"),
    ("bench", B + " out={tmp}/notes.md"),
    ("bench", B + " out={tmp}/notes.txt"),
    ("bench", B + " out={dqn}/metrics.json"),
    ("bench", B + " out={dqn}/checkpoint.pt"),
    ("bench", B + " out={empty}"),
    ("bench", B + " out={file}/r.json"),
    ("bench", B + " out={fifo_bench}"),
    ("bench", B + " out={ro}/r.json"),
    ("bench", B + " out={tmp}/thesis.png"),
    # ---------------------------------------------------------------- bench: the references' cache
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={file}"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={fifo}"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={zerolink}"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={tmp}/cache-fifo"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={tmp}/cache-zero"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={tmp}/cache-sparse"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={tmp}/cache-deep"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={tmp}/cache-types"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={tmp}/cache-short"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={tmp}/cache-worse"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={tmp}/cache-nan"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir={ro}"),
    ("bench", "tiny agent=random tasks=[tiny_3x3] cache_dir="),
    # ---------------------------------------------------------------- bench compare
    ("bench", "compare"),
    ("bench", "compare {res}"),
    ("bench", "compare {res} {res} {res}"),
    ("bench", "compare {res} {tmp}/nothing.json"),
    ("bench", "compare {res} {tmp}/res/fifo.json"),
    ("bench", "compare {res} {tmp}/res/zero.json"),
    ("bench", "compare {res} {tmp}/res/sparse.json"),
    ("bench", "compare {res} {empty}"),
    ("bench", "compare {res} {file}"),
    ("bench", "compare {res} {tab}/metrics.json"),
    ("bench", "compare {res} {tab}"),
    ("bench", "compare {res} {tmp}/res/nosuite.json"),
    ("bench", "compare {res} {tmp}/res/deep.json"),
    ("bench", "compare {res} {tmp}/res/strscore.json"),
    ("bench", "compare {res} {tmp}/res/naniqm.json"),
    ("bench", "compare {res} {tmp}/res/othersuite.json"),
    ("bench", "compare {res} {tmp}/res/version2.json"),
    ("bench", "compare {res} {tmp}/res/versiontrue.json"),
    ("bench", "compare {res} {tmp}/res/nosubmission.json"),
    ("bench", "compare {res} {tmp}/res/taskstext.json"),
    ("bench", "compare {res} {tmp}/res/notasks.json"),
    ("bench", "compare {res} {tmp}/res/scoresshort.json"),
    ("bench", "compare {res} {tmp}/res/list.json"),
    ("bench", "compare {res} {tmp}/res/latin1.json"),
    # ---------------------------------------------------------------- bench leaderboard
    ("bench", "leaderboard results={tmp}/nothing out={tmp}/lb-0.md"),
    ("bench", "leaderboard results={file} out={tmp}/lb-1.md"),
    ("bench", "leaderboard results={fifo} out={tmp}/lb-2.md"),
    ("bench", "leaderboard results={lb}/fifo out={tmp}/lb-3.md"),
    ("bench", "leaderboard results={lb}/zero out={tmp}/lb-4.md"),
    ("bench", "leaderboard results={lb}/sparse out={tmp}/lb-5.md"),
    ("bench", "leaderboard results={lb}/nosuite out={tmp}/lb-6.md"),
    ("bench", "leaderboard results={lb}/unknownsuite out={tmp}/lb-7.md"),
    ("bench", "leaderboard results={lb}/naniqm out={tmp}/lb-8.md"),
    ("bench", "leaderboard results={lb}/deep out={tmp}/lb-9.md"),
    ("bench", "leaderboard results={lb}/strscore out={tmp}/lb-10.md"),
    ("bench", "leaderboard results={lb}/noenvironment out={tmp}/lb-11.md"),
    ("bench", "leaderboard results={lb}/empty out={tmp}/lb-12.md"),
    ("bench", "leaderboard results={lb}/partial out={tmp}/lb-13.md"),
    ("bench", "leaderboard results={lb}/linkout out={tmp}/lb-14.md"),
    ("bench", "leaderboard results={lb}/ok out={tmp}/notes.md"),
    ("bench", "leaderboard results={lb}/ok out={fifo_leaderboard}"),
    ("bench", "leaderboard results={lb}/ok out={empty}"),
    ("bench", "leaderboard results={lb}/ok out={file}/page.md"),
    ("bench", "leaderboard results={lb}/ok out={zerolink}"),
    ("bench", "leaderboard results={lb}/ok out={sparse}"),
    ("bench", "leaderboard results={lb}/ok out={tmp}/thesis.png"),
    ("bench", "leaderboard results={lb}/ok out={ro}/page.md"),
    ("bench", "leaderboard results={lb}/ok results={lb}/naniqm out={tmp}/lb-15.md"),
    ("bench", "leaderboard results={lb}/ok out="),
    ("bench", "leaderboard results= out={tmp}/lb-16.md"),
    ("bench", "leaderboard results={lb}/ok out={tmp}/lb-17.md paper"),
    ("bench", "leaderboard results={lb}/ok out={tmp}/user/page.md"),
    # ---------------------------------------------------------------- bench list
    ("bench", "list paper"),
    ("bench", "list --suite=energy"),
    # ---------------------------------------------------------------- a run directory holding another run's files
    ("train", "resume={swap_train}"),
    ("train", "resume={swaplink_train}"),
    ("train", "resume={swapprev_train}"),
    ("train", "resume={swapset_train}"),
    ("evaluate", "checkpoint={swap_evaluate} eval.num_starts=2"),
    ("evaluate", "checkpoint={swaplink_evaluate} eval.num_starts=2"),
    ("evaluate", "checkpoint={swapprev_evaluate} eval.num_starts=2"),
    ("evaluate", "checkpoint={swapset_evaluate} eval.num_starts=2"),
    ("render", "{swap_render} eval.video_starts=1"),
    ("render", "{swapprev_render} eval.video_starts=1"),
    ("report", "{swapmetrics_report}"),
    ("bench", "tiny checkpoint={swap_bench} tasks=[tiny_3x3] cache_dir={cache} out={tmp}/swap.json"),
    ("bench", "tiny checkpoint={swapprev_bench} tasks=[tiny_3x3] cache_dir={cache} out={tmp}/swapprev.json"),
    ("render", "{set} {tab} eval.video_starts=1"),
    # ---------------------------------------------------------------- train: n-step returns
    ("train", f"agent=dqn {T} agent.n_step=1000000000000"),
    ("train", f"agent=dqn {T} agent.n_step=0"),
    ("train", f"agent=dqn {T} agent.n_step=-3"),
    ("train", f"agent=dqn {T} agent.n_step=2.5"),
    ("train", f"agent=dqn {T} agent.n_step=nan"),
    ("train", f"agent=dqn {T} agent.n_step=[3]"),
    ("train", "agent=tabular agent.episodes=2 agent.runs=1 eval.num_starts=2 agent.n_step=3"),
    ("train", "resume={dqn_resume1} agent.n_step=4"),
    ("evaluate", "checkpoint={dqn} eval.num_starts=2 agent.n_step=5"),
    # ---------------------------------------------------------------- train: prioritized replay
    ("train", f"{S} agent.replay=prioritized"),
    ("train", f"agent=dqn {T} agent.replay=Prioritized"),
    ("train", f"agent=dqn {T} agent.replay=per"),
    ("train", f"agent=dqn {T} agent.priority_alpha=0.5"),
    ("train", f"agent=dqn {T} agent.priority_beta=0.7"),
    ("train", f"agent=dqn {T} agent.replay=prioritized agent.priority_alpha=0"),
    ("train", f"agent=dqn {T} agent.replay=prioritized agent.priority_alpha=1.5"),
    ("train", f"agent=dqn {T} agent.replay=prioritized agent.priority_beta=-0.1"),
    ("train", f"agent=dqn {T} agent.replay=prioritized agent.priority_beta=nan"),
    ("train", f"agent=dqn {T} agent.replay=prioritized agent.buffer_size=100000000000"),
    ("train", "resume={dqn_resume2} agent.replay=prioritized"),
    # ---------------------------------------------------------------- train: the curriculum
    ("train", f"agent=dqn {T} agent.curriculum=loss"),
    ("train", f"{S} agent.curriculum=hardest"),
    ("train", f"{S} agent.curriculum=loss"),
    ("train", "agent=tabular agent.episodes=2 agent.runs=1 eval.num_starts=2 agent.curriculum=loss"),
    # ---------------------------------------------------------------- train: demonstrations
    ("train", f"agent=dqn {T} agent.demonstrations=oracle"),
    ("train", f"{S} agent.demonstrations=expert"),
    ("train", f"{S} agent.demo_transitions=5000"),
    ("train", f"{S} agent.margin=0.5"),
    ("train", f"{S} agent.demo_batch_share=0.5"),
    ("train", f"{S} agent.demonstrations=oracle agent.demo_batch_share=0.95"),
    ("train", f"{S} agent.demonstrations=oracle agent.demo_batch_share=0"),
    ("train", f"{S} agent.demonstrations=oracle agent.margin=-1"),
    ("train", f"{S} agent.demonstrations=oracle agent.demo_transitions=0"),
    ("train", f"{S} agent.demonstrations=oracle agent.demo_transitions=100000 agent.buffer_size=64"),
    ("train", f"{S} agent.demonstrations=oracle agent.demo_transitions=1000000000000"),
    ("train", f"{S} agent.demonstrations=oracle {E}"),
    ("train", "agent=tabular agent.episodes=2 agent.runs=1 eval.num_starts=2 agent.demonstrations=oracle"),
    # ---------------------------------------------------------------- the lookahead
    ("train", "agent=tabular agent.episodes=2 agent.runs=1 eval.num_starts=2 eval.lookahead=2"),
    ("train", "agent=random eval.num_starts=2 eval.lookahead=2"),
    ("train", f"agent=dqn {T} eval.lookahead=-1"),
    ("train", f"agent=dqn {T} eval.lookahead=1.5"),
    ("train", f"agent=dqn {T} eval.lookahead=true"),
    ("train", f"agent=dqn {T} eval.lookahead=1000000000"),
    ("train", f"agent=dqn {T} eval.lookahead=12 eval.lookahead_width=0"),
    ("train", f"agent=dqn {T} eval.lookahead_width=4"),
    ("train", f"agent=dqn {T} eval.lookahead=2 eval.lookahead_width=-1"),
    ("train", f"agent=dqn {T} eval.lookahead=2 eval.lookahead_width=2.5"),
    ("evaluate", "checkpoint={dqn} eval.num_starts=2 eval.lookahead=1000000000"),
    ("evaluate", "checkpoint={dqn} eval.num_starts=2 eval.lookahead=10 eval.lookahead_width=0"),
    ("evaluate", "checkpoint={tab} eval.num_starts=2 eval.lookahead=2"),
    ("evaluate", "checkpoint={dqn} eval.num_starts=2 eval.lookahead_width=3"),
    ("render", "{dqn} eval.video_starts=1 eval.lookahead=1000000000"),
    # ---------------------------------------------------------------- large grids and teams
    ("train", f"agent=dqn {T} env.grid=[100000,100000] agent.n_step=3"),
    ("train", f"agent=dqn {T} env.grid=[20000,20000] agent.replay=prioritized"),
    ("train", f"{S} agent.sizes=[[2,100000,100000]]"),
    ("train", f"{S} agent.demonstrations=oracle agent.sizes=[[2,5000,5000]]"),
    ("train", "agent=oracle eval.num_starts=2 env.grid=[1000000,1000000]"),
    ("train", "agent=random eval.num_starts=2 env.grid=[2147483648,2]"),
    ("train", "agent=random eval.num_starts=2 env.grid=[4294967297,1]"),
    ("train", "agent=oracle eval.num_starts=2 env.grid=[5000,5000] env.num_uavs=40"),
    ("train", f"agent=random eval.num_starts=2 {F} env.recharge_steps=2 env.num_spares=1000000"),
    ("train", f"agent=random eval.num_starts=2 {E} env.battery_wh=1e12"),
    ("train", f"agent=dqn {T.replace('agent.worlds=2', 'agent.worlds=100000000')} env.grid=[4,4]"),
    ("evaluate", "checkpoint={set} eval.num_starts=1 env.grid=[50000,50000] env.num_uavs=50"),
    ("evaluate", "checkpoint={set} eval.num_starts=100000000 env.grid=[100,100] env.num_uavs=20"),
]

C = "agent=random eval.num_starts=2 env=a2g_urban"  # a physical channel: the cities' and the levels' options are read
LEVELS = "env.altitudes_m=[30,100,300]"
MANY_LEVELS = "env.altitudes_m=[" + ",".join(str(30 + k) for k in range(65)) + "]"
CITY_CASES = [
    # ---------------------------------------------------------------- cities of buildings and altitude levels
    ("train", "agent=random eval.num_starts=2 env.city=urban"),
    ("train", f"{C} env.city=atlantis"),
    ("train", f"{C} env.city=Urban"),
    ("train", f"{C} env.city=dense_urban"),
    ("train", f"{C} env.city=urban env.environment=suburban"),
    ("train", f"{C} env.city=urban env.city_alpha=1"),
    ("train", f"{C} env.city=urban env.city_alpha=-0.3"),
    ("train", f"{C} env.city=urban env.city_beta=1e12"),
    ("train", f"{C} env.city=urban env.city_gamma=inf"),
    ("train", f"{C} env.city=urban env.city_gamma=abc"),
    ("train", f"{C} env.city=urban env.city_seed=-1"),
    ("train", f"{C} env.city=urban env.city_seed=1.5"),
    ("train", f"{C} env.city=urban env.city_seed=9223372036854775808"),
    ("train", f"{C} env.city=urban env.city_seed=4611686018427387904"),
    ("train", f"{C} env.city_seed=3"),
    ("train", f"{C} env.los=statistical"),
    ("train", f"{C} env.city=urban env.los=ray_traced"),
    ("train", f"{C} env.city=highrise env.environment=highrise"),
    ("train", f"{C} env.city=highrise env.environment=highrise {LEVELS} env.altitude_m=30 env.city_seed=1"),
    ("train", f"{C} env.altitudes_m=300"),
    ("train", f"{C} env.altitudes_m=[300,30]"),
    ("train", f"{C} env.altitudes_m=[30,30]"),
    ("train", f"{C} env.altitudes_m=[]"),
    ("train", f"{C} env.altitudes_m=[0,100]"),
    ("train", f"{C} env.altitudes_m=[30,1e30]"),
    ("train", f"{C} env.altitudes_m=[30,nan]"),
    ("train", f"{C} env.altitudes_m=[a,b]"),
    ("train", f"{C} {MANY_LEVELS}"),
    ("train", f"{C} {LEVELS} {E} env.recharge_steps=3"),
    ("train", f"{C} {LEVELS} {E} env.battery_wh=20"),
    ("train", f"{C} env.channel=tr36777_uma env.altitudes_m=[10,100]"),
    ("train", f"{C} env.city=urban {LEVELS} env.grid=[3000,3000] env.num_uavs=2"),
    ("train", f"agent=tabular env=a2g_urban {MANY_LEVELS.replace(',94]', ']')} env.grid=[4,4]"),
    ("train", f"agent=tabular env=a2g_urban {LEVELS} env.grid=[10,10] env.num_uavs=3"),
    ("train", f"{S} env=a2g_urban env.grid=[4,4] agent.cities=[0,1]"),
    ("train", f"{S} env=a2g_urban env.city=urban env.grid=[4,4] agent.cities=[{','.join(map(str, range(17)))}]"),
    ("train", f"{S} env=a2g_urban env.city=urban env.grid=[4,4] agent.cities=[4611686018427387904]"),
    ("train", f"{S} env=a2g_urban env.city=urban env.grid=[4,4] agent.cities=[1,1]"),
    ("train", f"{T} env=a2g_urban env.city=urban env.grid=[4,4] agent.cities=[0,1]"),
    ("train", f"{T} env=a2g_urban {LEVELS} env.grid=[4,4] eval.lookahead=1"),
    ("evaluate", f"checkpoint={{set}} eval.num_starts=2 {LEVELS}"),
    ("evaluate", "checkpoint={set} eval.num_starts=2 env.city=urban"),
    ("evaluate", f"checkpoint={{tab}} eval.num_starts=2 {LEVELS}"),
    ("bench", "city agent=random tasks=[city_nowhere_n6]"),
    ("bench", "city agent=random tasks=[tiny_3x3]"),
    ("bench", "cities agent=random"),
]

L = "agent=dqn env.observation=local agent.iterations=1 agent.worlds=2 eval.num_starts=2"  # local observations
LOCAL_CASES = [
    # ---------------------------------------------------------------- local observations and messages
    ("train", "agent=random eval.num_starts=2 env.observation=nearby"),
    ("train", "agent=random eval.num_starts=2 env.observation=Local"),
    ("train", "agent=random eval.num_starts=2 env.comm_radius=2"),
    ("train", "agent=random eval.num_starts=2 env.message_size=4"),
    ("train", f"{L} env.comm_radius=-1"),
    ("train", f"{L} env.comm_radius=inf"),
    ("train", f"{L} env.comm_radius=nan"),
    ("train", f"{L} env.comm_radius=abc"),
    ("train", f"{L} env.comm_radius=[1,2]"),
    ("train", f"{L} env.message_size=-1"),
    ("train", f"{L} env.message_size=65"),
    ("train", f"{L} env.message_size=2.5"),
    ("train", f"{L} env.message_size=1000000000000"),
    ("train", f"{L} env.message_size=true"),
    ("train", f"{L} agent.head=joint env.grid=[3,3]"),
    ("train", f"{L} agent.network=set agent.mixer=mean env.message_size=2"),
    ("train", f"{L} env.message_size=2 agent.n_step=3"),
    ("train", f"{L} eval.lookahead=1 agent.mixer=vdn"),
    ("train", "agent=tabular env.observation=local env.grid=[3,3]"),
    ("train", f"{L} env.grid=[3000,3000] env.num_uavs=2000"),
    ("train", f"{L} env.num_uavs=1000 env.grid=[100,100] env.message_size=64"),
    ("evaluate", "checkpoint={tab} eval.num_starts=2 env.observation=local"),
    ("evaluate", "checkpoint={set} eval.num_starts=2 env.comm_radius=2"),
    ("benchmarl", "algorithm=mappo task=uavrl/tiny_4x4 env.observation=local env.message_size=2"),
    ("bench", "decentralised agent=random tasks=[dec_n6_10x10_r3]"),
    ("bench", "decentralized agent=random"),
]

GROUPS = {"old": CASES, "new": NEW_CASES, "cities": CITY_CASES, "local": LOCAL_CASES}
CACHE_RECOMPUTED = r"warning: the references' cache entry .* is damaged \(.*\): recomputed and rewritten"
# cases whose documented answer is to go on and say so: the pattern its output must hold (else it is "accepted")
HONOURED = {
    # the cache is the benchmark's own derived data: a damaged or forged entry is recomputed (docs/leaderboard.md)
    **{
        f"tiny agent=random tasks=[tiny_3x3] cache_dir={{tmp}}/cache-{kind}": CACHE_RECOMPUTED
        for kind in ("fifo", "zero", "sparse", "deep", "types", "short", "worse", "nan")
    },
    # a submission's name is a label, escaped in every page, never a path: out= is written where it was asked
    B + " name=../../escape out={tmp}/escape.json": r"escape\.json",
    # the oracle's demonstrations are kept in their own store beside the replay buffer (DQfD; docs/settings.md)
    f"{S} agent.demonstrations=oracle agent.demo_transitions=100000 agent.buffer_size=64": r"evaluate it again",
}
OUTCOMES = (
    "refused",
    "refused, names another",
    "honoured",
    "traceback",
    "hang",
    "out of memory",
    "accepted",
    "data loss",
)
# the files a command must leave as they are: the users' own and the runs' (dotfiles, events and caches may change)
SENTINELS = {"notes.txt", "notes.md", "thesis.md", "thesis.png", "file.txt", "leaderboard-paper.png"}
SENTINELS |= {"checkpoint.pt", "checkpoint.prev.pt", "config.yaml", "metrics.json", "ours.json", "ours.md", "ours.png"}
SPARSE_BYTES = 20 * 2**30
BENCH_WORDS = ("compare", "leaderboard", "list", "paper", "core", "energy", "zero_shot", "tiny")


def python_module(root: Path, module: str, *args: str) -> None:
    """``python -m <module> <args>`` in ``root``, which must succeed (a fixture)."""
    subprocess.run([sys.executable, "-m", module, *args], check=True, capture_output=True, cwd=root)


def make_fixtures(root: Path) -> dict[str, str]:
    """Two small runs, the special files and a sentinel ``notes.txt`` in every directory; returns the placeholders."""
    runs = {
        "tab": "agent=tabular agent.episodes=2 agent.runs=1 eval.num_starts=2",
        "set": f"agent=dqn agent.network=set agent.mixer=vdn {TINY_DQN} eval.num_starts=2",
    }
    for name, overrides in runs.items():
        python_module(root, "uavrl.train", *overrides.split(), "progress=false", f"run_dir={root / name}")
    (root / "file.txt").write_text("not a run\n")
    os.mkfifo(root / "fifo")
    (root / "empty").mkdir()
    (root / "zero").mkdir()
    (root / "zero" / "checkpoint.pt").write_bytes(b"")
    for directory in (root, root / "tab", root / "set", root / "empty", root / "zero"):
        (directory / "notes.txt").write_text("a user's own notes\n")
    places = {name: str(root / name) for name in ("tab", "set", "empty", "zero", "fifo")}
    return places | {"file": str(root / "file.txt"), "tmp": str(root)}


def sparse_file(path: Path) -> None:
    with open(path, "wb") as handle:
        handle.truncate(SPARSE_BYTES)


def read_only(path: Path) -> None:
    """``path`` made read-only even for root (immutable), else by its mode."""
    path.mkdir(parents=True, exist_ok=True)
    if subprocess.run(["chattr", "+i", str(path)], capture_output=True).returncode != 0:
        path.chmod(0o555)


def damaged_results(base: dict) -> dict[str, str]:
    """Results files that say the right format and version and are malformed beyond it, as text by name."""

    def changed(change) -> str:
        results = json.loads(json.dumps(base))
        change(results)
        return json.dumps(results)

    def nan_iqm(r):
        r["aggregate"].update(iqm=float("nan"), iqm_ci=[float("nan")] * 2)
        r["tasks"][0]["mean_score"] = float("nan")

    head = json.dumps({"format": base["format"], "version": base["version"], "suite": base["suite"]})[:-1]
    return {
        "nosuite": changed(lambda r: r.pop("suite")),
        "deep": head + ', "tasks": ' + "[" * 100_000 + "]" * 100_000 + "}",
        "strscore": changed(lambda r: (r["aggregate"].update(iqm="high"), r["tasks"][0].update(mean_score="high"))),
        "naniqm": changed(nan_iqm),
        "othersuite": changed(lambda r: r.update(suite="energy")),
        "unknownsuite": changed(lambda r: r.update(suite="nope")),
        "version2": changed(lambda r: r.update(version=2)),
        "versiontrue": changed(lambda r: r.update(version=True)),
        "nosubmission": changed(lambda r: r.pop("submission")),
        "noenvironment": changed(lambda r: r.pop("environment")),
        "taskstext": changed(lambda r: r.update(tasks="tiny_3x3")),
        "notasks": changed(lambda r: r.update(tasks=[], aggregate={})),
        "scoresshort": changed(lambda r: r["tasks"][0].update(scores=[[0.5]], values=[[0.0]])),
        "list": json.dumps([base]),
        "latin1": head + ', "name": "caf\xe9"}',
    }


def signed(key: str, payload: dict) -> str:
    """A cache entry holding ``payload``, its checksum recomputed as anyone can (uavrl.bench.cache)."""
    digest = hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()
    return json.dumps({"key": key, "sha256": digest, "payload": payload})


def make_new_fixtures(root: Path, places: dict[str, str]) -> dict[str, str]:
    """The new group's fixtures (module doc, and the comment above NEW_CASES); returns their placeholders."""
    python_module(root, "uavrl.train", "agent=dqn", *TINY_DQN.split(), "eval.num_starts=2", "progress=false",
                  f"run_dir={root / 'dqn'}")  # fmt: skip
    python_module(root, "uavrl.bench", "tiny", "agent=random", "tasks=[tiny_3x3]", f"cache_dir={root / 'cache'}",
                  f"out={root / 'ours.json'}")  # fmt: skip
    (root / "notes.md").write_text("# my notes\n")
    (root / "thesis.md").write_text("# chapter 3: results\n")
    (root / "thesis.png").write_bytes(b"\x89PNG a user's figure")
    (root / "zero.lnk").symlink_to("/dev/zero")
    sparse_file(root / "big.json")
    read_only(root / "ro")
    (root / "user" / "figures").mkdir(parents=True)
    (root / "user" / "figures" / "leaderboard-paper.png").write_bytes(b"a user's figure")
    # results files: ours, damaged ones beside it, and folders for the leaderboard (a full-protocol file of suite
    # paper, the only kind its page shows, and one damaged file beside it)
    ours = json.loads((root / "ours.json").read_text())
    res = root / "res"
    res.mkdir()
    for name, text in damaged_results(ours).items():
        (res / f"{name}.json").write_bytes(text.encode("latin-1" if name == "latin1" else "utf-8"))
    os.mkfifo(res / "fifo.json")
    (res / "zero.json").symlink_to("/dev/zero")
    sparse_file(res / "sparse.json")
    full = json.loads(json.dumps(ours))
    full.update(suite="paper", protocol="full")
    full["tasks"][0]["task"] = "paper_6x6"
    lb = root / "lb"
    damaged = damaged_results(full)
    for name in ("ok", "fifo", "zero", "sparse", "nosuite", "unknownsuite", "naniqm", "deep", "strscore",
                 "noenvironment", "linkout"):  # fmt: skip
        (lb / name).mkdir(parents=True)
        (lb / name / "paper.json").write_text(json.dumps(full))
        if name in damaged:
            (lb / name / "bad.json").write_text(damaged[name])
    os.mkfifo(lb / "fifo" / "bad.json")
    (lb / "zero" / "bad.json").symlink_to("/dev/zero")
    sparse_file(lb / "sparse" / "bad.json")
    outside = json.loads(json.dumps(full))
    outside["submission"]["name"] = "from outside the folder"
    (root / "outside.json").write_text(json.dumps(outside))
    (lb / "linkout" / "bad.json").symlink_to(root / "outside.json")
    (lb / "empty").mkdir()
    (lb / "partial").mkdir()
    (lb / "partial" / "ours.json").write_text(json.dumps(ours))
    # caches: the entry of tiny_3x3 as a FIFO, a link to /dev/zero, sparse, too deep, and re-signed with bad payloads
    entry = next((root / "cache").glob("*.json"))
    key, payload = entry.stem, json.loads(entry.read_text())["payload"]
    reference, random_values = payload["reference"]["values"], payload["baselines"]["random"]["values"]
    resigned = {
        "types": {**payload, "reference": {**payload["reference"], "values": ["x"] * len(reference)}},
        "short": {**payload, "reference": {**payload["reference"], "values": reference[:3]}},
        "worse": {**payload, "reference": {**payload["reference"], "values": [v - 1 for v in random_values]}},
        "nan": {**payload, "reference": {**payload["reference"], "values": [float("nan")] * len(reference)}},
    }
    for name in ("fifo", "zero", "sparse", "deep", *resigned):
        (root / f"cache-{name}").mkdir()
    os.mkfifo(root / "cache-fifo" / entry.name)
    (root / "cache-zero" / entry.name).symlink_to("/dev/zero")
    sparse_file(root / "cache-sparse" / entry.name)
    (root / "cache-deep" / entry.name).write_text('{"key": "' + key + '", "payload": ' + "[" * 100_000 + "]" * 100_000)
    for name, changed in resigned.items():
        (root / f"cache-{name}" / entry.name).write_text(signed(key, changed))
    # run directories holding another run's checkpoint, one copy per command that reads them
    new = {"dqn": str(root / "dqn"), "res": str(root / "ours.json"), "cache": str(root / "cache"), "lb": str(lb)}
    new |= {"zerolink": str(root / "zero.lnk"), "sparse": str(root / "big.json"), "ro": str(root / "ro")}
    for command in ("bench", "leaderboard"):  # a FIFO of its own for each case that may write over one
        os.mkfifo(root / f"fifo-{command}")
        new[f"fifo_{command}"] = str(root / f"fifo-{command}")
    tab_checkpoint = root / "tab" / "checkpoint.pt"
    for command in ("train", "evaluate", "render", "report", "bench"):
        for kind, source in (("swap", "dqn"), ("swaplink", "dqn"), ("swapprev", "dqn"), ("swapset", "tab")):
            copy = Path(shutil.copytree(root / source, root / f"{kind}-{command}", symlinks=True))
            checkpoint = copy / "checkpoint.pt"
            if kind == "swap":
                shutil.copy(tab_checkpoint, checkpoint)
            elif kind == "swaplink":
                checkpoint.unlink()
                checkpoint.symlink_to(tab_checkpoint)
            elif kind == "swapprev":
                checkpoint.write_bytes(b"")
                shutil.copy(tab_checkpoint, copy / "checkpoint.prev.pt")
            else:
                shutil.copy(root / "set" / "checkpoint.pt", checkpoint)
            new[f"{kind}_{command}"] = str(copy)
    swapped = Path(shutil.copytree(root / "dqn", root / "swapmetrics-report"))
    shutil.copy(root / "tab" / "metrics.json", swapped / "metrics.json")
    new["swapmetrics_report"] = str(swapped)
    for name in ("dqn_resume1", "dqn_resume2"):
        new[name] = str(shutil.copytree(root / "dqn", root / name))
    return places | new


def snapshot(root: Path) -> dict[str, str]:
    """A digest of every file the fixtures hold that a command must not change: the sentinels, the runs' files and
    the results files (a 20 GB sparse file by its size and time)."""
    kept = {}
    for path in root.rglob("*"):
        name = str(path.relative_to(root))
        watched = path.name in SENTINELS or name.startswith(("res/", "lb/"))
        if watched and path.is_file() and not path.is_symlink():
            status = path.stat()
            content = f"{status.st_size} {status.st_mtime_ns}".encode() if status.st_size > 2**26 else path.read_bytes()
            kept[name] = hashlib.sha256(content).hexdigest()
    return kept


def restore(path: Path, content: bytes | None) -> bool:
    """Write a fixture's file back as it was (a file, link or nothing in its place); whether it could."""
    if content is None or path.is_dir() and not path.is_symlink():
        return False
    try:
        if path.is_symlink() or path.exists():
            path.unlink()
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content)
    except OSError:
        return False
    return True


def typed_words(command: str, args: list[str]) -> list[str]:
    """What a refusal may name: each setting typed (its key), each flag, each path argument (for ``uavrl.bench`` also
    a word that is no command or suite, and a path typed as a value)."""
    words = []
    for arg in args:
        key, equals, value = arg.partition("=")
        if arg.startswith("--"):
            words.append(key)
        elif equals:
            words.append(key.lstrip("+~"))
            if command == "bench" and "/" in value:
                words.append(value)
        elif not arg.startswith("-"):
            words.append(arg if command in ("report", "render", "bench") else key)
    chosen = [w for w in words if w and not (command == "bench" and w in BENCH_WORDS)]
    return chosen or args[:1]  # a bare command word: its refusal names it


def run_case(command: str, args: list[str], cwd: Path, timeout: float, memory: int | None = None) -> dict:
    """The case as a process of its own (its CPU time read by ``/usr/bin/time``), killed with its children at
    ``timeout``, its address space capped at ``memory`` bytes when given."""
    argv = [sys.executable, "-m", f"uavrl.{command}", *args]
    if command in ("train", "evaluate", "render", "reproduce"):
        argv.append("progress=false")

    def cap() -> None:
        if memory:
            resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

    with tempfile.NamedTemporaryFile("r", suffix=".time") as clock:
        started = time.perf_counter()
        for attempt in range(10):  # a machine out of processes for a moment (EAGAIN) is waited for
            try:
                process = subprocess.Popen(
                    ["/usr/bin/time", "-f", "%U %S", "-o", clock.name, *argv],
                    cwd=cwd,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                    start_new_session=True,
                    text=True,
                    preexec_fn=cap,
                )
                break
            except BlockingIOError:
                time.sleep(2 * (attempt + 1))
        timed_out = threading.Event()

        def kill():
            timed_out.set()
            os.killpg(process.pid, signal.SIGKILL)

        timer = threading.Timer(timeout, kill)
        timer.start()
        stdout, stderr = process.communicate()
        timer.cancel()
        wall = time.perf_counter() - started
        times = clock.read().split()
    stderr = "\n".join(
        line for line in stderr.splitlines() if not line.startswith(("Command exited with", "Command terminated by"))
    )
    cpu = sum(map(float, times[-2:])) if len(times) >= 2 else None
    return {
        "rc": process.returncode,
        "stdout": stdout,
        "stderr": stderr,
        "wall": wall,
        "cpu": cpu,
        "timed_out": timed_out.is_set(),
    }


OUT_OF_MEMORY = (
    "MemoryError",
    "out of memory",
    "can't allocate memory",
    "cannot allocate memory",
    "unable to allocate",
)


def classify(command: str, args: list[str], result: dict, lost: bool, text: str = "") -> str:
    stderr = result["stderr"].strip()
    if lost:
        return "data loss"
    if result["timed_out"]:
        return "hang"
    if result["rc"] in (-9, 137) or any(words.lower() in stderr.lower() for words in OUT_OF_MEMORY):
        return "out of memory"
    if "Traceback (most recent call last)" in stderr:
        return "traceback"
    if result["rc"] == 0:
        honoured = text in HONOURED and re.search(HONOURED[text], result.get("stdout", "") + stderr)
        return "honoured" if honoured else "accepted"
    lines = [line for line in stderr.splitlines() if line.strip()]
    words = typed_words(command, args)
    if command == "report":  # argparse's own refusals: "usage: ..." then "error: ..."
        lines = [line for line in lines if not line.startswith("usage:") and not line.startswith("  ")]
    one_line = len(lines) == 1 and "error:" in lines[0]
    if one_line and any(word in lines[0] for word in words):
        return "refused"
    return "refused, names another"


def summary(results: list[tuple], options) -> None:
    """The counts per group, the median refusal times per group and every case not refused cleanly."""
    groups = list(dict.fromkeys(group for group, *_ in results))
    columns = [*groups, "all"] if len(groups) > 1 else groups
    chosen = {g: [r for r in results if g in ("all", r[0])] for g in columns}
    machine = f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}, Python {sys.version.split()[0]}"
    print(f"{len(results)} cases, {machine}, timeout {options.timeout:g} s, {options.jobs} at once\n")
    print("| outcome | " + " | ".join(f"{g} cases" for g in columns) + " |\n|---|" + "---:|" * len(columns))
    for outcome in OUTCOMES:
        print(f"| {outcome} | " + " | ".join(str(sum(r[-1] == outcome for r in chosen[g])) for g in columns) + " |")
    print("| **all** | " + " | ".join(str(len(chosen[g])) for g in columns) + " |")
    for g in columns:
        refusals = [r[3] for r in chosen[g] if r[-1].startswith("refused")]
        walls = [r["wall"] for r in refusals]
        cpus = [r["cpu"] for r in refusals if r["cpu"] is not None]
        if walls:
            print(f"\n{g}: refusals median {statistics.median(walls):.2f} s wall (max {max(walls):.1f} s), ", end="")
            print(f"median {statistics.median(cpus):.2f} s CPU (max {max(cpus):.1f} s)" if cpus else "")
    print("\nnot refused cleanly:")
    for group, command, text, result, outcome in results:
        if outcome not in ("refused", "honoured"):
            last = (result["stderr"].strip().splitlines() or [""])[-1][:160]
            print(f"- [{group}] [{outcome}] uavrl.{command} {text}: {last}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--group", choices=("old", "new", "cities", "local", "all"), default="all", help="which cases (module doc)"
    )
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds before a case counts as a hang")
    parser.add_argument("--jobs", type=int, default=2, help="cases run at once")
    parser.add_argument("--memory-gib", type=float, default=6, help="address space of each new case's process")
    parser.add_argument("--only", help="only the cases of this command, or whose arguments hold this word")
    parser.add_argument("--out", help="write every case's result here as JSON")
    options = parser.parse_args()
    cases = [
        (group, command, text)
        for group, listed in GROUPS.items()
        if options.group in ("all", group)
        for command, text in listed
        if options.only in (None, command) or options.only in text
    ]
    memory = int(options.memory_gib * 2**30)
    with tempfile.TemporaryDirectory(prefix="hostile-") as tmp:
        root = Path(tmp)
        try:
            places = make_fixtures(root)
            if any(group == "new" for group, *_ in cases):
                places = make_new_fixtures(root, places)
            before = snapshot(root)
            originals = {name: (root / name).read_bytes() for name in before if (root / name).stat().st_size <= 2**26}
            lock = threading.Lock()

            def one(case):
                group, command, text = case
                args = shlex.split(text.format(**places))
                result = run_case(command, args, root, options.timeout, memory if group != "old" else None)
                with lock:  # the fixtures' own files only (a case that runs may write runs of its own beside them)
                    now = snapshot(root)
                    changed = [name for name, digest in before.items() if now.get(name) != digest]
                    for name in changed:  # put back, so that the next case that loses it is caught too
                        if restore(root / name, originals.get(name)):
                            now[name] = before[name]
                    before.update({name: now.get(name) for name in before})
                    lost = bool(changed)
                    outcome = classify(command, args, result, lost, text)
                    print(f"{outcome:>22}  [{group}] uavrl.{command} {text}", file=sys.stderr, flush=True)
                return group, command, text, result, outcome

            with ThreadPoolExecutor(options.jobs) as pool:
                results = list(pool.map(one, cases))
        finally:
            subprocess.run(["chattr", "-i", str(root / "ro")], capture_output=True)
            if (root / "ro").exists():
                (root / "ro").chmod(0o755)
    summary(results, options)
    if options.out:
        rows = [{"group": g, "command": c, "args": t, "outcome": o, **r} for g, c, t, r, o in results]
        Path(options.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
