"""A study's report: ``python -m uavrl.report <run dirs or sweep dirs> [--out DIR]``.

Every ``metrics.json`` under the given directories (with the run's
``config.yaml`` and TensorBoard curves beside it) becomes one run; runs are
grouped by setting (the scenario, else the environment) and by agent (with the
settings that tell apart the runs of one agent in one setting, e.g.
``dqn agent.mixer=qmix``).  Each cell's seeds give the mean of each yardstick
metric with a 95% percentile-bootstrap confidence interval (numpy, a fixed
seed: the same runs give the same report) and, with 5 seeds or more, the
interquartile mean (rliable's recommendation).  ``report.md`` holds the tables,
the number of seeds per cell (cells with fewer than 3 flagged) and, per
setting, a PNG of the metrics (agents side by side, the baselines -- random,
oracle, planner -- as reference lines, one legend naming every agent with its
seeds) and one of the learning curves (mean over seeds with a 95% bootstrap
band).

A run whose files cannot be used (``metrics.json`` or ``config.yaml``
truncated, empty, not an object, a metric or setting of the wrong type, an
interpolation ``${...}``) is skipped: one ``warning:`` line on stderr names
it and why, ``report.md`` lists it, and the other runs are reported.  Saved
files are read as plain data: YAML without tags or aliases, interpolations
never resolved.  A NaN, infinite or null metric is missing (``-``, or
``(n=k)`` beside the seeds that have it), never ``nan``; where no run of a setting has one metric to plot,
``report.md`` says so in place of its metrics figure.

The command line is checked before numpy and matplotlib are imported; the report itself is
:func:`uavrl.experiment.reporting.report`'s.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from uavrl.envs._moved import moved_names

# uavrl 0.2's names of this module that moved to the library (report, iqm, bootstrap_ci, ...): deprecated aliases
__getattr__ = moved_names(__name__, "uavrl.experiment.io", "uavrl.experiment.saved", "uavrl.experiment.reporting")

MAX_RESAMPLES = 10**6  # bootstrap resamples: 10^6 draws of 64 seeds take 1 GB


class OneLineParser(argparse.ArgumentParser):
    def error(self, message: str):
        raise SystemExit(f"error: {message} (python -m uavrl.report --help)")


def main(argv=None) -> None:
    """``python -m uavrl.report``: the command line checked, then the report written and its path printed.

    Args:
        argv: the arguments; None: ``sys.argv[1:]``.
    """
    parser = OneLineParser(prog="python -m uavrl.report", description=__doc__.split("\n\n")[0])
    parser.add_argument("paths", nargs="+", help="run directories or sweep directories (searched for metrics.json)")
    parser.add_argument("--out", help="where report.md and the PNGs go (default: the one directory given)")
    parser.add_argument("--resamples", type=int, default=10_000, help="bootstrap resamples (default 10000)")
    parser.add_argument("--seed", type=int, default=0, help="the bootstrap's random seed (default 0)")
    args = parser.parse_args(argv)
    if args.out is None and len(args.paths) > 1:
        parser.error("--out is needed with several directories")
    if not 1 <= args.resamples <= MAX_RESAMPLES:
        parser.error(
            f"--resamples={args.resamples} is invalid: it must be a whole number in [1, {MAX_RESAMPLES:,}] (a cell's "
            "draws take resamples x seeds x 16 bytes, and the default 10,000 already fixes the interval to ~1%)"
        )
    if args.seed < 0:
        parser.error(f"--seed={args.seed} is invalid: it must be a whole number >= 0")
    if args.out is not None and Path(args.out).exists() and not Path(args.out).is_dir():
        parser.error(f"--out={args.out} is invalid: it is a file, not a directory")
    from uavrl.experiment import reporting  # numpy, matplotlib, TensorBoard's reader: once the arguments are good

    try:
        path = reporting.report(args.paths, args.out or args.paths[0], args.resamples, args.seed)
    except (OSError, reporting.DamagedRun) as err:
        raise SystemExit(f"error: {err}") from None
    print(f"report: {path} (figures beside it)")


if __name__ == "__main__":
    main()
