"""The statistics equal rliable's (and SciPy's) own on fixed arrays, and count diverged seeds."""

import numpy as np
import pytest
import scipy.stats
from rliable import library, metrics

from ermrl.analysis import statistics

# rliable calls arch with random_state, which arch deprecates; ermrl silences it (statistics._seeded), these
# direct calls to rliable for reference values do not
pytestmark = pytest.mark.filterwarnings("ignore:random_state is deprecated:FutureWarning")

SCORES = np.random.default_rng(0).normal(100.0, 30.0, size=12)
PNG = b"\x89PNG\r\n\x1a\n"


def rliable_iqm(scores, reps, seed):
    np.random.seed(seed)  # rliable's stratified bootstrap draws from NumPy's global generator
    point, interval = library.get_interval_estimates({"m": scores}, lambda x: np.array([metrics.aggregate_iqm(x)]),
                                                     reps=reps, random_state=np.random.RandomState(seed))
    return point["m"][0], interval["m"][0, 0], interval["m"][1, 0]


def test_iqm_and_its_interval_equal_rliables():
    s = statistics.summarize(SCORES, reps=500, seed=3)
    assert (s.iqm, s.iqm_low, s.iqm_high) == rliable_iqm(SCORES[:, None], 500, 3)  # to the bit
    assert s.iqm == pytest.approx(scipy.stats.trim_mean(SCORES, 0.25))  # an independent check (n divisible by 4)
    assert s.iqm_low < s.iqm < s.iqm_high
    assert (s.mean, s.std, s.n, s.n_diverged) == (pytest.approx(SCORES.mean()), pytest.approx(SCORES.std()), 12, 0)


def test_probability_of_improvement_equals_rliables():
    x, y = SCORES[:6, None], SCORES[6:, None] + 20
    np.random.seed(1)
    point, interval = library.get_interval_estimates({"xy": [x, y]}, metrics.probability_of_improvement, reps=400,
                                                     random_state=np.random.RandomState(1))
    ours = statistics.probability_of_improvement(SCORES[:6], SCORES[6:] + 20, reps=400, seed=1)
    assert ours == (point["xy"], *np.ravel(interval["xy"]))  # to the bit
    assert statistics.probability_of_improvement([5.0, 6.0, 7.0], [1.0, 2.0], reps=200)[0] == 1.0
    assert statistics.probability_of_improvement(SCORES, SCORES, reps=200)[0] == 0.5


def test_the_fast_statistics_are_rliables_to_the_bit():
    """The IQM and P(X > Y) that the bootstraps resample are rliable's own numbers, on runs with and without ties,
    one task and several, sizes divisible by 4 or not, identical columns."""
    rng = np.random.default_rng(7)
    for n_x, n_y, tasks in ((10, 10, 1), (3, 7, 1), (9, 5, 3), (2, 2, 2), (13, 1, 1)):
        for draw in (lambda n: rng.normal(100.0, 30.0, (n, tasks)), lambda n: rng.integers(0, 4, (n, tasks)) * 250.0):
            x, y = draw(n_x), draw(n_y)
            assert statistics._iqm(x) == metrics.aggregate_iqm(x)
            assert statistics._improvement(x, y) == metrics.probability_of_improvement(x, y)
            assert statistics._improvement(x, x) == metrics.probability_of_improvement(x, x) == 0.5


def test_a_diverged_seed_is_counted_and_left_out():
    s = statistics.summarize([10.0, None, 30.0, float("nan"), 20.0], reps=200)
    assert (s.n, s.n_diverged) == (5, 2)
    assert s.mean == pytest.approx(20.0) and s.std == pytest.approx(np.std([10.0, 30.0, 20.0]))
    p = statistics.probability_of_improvement([3.0, None, 4.0], [1.0, 2.0], reps=200)
    assert p[0] == 1.0
    none = statistics.summarize([None, float("nan")])
    assert (none.n, none.n_diverged, none.mean, none.iqm) == (2, 2, None, None)


def test_aggregate_iqm_over_tasks_equals_rliables(tmp_path):
    scores = {"ER-MRL": np.random.default_rng(1).normal(1.2, 0.3, (5, 3)),
              "PPO": np.random.default_rng(2).normal(1.0, 0.2, (5, 3))}
    ours = statistics.aggregate_iqm(scores, reps=300, seed=4)
    for m, s in scores.items():
        assert ours[m] == pytest.approx(rliable_iqm(s, 300, 4), abs=1e-12)
    path = statistics.performance_profile(scores, tmp_path / "profile.png", reps=100)
    assert path.read_bytes()[:8] == PNG


def test_paired_difference_equals_scipys_and_drops_unfinished_pairs():
    """Mean of x − y with SciPy's BCa bootstrap CI and Wilcoxon p on the same differences; a pair with a diverged
    value is left out; zero differences (two scores at a ceiling) count in the mean but not in Wilcoxon."""
    x, y = SCORES[:8] + 15.0, SCORES[4:]
    d = statistics.paired_difference(x, y, reps=2000, seed=5)
    ci = scipy.stats.bootstrap((x - y,), np.mean, n_resamples=2000, method="BCa", random_state=5).confidence_interval
    assert (d.n, d.mean, d.low, d.high) == (8, pytest.approx((x - y).mean()), pytest.approx(ci.low),
                                            pytest.approx(ci.high))
    assert d.p == pytest.approx(scipy.stats.wilcoxon(x - y).pvalue) and d.n_above == int((x > y).sum())
    tied = statistics.paired_difference([500.0, 500.0, 300.0, None, 420.0], [500.0, 480.0, 250.0, 10.0, 400.0])
    assert (tied.n, tied.mean, tied.n_above) == (4, pytest.approx(22.5), 3)
    assert tied.p == pytest.approx(scipy.stats.wilcoxon([20.0, 50.0, 20.0]).pvalue)
    same = statistics.paired_difference([2.0, 3.0], [1.0, 2.0])
    assert (same.mean, same.low, same.high) == (1.0, 1.0, 1.0)
    assert str(same) == "+1 [+1, +1], Wilcoxon p = 0.5, 2 of 2 above"
    all_above = statistics.paired_difference(np.arange(10.0) + 1.0, np.zeros(10))  # exact p = 2 / 2**10
    assert "Wilcoxon p = 0.002, 10 of 10 above" in str(all_above)
    with pytest.raises(ValueError, match="at least 2 finite pairs, got 1"):
        statistics.paired_difference([1.0, None], [0.0, 1.0])
    with pytest.raises(ValueError, match=r"the same length, got \(2,\) and \(3,\)"):
        statistics.paired_difference([1.0, 2.0], [1.0, 2.0, 3.0])


def test_format_ci():
    assert statistics.format_ci(412.34, 388.0, 430.06) == "412.3 [388.0, 430.1]"
    assert statistics.format_ci(None, None, None) == "—"
