"""Statistics for few-seed RL results, computed with ``rliable`` (Agarwal et al. 2021, the field's standard).

- the interquartile mean (IQM) with a 95% stratified-bootstrap confidence interval (percentile method);
- the probability of improvement P(X > Y) of one model over another, with its CI;
- the aggregate IQM over several tasks' normalized scores, and performance profiles;
- the paired difference of two measurements of the same runs (SciPy: BCa bootstrap CI, Wilcoxon signed-rank).

Seeds that diverged (None or NaN) are counted in ``n_diverged`` and left out of the statistics, never silently.
rliable (with pandas and arch) is imported inside the functions: it is slow to import.
"""

from __future__ import annotations

import contextlib
import dataclasses
import warnings
from pathlib import Path

import numpy as np

CONFIDENCE = 0.95


def _rng(seed: int) -> np.random.RandomState:
    return np.random.RandomState(seed)


@contextlib.contextmanager
def _seeded(seed: int):
    """rliable's stratified bootstraps draw their indices from NumPy's *global* generator (whatever random_state
    says), so seed it for reproducible CIs and restore it afterwards. Also silences arch's warning that
    ``random_state`` (which rliable passes) is deprecated."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="random_state is deprecated", category=FutureWarning)
            yield
    finally:
        np.random.set_state(state)


def _floats(values) -> np.ndarray:
    """``values`` (any shape, None for a diverged seed) as a float array of the same shape, None -> NaN."""
    shape = np.shape(values)
    return np.array([np.nan if v is None else v for v in np.ravel(np.asarray(values, dtype=object))],
                    float).reshape(shape)


def _finite(scores) -> tuple[np.ndarray, int]:
    """(finite scores (m,), number of non-finite entries) of a 1-D sequence with None/NaN for diverged seeds."""
    x = np.ravel(_floats(scores))
    ok = np.isfinite(x)
    return x[ok], int((~ok).sum())


@dataclasses.dataclass(frozen=True)
class ScoreSummary:
    """One model's final scores on one task, over seeds."""

    n: int
    """Seeds given, diverged ones included."""
    n_diverged: int
    """Seeds whose score is None/NaN (diverged, or no episode); left out of the statistics below."""
    mean: float | None
    std: float | None
    """Population std (ddof 0), as the paper's shaded bands."""
    iqm: float | None
    iqm_low: float | None
    iqm_high: float | None
    """The IQM's 95% stratified-bootstrap CI."""

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


# The two statistics below are rliable's own (``metrics.aggregate_iqm``, ``metrics.probability_of_improvement``),
# computed by the same steps, so to the same bits (tests/test_statistics.py checks it on random and tied scores).
# They exist for speed only: rliable's bootstrap calls its statistic once a resample (2000 a CI), and SciPy's
# trim_mean and mannwhitneyu, which rliable's versions call, spend ≈ 1.4 ms a call on argument checks (and
# mannwhitneyu on an exact p-value that the statistic discards). The default suite's short test phases spent
# ≈ 30% of their time in them.


def _iqm(scores: np.ndarray) -> float:
    """The interquartile mean over every run and task of ``scores`` (n_runs, n_tasks): SciPy's 25% trim_mean
    (partition, then the mean of the middle), as rliable's ``metrics.aggregate_iqm``."""
    a = np.ravel(scores)
    cut = int(0.25 * a.size)
    return np.mean(np.partition(a, (cut, a.size - cut - 1))[cut:a.size - cut])


def _improvement(x: np.ndarray, y: np.ndarray) -> float:
    """P(X > Y) of ``x`` (n_x, n_tasks) over ``y`` (n_y, n_tasks), as rliable's ``metrics.probability_of_improvement``:
    per task the Mann-Whitney U statistic of x over y (ties count half) over n_x · n_y, 0.5 where both columns are
    identical, averaged over tasks."""
    per_task = [0.5 if np.array_equal(a, b) else
                ((a[:, None] > b[None, :]).sum() + 0.5 * (a[:, None] == b[None, :]).sum()) / (len(a) * len(b))
                for a, b in zip(x.T, y.T)]
    return np.mean(per_task)


def iqm_interval(scores: np.ndarray, reps: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """(IQM, low, high) of ``scores`` (n_runs,) or (n_runs, n_tasks), with rliable's stratified bootstrap."""
    from rliable import library

    scores = np.asarray(scores, float)
    scores = scores[:, None] if scores.ndim == 1 else scores
    with _seeded(seed):
        point, interval = library.get_interval_estimates({"m": scores}, lambda x: np.array([_iqm(x)]),
                                                         reps=reps, confidence_interval_size=CONFIDENCE,
                                                         random_state=_rng(seed))
    return float(point["m"][0]), float(interval["m"][0, 0]), float(interval["m"][1, 0])


def summarize(scores, reps: int = 2000, seed: int = 0) -> ScoreSummary:
    """``scores``: (n_seeds,) final scores of one model on one task, None/NaN for a diverged seed. With one
    finite score the CI is that point; with none, every statistic is None."""
    x, bad = _finite(scores)
    n = len(x) + bad
    if len(x) == 0:
        return ScoreSummary(n, bad, None, None, None, None, None)
    if len(x) == 1:
        v = float(x[0])
        return ScoreSummary(n, bad, v, 0.0, v, v, v)
    iqm, low, high = iqm_interval(x, reps, seed)
    return ScoreSummary(n, bad, float(x.mean()), float(x.std()), iqm, low, high)


def probability_of_improvement(x, y, reps: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """(P(X > Y), low, high): the probability that a run of model x beats a run of model y (ties count half,
    by the Mann-Whitney U statistic), averaged over tasks, with a 95% CI from rliable's independent stratified
    bootstrap. ``x`` (n_x,) or (n_x, n_tasks), ``y`` likewise with the same tasks; runs with a non-finite score
    in any task are left out."""
    from rliable import library

    def clean(a):
        a = _floats(a)
        a = a[:, None] if a.ndim == 1 else a
        return a[np.isfinite(a).all(axis=1)]

    x, y = clean(x), clean(y)
    if len(x) == 0 or len(y) == 0:
        raise ValueError("probability of improvement needs at least one finite run of each model")
    if len(x) == 1 and len(y) == 1:  # nothing to resample: the CI is the point
        p = float(_improvement(x, y))
        return p, p, p
    with _seeded(seed):
        point, interval = library.get_interval_estimates({"xy": [x, y]}, _improvement,
                                                         reps=reps, confidence_interval_size=CONFIDENCE,
                                                         random_state=_rng(seed))
    low, high = np.ravel(interval["xy"])
    return float(np.ravel(point["xy"])[0]), float(low), float(high)


@dataclasses.dataclass(frozen=True)
class PairedDifference:
    """x − y over paired runs (the same seed, or the same agent measured twice)."""

    n: int
    """Pairs with both values finite (the others are left out)."""
    mean: float
    low: float
    high: float
    """The mean difference's 95% bootstrap CI (SciPy, BCa, 10,000 resamples)."""
    p: float
    """Wilcoxon signed-rank p-value (SciPy; zero differences, e.g. two scores at a ceiling, are dropped); NaN with
    fewer than 2 non-zero differences."""
    n_above: int
    """Pairs where x > y."""

    def __str__(self) -> str:
        """Two significant digits for p, so that a small one (10 of 10 pairs on one side: 0.002) is not shown as 0."""
        return (f"{self.mean:+.3g} [{self.low:+.3g}, {self.high:+.3g}], Wilcoxon p = {self.p:.2g}, "
                f"{self.n_above} of {self.n} above")


def paired_difference(x, y, reps: int = 10_000, seed: int = 0) -> PairedDifference:
    """The paired difference x − y of two (n,) sequences (None/NaN: left out with its pair), with the BCa CI of
    its mean and the Wilcoxon signed-rank p-value. ValueError with fewer than 2 finite pairs."""
    from scipy import stats

    a, b = _floats(x), _floats(y)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"paired values need two sequences of the same length, got {a.shape} and {b.shape}")
    diff = (a - b)[np.isfinite(a) & np.isfinite(b)]
    if len(diff) < 2:
        raise ValueError(f"a paired difference needs at least 2 finite pairs, got {len(diff)}")
    if np.all(diff == diff[0]):  # nothing varies: BCa is undefined, and the CI is the point
        low = high = float(diff[0])
    else:
        ci = stats.bootstrap((diff,), np.mean, n_resamples=reps, method="BCa", confidence_level=CONFIDENCE,
                             random_state=seed).confidence_interval
        low, high = float(ci.low), float(ci.high)
    nonzero = diff[diff != 0]
    p = float(stats.wilcoxon(nonzero).pvalue) if len(nonzero) >= 2 else float("nan")
    return PairedDifference(len(diff), float(diff.mean()), low, high, p, int((diff > 0).sum()))


def aggregate_iqm(scores: dict[str, np.ndarray], reps: int = 2000, seed: int = 0) -> dict[str, tuple[float, float, float]]:
    """{model: (n_runs, n_tasks) normalized scores} -> {model: (IQM, low, high)} over every run and task, the
    bootstrap stratified over tasks (rliable). Non-finite scores must be handled by the caller."""
    return {m: iqm_interval(np.asarray(s, float), reps, seed) for m, s in scores.items()}


def performance_profile(scores: dict[str, np.ndarray], path: Path | str, thresholds=None, reps: int = 2000,
                        seed: int = 0) -> Path:
    """Plots rliable's performance profiles, the fraction of runs whose normalized score exceeds τ with 95% CI
    bands, for {model: (n_runs, n_tasks)} into ``path`` (PNG), written atomically."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from rliable import library, plot_utils

    from ermrl.storage import atomic_path

    scores = {m: np.asarray(s, float) for m, s in scores.items()}
    if thresholds is None:
        allv = np.concatenate([s.ravel() for s in scores.values()])
        allv = allv[np.isfinite(allv)]
        lo, hi = (float(allv.min()), float(allv.max())) if allv.size else (0.0, 1.0)
        thresholds = np.linspace(min(lo, 0.0), max(hi, 1.0), 81)
    with _seeded(seed):
        profiles, cis = library.create_performance_profile(scores, thresholds, reps=reps)
    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    colors = {m: f"C{i}" for i, m in enumerate(scores)}
    plot_utils.plot_performance_profiles(profiles, thresholds, performance_profile_cis=cis, colors=colors, ax=ax,
                                         xlabel="normalized score (τ)", ylabel="fraction of runs with score > τ")
    ax.legend([Line2D([0], [0], color=c) for c in colors.values()], list(colors), fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    return Path(path)


def format_ci(value, low, high, digits: int = 1) -> str:
    """'412.3 [388.0, 430.1]', or '—' without a value."""
    if value is None:
        return "—"
    return f"{value:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"
