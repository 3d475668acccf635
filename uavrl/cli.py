"""The commands' front end: compose the Hydra config, run the command, report a mistake in one line.

A user's mistake (a bad setting, a missing or unreadable file, an unknown
override) ends the command with ``error: <one line>`` on stderr and exit
status 1, never a traceback.  Hydra's own flags (``--help``, ``--cfg job``,
``--multirun``, ...) go to Hydra's command line unchanged.

A sweep (``-m``) of ``configs/config.yaml`` writes every job's run directory
to ``<sweep_dir>/<its overrides>/seed=<seed>`` (:func:`split_sweep_dir`,
:func:`claim_job_dir`): unique within the sweep, readable, and the same name
for the same overrides whatever the launcher (basic, joblib, Ray).
"""

from __future__ import annotations

import functools
import os
import re
import shlex
import sys
from datetime import datetime
from pathlib import Path
from typing import Callable

from omegaconf import DictConfig
from omegaconf.errors import OmegaConfBaseException

from uavrl.config import MOVED, config_dir
from uavrl.envs.config import InvalidOption
from uavrl.envs.rules import path, rules_of, shown
from uavrl.experiment.io import claim_dir
from uavrl.schema import BenchmarlSchema, ReproduceSchema, RunSchema

Command = Callable[[DictConfig, list], object]
BENCHMARL_INSTALL = 'pip install torch==2.13.0 -e ".[benchmarl]"'  # the extra uavrl.benchmarl and its library need
# settings that moved: an override of the old name says the new one
RENAMED = MOVED
# settings that hold a file system path (every command's, by their rule): a path Hydra's override grammar cannot read
# unquoted (letters beyond ASCII, ~ # & ' ( ) [ ] =) is quoted for it, so a path works as the shell passes it
PATH_SETTINGS = {
    name
    for schema in (RunSchema, ReproduceSchema, BenchmarlSchema)
    for name, rule in rules_of(schema).items()
    if rule.allowed.startswith(path().allowed)
}


def run_command(
    config_name: str,
    command: Command,
    option_settings: dict[str, str],
    check: Callable[[DictConfig, list], None] | None = None,
) -> None:
    """Compose ``config_name`` with the command line's overrides and run ``command(cfg, overrides)``.

    ``option_settings`` names the model's options as the command's users type
    them (``grid`` -> ``env.grid``), for errors raised by the model.  ``check(cfg,
    overrides)`` refuses a bad config; a command that passes it writes run directories: in
    a sweep (``-m``) each job gets its own under ``sweep_dir``, and every job is
    checked before any starts.
    """
    overrides = sys.argv[1:] = readable(sys.argv[1:])
    # TorchRL logs every buffer it allocates at INFO; a user's RL_LOGGING_LEVEL still wins (read when it is imported)
    os.environ.setdefault("RL_LOGGING_LEVEL", "WARNING")
    if any(arg.startswith("-") for arg in overrides):
        import hydra
        from hydra.core.hydra_config import HydraConfig
        from hydra.types import RunMode

        sweeps_runs = check is not None and any(arg in SWEEP_FLAGS for arg in overrides)
        if sweeps_runs:
            overrides, sweep_dir = split_sweep_dir(overrides)
            _reported(
                lambda _cfg, _overrides: check_sweep(config_name, overrides, sweep_dir, check),
                None,
                [],
                option_settings,
            )
            sys.argv[1:] = [*overrides, sweep_dir_override(sweep_dir or new_sweep_dir())]

        @functools.wraps(command)  # Hydra names the app after the wrapped command
        def task(cfg: DictConfig) -> None:
            hydra_cfg = HydraConfig.get()
            if sweeps_runs and hydra_cfg.mode == RunMode.MULTIRUN:
                # checked before the sweep started; what fails now is the launcher's to report, and a job that
                # exits would take a Ray worker with it
                cfg.run_dir = claim_job_dir(hydra_cfg.runtime.output_dir, cfg.seed)
                command(cfg, list(hydra_cfg.overrides.task))
                return
            _reported(command, cfg, list(hydra_cfg.overrides.task), option_settings)

        hydra.main(config_path=config_dir(), config_name=config_name, version_base=None)(task)()
        return
    _reported(command, compose_config(config_name, overrides), overrides, option_settings)


SWEEP_FLAGS = ("-m", "--multirun")


def hydra_quoted(value: str) -> str:
    """``value`` as a single-quoted string of Hydra's override grammar (which reads it back unchanged): a quote is
    escaped, and so are the backslashes before a quote or at the end."""
    escaped = re.sub(r"(\\*)('|\Z)", lambda m: m.group(1) * 2 + ("\\'" if m.group(2) else ""), value)
    return f"'{escaped}'"


def shell_word(text: str) -> str:
    """``text`` as one word to paste into a POSIX shell: double quotes where they suffice (``key="'a b'"``), else
    :func:`shlex.quote`."""
    if shlex.quote(text) == text:
        return text
    key, _, value = text.partition("=")
    if value and re.fullmatch(r"[\w.+~]+", key) and not re.search(r'["$`\\!]', value):
        return f'{key}="{value}"'
    return shlex.quote(text)


def typed(setting: str, value) -> str:
    """The override that sets ``setting`` to the string ``value``, quoted for Hydra when it needs it and for the
    shell: ``checkpoint='/tmp/my runs/x'``, ``checkpoint="'/tmp/a,b'"``."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    plain = f"{setting}={value}"
    try:
        reads_as_typed = OverridesParser.create().parse_override(plain).value() == str(value)
    except HydraException:
        reads_as_typed = False
    return shell_word(plain if reads_as_typed else f"{setting}={hydra_quoted(str(value))}")


def readable(args: list[str]) -> list[str]:
    """The command line's overrides as Hydra's grammar reads them.  A value with a character the grammar refuses
    unquoted (a letter beyond ASCII, # & ' ; ...), and a path setting's value it cannot read unquoted (also ( ) [ ] =),
    is quoted for it: it cannot have meant anything else, and the setting's rule then judges it.  An override that
    stays unreadable is one line."""
    from antlr4.error.Errors import LexerNoViableAltException
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    parser = OverridesParser.create()
    readable_args = []
    for arg in args:
        key, equals, value = arg.partition("=")
        if arg.startswith("-") or not equals:  # Hydra's flags and their values
            readable_args.append(arg)
            continue
        try:
            parser.parse_override(arg)
        except HydraException as err:
            if key.lstrip("+~") not in PATH_SETTINGS and not isinstance(err.__cause__, LexerNoViableAltException):
                raise SystemExit(unreadable(arg, err)) from None
            try:
                parser.parse_override(f"{key}={hydra_quoted(value)}")
            except HydraException as still:  # the setting's name itself
                raise SystemExit(unreadable(arg, still)) from None
            readable_args.append(f"{key}={hydra_quoted(value)}")
            continue
        readable_args.append(arg)
    keys = [arg.partition("=")[0].lstrip("+~") for arg in readable_args if "=" in arg and not arg.startswith("-")]
    twice = next((key for key in keys if keys.count(key) > 1), None)
    if twice:  # Hydra keeps the last value without a word
        given = " ".join(arg for arg in args if arg.partition("=")[0].lstrip("+~") == twice)
        raise SystemExit(f"error: {given} is invalid: {twice} is given {keys.count(twice)} times: give it once")
    return readable_args


def unreadable(arg: str, err: Exception) -> str:
    reason = str(err).strip().splitlines()[0]
    return f"error: {arg} cannot be read: {reason} (type setting=value, e.g. agent.episodes=50 or env.grid=[6,6])"


def split_sweep_dir(overrides: list[str]) -> tuple[list[str], Path | None]:
    """A sweep's command line without ``sweep_dir``, and that directory made absolute (None when not given), so jobs
    started anywhere agree on it."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    keys = [arg.split("=", 1)[0].lstrip("+~") for arg in overrides]
    if "run_dir" in keys:
        raise SystemExit(
            "error: run_dir is invalid in a sweep (-m): each job runs in <sweep_dir>/<its overrides>/seed=<seed>; "
            "set sweep_dir instead"
        )
    given = [arg for arg, key in zip(overrides, keys, strict=True) if key == "sweep_dir"]
    rest = [arg for arg, key in zip(overrides, keys, strict=True) if key != "sweep_dir"]
    value = OverridesParser.create().parse_override(given[-1]).value() if given else None
    if value is None:
        return rest, None
    if not isinstance(value, (str, int, float)):  # a sweep over sweep_dir (a,b) or a list
        raise SystemExit(f"error: {given[-1]} is invalid: give one sweep_dir")
    sweep_dir = Path(str(value)).expanduser().resolve()
    if sweep_dir.exists() and not sweep_dir.is_dir():
        raise SystemExit(f"error: {given[-1]} is invalid: it is a file, not a directory")
    return rest, sweep_dir


def new_sweep_dir() -> Path:
    """A new ``runs/sweeps/<timestamp>`` (``-1``, ``-2``, ... when taken), absolute."""
    return claim_dir(Path("runs") / "sweeps" / datetime.now().strftime("%Y%m%d-%H%M%S")).resolve()


def sweep_dir_override(sweep_dir: Path) -> str:
    return f"sweep_dir={hydra_quoted(str(sweep_dir))}"


def claim_job_dir(output_dir: str, seed: int) -> str:
    """``<output_dir>/seed=<seed>``, created here; refused if it exists (a sweep into the same ``sweep_dir`` ran these
    overrides already: nothing it wrote is overwritten)."""
    run_dir = Path(output_dir) / f"seed={seed}"
    try:
        run_dir.mkdir(parents=True)
    except FileExistsError:
        raise FileExistsError(f"{run_dir} already exists (an earlier sweep's job): give a new sweep_dir") from None
    return str(run_dir)


def sweep_jobs(overrides: list[str]) -> list[list[str]]:
    """The overrides of each job of a sweep, as Hydra's basic sweeper splits them (Hydra's own flags dropped)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser

    task = [arg for arg in overrides if not arg.startswith("-") and not arg.lstrip("+~").startswith("hydra")]
    parsed = OverridesParser.create().parse_overrides(task)
    return BasicSweeper.split_arguments(parsed, max_batch_size=None)[0]


def check_sweep(config_name: str, overrides: list[str], sweep_dir: Path | None, check: Callable | None) -> None:
    """Every job of a sweep composed and checked, and its run directory in ``sweep_dir`` free, before any starts."""
    from omegaconf import open_dict

    for job in sweep_jobs(overrides):
        cfg = compose_config(config_name, job, return_hydra_config=True)
        run_dir = Path(sweep_dir or "") / cfg.hydra.job.override_dirname / f"seed={cfg.seed}"
        if sweep_dir is not None and run_dir.exists():
            raise FileExistsError(f"{run_dir} already exists (an earlier sweep's job): give a new sweep_dir")
        if check is not None:
            with open_dict(cfg):
                del cfg["hydra"]
            check(cfg, job)


def compose_config(config_name: str, overrides: list[str], return_hydra_config: bool = False) -> DictConfig:
    """The config with ``overrides``, as ``@hydra.main`` composes it; Hydra's message in one line when it cannot."""
    from hydra import compose, initialize_config_dir
    from hydra.errors import HydraException

    chosen = {override.split("=", 1)[0] for override in overrides}
    for override in overrides:
        key = override.split("=", 1)[0].lstrip("+~")
        if key in RENAMED:
            raise SystemExit(f"error: {key} is now {RENAMED[key]}: write {override.replace(key, RENAMED[key], 1)}")
        # the run's scenario section is null unless one is chosen: Hydra cannot set a key inside it
        if config_name == "config" and key.startswith("scenario.") and "scenario" not in chosen:
            example = f"scenario=paper_6x6 {override}"
            raise SystemExit(f"error: {override} is invalid: no scenario is chosen; choose one first, e.g. {example}")
    try:
        with initialize_config_dir(config_dir=config_dir(), version_base=None):
            return compose(config_name=config_name, overrides=overrides, return_hydra_config=return_hydra_config)
    except (HydraException, OmegaConfBaseException) as err:
        message = wrong_type(err) or hydra_message(err)
        if any(override.split("=", 1)[0] == "resume" for override in overrides):
            # composed before the saved run is read: another agent's setting fails against the default agent's schema
            message += " (resume= continues the saved run with its own settings: give resume=<run dir> alone)"
        raise SystemExit(f"error: {message}") from None


def wrong_type(err: Exception) -> str | None:
    """``<setting>=<value> is invalid: ...`` for a value the schema's type refuses (:mod:`uavrl.schema`), else None."""
    from omegaconf.errors import ValidationError

    cause = err.__cause__
    if not isinstance(cause, ValidationError) or not getattr(cause, "full_key", None):
        return None
    expected = {"Integer": "a whole number", "Boolean": "true or false", "Float": "a number", "String": "text"}
    converted = re.search(r"could not be converted to (\w+)|is not a valid (bool)", str(cause))
    name = converted and (converted.group(1) or "Boolean")
    listed = "is not a ListConfig, list or tuple" in str(cause)
    kind = expected.get(name, name) if converted else "a list, e.g. [1, 2]" if listed else "of the setting's type"
    return f"{cause.full_key}={shown(cause.value)} is invalid: it must be {kind}"


def hydra_message(err: Exception) -> str:
    """Hydra's message, short: its first line, the first line of its cause, the options it lists."""
    parts = [(str(err).strip().splitlines() or [type(err).__name__])[0].rstrip(".")]
    if err.__cause__ is not None and str(err.__cause__).strip():
        parts.append(str(err.__cause__).strip().splitlines()[0])
    line = ": ".join(parts)
    options = getattr(err, "options", None)  # MissingConfigException: the configs of the group
    return f"{line} (available: {', '.join(options)})" if options else line


def one_line(err: BaseException) -> str:
    return " ".join(str(err).split())


def _reported(command: Command, cfg: DictConfig, overrides: list[str], option_settings: dict[str, str]) -> None:
    try:
        command(cfg, overrides)
    except InvalidOption as err:
        raise SystemExit(f"error: {err.renamed(option_settings)}") from None
    except (ValueError, OSError) as err:
        raise SystemExit(f"error: {one_line(err)}") from None
    except KeyboardInterrupt as err:
        notes = getattr(err, "__notes__", [])
        print(f"interrupted{': ' + notes[0] if notes else ''}", file=sys.stderr)
        raise SystemExit(128 + getattr(err, "signum", 2)) from None  # the shell's status for death by that signal
