"""Every code block of README.md and docs/*.md runs as written.

Per Markdown file, in file order and in a fresh temporary directory (the working directory of all its blocks):

- a ```python block runs in-process; the blocks of one file share one namespace;
- a ```bash block runs line by line through bash (a line ending in ``\\`` continues on the next), so a later
  command finds the run directory an earlier one wrote (``run_dir=runs/NAME``);
- ``python -m uavrl.train|evaluate|render|reproduce|benchmarl`` get small "smoke" overrides in place of the reader's
  values of the same settings (:func:`smoked`), so they run in seconds with the reader's settings otherwise;
- a block with ``<!-- doc-test: prints TEXT -->`` on the line right below its closing fence must print ``TEXT``
  (its lines' standard output and error, or a Python block's standard output): what the page says it shows;
- a block with ``<!-- doc-test: skip REASON -->`` on the line right above its fence does not run (a ``pip install``,
  a GPU-only line), and neither does a block that needs an extra that is not installed (Ray, Gymnasium, BenchMARL,
  ...), nor the blocks after it (they may use what it makes): the test then says so as a skip, after running the
  blocks before it. ```text and other languages are output, not run.

The fast test of each file parses its blocks, compiles its Python and composes every ``python -m uavrl.X`` line's
settings with the smoke overrides, checking them as the commands do before torch is imported (``uavrl.settings``):
a mistyped setting in the docs fails here in a second. Running the blocks is ``slow`` (CI's docs leg runs it with every
extra installed; in-process, a page's snippets hold up to ~0.8 GB, over the fast suite's memory).

``python tests/project/test_doc_blocks.py smoked ARGS`` prints ``ARGS`` with the smoke overrides (one a line): the
bash blocks' ``python`` calls it.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SKIP_COMMENT = re.compile(r"^<!--\s*doc-test:\s*skip\b\s*(?P<reason>.*?)\s*-->$")
PRINTS_COMMENT = re.compile(r"^<!--\s*doc-test:\s*prints\s+(?P<text>.+?)\s*-->$")
FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})\s*(?P<info>[^`\s]*)")
RUN_LANGUAGES = {"python": "python", "py": "python", "bash": "bash", "sh": "bash", "shell": "bash"}
LINE_TIMEOUT_S = 600  # a line still running by then (a server, a full-size run) fails the test instead of hanging it

# what the optional extras install, and how a block shows that it needs one
EXTRAS = {
    "ray": ("hydra_plugins.hydra_ray_launcher", re.compile(r"hydra/launcher=ray|\bimport ray\b|^\s*ray\s", re.M)),
    "joblib": ("hydra_plugins.hydra_joblib_launcher", re.compile(r"hydra/launcher=joblib")),
    "gym": ("gymnasium", re.compile(r"gymnasium|gym_env|pettingzoo")),
    "gym (pettingzoo)": ("pettingzoo", re.compile(r"pettingzoo")),
    "gym (stable-baselines3)": ("stable_baselines3", re.compile(r"stable_baselines3|sb3_contrib")),
    "gym (sb3-contrib)": ("sb3_contrib", re.compile(r"sb3_contrib")),
    "benchmarl": ("benchmarl", re.compile(r"benchmarl")),
    "bench": ("rliable", re.compile(r"uavrl\.bench\b")),
}

# the smoke overrides: small sizes of the settings that set a command's length, later than the reader's so they win
EVAL_SMOKE = ["progress=false", "eval.num_starts=4", "eval.horizon=12"]
AGENT_SMOKE = {
    "tabular": ["agent.episodes=3", "agent.runs=2", "env.max_steps=200"],
    "dqn": [
        "agent.iterations=3",
        "agent.worlds=4",
        "agent.updates=2",
        "agent.batch_size=16",
        "agent.learning_starts=16",
        "agent.buffer_size=512",
        "env.max_steps=10",
    ],
    "random": [],
    "oracle": [],
    "planner": [],
}
REPRODUCE_SMOKE = [
    "progress=false",
    "grids=[2,3]",
    "figure_grid=3",
    "runs=2",
    "episodes=3",
    "steps=200",
    "eval_starts=4",
]
BENCHMARL_SMOKE = [
    "experiment.max_n_frames=240",
    "experiment.on_policy_n_envs_per_worker=4",
    "experiment.off_policy_n_envs_per_worker=4",
    "experiment.on_policy_collected_frames_per_batch=120",
    "experiment.off_policy_collected_frames_per_batch=120",
    "experiment.evaluation_interval=120",
    "experiment.evaluation_episodes=2",
]
# Hydra config of each command that composes one, and the commands whose length the smoke overrides shorten
CONFIG_OF = {"train": "config", "evaluate": "config", "render": "config", "reproduce": "reproduce"}


@dataclass
class Block:
    """A fenced code block of a Markdown file."""

    path: Path
    line: int  # 1-based line of its opening fence
    language: str  # "python", "bash", or the info string of a block that is not run
    text: str
    skip_reason: str | None  # the doc-test skip comment's reason, when the block carries one
    prints: str | None = None  # what the doc-test prints comment below it says the block prints

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def blocks_of(path: Path) -> list[Block]:
    """The fenced code blocks of ``path``, with the skip comment on the line above each fence."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    index = 0
    while index < len(lines):
        opening = FENCE.match(lines[index])
        if not opening:
            index += 1
            continue
        fence, start = opening.group("fence"), index
        body = []
        index += 1
        while index < len(lines) and not re.match(rf"^ {{0,3}}{fence[0]}{{{len(fence)},}}\s*$", lines[index]):
            body.append(lines[index])
            index += 1
        if index == len(lines):
            raise ValueError(f"{path.relative_to(ROOT)}:{start + 1}: the code block is never closed")
        above = lines[start - 1].strip() if start > 0 else ""
        skip = SKIP_COMMENT.match(above)
        prints = PRINTS_COMMENT.match(lines[index + 1].strip()) if index + 1 < len(lines) else None
        info = opening.group("info").lower()
        language, text = RUN_LANGUAGES.get(info, info or "text"), "\n".join(body)
        blocks.append(Block(path, start + 1, language, text, skip and skip["reason"], prints and prints["text"]))
        index += 1
    return blocks


def bash_lines(text: str) -> list[str]:
    """The commands of a bash block: one per line, a trailing backslash joining the next line; blank lines and
    comments dropped."""
    commands, current = [], ""
    for line in text.splitlines():
        if line.rstrip().endswith("\\"):
            current += line.rstrip()[:-1] + " "
            continue
        command = (current + line).strip()
        current = ""
        if command and not command.startswith("#"):
            commands.append(command)
    if current.strip():
        commands.append(current.strip())
    return commands


def missing_extras(text: str) -> list[str]:
    """The extras ``text`` needs that are not installed."""
    return [name for name, (module, uses) in EXTRAS.items() if uses.search(text) and not installed(module)]


def installed(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # a parent package is missing
        return False


def uavrl_commands(line: str) -> list[list[str]]:
    """The arguments after ``python -m`` of each ``python -m uavrl.X ...`` of a shell line (``&&`` and ``;`` split
    commands; a comment ends the line)."""
    lexer = shlex.shlex(line, posix=True, punctuation_chars=";&|")
    lexer.whitespace_split = True
    lexer.commenters = "#"
    words = list(lexer)
    commands, current = [], []
    for word in [*words, ";"]:
        if word in {";", "&&", "||", "|", "&"}:
            for start in range(len(current) - 2):
                if re.fullmatch(r"python3?", Path(current[start]).name) and current[start + 1] == "-m":
                    if current[start + 2].startswith("uavrl."):
                        commands.append(current[start + 2 :])
                    break
            current = []
        else:
            current.append(word)
    return commands


def smoke(arguments: list[str]) -> list[str]:
    """The overrides appended to ``python -m uavrl.<command> <overrides>`` so that it runs in seconds."""
    command, overrides = arguments[0].removeprefix("uavrl."), arguments[1:]
    settings = dict(override.split("=", 1) for override in overrides if "=" in override and override[0] != "-")
    if command == "train":
        if "resume" in settings:  # a resumed run keeps its saved settings
            return ["progress=false"]
        agents = settings.get("agent", "tabular").split(",")  # a sweep over agents shares the common overrides only
        extra = AGENT_SMOKE.get(agents[0], []) if len(agents) == 1 else []
        return [*EVAL_SMOKE, *extra]
    if command in {"evaluate", "render"}:
        return list(EVAL_SMOKE)
    if command == "reproduce":
        return list(REPRODUCE_SMOKE)
    if command == "benchmarl":
        return list(BENCHMARL_SMOKE)
    return []


def smoked(arguments: list[str]) -> list[str]:
    """``arguments`` (``uavrl.<command> <overrides>``) with the smoke overrides in place of the reader's own values of
    the same settings (a setting typed twice is refused)."""
    extra = smoke(arguments)
    replaced = {override.split("=", 1)[0] for override in extra}
    kept = [arg for arg in arguments[1:] if arg.lstrip("+~").split("=", 1)[0] not in replaced or "=" not in arg]
    return [arguments[0], *kept, *extra]


def check_command(arguments: list[str]) -> None:
    """Compose ``python -m uavrl.<command> <overrides>`` with its smoke overrides and check its settings as the command
    does before torch is imported (a one-line SystemExit or ValueError when one is invalid)."""
    from uavrl.cli import compose_config, readable, sweep_jobs
    from uavrl.envs.rules import check
    from uavrl.settings import REPRODUCE_SETTINGS, check_run, check_scenario

    command = arguments[0].removeprefix("uavrl.")
    if importlib.util.find_spec(f"uavrl.{command}") is None:
        raise ValueError(f"python -m uavrl.{command}: no such command")
    if command not in CONFIG_OF:
        return
    overrides = [arg for arg in smoked(arguments)[1:] if not arg.startswith("-") and "=" in arg]
    positional = arguments[1] if arguments[1:2] and "=" not in arguments[1] and arguments[1][0] != "-" else None
    if positional is not None:  # reproduce table2|figures, render <run dir>
        overrides.append(f"command={positional}" if command == "reproduce" else f"checkpoint={positional}")
    overrides = readable(overrides)  # a path Hydra cannot read unquoted is quoted, as the commands do
    jobs = sweep_jobs(overrides) if any(arg in {"-m", "--multirun"} for arg in arguments) else [overrides]
    for given in jobs:
        job = [arg for arg in given if not arg.lstrip("+~").startswith("hydra")]
        cfg = compose_config(CONFIG_OF[command], job)
        if command == "reproduce":
            check(cfg, REPRODUCE_SETTINGS)
        else:
            check_run(cfg)
            check_scenario(cfg)


def markdown_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def bash_prelude() -> str:
    """``python`` of the bash blocks: this interpreter, with the smoke overrides appended to ``-m uavrl.X``; the
    blocks' tools (``ruff``, ``pre-commit``) from this interpreter's environment, activated or not."""
    return f"""
set -eo pipefail
export MPLBACKEND=Agg
export PATH={shlex.quote(str(Path(sys.executable).parent))}:"$PATH"
python() {{
    if [ "$1" = -m ] && [[ "$2" == uavrl.* ]]; then
        local smoked
        mapfile -t smoked < <({shlex.quote(sys.executable)} {shlex.quote(__file__)} smoked "${{@:2}}")
        set -- -m "${{smoked[@]}}"
    fi
    {shlex.quote(sys.executable)} "$@"
}}
python3() {{ python "$@"; }}
"""


def run_bash_line(line: str, cwd: Path, where: str) -> str:
    """``line`` run through bash from ``cwd``; its standard output and error, or an AssertionError naming ``where``
    when it fails or runs past :data:`LINE_TIMEOUT_S`."""
    try:
        done = subprocess.run(
            ["bash", "-c", bash_prelude() + line],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=LINE_TIMEOUT_S,
        )
    except subprocess.TimeoutExpired:
        raise AssertionError(f"{where}: `{line}` still ran after {LINE_TIMEOUT_S} s") from None
    if done.returncode != 0:
        output = (done.stdout + done.stderr).strip().splitlines()[-20:]
        raise AssertionError(f"{where}: `{line}` exited {done.returncode}:\n" + "\n".join(output))
    return done.stdout + done.stderr


def run_python_block(block: Block, namespace: dict) -> str:
    """``block`` run in ``namespace``; what it printed (also shown, as pytest captures it)."""
    code = compile("\n" * (block.line) + block.text, str(block.path), "exec")  # tracebacks name the file's lines
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(code, namespace)
    sys.stdout.write(printed.getvalue())
    return printed.getvalue()


# ---------------------------------------------------------------------------------------------------------- tests
@pytest.mark.parametrize("path", [pytest.param(p, id=str(p.relative_to(ROOT))) for p in markdown_files()])
def test_blocks_are_well_formed(path: Path):
    """Every block parses, every skip says why, and every uavrl command's settings (with the smoke overrides)
    are valid."""
    problems = []
    for block in blocks_of(path):
        if block.skip_reason is not None:
            if not block.skip_reason:
                problems.append(f"{block.where}: a doc-test skip comment must give its reason")
            continue
        if block.language == "python":
            try:
                compile(block.text, block.where, "exec")
            except SyntaxError as err:
                problems.append(f"{block.where}: {err}")
        elif block.language == "bash":
            for line in bash_lines(block.text):
                if missing_extras(line):
                    continue
                for arguments in uavrl_commands(line):
                    try:
                        check_command(arguments)
                    except (SystemExit, ValueError) as err:
                        problems.append(f"{block.where}: `{line}`: {err}")
    assert not problems, "\n".join(problems)


@pytest.mark.slow
@pytest.mark.parametrize("path", markdown_files(), ids=lambda path: str(path.relative_to(ROOT)))
def test_blocks_run(path: Path, tmp_path: Path, monkeypatch):
    """Every block of the file runs, in order, in a fresh directory."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict = {"__name__": "__doc_blocks__"}
    skipped = []
    for block in blocks_of(path):
        if block.skip_reason is not None or block.language not in {"python", "bash"}:
            continue
        needs = missing_extras(block.text)
        if needs:  # the blocks after it may use what it makes (a sweep's directory): they wait for the extra too
            skipped.append(f"{block.where} and the blocks after it (needs {', '.join(needs)})")
            break
        if block.language == "python":
            output = run_python_block(block, namespace)
        else:
            output = "".join(run_bash_line(line, tmp_path, block.where) for line in bash_lines(block.text))
        if block.prints is not None and block.prints not in output:
            raise AssertionError(f"{block.where}: the page says it prints {block.prints!r}; it printed:\n{output}")
    if skipped:
        pytest.skip(f"ran the blocks before; not installed for: {'; '.join(skipped)}")


def test_smoke_overrides_shorten_the_commands():
    """The smoke overrides set the length of each command: the runs they compose are small."""
    from uavrl.cli import compose_config

    tabular = compose_config("config", ["agent=tabular", *smoke(["uavrl.train", "agent=tabular"])])
    assert tabular.agent.episodes * tabular.agent.runs * tabular.env.max_steps <= 2_000
    dqn = compose_config("config", ["agent=dqn", "scenario=size_free", *smoke(["uavrl.train", "agent=dqn"])])
    assert dqn.agent.iterations * dqn.agent.updates <= 10 and dqn.eval.num_starts <= 4
    reproduce = compose_config("reproduce", ["command=table2", *smoke(["uavrl.reproduce", "table2"])])
    assert reproduce.runs * reproduce.episodes * len(reproduce.grids) <= 20
    assert smoke(["uavrl.train", "resume=runs/x"]) == ["progress=false"]  # a resumed run keeps its settings
    assert smoked(["uavrl.train", "agent=dqn", "agent.iterations=50", "seed=1"])[:3] == [
        "uavrl.train",
        "agent=dqn",
        "seed=1",
    ]


def a_page(tmp_path: Path, monkeypatch, text: str) -> Path:
    """A page of ``text`` in ``tmp_path``, which the harness takes for the repository's root."""
    page = tmp_path / "page.md"
    page.write_text(text)
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    return page


def test_harness_reads_blocks_and_skips(tmp_path: Path, monkeypatch):
    """The parser finds the language, the line and the skip reason; a failing line fails the test."""
    page = a_page(
        tmp_path,
        monkeypatch,
        "text\n\n<!-- doc-test: skip pip install -->\n```bash\npip install x\n```\n\n"
        "```python\nvalue = 1\n```\n\n```bash\necho a \\\n  b  # comment\n# only a comment\nfalse\n```\n",
    )
    found = blocks_of(page)
    assert [(b.language, b.line, b.skip_reason) for b in found] == [
        ("bash", 4, "pip install"),
        ("python", 8, None),
        ("bash", 12, None),
    ]
    assert bash_lines(found[2].text) == ["echo a    b  # comment", "false"]
    run_bash_line("echo a b", tmp_path, "page.md:12")
    with pytest.raises(AssertionError, match="exited 1"):
        run_bash_line("false", tmp_path, "page.md:12")
    assert uavrl_commands("cd x && python -m uavrl.train agent=dqn seed=1  # note") == [
        ["uavrl.train", "agent=dqn", "seed=1"]
    ]
    with pytest.raises(ValueError, match="agent.alpha=2"):
        check_command(["uavrl.train", "agent=tabular", "agent.alpha=2"])
    with pytest.raises(SystemExit, match="no_such_setting"):
        check_command(["uavrl.train", "agent=tabular", "agent.no_such_setting=1"])


def test_a_block_prints_what_its_page_says(tmp_path: Path, monkeypatch):
    """``<!-- doc-test: prints TEXT -->`` below a block: its output must hold TEXT, or the page's test fails."""
    page = a_page(
        tmp_path,
        monkeypatch,
        "```python\nprint(6 * 7)\n```\n<!-- doc-test: prints 42 -->\n\n"
        "```bash\necho one && echo two >&2\n```\n<!-- doc-test: prints two -->\n",
    )
    assert [block.prints for block in blocks_of(page)] == ["42", "two"]
    test_blocks_run(page, tmp_path, monkeypatch)
    page.write_text(page.read_text().replace("prints 42", "prints 43"))
    with pytest.raises(AssertionError, match="page.md:1: the page says it prints '43'; it printed:\n42"):
        test_blocks_run(page, tmp_path, monkeypatch)


def test_link_check_finds_dead_links(tmp_path: Path):
    """docs/check_links.py (the docs build's offline link check) passes a site whose links resolve and names every
    dead link, missing anchor and missing image of one that has them."""
    spec = importlib.util.spec_from_file_location("check_links", ROOT / "docs" / "check_links.py")
    check_links = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(check_links)
    (tmp_path / "api").mkdir()
    (tmp_path / "logo.png").write_bytes(b"png")
    (tmp_path / "api" / "page.html").write_text('<h2 id="usage">Usage</h2><a href="../index.html#top">home</a>')
    (tmp_path / "index.html").write_text(
        '<p id="top"><a href="api/page.html#usage">api</a> <a href="https://example.org/x">out</a>'
        ' <a href="#top">top</a> <img src="logo.png"></p>'
    )
    assert check_links.dead_links(tmp_path) == []
    assert check_links.main([str(tmp_path)]) == 0
    (tmp_path / "api" / "page.html").write_text(
        '<a href="../gone.html">a</a> <a href="../index.html#nowhere">b</a> <img src="../missing.png">'
    )
    assert check_links.dead_links(tmp_path) == [
        "api/page.html: link '../gone.html': gone.html is missing",
        "api/page.html: link '../index.html#nowhere': no anchor #nowhere in index.html",
        "api/page.html: image '../missing.png': missing.png is missing",
        "index.html: link 'api/page.html#usage': no anchor #usage in api/page.html",  # the anchor went with it
    ]
    assert check_links.main([str(tmp_path)]) == 1


if __name__ == "__main__" and sys.argv[1:2] == ["smoked"]:
    sys.stdout.write("".join(f"{argument}\n" for argument in smoked(sys.argv[2:])))
