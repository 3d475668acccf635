"""The commands' front end: compose the Hydra config, run the command, report a mistake in one line.

A user's mistake (a bad setting, a missing or unreadable file, an unknown
override) ends the command with ``error: <one line>`` on stderr and exit
status 1, never a traceback.  Hydra's own flags (``--help``, ``--cfg job``,
``--multirun``, ...) go to Hydra's command line unchanged.
"""

from __future__ import annotations

import functools
import re
import sys
from typing import Callable

from omegaconf import DictConfig
from omegaconf.errors import OmegaConfBaseException

from uavrl.config import MOVED, config_dir
from uavrl.envs.config import InvalidOption
from uavrl.settings import shown

Command = Callable[[DictConfig, list], object]
# settings that moved: an override of the old name says the new one
RENAMED = MOVED


def run_command(config_name: str, command: Command, option_settings: dict[str, str]) -> None:
    """Compose ``config_name`` with the command line's overrides and run ``command(cfg, overrides)``.

    ``option_settings`` names the model's options as the command's users type
    them (``grid`` -> ``env.grid``), for errors raised by the model.
    """
    overrides = sys.argv[1:]
    if any(arg.startswith("-") for arg in overrides):
        import hydra
        from hydra.core.hydra_config import HydraConfig

        @functools.wraps(command)  # Hydra names the app after the wrapped command
        def task(cfg: DictConfig) -> None:
            _reported(command, cfg, list(HydraConfig.get().overrides.task), option_settings)

        hydra.main(config_path=config_dir(), config_name=config_name, version_base=None)(task)()
        return
    _reported(command, compose_config(config_name, overrides), overrides, option_settings)


def compose_config(config_name: str, overrides: list[str]) -> DictConfig:
    """The config with ``overrides``, as ``@hydra.main`` composes it; Hydra's message in one line when it cannot."""
    from hydra import compose, initialize_config_dir
    from hydra.errors import HydraException

    for override in overrides:
        key = override.split("=", 1)[0].lstrip("+~")
        if key in RENAMED:
            raise SystemExit(f"error: {key} is now {RENAMED[key]}: write {override.replace(key, RENAMED[key], 1)}")
    try:
        with initialize_config_dir(config_dir=config_dir(), version_base=None):
            return compose(config_name=config_name, overrides=overrides)
    except (HydraException, OmegaConfBaseException) as err:
        raise SystemExit(f"error: {wrong_type(err) or hydra_message(err)}") from None


def wrong_type(err: Exception) -> str | None:
    """``<setting>=<value> is invalid: ...`` for a value the schema's type refuses (:mod:`uavrl.schema`), else None."""
    from omegaconf.errors import ValidationError

    cause = err.__cause__
    if not isinstance(cause, ValidationError) or not getattr(cause, "full_key", None):
        return None
    expected = {"Integer": "a whole number", "Boolean": "true or false", "Float": "a number", "String": "text"}
    converted = re.search(r"could not be converted to (\w+)|is not a valid (bool)", str(cause))
    name = converted and (converted.group(1) or "Boolean")
    kind = expected.get(name, name) if converted else "of the setting's type"
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
        raise SystemExit(130) from None
