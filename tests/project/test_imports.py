"""The tabular commands run without TorchRL: the physics is a world layer with no TorchRL import."""

import subprocess
import sys

import pytest

HEAVY = ("torchrl", "tensordict")
# runs a command's module in this process, then prints which of HEAVY it imported
PROBE = """
import runpy, sys
sys.argv = sys.argv[1:]
try:
    runpy.run_module(sys.argv[0], run_name="__main__", alter_sys=True)
finally:
    print("IMPORTED", sorted({m.split(".")[0] for m in sys.modules} & {%s}))
""" % ", ".join(map(repr, HEAVY))


@pytest.mark.parametrize(
    "command",
    [
        ["uavrl.reproduce", "table2", "grids=[2]", "runs=2", "episodes=2", "eval_starts=4", "out_dir={out}"],
        ["uavrl.train", "agent=tabular", "env.grid=[3,3]", "agent.episodes=2", "env.max_steps=50", "run_dir={out}"],
    ],
    ids=["reproduce", "train-tabular"],
)
def test_tabular_commands_import_neither_torchrl_nor_tensordict(command, tmp_path):
    args = [arg.format(out=tmp_path / "out") for arg in command] + ["progress=false"]
    done = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "IMPORTED []" in done.stdout, done.stdout[-500:]


def test_the_probe_sees_torchrl_where_it_is_used(tmp_path):
    """The probe itself: a command that does use TorchRL (the DQN) is reported."""
    args = ["uavrl.train", "agent=dqn", "env.grid=[3,3]", "agent.iterations=1", "agent.worlds=2"]
    args += ["agent.learning_starts=1000", "eval.num_starts=2", "progress=false", f"run_dir={tmp_path / 'out'}"]
    done = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "IMPORTED ['tensordict', 'torchrl']" in done.stdout


def test_a_second_process_loads_the_learner_kernels_from_the_cache(tmp_path):
    """numba's cache=True: once a process has compiled the learner's kernels, the next one loads them, compiling
    nothing."""
    learn = (
        "import numba\n"
        "from uavrl.agents.tabular import TeamQLearner, kernels\n"
        "from uavrl.envs import make_config\n"
        "for shared in (False, True):\n"
        "    TeamQLearner(make_config('paper', grid=(3, 3), max_steps=20), runs=2, shared_table=shared).run_episode()\n"
        "for kernel in (kernels._episode_per_run, kernels._episode_shared):\n"
        "    hits, misses = (sum(counts.values()) for counts in (kernel.stats.cache_hits, kernel.stats.cache_misses))\n"
        "    print(kernel.__name__, hits, 'hits', misses, 'misses')\n"
    )
    for _ in range(2):  # the first process may compile (a fresh checkout); the second must not
        done = subprocess.run([sys.executable, "-c", learn], capture_output=True, text=True, cwd=tmp_path)
        assert done.returncode == 0, done.stderr[-2000:]
    loaded = ["_episode_per_run 1 hits 0 misses", "_episode_shared 1 hits 0 misses"]
    assert done.stdout.split("\n")[:2] == loaded, done.stdout


def test_no_module_imports_upward():
    """docs/architecture.md's layers: the model (``envs/``) imports nothing of the agents or commands, the agents and
    the modules beside them nothing of the commands; no command imports ``uavrl.train``."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    commands = {"train", "evaluate", "reproduce", "report", "benchmarl", "render", "cli", "settings", "config"}
    library = {"runs", "rundir", "saved", "protocol", "policy", "training", "evaluating", "rendering", "reproducing"}
    library |= {"reporting", "benchmarl", "missions"}
    agents_layer = {"evaluation", "compat", "schema", "rules"}  # uavrl/: 0.2's paths and the settings' schemas
    beside_agents = {"checkpoints", "logger", "video", "plots", "io"}  # uavrl/experiment/
    layers = {"model": [*root.glob("envs/**/*.py")], "agents": [*root.glob("agents/**/*.py")]}
    layers["agents"] += [root / "uavrl" / f"{name}.py" for name in agents_layer]
    layers["agents"] += [root / "uavrl" / "experiment" / f"{name}.py" for name in beside_agents]
    layers["commands"] = [root / "uavrl" / f"{name}.py" for name in commands]
    layers["commands"] += [root / "uavrl" / "experiment" / f"{name}.py" for name in library]
    above = {
        "model": ("uavrl.experiment", "uavrl.agents", *(f"uavrl.{name}" for name in (*commands, *agents_layer))),
        "agents": ("uavrl.experiment." + name for name in library),
        "commands": ("uavrl.train",),
    }
    above["agents"] = (*above["agents"], *(f"uavrl.{name}" for name in commands))
    upward = []
    for layer, files in layers.items():
        for file in files:
            for node in ast.walk(ast.parse(file.read_text())):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
                names += [node.module] if isinstance(node, ast.ImportFrom) and node.module else []
                upward += [f"{file.relative_to(root)}: {n}" for n in names if n.startswith(above[layer])]
    assert upward == []


# envs/'s layers in import order (docs/architecture.md): a module imports only earlier layers, or its own subpackage
ENVS_LAYERS = [
    {"_moved", "compat", "errors"},  # _moved, errors: standard library; compat: TorchRL only
    {"physics.radio", "physics.power", "physics.sensing"},  # standard library and the one-line errors
    {"limits"},
    {"rules"},
    {"config"},
    {"physics"},
    {"solvers"},
    {"world"},
    {"render"},
    {"env", "adapters"},
]
ENVS_PACKAGES = {"physics", "solvers", "adapters"}


def envs_layer(module: str) -> tuple[int, str]:
    """(layer, group) of a module of envs/ named relative to it, e.g. ``physics.grid``; the group is its
    subpackage or, directly in envs/, the module itself."""
    group = module.split(".")[0]
    for rank, names in enumerate(ENVS_LAYERS):
        if module in names or group in names:
            return rank, group
    raise AssertionError(f"envs/{module}: in no layer of ENVS_LAYERS")


def test_envs_layers_import_only_earlier_layers():
    """compat, physics/radio and power, limits, rules, config (standard library only), the rest of physics, the
    solvers, the World,
    drawing, then the TorchRL env and the other frameworks' adapters: no module of envs/ imports a later layer, nor
    a module of its own layer outside its subpackage."""
    import ast
    from pathlib import Path

    envs = Path(__file__).resolve().parents[2] / "envs"
    upward = []
    for file in envs.glob("**/*.py"):
        if file.name == "__init__.py":
            continue
        package = file.parent.relative_to(envs).parts
        module = ".".join([*package, file.stem])
        rank, group = envs_layer(module)
        for node in ast.walk(ast.parse(file.read_text())):
            if not isinstance(node, ast.ImportFrom) or node.level == 0:
                continue
            base = [*package[: len(package) - node.level + 1], *(node.module.split(".") if node.module else [])]
            targets = [".".join(base)] if node.module and base[-1] not in ENVS_PACKAGES else []
            targets += [".".join([*base, a.name]) for a in node.names if not node.module or base[-1] in ENVS_PACKAGES]
            for target in targets:
                target_rank, target_group = envs_layer(target)
                if target_rank > rank or (target_rank == rank and target_group != group):
                    upward.append(f"envs/{module}: {target}")
    assert upward == []


def test_the_0_1_module_paths_name_the_moved_modules():
    """``uavrl.envs.<name>`` of uavrl 0.1 (``uavrl.envs.MOVED``) imports the module of its subpackage itself, which
    keeps its own spec; an unknown name still fails as any missing module does."""
    import importlib
    import importlib.util

    from uavrl.envs import MOVED

    optional = {"gym_env": "gymnasium", "pettingzoo_env": "pettingzoo"}
    for name, package in MOVED.items():
        if name in optional and importlib.util.find_spec(optional[name]) is None:
            continue
        old, new = (
            importlib.import_module(f"uavrl.envs.{name}"),
            importlib.import_module(f"uavrl.envs.{package}.{name}"),
        )
        assert old is new and new.__spec__.name == f"uavrl.envs.{package}.{name}", name
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("uavrl.envs.no_such_module")


def project_imports() -> dict[str, set[str]]:
    """Each module of the package (by installed name) and the package's modules it imports, at the top or inside a
    function (not those imported for type checkers only)."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    modules = {}
    for package, folder in (
        ("uavrl", "uavrl"),
        ("uavrl.envs", "envs"),
        ("uavrl.agents", "agents"),
        ("uavrl.configs", "configs"),
    ):
        for file in (root / folder).rglob("*.py"):
            parts = [p for p in file.relative_to(root / folder).with_suffix("").parts if p != "__init__"]
            modules[".".join([package, *parts])] = file
    graph = {}
    for name, file in modules.items():
        here = name.split(".") if file.name == "__init__.py" else name.split(".")[:-1]
        graph[name] = set()
        tree = ast.parse(file.read_text())
        typing_only = {  # under `if TYPE_CHECKING:`: never run
            id(sub)
            for node in ast.walk(tree)
            if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING"
            for sub in ast.walk(node)
        }
        for node in ast.walk(tree):
            if id(node) in typing_only:
                continue
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = ".".join(here[: len(here) - node.level + 1] + [node.module or ""]) if node.level else node.module
                base = base.rstrip(".")
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
            else:
                continue
            for imported in targets:
                target = imported
                while target and target not in modules:
                    target = target.rpartition(".")[0]
                if target and target != name:
                    graph[name].add(target)
    return graph


def test_the_agents_import_nothing_of_the_commands_layer():
    """agents/ (uavrl.agents) imports only itself and envs/, inside functions too: the commands and their library
    (uavrl.*) sit above it."""
    upward = sorted(
        f"{m} -> {t}"
        for m, targets in project_imports().items()
        for t in targets
        if m.startswith("uavrl.agents") and not t.startswith(("uavrl.agents", "uavrl.envs"))
    )
    assert upward == []


def test_no_import_cycle_counting_imports_inside_functions():
    graph = project_imports()
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(module, path):
        state[module] = 1
        for target in sorted(graph[module]):
            if state.get(target) == 1:
                raise AssertionError("import cycle: " + " -> ".join([*path[path.index(target) :], target]))
            if target not in state:
                visit(target, [*path, target])
        state[module] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])


MAX_DEFERRED_IMPORTS = 15  # the bound: imports of the project's own modules inside functions


def deferred_imports() -> list[tuple[str, int, str]]:
    """``(file, line, the line's text)`` of each import of the package's own modules (``uavrl...`` or relative)
    inside a function of uavrl/, envs/ or agents/, not under ``if TYPE_CHECKING:``."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    found = set()
    for folder in ("uavrl", "envs", "agents"):
        for file in sorted((root / folder).rglob("*.py")):
            text = file.read_text()
            tree = ast.parse(text)
            typing_only = {
                id(sub)
                for node in ast.walk(tree)
                if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING"
                for sub in ast.walk(node)
            }
            lines = text.splitlines()
            for function in ast.walk(tree):
                if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                for node in ast.walk(function):
                    if id(node) in typing_only:
                        continue
                    if isinstance(node, ast.Import):
                        own = any(a.name == "uavrl" or a.name.startswith("uavrl.") for a in node.names)
                    elif isinstance(node, ast.ImportFrom):
                        module = node.module or ""
                        own = node.level > 0 or module == "uavrl" or module.startswith("uavrl.")
                    else:
                        continue
                    if own:
                        found.add((str(file.relative_to(root)), node.lineno, lines[node.end_lineno - 1]))
    return sorted(found)


def test_few_imports_inside_functions_each_with_its_reason():
    """At most 15 imports of the package's own modules inside functions (the commands' one deferred import of their
    library after the torch-free check, and the few that keep TorchRL, TensorDict or torch off a path that does not
    need them), each with a comment on its line saying why."""
    deferred = deferred_imports()
    assert len(deferred) <= MAX_DEFERRED_IMPORTS, "\n".join(f"{f}:{n}: {line.strip()}" for f, n, line in deferred)
    unexplained = [f"{f}:{n}: {line.strip()}" for f, n, line in deferred if "#" not in line]
    assert unexplained == []
