"""The channel models' constants, units and ranges of validity (docs/model.md, Channel models); standard library only.

:mod:`uavrl.envs.pathloss` computes the models' path losses from these numbers, :mod:`uavrl.envs.limits` and
:class:`~uavrl.envs.config.ModelConfig` check the options against the ranges below before torch is imported.

Example:
    >>> round(noise_dbm(bandwidth_mhz=10.0, noise_figure_db=9.0), 2)  # -174 dBm/Hz + 70 dB + 9 dB
    -95.0
    >>> AL_HOURANI["urban"]  # (a, b, eta_LoS dB, eta_NLoS dB)
    (9.61, 0.16, 1.0, 20.0)
"""

from __future__ import annotations

import math

# "paper" and "reference_code" are one law, g0 d^-alpha, with the parameters of the paper (g0 = 1, alpha = 2) and of
# the authors' code (2 d^-4); the other two are air-to-ground models in physical units
POWER_LAWS = {"paper": (1.0, 2.0), "reference_code": (2.0, 4.0)}  # channel: (g0, alpha)
PHYSICAL_CHANNELS = ("al_hourani", "tr36777_uma")
CHANNELS = (*POWER_LAWS, *PHYSICAL_CHANNELS)

SPEED_OF_LIGHT = 299_792_458.0  # m/s
THERMAL_NOISE_DBM_PER_HZ = -174.0  # kT at 290 K

# Al-Hourani, Kandeepan, Lardner, "Optimal LAP altitude for maximum coverage", IEEE WCL 3(6):569-572, 2014:
# the S-curve parameters (a, b) and the mean excess losses (eta_LoS, eta_NLoS) in dB over free space at 2 GHz
AL_HOURANI = {
    "suburban": (4.88, 0.43, 0.1, 21.0),
    "urban": (9.61, 0.16, 1.0, 20.0),
    "dense_urban": (12.08, 0.11, 1.6, 23.0),
    "highrise": (27.23, 0.08, 2.3, 34.0),
}
ENVIRONMENTS = tuple(AL_HOURANI)

# Where each model holds (docs/model.md, Channel models): the option's range and the reason given when it is left.
# The carrier ranges are our choices (Al-Hourani's letter uses 2 GHz; TR 36.777 studies LTE bands below 6 GHz);
# TR 36.777's UMa-AV formulas hold for UAV heights 22.5 m < h <= 300 m and horizontal distances d_2D <= 4 km.
CARRIER_GHZ = {"al_hourani": (0.7, 5.8), "tr36777_uma": (0.5, 6.0)}
UMA_AV_HEIGHT_M = (22.5, 300.0)
UMA_AV_MAX_D2D_M = 4000.0
UMA_AV_ALL_LOS_ABOVE_M = 100.0  # TR 36.777 Table B-1: P_LoS = 1 above 100 m, and Table B-2 has no NLoS loss there
BANDWIDTH_MHZ = (1e-3, 1e4)  # 1 kHz to 10 GHz: what a thermal-noise floor of -174 dBm/Hz is used for
NOISE_FIGURE_DB = (0.0, 30.0)  # a receiver adds noise: 0 dB is the ideal one
POWER_DBM = (-100.0, 100.0)  # -100 dBm (0.1 pW) to 100 dBm (10 MW)


def dbm_to_watts(dbm: float) -> float:
    return 10 ** ((dbm - 30) / 10)


def noise_dbm(bandwidth_mhz: float, noise_figure_db: float) -> float:
    """The receiver's noise power in dBm: ``-174 dBm/Hz + 10 log10(B / 1 Hz) + NF``."""
    return THERMAL_NOISE_DBM_PER_HZ + 10 * math.log10(bandwidth_mhz * 1e6) + noise_figure_db


def free_space_db(distance_m: float, carrier_ghz: float) -> float:
    """``FSPL = 20 log10(4 pi f_c d / c)`` in dB of a distance in metres and a carrier in GHz (a float; the tensor
    form is :func:`uavrl.envs.pathloss.free_space_db`)."""
    return 20 * math.log10(4 * math.pi * carrier_ghz * 1e9 * distance_m / SPEED_OF_LIGHT)
