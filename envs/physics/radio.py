"""The channel models' constants, units and ranges of validity (docs/model.md, Channel models); standard library only.

:mod:`uavrl.envs.physics.pathloss` computes the models' path losses from these numbers, :mod:`uavrl.envs.limits` and
:class:`~uavrl.envs.config.ModelConfig` check the options against the ranges below before torch is imported.

Example:
    >>> round(noise_dbm(bandwidth_mhz=10.0, noise_figure_db=9.0), 2)  # -174 dBm/Hz + 70 dB + 9 dB
    -95.0
    >>> AL_HOURANI["urban"]  # (a, b, eta_LoS dB, eta_NLoS dB)
    (9.61, 0.16, 1.0, 20.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# "paper" and "reference_code" are one law, g0 d^-alpha, with the parameters of the paper (g0 = 1, alpha = 2) and of
# the authors' code (2 d^-4); the other two are air-to-ground models in physical units
POWER_LAWS = {"paper": (1.0, 2.0), "reference_code": (2.0, 4.0)}  # channel: (g0, alpha)
PHYSICAL_CHANNELS = ("al_hourani", "tr36777_uma", "tr36777_umi", "tr36777_rma")
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
# (alpha, beta per km^2, gamma m) of the four standard environments: Holis and Pechac, "Elevation dependent shadowing
# model for mobile communications via high altitude platforms in built-up areas", IEEE Trans. Antennas Propag.
# 56(4):1078-1084, 2008, as Al-Hourani, Kandeepan, Lardner, IEEE WCL 3(6):569-572, 2014 (section II-B) list them;
# the names are those of radio.AL_HOURANI, whose (a, b) were fitted to these cities
P1410 = {
    "suburban": (0.1, 750.0, 8.0),
    "urban": (0.3, 500.0, 15.0),
    "dense_urban": (0.5, 300.0, 20.0),
    "highrise": (0.5, 300.0, 50.0),
}
# The letter models low-altitude platforms and names no height range (its fits are in the elevation angle alone);
# ITU Radio Regulations No. 1.66A puts high-altitude platform stations at 20 to 50 km: below 20 km (our choice)
AL_HOURANI_HEIGHT_M = (0.0, 20_000.0)  # (low, high): h in it

# Where each model holds (docs/model.md, Channel models): the option's range and the reason given when it is left.
# The carrier ranges are our choices (Al-Hourani's letter uses 2 GHz; TR 36.777 studies LTE bands below 6 GHz).
CARRIER_GHZ = {
    "al_hourani": (0.7, 5.8),
    "tr36777_uma": (0.5, 6.0),
    "tr36777_umi": (0.5, 6.0),
    "tr36777_rma": (0.5, 6.0),
}


@dataclass(frozen=True)
class AerialScenario:
    """One scenario of 3GPP TR 36.777 Annex B (Tables B-1, B-2) for aerial UEs: where its formulas hold (the UAV's
    height ``h`` and the horizontal distance ``d_2D``, metres) and the height above which ``P_LoS = 1``.

    Args:
        name: the standard's name of the scenario (``"UMa-AV"``, ``"UMi-AV"``, ``"RMa-AV"``).
        height_m: the heights ``(low, high]`` in m where its formulas hold.
        max_d2d_m: the largest horizontal distance ``d_2D`` in m where they hold.
        all_los_above_m: the height in m above which every link is in line of sight (``inf``: none).
    """

    name: str
    height_m: tuple[float, float]  # (low, high]: h in it
    max_d2d_m: float
    all_los_above_m: float


TR36777 = {
    "tr36777_uma": AerialScenario("UMa-AV", (22.5, 300.0), 4000.0, 100.0),
    "tr36777_umi": AerialScenario("UMi-AV", (22.5, 300.0), 4000.0, math.inf),
    "tr36777_rma": AerialScenario("RMa-AV", (10.0, 300.0), 10000.0, 40.0),
}
BANDWIDTH_MHZ = (1e-3, 1e4)  # 1 kHz to 10 GHz: what a thermal-noise floor of -174 dBm/Hz is used for
NOISE_FIGURE_DB = (0.0, 30.0)  # a receiver adds noise: 0 dB is the ideal one
POWER_DBM = (-100.0, 100.0)  # -100 dBm (0.1 pW) to 100 dBm (10 MW)


def dbm_to_watts(dbm: float) -> float:
    """A power of ``dbm`` dBm in watts.

    >>> dbm_to_watts(30.0), dbm_to_watts(0.0)
    (1.0, 0.001)
    """
    return 10 ** ((dbm - 30) / 10)


def noise_dbm(bandwidth_mhz: float, noise_figure_db: float) -> float:
    """The receiver's noise power in dBm: ``-174 dBm/Hz + 10 log10(B / 1 Hz) + NF``.

    Args:
        bandwidth_mhz: the bandwidth ``B`` in MHz.
        noise_figure_db: the receiver's noise figure ``NF`` in dB.

    Example:
        >>> noise_dbm(10.0, 9.0)
        -95.0
    """
    return THERMAL_NOISE_DBM_PER_HZ + 10 * math.log10(bandwidth_mhz * 1e6) + noise_figure_db


def free_space_db(distance_m, carrier_ghz: float, log10=math.log10):
    """``FSPL = 20 log10(4 pi f_c d / c)`` in dB of a distance in metres and a carrier in GHz: of a float, or of a
    tensor with ``log10=torch.log10`` (:func:`uavrl.envs.physics.pathloss.free_space_db`), one formula for both.

    Example:
        >>> round(free_space_db(100.0, 2.0), 4)
        78.4684
    """
    return 20 * log10(distance_m * (4 * math.pi * carrier_ghz * 1e9 / SPEED_OF_LIGHT))


def tr36777_los_parameters(channel: str, log_h, maximum):
    """TR 36.777 Table B-1: ``(p_1, d_1)`` in metres of the LoS probability ``d_1 / d_2D + exp(-d_2D / p_1)
    (1 - d_1 / d_2D)`` beyond ``d_1``, for ``log_h = log10(h / 1 m)``.  Arithmetic and ``maximum(x, floor)`` only, so
    plain floats and tensors share the formulas.

    Args:
        channel: ``"tr36777_uma"``, ``"tr36777_umi"`` or ``"tr36777_rma"``.
        log_h: ``log10`` of the UAV's height in m (a float or a tensor).
        maximum: ``maximum(x, floor)`` for the type of ``log_h``.
    """
    if channel == "tr36777_uma":
        return 4300 * log_h - 3800, maximum(460 * log_h - 700, 18.0)
    if channel == "tr36777_umi":
        return 233.98 * log_h - 0.95, maximum(294.05 * log_h - 432.94, 18.0)
    return maximum(15021 * log_h - 16053, 1000.0), maximum(1350.8 * log_h - 1602, 18.0)


def tr36777_losses_db(channel: str, log_d, log_h, carrier_ghz: float, maximum):
    """TR 36.777 Table B-2: ``(PL_LoS, PL_NLoS)`` in dB for ``log_d = log10(d_3D / 1 m)`` and ``log_h``, the carrier in
    GHz; ``maximum(x, y)`` of floats or tensors (see :func:`tr36777_los_parameters`).  The free-space term is the
    standard's ``20 log10(40 pi d_3D f_c / 3)`` (c = 3e8 m/s).

    Args:
        channel: ``"tr36777_uma"``, ``"tr36777_umi"`` or ``"tr36777_rma"``.
        log_d: ``log10`` of the 3-D distance in m (a float or a tensor).
        log_h: ``log10`` of the UAV's height in m.
        carrier_ghz: the carrier frequency in GHz.
        maximum: ``maximum(x, y)`` for the type of ``log_d``.
    """
    log_f = math.log10(carrier_ghz)
    free_space = 20 * math.log10(40 * math.pi * carrier_ghz / 3)  # plus 20 log10(d_3D)
    if channel == "tr36777_uma":
        los = 28.0 + 22 * log_d + 20 * log_f
        return los, -17.5 + (46 - 7 * log_h) * log_d + free_space
    if channel == "tr36777_umi":
        los = maximum(20 * log_d + free_space, 30.9 + (22.25 - 0.5 * log_h) * log_d + 20 * log_f)
        return los, maximum(los, 32.4 + (43.2 - 7.6 * log_h) * log_d + 20 * log_f)
    los = maximum(23.9 - 1.8 * log_h, 20.0) * log_d + free_space
    return los, maximum(los, -12 + (35 - 5.3 * log_h) * log_d + free_space)
