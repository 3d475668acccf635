"""Aggregate scores with rliable (Agarwal et al., NeurIPS 2021): the interquartile mean (IQM), mean, median and
optimality gap of the normalised scores with stratified bootstrap confidence intervals, score distributions
(performance profiles), and the probability of improvement of one results file over another.

The score matrix of a results file is rliable's ``(num_runs, num_tasks)``: a column per scored task, a row per held-out
start of each training run (runs x starts rows, the same in every task), so the bootstrap resamples starts and runs
within each task.  Every estimate calls rliable's own functions; rliable's stratified bootstrap draws its resamples
from numpy's global generator (``np.random.choice``, whatever ``random_state`` says), so each estimate runs with that
generator seeded :data:`BOOTSTRAP_SEED` (:func:`seeded`, its state restored after) and the same scores give the same
intervals, bit for bit.
"""

from __future__ import annotations

import contextlib
import warnings

BOOTSTRAP_SEED = 0
REPS = 5000  # bootstrap replications
CONFIDENCE = 0.95
PROFILE_TAUS = [round(0.05 * k, 2) for k in range(-4, 25)]  # normalised score thresholds of the profiles, -0.2 .. 1.2
METRICS = ("iqm", "mean", "median", "optimality_gap")


@contextlib.contextmanager
def seeded(seed: int = BOOTSTRAP_SEED):
    """numpy's global generator seeded ``seed`` inside, restored after; arch's notice that ``random_state`` is
    deprecated (rliable passes one) silenced."""
    import numpy as np

    state = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="random_state is deprecated", category=FutureWarning)
            yield np.random.RandomState(seed)
    finally:
        np.random.set_state(state)


def _rliable():
    try:
        from rliable import library, metrics
    except ImportError as err:
        raise ImportError(f"the benchmark's statistics need rliable ({err}): pip install 'uavrl[bench]'") from None
    return library, metrics


def score_matrix(results: dict, tasks: list[str] | None = None):
    """``(matrix [runs x starts, tasks], task names)`` of a results file's normalised scores (``tasks``: these, in
    this order; default every scored task)."""
    import numpy as np

    scored = {t["task"]: t for t in results["tasks"] if t["status"] == "scored"}
    names = [name for name in (tasks or list(scored)) if name in scored]
    columns = [np.asarray(scored[name]["scores"], dtype=np.float64).reshape(-1) for name in names]
    if len({len(c) for c in columns}) > 1:
        raise ValueError("the tasks were scored from different numbers of starts or runs: no common score matrix")
    return (np.stack(columns, 1) if columns else np.zeros((0, 0))), names


def aggregates(metrics):
    """rliable's aggregate functions, in the order of :data:`METRICS`."""
    import numpy as np

    return lambda x: np.array(
        [
            metrics.aggregate_iqm(x),
            metrics.aggregate_mean(x),
            metrics.aggregate_median(x),
            metrics.aggregate_optimality_gap(x),
        ]
    )


def aggregate(results: dict, reps: int = REPS) -> dict:
    """The suite's aggregate of a results file: each of :data:`METRICS` with its 95% stratified bootstrap CI, and the
    score distribution (performance profile) at :data:`PROFILE_TAUS` with its CIs, from ``reps`` bootstrap
    replications; empty when no task was scored."""

    matrix, names = score_matrix(results)
    if not names:
        return {"tasks": [], "note": "no task of the suite could be scored"}
    library, metrics = _rliable()
    with seeded() as random_state:
        point, interval = library.get_interval_estimates(
            {"x": matrix},
            aggregates(metrics),
            reps=reps,
            confidence_interval_size=CONFIDENCE,
            random_state=random_state,
        )
    with seeded() as random_state:
        profile, profile_ci = library.get_interval_estimates(
            {"x": matrix},
            lambda x: library.score_distributions(x, PROFILE_TAUS),
            reps=reps,
            confidence_interval_size=CONFIDENCE,
            random_state=random_state,
        )
    out = {"tasks": names, "rows": int(matrix.shape[0]), "reps": reps, "confidence": CONFIDENCE}
    for k, name in enumerate(METRICS):
        out[name] = float(point["x"][k])
        out[f"{name}_ci"] = [float(interval["x"][0][k]), float(interval["x"][1][k])]
    out["profile"] = {
        "taus": PROFILE_TAUS,
        "fraction": [float(v) for v in profile["x"]],
        "ci_low": [float(v) for v in profile_ci["x"][0]],
        "ci_high": [float(v) for v in profile_ci["x"][1]],
    }
    return out


def probability_of_improvement(a: dict, b: dict, reps: int = REPS) -> dict:
    """P(A > B) (rliable's ``probability_of_improvement``: the mean over tasks of the Mann-Whitney statistic of A's
    scores against B's) over the tasks both results ``a`` and ``b`` scored, with its 95% stratified bootstrap CI from
    ``reps`` replications."""
    import numpy as np

    if a["suite"] != b["suite"]:
        raise ValueError(f"the files score different suites ({a['suite']}, {b['suite']}): compare one suite")
    _, names_a = score_matrix(a)
    _, names_b = score_matrix(b)
    common = [name for name in names_a if name in names_b]
    if not common:
        raise ValueError("the two files share no scored task: nothing to compare")
    x, _ = score_matrix(a, common)
    y, _ = score_matrix(b, common)
    library, metrics = _rliable()
    with seeded() as random_state:
        point, interval = library.get_interval_estimates(
            {"p": [x, y]},
            lambda x, y: np.array([metrics.probability_of_improvement(x, y)]),
            reps=reps,
            confidence_interval_size=CONFIDENCE,
            random_state=random_state,
        )
    return {
        "tasks": common,
        "probability": float(point["p"][0]),
        "ci": [float(interval["p"][0][0]), float(interval["p"][1][0])],
    }
