"""Deprecated: uavrl 0.2's path of :mod:`uavrl.experiment.video`, which this module is; it goes in 0.4."""

from uavrl.envs._moved import alias

alias(__name__, "uavrl.experiment.video")
