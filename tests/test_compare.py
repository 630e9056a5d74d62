"""`ermrl compare` (C14-C17 and the lr diagnostics): reservoir variants' test phases and train runs, compared seed
by seed."""

import json
from pathlib import Path

import numpy as np
import pytest

from ermrl import storage
from ermrl.analysis import variants
from ermrl.analysis.statistics import format_ci, paired_difference, probability_of_improvement, summarize

from cli_runs import ermrl

DATA = Path(__file__).resolve().parent.parent / "docs" / "data"
SMALL = [500.0, 480.0, 210.0, 30.0, 500.0, 420.0, 190.0, 100.0, 440.0, 230.0]
LARGE = [100.0, None, 210.0, 50.0, 180.0, 20.0, 90.0, 100.0, 40.0, 230.0]  # seed 1001 diverged
PPO = [40.0, 35.0, 52.0, 28.0, 44.0, 39.0, 31.0, 47.0, 36.0, 41.0]


def _run(*args):
    return ermrl("compare", *args)


def _summary(folder: Path, *ermrl_rows) -> Path:
    folder.mkdir(parents=True)
    path = folder / "summary.json"
    path.write_text(json.dumps(
        [*({"model": "ER-MRL lr 0.0001", "kind": "ER-MRL", "per_seed": r, "auc_early_mean": 12.5} for r in ermrl_rows),
         {"model": "PPO (same observation)", "kind": "PPO", "per_seed": PPO, "auc_early_mean": 3.0}]))
    return path


def test_table_gives_every_variant_and_pairs_their_seeds(tmp_path):
    small, large = _summary(tmp_path / "small", SMALL), _summary(tmp_path / "large", LARGE)
    done = _run(f"100 units={small}", f"1000 units={large}", "--compare", "100 units", "1000 units")
    assert done.returncode == 0, done.stderr
    s = summarize(SMALL)
    assert f"| ER-MRL, 100 units | 10 | {s.mean:.1f} ± {s.std:.1f} | {format_ci(s.iqm, s.iqm_low, s.iqm_high)} | 12.5 |" \
        in done.stdout
    kept = [v for v in LARGE if v is not None]
    assert f"| ER-MRL, 1000 units | 9 | {summarize(kept).mean:.1f} ± {summarize(kept).std:.1f} |" in done.stdout
    assert f"| PPO (same observation) | 10 | {summarize(PPO).mean:.1f} ± {summarize(PPO).std:.1f} |" in done.stdout
    p = format_ci(*probability_of_improvement(SMALL, kept), digits=2)
    paired = paired_difference([v for v, w in zip(SMALL, LARGE) if w is not None], kept)
    assert f"- P(100 units > 1000 units) = {p}; paired 100 units − 1000 units over 9 seeds: {paired}" in done.stdout
    done = _run(f"100 units={small}", "--compare", "100 units", "PPO (same observation)")  # a PPO row, by its name
    assert done.returncode == 0, done.stderr
    p, paired = format_ci(*probability_of_improvement(SMALL, PPO), digits=2), paired_difference(SMALL, PPO)
    assert f"- P(100 units > PPO (same observation)) = {p}; paired 100 units − PPO (same observation) over 10 " \
           f"seeds: {paired}" in done.stdout


def _curves(folder: Path, ermrl: np.ndarray, models=("ER-MRL lr 0.0001", "PPO (same observation)")) -> None:
    """Writes folder/curves.csv: ``ermrl`` (S, 3) for the ER-MRL model, a flat PPO curve, at 2048, 4096, 6144."""
    steps = np.array([2048, 4096, 6144])
    values = {models[0]: ermrl, models[1]: np.full_like(ermrl, 40.0)}
    storage.write_curves_csv(folder / "curves.csv", {m: (steps, values[m]) for m in models},
                             {m: np.arange(1000, 1000 + len(ermrl)) for m in models})


def test_figure_draws_each_variants_curve_and_the_ppo_curves(tmp_path):
    """--figure: the ER-MRL curve of each variant, named by its label, then the first test phase's PPO curve,
    read back from each curves.csv; drawn as a PNG."""
    small, large = _summary(tmp_path / "small", SMALL), _summary(tmp_path / "large", LARGE)
    rising = np.array([[20.0, 200.0, 480.0], [30.0, 250.0, 500.0]])
    _curves(small.parent, rising)
    _curves(large.parent, rising / 2)
    done = _run(f"100 units={small}", f"1000 units={large}", "--figure", tmp_path / "fig.png")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "fig.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    done = _run(f"100 units={small}", f"1000 units={large}", "--figure", tmp_path / "titled.png",
                "--title", "two learning rates")  # the same curves under another title: another image
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "titled.png").read_bytes() != (tmp_path / "fig.png").read_bytes()
    drawn = variants.curves({"100 units": [small], "1000 units": [large]})
    assert list(drawn) == ["ER-MRL, 100 units", "ER-MRL, 1000 units", "PPO (same observation)"]
    np.testing.assert_array_equal(drawn["ER-MRL, 100 units"][0], [2048, 4096, 6144])
    np.testing.assert_array_equal(drawn["ER-MRL, 1000 units"][1], rising / 2)
    np.testing.assert_array_equal(drawn["PPO (same observation)"][1], np.full((2, 3), 40.0))


def test_an_ermrl_train_run_is_a_variant_too(tmp_path):
    """C17's sweep trains each variant with `ermrl train` (seeds 1000, 1001): its summary.json and curves.csv are
    read like a test phase's (its AUC: the curve's mean over the first 300k steps), paired seed by seed with a
    test phase's ER-MRL row."""
    run = tmp_path / "sparse"
    done = ermrl("train", "--seeds", "2", "--first-seed", "1000", "--timesteps", "4096", "--rc-connectivity", "0.05",
                 "--no-save-agents", "--quiet", "--out", run)
    assert done.returncode == 0, done.stderr
    trained = json.loads((run / "summary.json").read_text())
    scores = dict(zip(trained["seeds"], trained["fitness"]))
    phase = _summary(tmp_path / "phase", [300.0, 100.0])
    _curves(phase.parent, np.array([[10.0, 200.0, 300.0], [10.0, 50.0, 100.0]]))
    done = _run(f"sparse={run / 'summary.json'}", f"default={phase}", "--compare", "sparse", "default",
                "--figure", tmp_path / "fig.png")
    assert done.returncode == 0, done.stderr
    s = summarize(list(scores.values()))
    (_, curve), = storage.read_curves_csv(run / "curves.csv").values()  # (2 seeds, 2 updates): AUC over all
    auc = np.nanmean(np.nanmean(curve, axis=1))
    assert f"| ER-MRL, sparse | 2 | {s.mean:.1f} ± {s.std:.1f} | {format_ci(s.iqm, s.iqm_low, s.iqm_high)} | " \
           f"{auc:.1f} |" in done.stdout
    paired = paired_difference([scores[1000], scores[1001]], [300.0, 100.0])
    assert f"paired sparse − default over 2 seeds: {paired}" in done.stdout
    assert (tmp_path / "fig.png").read_bytes()[:4] == b"\x89PNG"
    plain = tmp_path / "plain"  # a run without reservoir is named as PPO, not as ER-MRL
    done = ermrl("train", "--no-reservoir", "--seeds", "2", "--first-seed", "1000", "--timesteps", "2048",
                 "--no-save-agents", "--quiet", "--out", plain)
    assert done.returncode == 0, done.stderr
    done = _run(f"sparse={run / 'summary.json'}", f"masked={plain / 'summary.json'}", "--compare", "sparse", "masked")
    assert done.returncode == 0, done.stderr
    assert "| ER-MRL, sparse | 2 |" in done.stdout and "| PPO, masked | 2 |" in done.stdout
    assert "ER-MRL, masked" not in done.stdout
    (bad := tmp_path / "bad.json").write_text(json.dumps({"seeds": [1000]}))
    done = _run(f"a={bad}")
    assert done.returncode == 2
    assert done.stderr == f"ermrl compare: error: {bad} is neither a test phase's nor an `ermrl train` run's " \
                          "summary.json\n"


def _refused(cases, figure: Path) -> None:
    """Each (args, message) of ``cases`` is refused: exit 2, one line naming ``message``, no output, no figure."""
    for args, message in cases:
        done = _run(*args)
        assert done.returncode == 2, (args, done.stderr)
        assert done.stderr.count("\n") == 1 and done.stderr.startswith("ermrl compare: error: "), (args, done.stderr)
        assert message in done.stderr, (args, done.stderr)
        assert done.stdout == ""
    assert not figure.exists()


def test_bad_input_is_one_line_and_exit_code_2(tmp_path):
    small = _summary(tmp_path / "small", SMALL)
    two_rates = _summary(tmp_path / "two", SMALL, LARGE)
    cases = [
        ((f"a={two_rates}",), f"{two_rates} has 2 ER-MRL rows; give a test phase of one learning rate"),
        ((f"a={small}", "--compare", "a", "b"), "--compare names 'b', which is none of the variants or PPO rows (a, PPO (same observation))"),
        ((f"a={small}", f"a={small}"), "two variants are named 'a'; name each once"),
        ((str(small),), f"{str(small)!r} is not LABEL=SUMMARY.json"),
        ((f"a={tmp_path / 'missing.json'}",), f"{tmp_path / 'missing.json'} is not a file; give a test phase's or "
                                              "an `ermrl train` run's summary.json"),
        ((f"a={small}", "--figure", tmp_path / "f.png"), "No such file or directory"),  # no curves.csv beside it
    ]
    other = _summary(tmp_path / "other", SMALL)
    _curves(other.parent, np.ones((2, 3)), models=("ER-MRL lr 0.0003", "PPO (same observation)"))
    cases.append(((f"a={other}", "--figure", tmp_path / "f.png"),
                  f"{other.parent / 'curves.csv'} has no curve of 'ER-MRL (learning rate 0.0001)'; give the "
                  "curves.csv"))
    _refused(cases, tmp_path / "f.png")


def _train_run(folder: Path, scores: dict[int, float], curve: np.ndarray, steps=(2048, 4096, 6144)) -> Path:
    """An `ermrl train` run's summary.json ({seed: final score}) and curves.csv (``curve``: (S, I) at ``steps``)."""
    folder.mkdir(parents=True)
    (path := folder / "summary.json").write_text(json.dumps(
        {"env_id": "PendulumNoVel-v1", "seeds": list(scores), "fitness": list(scores.values())}))
    storage.write_curves_csv(folder / "curves.csv", {"ER-MRL": (np.array(steps), curve)},
                             {"ER-MRL": np.array(list(scores))})
    return path


def test_ermrl_train_runs_on_other_seeds_join_into_one_variant(tmp_path):
    """'LABEL=A.json,B.json' pools two `ermrl train` runs' seeds (e.g. the test seeds and ten more): one row over
    all of them, paired seed by seed with a test phase, their AUC over the stacked curves, one curve drawn."""
    first = _train_run(tmp_path / "first", {1000: -300.0, 1001: -200.0},
                       np.array([[-900.0, -500, -300], [-800, -400, -200]]))
    more = _train_run(tmp_path / "more", {1002: -250.0, 1003: -150.0},
                      np.array([[-700.0, -300, -250], [-600, -200, -150]]))
    phase = _summary(tmp_path / "phase", [-350.0, -260.0, -240.0, -400.0])  # seeds 1000-1003
    _curves(phase.parent, np.full((4, 3), -300.0))
    pooled = [-300.0, -200.0, -250.0, -150.0]
    done = _run(f"20 seeds={first},{more}", f"default={phase}", "--compare", "20 seeds", "default",
                "--figure", tmp_path / "fig.png")
    assert done.returncode == 0, done.stderr
    s = summarize(pooled)
    auc = np.mean([-900, -500, -300, -800, -400, -200, -700, -300, -250, -600, -200, -150])
    assert f"| ER-MRL, 20 seeds | 4 | {s.mean:.1f} ± {s.std:.1f} | {format_ci(s.iqm, s.iqm_low, s.iqm_high)} | " \
           f"{auc:.1f} |" in done.stdout
    paired = paired_difference(pooled, [-350.0, -260.0, -240.0, -400.0])
    assert f"paired 20 seeds − default over 4 seeds: {paired}" in done.stdout
    assert (tmp_path / "fig.png").read_bytes()[:4] == b"\x89PNG"
    overlapping = _train_run(tmp_path / "again", {1001: -100.0}, np.ones((1, 3)))
    longer = _train_run(tmp_path / "longer", {1004: -100.0}, np.ones((1, 2)), steps=(2048, 8192))
    cases = [
        ((f"a={first},{overlapping}",), f"{first} and {overlapping} both have seed 1001; join runs of other seeds"),
        ((f"a={first},{phase}",), f"{phase} is a test phase's summary.json; only `ermrl train` runs (which record "
                                  "their seeds) can be joined with ','"),
        ((f"a={first},{longer}", "--figure", tmp_path / "f.png"),
         f"{longer.parent / 'curves.csv'} has other update steps than {first.parent / 'curves.csv'}; join runs of "
         "the same --timesteps"),
        ((f"a={first},",), f"'a={first},' is not LABEL=SUMMARY.json"),
    ]
    _refused(cases, tmp_path / "f.png")


def test_the_committed_lr_diagnostic_is_what_compare_prints(tmp_path):
    """The committed table of step observed_units_lr3e4 (docs/data/observed-units-small/1000-of-1000/), printed again
    from the committed summaries and curves: the same bytes; its figure too, as a PNG."""
    d = DATA / "observed-units-small" / "1000-of-1000"
    done = _run(f"1000 of 1000, lr 1e-4={d / 'test' / 'summary.json'}",
                f"1000 of 1000, lr 3e-4={d / 'ermrl-lr3e-4' / 'summary.json'}",
                "--compare", "1000 of 1000, lr 3e-4", "1000 of 1000, lr 1e-4",
                "--title", "evolved Φ* at PPO lr 1e-4 and 3e-4, the same seeds", "--figure", tmp_path / "lr.png")
    assert done.returncode == 0, done.stderr
    assert done.stdout == (d / "lr3e-4-vs-1e-4.md").read_text(encoding="utf-8")
    assert (tmp_path / "lr.png").read_bytes()[:4] == b"\x89PNG"


def test_a_figure_path_that_cannot_be_written_is_refused_before_any_work(tmp_path):
    summary = _summary(tmp_path / "small", SMALL)
    (tmp_path / "file").write_text("")
    done = _run(f"a={summary}", "--figure", tmp_path / "file" / "fig.png")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith("ermrl compare: error: --figure ") and done.stderr.count("\n") == 1


def test_a_test_phase_run_without_auc_steps_gets_its_early_auc_from_its_curves():
    """The converged HalfCheetah study's test phase ran without ``auc_steps``; its PPO model is the baseline store's,
    the same as the small study's test phase, which computed its AUC over 0–300k when it ran: read from the curves,
    the two agree, and the ER-MRL row gets one too."""
    late = DATA / "locomotion-converged" / "halfcheetah-gen19" / "test" / "summary.json"
    assert all(r.get("auc_early_mean") is None for r in json.loads(late.read_text()))
    ermrl_row, (ppo,) = variants.read_rows(late)
    _, (ppo_then,) = variants.read_rows(DATA / "locomotion-small" / "halfcheetah-2res" / "test" / "summary.json")
    assert ppo["auc_early_mean"] == pytest.approx(ppo_then["auc_early_mean"], rel=1e-6)  # curves.csv rounds
    assert 0 < ermrl_row["auc_early_mean"] < ermrl_row["auc_mean"]
    assert variants.read_rows(late, auc=False)[0].get("auc_early_mean") is None


def test_each_comparison_also_pairs_the_seeds_early_auc():
    """Per seed, the mean of the curve over 0–300k from curves.csv: its paired mean difference is the difference of
    the test phase's own auc_early_mean (small study: 269.6 − 20.2), and every seed is paired."""
    small = DATA / "locomotion-small" / "halfcheetah-2res" / "test" / "summary.json"
    rows = json.loads(small.read_text())
    by_seed = variants.early_auc_by_seed([small], rows[0]["model"])
    assert sorted(by_seed) == list(range(1000, 1010))
    assert np.mean(list(by_seed.values())) == pytest.approx(rows[0]["auc_early_mean"], rel=1e-6)
    out = variants.table({"small": [small]}, [("small", "PPO (same observation)")])
    line = next(x for x in out.splitlines() if "AUC 0–300k: paired" in x)
    assert line.startswith("  - AUC 0–300k: paired small − PPO (same observation) over 10 seeds: +249 [")
    assert line.endswith("10 of 10 above")
    assert variants.early_auc_by_seed([small], "no such model") == {}
