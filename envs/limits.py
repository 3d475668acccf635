"""Which values of the model's numbers keep its rates finite and positive (standard library only).

The rates of docs/model.md (How good a configuration is) are computed in float64:
channel gains ``g0 d^-alpha`` (``d`` in metres) or ``10^(-PL / 10)`` of a physical
model's path loss (docs/model.md, Channel models; its ranges of validity are
:func:`radio_problem`'s), SNRs ``g = P |h|^2 / noise``, the
amplify-and-forward term ``c = g1 g2 / (1 + g1 + g2)`` (or the authors'
``A / (1 + A)``, ``A = reference_gain |h|^2 |h|^2``) and ``R = 1/2 log2(1 + sum)``.
A gain or an SNR product beyond float64 turns a rate into NaN; a best cell whose
term ``c`` lies below float64's resolution next to 1 makes that network's rate 0
everywhere, and then ``U*`` (and every ``U / U*``) is undefined.  The checks work
on the logarithms of these quantities, over the distances every cell and every
layout the options allow can produce, so they cost microseconds whatever the
grid: :class:`~uavrl.envs.config.ModelConfig` runs them before anything is built.

Example:
    >>> values = dict(grid=(6, 6), num_uavs=2, layout="line", fading="none", cell_size=10.0, altitude=6.0,
    ...               alpha=2.0, g0=1.0, p_pt=0.01, p_s=0.02, p_u=0.02, noise=1e-9, direct_links=False,
    ...               rate_model="af", reference_gain=200.0, reward="delta", beta1=1.0, beta2=1.0, channel="paper")
    >>> physics_problem(values) is None
    True
    >>> physics_problem({**values, "p_u": 1e308})[:42]
    'the SNR product g1 g2 of the AF term c = g'
"""

from __future__ import annotations

import math
import numbers
import sys

from .physics import radio
from .physics.sensing import LOCAL_NODE_FEATURES, local_slot_features

NODE_NAMES = ("PT", "PR", "S", "E")
OWN_FEATURES = 13  # a UAV's (x, y, task) and the contributions at its cell and its 4 neighbours
NODE_FEATURES = 12  # PT, PR, S, E as (x / L1, y / L2, z / h): the last entries of the state
VERTICAL_FEATURES = 5  # with altitude levels, a UAV's level and the contributions a climb and a descent reach
SEED_LIMIT = 2**63  # seeds are int64: a seed (a run's, a world's) is a whole number in [0, 2^63), wrapped below it
_LOG_MAX = math.log10(sys.float_info.max)  # float64's largest number, 1.8e308
_LOG_MIN = math.log10(sys.float_info.min)  # its smallest normal number, 2.2e-308
_LOG_RESOLUTION = math.log10(sys.float_info.epsilon)  # below this s, 1 + s is 1 in float64 and log2(1 + s) is 0
_LOG_FLOAT32_MAX = math.log10(3.4028234663852886e38)  # rewards are float32
FADING_PEAK = 32 * math.log(2)  # the largest Exp(1) power gain drawn from a 32-bit uniform (fading=rayleigh)
# The largest power gain each fading draws.  A Rician X = |a + b z|^2 with a^2 + b^2 = 1 and |z|^2 an Exp(1) draw is at
# most (a + b sqrt(FADING_PEAK))^2 <= 1 + FADING_PEAK (Cauchy-Schwarz), whatever the K-factor; a LoS/NLoS draw gives
# at most the LoS gain, which the physical channels' bounds already allow.
FADING_PEAKS = {"none": 1.0, "rayleigh": FADING_PEAK, "los_nlos": 1.0, "rician": 1 + FADING_PEAK}
# the options whose value the checks can blame, in the order they are tried
PHYSICAL = (
    *("p_pt", "p_s", "p_u", "noise", "cell_size", "altitude", "alpha", "g0", "reference_gain"),
    *("p_pt_dbm", "p_s_dbm", "p_u_dbm", "bandwidth_mhz", "noise_figure_db", "carrier_ghz"),
)
DECIBELS = ("p_pt_dbm", "p_s_dbm", "p_u_dbm", "noise_figure_db")  # options in dB: any real number, not only positive
# (network, its source node, its destination node, the source's power option)
NETWORKS = (("the primary network (R_PU)", 0, 1, "p_pt"), ("the emergency network (R_SE)", 2, 3, "p_s"))


def fixed_node_positions(layout: str, grid: tuple[int, int], height: float) -> list[tuple[float, float, float]] | None:
    """``(x, y, z)`` of PT, PR, S, E in cells for a fixed layout (docs/model.md, Where the four nodes are), else
    ``None`` (``layout="random"`` draws them at every reset)."""
    L1, L2 = grid
    if layout == "line":
        return [(0.0, L2 / 2, 0.0), (float(L1), L2 / 2, 0.0), (-L1 / 2, L2 / 2, height), (1.5 * L1, L2 / 2, height)]
    if layout == "reference_code":
        return [(0.0, 5.0, 0.0), (10.0, 5.0, 0.0), (-5.0, 5.0, 10.0), (15.0, 5.0, 10.0)]
    return None


def max_ground_distance_cells(layout: str, grid: tuple[int, int], height: float) -> float:
    """The largest horizontal distance in cells from PT or PR to a cell centre over the layouts the options allow."""
    L1, L2 = grid
    nodes = fixed_node_positions(layout, grid, height)
    if nodes is None:  # layout=random: the nodes lie in the grid widened by half a grid on each side
        return 1.5 * math.hypot(L1, L2)
    return max(math.hypot(max(abs(x), abs(x - L1 + 1)), max(abs(y), abs(y - L2 + 1))) for x, y, _ in nodes[:2])


def _shown(log10_value: float) -> str:
    """``10 ** log10_value`` as ``1.2e+600``, also beyond float64."""
    if math.isinf(log10_value):
        return "inf" if log10_value > 0 else "0"
    exponent = math.floor(log10_value)
    mantissa = 10 ** (log10_value - exponent)
    if mantissa >= 9.95:
        mantissa, exponent = 1.0, exponent + 1
    return f"{mantissa:.2g}e{exponent:+03d}"


def _log_sum(*logs: float) -> float:
    """``log10(sum of 10 ** l)`` without leaving float64."""
    top = max(logs)
    if top == -math.inf:
        return top
    return top + math.log10(sum(10 ** (log - top) for log in logs))


def _log10(value: float) -> float:
    return math.log10(value) if value > 0 else -math.inf


class _Channels:
    """The logarithms of the gains of ``values`` (the options, ``altitude`` resolved to the UAVs' height).

    The physical channels' mean path loss in dB lies between its LoS and its NLoS loss (free space for the air-to-air
    links UAV-S and UAV-E), each rising with the distance: gains use the low end for what could overflow and the high
    end for what must stay above float64's resolution (``pessimistic``).
    """

    def __init__(self, values: dict):
        self.v = values
        self.log_cell = _log10(values["cell_size"])
        self.physical = values["channel"] in radio.PHYSICAL_CHANNELS
        if self.physical:
            dbm = {"p_pt": "p_pt_dbm", "p_s": "p_s_dbm", "p_u": "p_u_dbm"}
            self.log_watts = {name: (values[option] - 30) / 10 for name, option in dbm.items()}
            self.log_watts["noise"] = (radio.noise_dbm(values["bandwidth_mhz"], values["noise_figure_db"]) - 30) / 10
        else:
            self.log_watts = {name: _log10(values[name]) for name in ("p_pt", "p_s", "p_u", "noise")}

    def _loss_db(self, metres: float, node: int, pessimistic: bool) -> float:
        """The least (or, ``pessimistic``, the largest) mean path loss in dB of a link ``metres`` long to ``node``."""
        v = self.v
        free = radio.free_space_db(metres, v["carrier_ghz"])
        if node >= 2:  # S and E fly at the UAVs' height: free space
            return free
        if v["channel"] == "al_hourani":
            _, _, eta_los, eta_nlos = radio.AL_HOURANI[v["environment"]]
            return free + (eta_nlos if pessimistic else eta_los)
        h = v["altitude"] * v["cell_size"]
        los, nlos = radio.tr36777_losses_db(v["channel"], math.log10(metres), math.log10(h), v["carrier_ghz"], max)
        if h > radio.TR36777[v["channel"]].all_los_above_m:
            return los
        return max(los, nlos) if pessimistic else min(los, nlos)

    def log_power(self, cells: float, node: int = 0) -> float:
        """``log10 d^-alpha`` at ``cells`` cells (``d`` in metres), the power torch computes before ``g0``; for the
        physical channels the largest mean gain ``10^(-PL / 10)``."""
        if cells == 0:
            return math.inf
        if self.physical:
            return -self._loss_db(cells * self.v["cell_size"], node, pessimistic=False) / 10
        return -self.v["alpha"] * (math.log10(cells) + self.log_cell)

    def log_gain(self, cells: float, node: int = 0, pessimistic: bool = False) -> float:
        if self.physical:
            return math.inf if cells == 0 else -self._loss_db(cells * self.v["cell_size"], node, pessimistic) / 10
        return self.log_power(cells) + _log10(self.v["g0"])

    def log_term(self, log_gain_src: float, log_gain_dst: float, src_power: str) -> float:
        """``log10 c`` of a UAV with those link gains: the AF term, or the authors' ``A / (1 + A)``."""
        v, w = self.v, self.log_watts
        if v["rate_model"] == "reference_code":
            a = _log10(v["reference_gain"]) + log_gain_src + log_gain_dst
            return a - _log_sum(0.0, a)
        g1 = log_gain_src + w[src_power] - w["noise"]
        g2 = log_gain_dst + w["p_u"] - w["noise"]
        return g1 + g2 - _log_sum(0.0, g1, g2)


def _distances(values: dict) -> tuple[list[tuple[float, float, float]], list[tuple[float, float]]]:
    """Per node, in cells: the least distance to a cell centre over every layout the options allow, the largest
    distance to its nearest cell, and the largest to any cell; per network, the least and largest direct distance."""
    (L1, L2), h = values["grid"], values["altitude"]
    nodes = fixed_node_positions(values["layout"], values["grid"], h)
    if nodes is None:  # layout=random: PT, PR on the ground, S, E aloft at least half a cell from every cell centre
        near, far, diagonal = math.hypot(L1 / 2 + 1, L2 / 2 + 1), 1.5 * math.hypot(L1, L2), math.hypot(L1, L2)
        ground, aloft = (h, math.hypot(near, h), math.hypot(far, h)), (0.5, near, far)
        return [ground, ground, aloft, aloft], [(0.6 * diagonal, 2 * diagonal)] * 2
    per_node = []
    for x, y, z in nodes:
        nearest = math.hypot(min(max(round(x), 0), L1 - 1) - x, min(max(round(y), 0), L2 - 1) - y, h - z)
        farthest = math.hypot(max(abs(x), abs(x - L1 + 1)), max(abs(y), abs(y - L2 + 1)), h - z)
        per_node.append((nearest, nearest, farthest))
    direct = [math.dist(nodes[src], nodes[dst]) for _, src, dst, _ in NETWORKS]
    return per_node, [(d, d) for d in direct]


def _best_term_at_least(values: dict, channels: _Channels, src: int, dst: int, power: str) -> float:
    """``log10`` of a lower bound on the largest term ``c`` of the network over the cells (mean channels).

    A fixed layout: the exact term at three cells (nearest the source, the destination, and their midpoint).
    A random one: the cell nearest the source, or nearest the destination, in the layout that puts it farthest.
    """
    (L1, L2), h = values["grid"], values["altitude"]
    nodes = fixed_node_positions(values["layout"], values["grid"], h)
    if nodes is None:
        (_, reach_src, far_src), (_, reach_dst, far_dst) = (_distances(values)[0][i] for i in (src, dst))
        return max(
            channels.log_term(channels.log_gain(reach_src, src, True), channels.log_gain(far_dst, dst, True), power),
            channels.log_term(channels.log_gain(far_src, src, True), channels.log_gain(reach_dst, dst, True), power),
        )
    a, b = nodes[src], nodes[dst]
    best = -math.inf
    for x, y in ((a[0], a[1]), (b[0], b[1]), ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)):
        cell = (min(max(round(x), 0), L1 - 1), min(max(round(y), 0), L2 - 1), h)
        gains = channels.log_gain(math.dist(cell, a), src, True), channels.log_gain(math.dist(cell, b), dst, True)
        best = max(best, channels.log_term(*gains, power))
    return best


def is_number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)


def radio_problem(values: dict) -> tuple[str, str] | None:
    """The option of a physical channel outside where its model holds (:mod:`uavrl.envs.physics.radio`), and why;
    ``None`` when every one lies inside.  ``values`` as :func:`physics_problem` reads them, with ``altitude_m``."""
    v, channel = values, values["channel"]
    low, high = radio.CARRIER_GHZ[channel]
    ranges = {
        "carrier_ghz": (low, high, f"channel={channel!r} holds for carriers (GHz)"),
        "bandwidth_mhz": (*radio.BANDWIDTH_MHZ, "give a bandwidth in MHz"),
        "noise_figure_db": (*radio.NOISE_FIGURE_DB, "give a receiver's noise figure in dB"),
        **{name: (*radio.POWER_DBM, "give a transmit power in dBm") for name in ("p_pt_dbm", "p_s_dbm", "p_u_dbm")},
    }
    for name, (low, high, what) in ranges.items():
        if not (is_number(v[name]) and low <= v[name] <= high):
            return name, f"{what} in [{low:g}, {high:g}]"
    if channel == "al_hourani":
        low, high = radio.AL_HOURANI_HEIGHT_M
        metres = v["altitude"] * v["cell_size"]
        if not low < metres < high:
            reason = (
                f"the UAVs fly at {metres:g} m, and Al-Hourani's model is of low-altitude platforms: heights below "
                f"{high:g} m, where ITU-R's high-altitude platforms begin (altitude_m sets the height in metres)"
            )
            return ("altitude_m" if v["altitude_m"] is not None else "altitude"), reason
    if channel in radio.TR36777:
        scenario = radio.TR36777[channel]
        low, high = scenario.height_m
        metres = v["altitude"] * v["cell_size"]
        if not low < metres <= high:
            reason = (
                f"the UAVs fly at {metres:g} m, and TR 36.777's {scenario.name} model holds for heights in "
                f"({low:g}, {high:g}] m (altitude_m sets the height in metres)"
            )
            return ("altitude_m" if v["altitude_m"] is not None else "altitude"), reason
        reach = max_ground_distance_cells(v["layout"], v["grid"], v["altitude"]) * v["cell_size"]
        if reach > scenario.max_d2d_m:
            reason = (
                f"a UAV can be {reach:.4g} m from PT or PR along the ground, and TR 36.777's {scenario.name} model "
                f"holds to {scenario.max_d2d_m:g} m: use smaller cells or a smaller grid"
            )
            return "cell_size", reason
    return None


def physics_problem(values: dict) -> str | None:
    """Why the options ``values`` would give NaN, infinite or everywhere-zero rates, or ``None`` when they do not.

    ``values`` holds :class:`~uavrl.envs.config.ModelConfig`'s options by name, ``altitude`` as the UAVs' height in
    cells.
    """
    v, channels = values, _Channels(values)
    per_node, direct = _distances(v)
    fade = math.log10(FADING_PEAKS[v["fading"]])
    law = "10^(-PL / 10)" if channels.physical else "g0 d^-alpha"
    for node, (name, (closest, _, _)) in enumerate(zip(NODE_NAMES, per_node, strict=True)):
        if closest == 0:
            return f"{name} sits on a UAV cell at UAV altitude (distance 0, an infinite channel gain)"
        power, gain = channels.log_power(closest, node), channels.log_gain(closest, node)
        if max(power, gain) + fade > _LOG_MAX:
            metres = f"{closest * v['cell_size']:.3g} m"
            return (
                f"the channel gain {law} from {name} to its nearest cell ({metres}) reaches "
                f"{_shown(max(power, gain) + fade)}, beyond float64's {_shown(_LOG_MAX)}, so the rates would be NaN"
            )
    largest_sum, af = -math.inf, v["rate_model"] == "af"
    for network, src, dst, power in NETWORKS:
        gain_src, gain_dst = (channels.log_gain(per_node[i][0], i) + fade for i in (src, dst))
        if af:
            snr_src = channels.log_watts[power] - channels.log_watts["noise"]
            snr_u = channels.log_watts["p_u"] - channels.log_watts["noise"]
            g1, g2 = gain_src + snr_src, gain_dst + snr_u
            if max(snr_src, snr_u, g1 + g2, max(g1, g2) + math.log10(3)) > _LOG_MAX:
                return (
                    f"the SNR product g1 g2 of the AF term c = g1 g2 / (1 + g1 + g2) reaches {_shown(g1 + g2)} in "
                    f"{network}, beyond float64's {_shown(_LOG_MAX)}, so the rates would be NaN"
                )
            largest_term = min(g1, g2)  # c < min(g1, g2)
        else:
            a = _log10(v["reference_gain"]) + gain_src + gain_dst
            if max(a, a - gain_dst) > _LOG_MAX:
                return (
                    f"the authors' A = reference_gain |h|^2 |h|^2 reaches {_shown(a)} in {network}, beyond float64's "
                    f"{_shown(_LOG_MAX)}, so the rates would be NaN"
                )
            largest_term = 0.0  # A / (1 + A) < 1
        log_direct = -math.inf
        if v["direct_links"]:
            log_direct = channels.log_gain(direct[src // 2][0]) + _log10(v[power]) - _log10(v["noise"]) + fade
        total = _log_sum(math.log10(v["num_uavs"]) + largest_term, log_direct)
        if total + math.log10(2) > _LOG_MAX:
            return (
                f"the sum inside the logarithm of {network} reaches {_shown(total)}, beyond float64's "
                f"{_shown(_LOG_MAX)}, so the rates would be infinite"
            )
        largest_sum = max(largest_sum, total)
        best = _best_term_at_least(v, channels, src, dst, power)
        if v["direct_links"]:
            best = _log_sum(best, channels.log_gain(direct[src // 2][1]) + _log10(v[power]) - _log10(v["noise"]))
        if best < _LOG_RESOLUTION:
            return (
                f"a UAV in the best cell adds only about {_shown(best)} inside the logarithm of {network}, below "
                f"float64's resolution {_shown(_LOG_RESOLUTION)} next to 1, so that rate would be 0 everywhere and "
                "U* (and every U / U*) undefined"
            )
    largest_rate = math.log2(1 + 10 ** min(largest_sum, _LOG_MAX - 1)) * (0.5 if af else 1.0)
    weight = abs(v["beta1"]) + abs(v["beta2"])  # reward="delta": |beta1 dR_PU + beta2 dR_SE| <= weight * the rate
    if v["reward"] == "delta" and weight and math.log10(weight) + _log10(largest_rate) > _LOG_FLOAT32_MAX:
        return (
            f"delta rewards weighted by |beta1| + |beta2| = {weight:.3g} reach "
            f"{_shown(math.log10(weight) + _log10(largest_rate))} for rates up to {largest_rate:.3g} bit/s/Hz, "
            "beyond float32's 3.4e+38 (the reward's dtype)"
        )
    return None


def allowed_range(values: dict, name: str, good: float) -> str:
    """The values of the option ``name`` with which ``values`` passes :func:`physics_problem`, as words.

    ``good`` is a value that passes (the preset's).  Along one option every condition is monotone, so what passes
    is one interval around ``good``: its ends are found by bisection, on ``log10`` of a positive option's value, on
    the value itself within ``[-1000, 1000]`` for one in dB (to 0.01 dB).
    """
    decibels = name in DECIBELS

    def passes(x: float) -> bool:
        return physics_problem({**values, name: x if decibels else 10**x}) is None

    def edge(inside: float, outside: float) -> float | None:
        if passes(outside):
            return None
        for _ in range(60):
            middle = (inside + outside) / 2
            inside, outside = (middle, outside) if passes(middle) else (inside, middle)
        return inside

    if decibels:
        unit = " dBm" if name.endswith("_dbm") else " dB"
        low, high = edge(good, -1000.0), edge(good, 1000.0)
        low_text = None if low is None else f"{math.ceil(low * 100) / 100:g}"
        high_text = None if high is None else f"{math.floor(high * 100) / 100:g}"
    else:  # printed with 3 digits, rounded towards the inside so that the printed ends pass too
        unit, centre = "", math.log10(good)
        low, high = edge(centre, _LOG_MIN), edge(centre, _LOG_MAX - 1e-9)
        low_text = None if low is None else _rounded(10**low, math.ceil)
        high_text = None if high is None else _rounded(10**high, math.floor)
    if low_text and high_text:
        return f"with the other settings as they are it must lie in [{low_text}, {high_text}]{unit}"
    if high_text:
        return f"with the other settings as they are it must be at most {high_text}{unit}"
    if low_text:
        return f"with the other settings as they are it must be at least {low_text}{unit}"
    return "no value of it passes with the other settings as they are"


def _rounded(value: float, direction) -> str:
    """``value`` to 3 significant digits, rounded by ``direction`` (``math.floor`` or ``math.ceil``)."""
    scale = 10 ** (math.floor(math.log10(value)) - 2)
    return f"{direction(value / scale) * scale:.3g}"


# ---------------------------------------------------------------------------------------------------------- sizes
DEFAULT_MEMORY_BUDGET = 4 * 2**30  # bytes a World (or a command's largest allocations) may take unless raised
EXACT_SOLVER_BUDGET = 2**30  # uavrl.envs.solvers.exact.MEMORY_BUDGET: beyond it the evaluation uses lower bounds


def num_configurations(num_positions: int, num_uavs: int) -> int:
    """Sets of N (position, task) pairs on distinct positions: ``C(P, N) 2^N``."""
    return math.comb(num_positions, num_uavs) * 2**num_uavs


def required_bytes(num_positions: int, num_uavs: int, num_actions: int = 6) -> int:
    """Memory of the exact solver (:class:`uavrl.envs.solvers.exact.ConfigurationSpace`) over ``num_positions``
    positions and ``num_actions`` per UAV: the int32 successor table, the configurations and one chunked sweep of
    ``2^23`` gathered values."""
    K, A = num_configurations(num_positions, num_uavs), num_actions**num_uavs
    return K * A * 4 + K * num_uavs * 16 + K * 8 * 8 + (1 << 23) * 16


def exact_solver_fits(
    num_positions: int, num_uavs: int, memory_budget: int = EXACT_SOLVER_BUDGET, num_actions: int = 6
) -> bool:
    """Whether :func:`required_bytes` is within ``memory_budget``; a team whose joint actions alone are over it is
    answered without counting the configurations (a binomial that takes seconds for 10^5 UAVs)."""
    if num_uavs * math.log(num_actions) + math.log(4) > math.log(max(memory_budget, 1)):
        return False
    return required_bytes(num_positions, num_uavs, num_actions) <= memory_budget


def table_bytes(cfg, num_tables: int) -> int:
    """Bytes of the tabular learner's Q tables plus the model tables it keeps beside them
    (:mod:`uavrl.agents.tabular.tables`), in plain integers so the commands check it before torch is imported; over
    ``num_positions`` (an upper bound in a city, where positions inside buildings are left out)."""
    A = cfg.num_joint_actions
    positions = cfg.num_positions**cfg.num_uavs  # placements
    configs = positions * 2**cfg.num_uavs
    # per placement and joint action: next cells (int32), valid flag, moves, the valid list; per configuration:
    # both rates (float64) and the Q row
    per_action, per_configuration = 4 + 1 + 1 + valid_list_itemsize(A), 8 + 8 + row_itemsize(cfg)
    return num_tables * cfg.num_states * A * 8 + positions * A * per_action + configs * per_configuration


def valid_list_itemsize(num_joint_actions: int) -> int:
    """Bytes of the smallest integer type that holds a joint action index."""
    return 1 if num_joint_actions <= 256 else 2 if num_joint_actions <= 2**15 else 4


def row_itemsize(cfg) -> int:
    """Bytes of the integer type of a Q table's row index."""
    return 4 if cfg.num_states < 2**31 else 8


def observation_size(
    num_uavs: int, energy: bool, levels: bool = False, local: bool = False, message_size: int = 0
) -> int:
    """Per-UAV observation entries of a World of ``num_uavs`` UAVs (spares included): its own (x, y, task) and
    contributions at its own and 4 next cells, the others' (x, y, task); under an energy model (``energy``) then its
    battery and service flag, and the others'; with altitude levels (``levels``) then its level and the contributions
    at the positions a climb and a descent reach (:data:`VERTICAL_FEATURES`), and the others' levels.  A ``local``
    observation holds its own part, then a slot per node and per other UAV (:mod:`uavrl.envs.physics.sensing`,
    ``message_size`` numbers of each other UAV's message).  The World's, the networks' and the costs' one formula.

    Example:
        >>> observation_size(2, energy=False), observation_size(2, energy=True), observation_size(2, False, True)
        (16, 20, 22)
        >>> observation_size(3, energy=False, local=True), observation_size(3, False, local=True, message_size=2)
        (37, 41)
    """
    if local:
        own = OWN_FEATURES + (2 if energy else 0) + (VERTICAL_FEATURES if levels else 0)
        return own + LOCAL_NODE_FEATURES + (num_uavs - 1) * local_slot_features(energy, levels, message_size)
    vertical = VERTICAL_FEATURES + num_uavs - 1 if levels else 0
    return OWN_FEATURES + 3 * (num_uavs - 1) + (2 * num_uavs if energy else 0) + vertical


def model_observation_size(cfg) -> int:
    """:func:`observation_size` of the model ``cfg`` (a :class:`~uavrl.envs.config.ModelConfig`)."""
    return observation_size(cfg.fleet_size, cfg.energy != "none", cfg.num_levels > 1, cfg.local, cfg.message_size)


def state_size(num_uavs: int, energy: bool, levels: bool = False) -> int:
    """Entries of a world's state: per UAV (x, y, task) and its contributions at its cell (under an energy model then
    its battery and service flag; with altitude levels then its level), then the 4 nodes' (x, y, z)."""
    return (7 if energy else 5) * num_uavs + (num_uavs if levels else 0) + NODE_FEATURES


PAIR_FEATURES = 3  # the size-free network's view of another UAV: (dx, dy) by the grid's span, exp(-its distance)


def local_set_sizes(energy: bool, levels: bool = False) -> tuple[int, int]:
    """Entries of a UAV's own input and of each UAV it hears to the size-free network on local observations
    (``LocalSetQCore``): its local observation's own part and node slots, and which of the positions its moves reach
    it hears held; each heard UAV's (dx, dy) by the grid's span (and its level offset), ``exp(-its distance)``, its
    task, under an energy model its battery and service flag.  Neither grows with N or the grid."""
    own = observation_size(1, energy, levels, local=True) + (6 if levels else 4)
    return own, PAIR_FEATURES + (1 if levels else 0) + 1 + (2 if energy else 0)


def set_input_size(energy: bool, levels: bool = False) -> int:
    """Entries of a UAV's own input to the size-free network (``SetQCore``): its observation's own part, the nodes,
    which of its 4 next cells another UAV holds (6 positions with altitude levels: ``levels``), under an energy model
    its battery and service flag, with altitude levels its observation's :data:`VERTICAL_FEATURES`."""
    return OWN_FEATURES + NODE_FEATURES + 4 + (2 if energy else 0) + (2 + VERTICAL_FEATURES if levels else 0)


def world_bytes(cfg, batch_size: int) -> int:
    """Peak bytes of ``World(cfg, batch_size)`` built, reset and stepped (measured: 1.0 GB for 1000x1000 and one
    world, 3.1 GB for 300x300 and 64 random layouts, 1.9 GB for 10^6 worlds of 4 UAVs on 6x6).

    The geometry and the per-code tables cost ~500 bytes a position (a cell at one level), each layout's tables ~520
    (while they are built: one set for a fixed layout, shared by every world); each world ~440 bytes a UAV and what a
    reset takes to place its UAVs (:func:`placement_bytes`).
    """
    C, N, B = cfg.num_positions, cfg.fleet_size, batch_size  # the tables are per position: per cell at one level
    layouts = B if cfg.layout == "random" else 1
    per_world = placement_bytes(cfg) + 440 * N + 64
    if cfg.energy != "none":  # the batteries, status and timers, and a step's ~12 [B, N] temporaries of energy
        per_world += 120 * N
    pair_tables = (2 * C) ** 2 * 200 if N == 2 and layouts == 1 and (2 * C) ** 2 <= 1 << 16 and not cfg.local else 0
    local = 0
    if cfg.local:  # the nodes heard by code per layout, the slots by displacement, a step's slots and messages
        slots = C + (cfg.energy != "none")
        heard = 2 * (2 * cfg.grid[0] - 1) * (2 * cfg.grid[1] - 1) * cfg.num_levels**2 * (5 if slots > C else 1)
        local = 2 * slots * 4 * LOCAL_NODE_FEATURES * 2 * layouts + 16 * heard
        per_world += 3 * 4 * N * (N - 1) * local_slot_features(cfg.energy != "none", cfg.num_levels > 1, 0)
        per_world += 3 * 4 * N * N * cfg.message_size
    return 500 * C + 520 * C * layouts + B * per_world + pair_tables + local


# grids of at most this many cells place a reset's UAVs as every published figure did (the N smallest of one random
# key per cell); larger ones draw N distinct cells directly (uavrl.envs.physics.streams.distinct_cells), at no cost
# per cell
KEYED_PLACEMENT_CELLS = 10_000


def placement_bytes(cfg) -> int:
    """Bytes a reset takes per world to place its UAVs on distinct cells (:meth:`uavrl.envs.physics.dynamics.Dynamics.
    start`): 16 a cell (a random key and its ordering) on grids of at most ``KEYED_PLACEMENT_CELLS`` cells, beyond
    ~64 a UAV whatever the grid's size."""
    return 16 * cfg.num_cells if cfg.num_cells <= KEYED_PLACEMENT_CELLS else 64 * cfg.fleet_size


def env_bytes(cfg, batch_size: int) -> int:
    """Peak bytes of ``UAVSpectrumEnv(batch_size, config=cfg)`` built and stepped: its World's, a step's output of
    every world, and its specs (the unbatched shapes of a step, each held ~3 times: a spec's zero, low and high)."""
    return world_bytes(cfg, batch_size) + (batch_size + 3) * frame_bytes(cfg)


def frame_bytes(cfg) -> int:
    """Bytes of one transition (a step's TensorDict and its ``"next"``) of ``UAVSpectrumEnv``, every key (the spares
    are agents too)."""
    N, energy, levels = cfg.fleet_size, cfg.energy != "none", cfg.num_levels > 1
    observation = 4 * N * model_observation_size(cfg)
    per_step = observation + 4 * state_size(N, energy, levels) + 6 * N + 16 * N + 8 * N + 8 * N + 64  # state, mask
    per_step += 8 * N if levels else 0  # the UAVs' levels
    return 2 * per_step


def stored_transition_bytes(cfg) -> int:
    """Bytes of one transition in the DQN's replay buffer, kept compact (``uavrl.agents.dqn.transitions``): each
    UAV's code now and next (int16, int32 past 32767 codes), its action (int8), under an energy model its battery and
    service flag now and next (float32), a random layout's nodes (float64), the joint action (the largest head's),
    the reward, done flags and the slot's index."""
    N = cfg.fleet_size
    code = 2 if 2 * (cfg.num_cells + 1) <= 2**15 - 1 else 4
    energy = 0 if cfg.energy == "none" else 2 * N * 2 * 4
    nodes = 4 * 3 * 8 if cfg.layout == "random" else 0
    return 2 * N * code + N + energy + nodes + 2 + 4 + 2 + 8  # joint action, reward, done flags, index


def bounds_bytes(cfg, num_starts: int, horizon: int) -> int:
    """Peak bytes of the evaluation's lower bounds (:mod:`uavrl.envs.solvers.bounds`) where the exact solver does not
    fit: each world's best reachable terms ``[K + 1, N]``, then the relaxation (chunks of (world, step) rows over every
    split of up to ``MAX_SPLIT_UAVS`` UAVs, or a few ``[rows, N]`` tensors beyond), and the optimal sets (at most
    ``MAX_CANDIDATES`` candidates, or ``[N, P]`` moves per listed set where they are searched)."""
    N, C, rows = cfg.num_uavs, cfg.num_positions, num_starts * (horizon + 1)
    # the positions scanned per UAV: those within the horizon (uavrl.envs.solvers.bounds.reach_size), at every level
    levels = range(1 - cfg.num_levels, cfg.num_levels)
    reach = min(C, sum(2 * k * (k + 1) + 1 for k in (horizon - abs(d) for d in levels) if k >= 0))
    chunk = 1 << 22  # uavrl.envs.solvers.bounds._CHUNK_ELEMENTS
    reachable = 2 * rows * N * 8 + min(num_starts * N * reach, max(chunk, N * reach)) * 48
    if N <= 10:  # uavrl.envs.solvers.bounds.MAX_SPLIT_UAVS
        relaxation = rows * 8 * 4 + max(chunk, 2**N) * 8 * 8
        candidates = 2_000_000 * N * 8 * 4
    else:
        relaxation = rows * N * 8 * 12
        candidates = N * C * 8 * 8
    return reachable + max(relaxation, candidates)


def default_horizon(grid) -> int:
    """Greedy evaluation length on a ``(L1, L2)`` grid (``eval.horizon`` null): enough steps to cross it twice."""
    return max(20, 2 * sum(grid))


def mission_steps(cfg) -> int:
    """The steps by which every UAV of ``cfg`` (an energy model) is home from a full battery (docs/model.md, What the
    numbers mean): a UAV serves at most ``floor((capacity - least reserve) / cheapest step)`` steps, leaves on the
    next, then flies home over at most the farthest cell's steps.  The least reserve is taken as the cheapest step
    plus the flight from the nearest cell, at most the reserve of any cell, so the count never falls short."""
    energies, (L1, L2), (bx, by) = cfg.step_energies, cfg.grid, cfg.base
    nearest = max(0, -bx, bx - (L1 - 1)) + max(0, -by, by - (L2 - 1))
    farthest = max(abs(bx), abs(bx - (L1 - 1))) + max(abs(by), abs(by - (L2 - 1)))
    cheapest = energies.cheapest
    serving = math.floor((energies.capacity - cheapest - energies.flight(nearest)) / cheapest)
    return serving + 1 + farthest


def evaluation_horizon(cfg) -> int:
    """The evaluation's default length (``eval.horizon`` null): :func:`default_horizon` of the grid, or under an
    energy model the whole mission (:func:`mission_steps`)."""
    return default_horizon(cfg.grid) if cfg.energy == "none" else mission_steps(cfg)


def evaluation_bytes(cfg, num_starts: int, horizon: int, tables: int = 0) -> int:
    """Peak bytes of an evaluation (:mod:`uavrl.agents.evaluation`): the starts' worlds, the greedy rollouts (``tables``
    > 0: the tabular agent's ``tables x num_starts`` worlds stepped together, keeping each step's outputs; else a
    TorchRL rollout of every transition) and the references: the exact solver where it fits, else the bounds."""
    if tables:
        rows = tables * num_starts
        play = world_bytes(cfg, rows) + rows * horizon * (6 * 8 + 24 * cfg.num_uavs)
    else:
        play = num_starts * horizon * frame_bytes(cfg)
    layouts = num_starts if cfg.layout == "random" else 1
    P, N, A = cfg.num_positions, cfg.num_uavs, cfg.joint_action_base
    if exact_solver_fits(P, N, num_actions=A):
        # the solver's tables and each layout's values over its configurations
        solver, configurations = required_bytes(P, N, A), num_configurations(P, N)
        references = solver + layouts * configurations * 8 * 4
    else:
        references = bounds_bytes(cfg, num_starts, horizon)
    return world_bytes(cfg, num_starts) + play + references


def gib(size: int) -> str:
    """``size`` bytes as ``12,345,678 bytes (11.8 MiB)``; beyond 2^60 bytes as ``1.2e+21 bytes``."""
    if size >= 2**60:
        return f"{_shown(math.log10(size))} bytes"
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if size >= scale:
            return f"{size:,} bytes ({size / scale:.3g} {unit})"
    return f"{size:,} bytes"
