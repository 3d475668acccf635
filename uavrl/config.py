"""Where the Hydra configs live and how a Hydra config becomes a model config (standard library and omegaconf only)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from uavrl.envs.config import OPTION_NAMES, InvalidOption, ModelConfig, make_config
from uavrl.schema import register
from uavrl.settings import check_run

# how the model's options are typed on the command line of uavrl.train and uavrl.evaluate
RUN_OPTION_SETTINGS = {name: f"env.{name}" for name in (*OPTION_NAMES, "preset")}


def config_dir() -> str:
    """Absolute path of the Hydra configs: the installed ``uavrl.configs`` package, else the checkout's ``configs/``.

    Their schemas (:mod:`uavrl.schema`) are registered with Hydra's ConfigStore on the way.
    """
    register()
    packaged = importlib.util.find_spec("uavrl.configs")  # the installed data package, else the checkout's configs/
    if packaged is not None and packaged.origin is not None:
        here = Path(packaged.origin).resolve().parent
        if (here / "config.yaml").exists():
            return str(here)
    return str(Path(__file__).resolve().parent.parent / "configs")


def model_config(cfg: DictConfig) -> ModelConfig:
    """The :class:`ModelConfig` of a run: the ``cfg.env`` options (null: the preset's value), the episode length
    ``env.max_steps`` among them."""
    options = {k: v for k, v in OmegaConf.to_container(cfg.env, resolve=True).items() if v is not None}
    options.pop("name", None)
    preset = options.pop("preset", "paper")
    if "grid" in options:
        options["grid"] = tuple(options["grid"])
    return make_config(preset, **options)


# where settings of earlier versions live now (saved run configs are read through saved_config)
MOVED = {
    "train.steps_per_episode": "env.max_steps",
    "train.episodes": "agent.episodes",
    "train.runs": "agent.runs",
    "train.iterations": "agent.iterations",
}


def saved_config(saved: dict, source: str = "the saved run") -> DictConfig:
    """The config a run directory saved, with the settings of earlier versions moved to where they live now.

    ``source`` (the file it came from) begins the one-line ValueError for a
    config no version of uavrl wrote: one without an ``agent`` or ``env``
    section, one with an interpolation (uavrl saves configs resolved, so
    nothing a saved file names, ``${oc.env:...}`` among them, is looked up), a
    setting outside its rule (:mod:`uavrl.settings`) or the model's.
    """
    from omegaconf.errors import OmegaConfBaseException

    for name, value in _settings_of(saved):
        if isinstance(value, str) and "${" in value:
            raise ValueError(
                f"{source}: its saved setting {name}={value!r} is an interpolation, and uavrl saves resolved configs: "
                "not a uavrl run"
            )
    for section in ("agent", "env"):
        if not isinstance(saved.get(section), dict):
            raise ValueError(f"{source}: its config has no {section} section: not a run config of this uavrl")
    try:
        cfg = OmegaConf.create(saved)
    except OmegaConfBaseException as err:
        raise ValueError(f"{source}: its config is not a uavrl run config ({' '.join(str(err).split())})") from None
    for old, new in MOVED.items():
        value = OmegaConf.select(cfg, old)
        if value is not None and OmegaConf.select(cfg, new) is None:
            OmegaConf.update(cfg, new, value)
        if value is not None:
            group, key = old.split(".")
            del cfg[group][key]
    try:
        check_run(cfg)
        model_config(cfg)
    except InvalidOption as err:
        raise ValueError(f"{source}: in its saved config, {err.renamed(RUN_OPTION_SETTINGS)}") from None
    except ValueError as err:
        raise ValueError(f"{source}: in its saved config, {err}") from None
    return cfg


def _settings_of(saved: dict, prefix: str = ""):
    """``(dotted name, value)`` of every leaf of a saved config."""
    for key, value in saved.items():
        if isinstance(value, dict):
            yield from _settings_of(value, f"{prefix}{key}.")
        elif isinstance(value, list):
            yield from ((f"{prefix}{key}[{i}]", item) for i, item in enumerate(value))
        else:
            yield f"{prefix}{key}", value
