"""The cost of one test-phase row's statistics: the IQM with its 95% CI and P(ER-MRL > PPO) with its CI, over 10
seeds, 2000 bootstrap resamples each (what ``ermrl test`` computes for every model and pair).

Times ermrl's statistics (``ermrl.analysis.statistics``) against the same rliable bootstraps fed rliable's own
statistic functions (``metrics.aggregate_iqm``, ``metrics.probability_of_improvement``), which compute the same
numbers through SciPy's per-call checks; checks that both give the same numbers; prints the medians.

    .venv/bin/python benchmarks/statistics_cost.py --repeats 5
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def rliable_reference(x: np.ndarray, y: np.ndarray, reps: int) -> tuple:
    """IQM CI of x, and P(x > y) with CI, from rliable with its own statistic functions, seeded as ermrl seeds it."""
    from rliable import library, metrics

    from ermrl.analysis.statistics import _rng, _seeded

    with _seeded(0):
        point, ci = library.get_interval_estimates({"m": x[:, None]}, lambda s: np.array([metrics.aggregate_iqm(s)]),
                                                   reps=reps, random_state=_rng(0))
    iqm = (point["m"][0], ci["m"][0, 0], ci["m"][1, 0])
    with _seeded(0):
        point, ci = library.get_interval_estimates({"xy": [x[:, None], y[:, None]]},
                                                   metrics.probability_of_improvement, reps=reps, random_state=_rng(0))
    return iqm, (float(np.ravel(point["xy"])[0]), *map(float, np.ravel(ci["xy"])))


def ours(x: np.ndarray, y: np.ndarray, reps: int) -> tuple:
    from ermrl.analysis import statistics

    s = statistics.summarize(x, reps)
    return (s.iqm, s.iqm_low, s.iqm_high), statistics.probability_of_improvement(x, y, reps)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed runs of each (default 5); medians printed")
    parser.add_argument("--reps", type=int, default=2000, help="bootstrap resamples (default 2000, as ermrl's)")
    args = parser.parse_args()
    for flag in ("repeats", "reps"):
        if getattr(args, flag) < 1:
            parser.error(f"--{flag} must be at least 1, got {getattr(args, flag)}")
    rng = np.random.default_rng(0)
    x, y = rng.normal(400.0, 80.0, 10), rng.normal(45.0, 5.0, 10)
    a, b = ours(x, y, args.reps), rliable_reference(x, y, args.reps)  # also imports rliable before timing
    if not np.array_equal(np.ravel(a), np.ravel(b)):
        raise SystemExit(f"statistics_cost.py: ermrl's statistics {a} differ from rliable's {b}")
    reference = "rliable's own statistics"
    times = {"ermrl": [], reference: []}
    for _ in range(args.repeats):
        for name, fn in (("ermrl", ours), (reference, rliable_reference)):
            start = time.perf_counter()
            fn(x, y, args.reps)
            times[name].append(time.perf_counter() - start)
    for name, t in times.items():
        print(f"{name}: median {np.median(t):.3f} s (min {min(t):.3f}, max {max(t):.3f}) for the IQM CI and P(X > Y) "
              f"CI of 10 seeds, {args.reps} resamples")
    print(f"ratio: {np.median(times[reference]) / np.median(times['ermrl']):.1f}×")


if __name__ == "__main__":
    main()
