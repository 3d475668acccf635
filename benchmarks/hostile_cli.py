"""Hostile command lines against every command, each run as a whole process, and what each one got.

    python benchmarks/hostile_cli.py [--timeout 60] [--jobs 2] [--only WORD] [--out results.json]

Every case is a mistake a user could type (sizes that cannot fit, settings that cannot go together, values of the
wrong kind, paths that are no run, options a part does not read), on ``uavrl.train``, ``uavrl.evaluate``,
``uavrl.render``, ``uavrl.reproduce``, ``uavrl.report``, ``uavrl.benchmarl`` and ``uavrl.schema``.  The script
first makes its own fixtures in a temporary directory (a tabular run and a size-free DQN run, trained for a few
seconds; a text file, a FIFO, a directory with no run; a sentinel ``notes.txt`` in each), then runs each case from
there with a wall-clock timeout and classifies it:

- ``refused``: exit status 1 and one line ``error: ...`` naming a setting the case typed (for ``report``, its flag
  or path);
- ``refused, names another``: one line, but none of what was typed;
- ``traceback``, ``hang`` (past the timeout), ``out of memory`` (killed, or ``MemoryError``);
- ``accepted``: exit status 0 (a silent accept: every case here is a mistake);
- ``data loss``: a sentinel file or a run's files changed or gone.

It prints a table of the counts, the cases that were not refused cleanly, and the median wall and CPU seconds of a
refusal (CPU: user + system of the process, which the load of other processes does not inflate).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shlex
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

OUTCOMES = ("refused", "refused, names another", "traceback", "hang", "out of memory", "accepted", "data loss")


def make_fixtures(root: Path) -> dict[str, str]:
    """Two small runs, the special files and a sentinel ``notes.txt`` in every directory; returns the placeholders."""
    runs = {
        "tab": "agent=tabular agent.episodes=2 agent.runs=1 eval.num_starts=2",
        "set": f"agent=dqn agent.network=set agent.mixer=vdn {TINY_DQN} agent.batch_size=8 eval.num_starts=2",
    }
    for name, overrides in runs.items():
        command = [sys.executable, "-m", "uavrl.train", *overrides.split(), "progress=false", f"run_dir={root / name}"]
        subprocess.run(command, check=True, capture_output=True, cwd=root)
    (root / "file.txt").write_text("not a run\n")
    os.mkfifo(root / "fifo")
    (root / "empty").mkdir()
    (root / "zero").mkdir()
    (root / "zero" / "checkpoint.pt").write_bytes(b"")
    for directory in (root, root / "tab", root / "set", root / "empty", root / "zero"):
        (directory / "notes.txt").write_text("a user's own notes\n")
    places = {name: str(root / name) for name in ("tab", "set", "empty", "zero", "fifo")}
    return places | {"file": str(root / "file.txt"), "tmp": str(root)}


def snapshot(root: Path) -> dict[str, str]:
    """A digest of every file the fixtures hold that a command must not change: the sentinels and the runs' files."""
    kept = {}
    for path in root.rglob("*"):
        if path.is_file() and (path.name in ("notes.txt", "checkpoint.pt", "config.yaml", "metrics.json")):
            kept[str(path.relative_to(root))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return kept


def typed_words(command: str, args: list[str]) -> list[str]:
    """What a refusal may name: each setting typed (its key), each flag, each path argument."""
    words = []
    for arg in args:
        key, equals, value = arg.partition("=")
        if arg.startswith("--"):
            words.append(key)
        elif equals:
            words.append(key.lstrip("+~"))
        elif not arg.startswith("-"):
            words.append(arg if command in ("report", "render") else key)
    return [w for w in words if w]


def run_case(command: str, args: list[str], cwd: Path, timeout: float) -> dict:
    """The case as a process of its own (its CPU time read by ``/usr/bin/time``), killed with its children at
    ``timeout``."""
    argv = [sys.executable, "-m", f"uavrl.{command}", *args]
    if command in ("train", "evaluate", "render", "reproduce"):
        argv.append("progress=false")
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


def classify(command: str, args: list[str], result: dict, lost: bool) -> str:
    stderr = result["stderr"].strip()
    if lost:
        return "data loss"
    if result["timed_out"]:
        return "hang"
    if result["rc"] in (-9, 137) or "MemoryError" in stderr or "out of memory" in stderr.lower():
        return "out of memory"
    if "Traceback (most recent call last)" in stderr:
        return "traceback"
    if result["rc"] == 0:
        return "accepted"
    lines = [line for line in stderr.splitlines() if line.strip()]
    words = typed_words(command, args)
    if command == "report":  # argparse's own refusals: "usage: ..." then "error: ..."
        lines = [line for line in lines if not line.startswith("usage:") and not line.startswith("  ")]
    one_line = len(lines) == 1 and "error:" in lines[0]
    if one_line and any(word in lines[0] for word in words):
        return "refused"
    return "refused, names another"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds before a case counts as a hang")
    parser.add_argument("--jobs", type=int, default=2, help="cases run at once")
    parser.add_argument("--only", help="only the cases of this command")
    parser.add_argument("--out", help="write every case's result here as JSON")
    options = parser.parse_args()
    cases = [(c, a) for c, a in CASES if options.only in (None, c)]
    with tempfile.TemporaryDirectory(prefix="hostile-") as tmp:
        root = Path(tmp)
        places = make_fixtures(root)
        before = snapshot(root)
        lock = threading.Lock()

        def one(case):
            command, text = case
            args = shlex.split(text.format(**places))
            result = run_case(command, args, root, options.timeout)
            with lock:  # the fixtures' own files only (a case that runs may write runs of its own beside them)
                now = snapshot(root)
                lost = any(now.get(name) != digest for name, digest in before.items())
                before.update({name: now.get(name) for name in before})
            return command, text, result, classify(command, args, result, lost)

        with ThreadPoolExecutor(options.jobs) as pool:
            results = list(pool.map(one, cases))
    counts = {outcome: sum(1 for *_, o in results if o == outcome) for outcome in OUTCOMES}
    refusals = [r for _, _, r, o in results if o.startswith("refused")]
    machine = f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}, Python {sys.version.split()[0]}"
    print(f"{len(results)} cases, {machine}, timeout {options.timeout:g} s, {options.jobs} at once\n")
    print("| outcome | cases |\n|---|---:|")
    for outcome, n in counts.items():
        print(f"| {outcome} | {n} |")
    walls = [r["wall"] for r in refusals]
    cpus = [r["cpu"] for r in refusals if r["cpu"] is not None]
    if walls:
        print(f"\nrefusals: median {statistics.median(walls):.2f} s wall (max {max(walls):.1f} s), ", end="")
        print(f"median {statistics.median(cpus):.2f} s CPU (max {max(cpus):.1f} s)" if cpus else "")
    print("\nnot refused cleanly:")
    for command, text, result, outcome in results:
        if outcome != "refused":
            last = (result["stderr"].strip().splitlines() or [""])[-1][:160]
            print(f"- [{outcome}] uavrl.{command} {text}: {last}")
    if options.out:
        rows = [{"command": c, "args": t, "outcome": o, **r} for c, t, r, o in results]
        Path(options.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
