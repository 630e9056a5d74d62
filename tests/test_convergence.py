"""The convergence rule of CMA-ES studies: its arithmetic, its replay on the committed 900-trial study, and
``ermrl evolve --until-converged`` on a real (tiny) study."""

import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import optuna
import pytest
from optuna.trial import TrialState

from ermrl.errors import ConfigError
from ermrl.evolution import convergence
from ermrl.evolution.convergence import Convergence, stop_generation
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import load_study

from cli_runs import ermrl as cli
from cli_runs import script

optuna.logging.set_verbosity(optuna.logging.WARNING)
PAPER = Path(__file__).resolve().parents[1] / "docs" / "data" / "partial-observability-paper" / "studies.log"
PAPER_STUDY = "partial-observability-paper-cartpole-1res"


def _spread(*values):
    return {g: {"lr": v, "sr": v} for g, v in enumerate(values, start=2)}


def test_the_rule_needs_g_narrow_generations_in_a_row_and_the_last_complete():
    rule = Convergence(width=0.01, generations=3)
    assert stop_generation(_spread(0.5, 0.009, 0.009, 0.02, 0.009, 0.009, 0.009, 0.009), rule) == 8
    assert stop_generation(_spread(0.009, 0.009), rule) is None
    assert stop_generation(_spread(0.009, 0.009, 0.009), rule, complete={2, 3}) is None
    assert stop_generation(_spread(0.009, 0.009, 0.009, 0.009), rule, complete={2, 3, 5}) == 5
    # one parameter still wide keeps the study going; a generation missing breaks the streak
    wide_sr = {g: {"lr": 0.001, "sr": 0.05 if g == 3 else 0.001} for g in range(2, 6)}
    assert stop_generation(wide_sr, rule) is None
    assert stop_generation({2: {"x": 0.0}, 3: {"x": 0.0}, 5: {"x": 0.0}}, rule) is None
    assert stop_generation(_spread(0.009), Convergence(0.01, 1)) == 2


def test_the_projection_extrapolates_each_parameters_rate_and_waits_for_the_slowest():
    rule = Convergence(width=0.01, generations=3)
    steady = {g: {"lr": 0.5 * 0.9 ** (g - 2), "sr": 0.2 * 0.8 ** (g - 2)} for g in range(2, 12)}
    projection = convergence.project(steady, rule)
    # lr reaches 0.01 when 0.9^(g-2) = 0.02, at g = 2 + ln 0.02 / ln 0.9; then 3 generations in a row
    assert projection.generation == pytest.approx(2 + math.log(0.02) / math.log(0.9) + 2)
    assert projection.window == (7, 11) and projection.slowest() == "lr"
    assert projection.factors == pytest.approx({"lr": 0.9, "sr": 0.8})
    assert convergence.project(steady, rule, window=10).generation == pytest.approx(projection.generation)
    flat = {g: {**v, "sr": 0.3} for g, v in steady.items()}
    assert convergence.project(flat, rule).generation is None and convergence.project(flat, rule).slowest() == "sr"
    assert convergence.project({g: steady[g] for g in range(2, 6)}, rule) is None  # 4 generations: too few
    narrow = {g: {"lr": 0.001, "sr": 0.001} for g in range(2, 8)}
    assert convergence.project(narrow, rule).generation == 7 + 2


def test_the_recent_projection_sees_a_spread_that_narrows_again_after_it_widened():
    """A spread that shrinks, widens for 12 generations and then shrinks again at × 0.9 for 8: the later half
    (generations 16–30) averages the widening into no stop; the last 8 generations see the × 0.9 and project the
    stop from it. With 16 generations or fewer the later half is no longer than 8 and there is no recent one."""
    rule = Convergence(width=0.01, generations=3)
    log_spread = {g: -1 - 0.05 * (g - 2) for g in range(2, 11)}
    log_spread.update({g: log_spread[10] + 0.08 * (g - 10) for g in range(11, 23)})
    log_spread.update({g: log_spread[22] + math.log10(0.9) * (g - 22) for g in range(23, 31)})
    spread = {g: {"sr": 10 ** v, "lr": 0.001} for g, v in log_spread.items()}
    assert convergence.project(spread, rule).window == (16, 30)
    assert convergence.project(spread, rule).generation is None
    recent = convergence.recent_projection(spread, rule)
    assert recent.window == (23, 30) and recent.factors["sr"] == pytest.approx(0.9)
    assert recent.generation == pytest.approx(30 + (-2 - log_spread[30]) / math.log10(0.9) + 2)
    assert convergence.recent_projection({g: spread[g] for g in range(2, 19)}, rule).window == (11, 18)  # 17: 9 > 8
    assert convergence.recent_projection({g: spread[g] for g in range(2, 18)}, rule) is None  # 16: the half is 8


def test_the_projection_history_repeats_the_projection_as_each_generation_stood():
    """A steady shrink projects the same stop from every generation; a spread that stops shrinking shows as None
    from the generation where the fit over the later half no longer falls."""
    rule = Convergence(width=0.01, generations=3)
    steady = {g: {"lr": 0.5 * 0.9 ** (g - 2), "sr": 0.2 * 0.8 ** (g - 2)} for g in range(2, 20)}
    history = convergence.projection_history(steady, rule)
    assert list(history) == list(range(10, 20))
    assert history == pytest.approx({g: 2 + math.log(0.02) / math.log(0.9) + 2 for g in range(10, 20)})
    assert list(convergence.projection_history(steady, rule, last=30)) == list(range(6, 20))  # from 5 generations
    stalled = {g: {**v, "lr": 0.5 * 0.9 ** (min(g, 10) - 2) * 1.01 ** max(g - 10, 0)} for g, v in steady.items()}
    history = convergence.projection_history(stalled, rule)
    assert history[10] == pytest.approx(2 + math.log(0.02) / math.log(0.9) + 2)
    assert history[19] is None and all(history[g] > history[10] for g in range(13, 19) if history[g] is not None)


def test_fitness_correlations_rank_each_parameter_within_the_generations_asked():
    """Fitness that falls with sr and ignores lr: ρ = −1 for sr, near 0 for lr; trials outside the generations,
    failed or of another generation are left out."""
    rng = np.random.default_rng(0)
    space = SearchSpace(fixed_iss=1.0)
    dists = space.distributions()
    trials = []
    for number in range(60):
        sr, lr = 10 ** rng.uniform(-2, 1), 10 ** rng.uniform(-2, 0)
        generation = number // 6
        trials.append(optuna.trial.create_trial(
            params={"sr": sr, "lr": lr}, distributions=dists, value=-math.log10(sr) if generation < 8 else math.log10(sr),
            user_attrs={"generation": generation}))
    rho = convergence.fitness_correlations(trials, space, (2, 7))
    assert rho["sr"] == (pytest.approx(-1.0), pytest.approx(0.0, abs=1e-12))
    assert abs(rho["lr"][0]) < 0.35 and rho["lr"][1] > 0.01
    assert convergence.fitness_correlations(trials, space, (8, 9))["sr"][0] == pytest.approx(1.0)
    assert convergence.fitness_correlations(trials, space, (20, 30)) == {}


@pytest.mark.parametrize("width, generations, message", [
    (0.0, 3, "`width` must be in (0, 10] decades, got 0.0"),
    (float("nan"), 3, "`width` must be in (0, 10] decades, got nan"),
    (0.01, 0, "`generations` must be in 1..1000, got 0"),
])
def test_a_bad_rule_is_refused_with_its_parameter(width, generations, message):
    """The library names Convergence's fields; the command line shows them as --converged-width and
    --converged-generations (test_bad_input.py)."""
    with pytest.raises(ConfigError) as e:
        Convergence(width, generations)
    assert (str(e.value), e.value.owner) == (message, Convergence)


def test_the_spread_read_back_from_the_paper_study_matches_the_sampled_phi():
    """The distributions stored by Optuna, read as decades, start where CMA-ES starts (σ0 = 1/6 of each
    parameter's range in Optuna's [0, 1] space, after one update) and describe the Φ the generations sampled:
    the distribution's mean at the last generation is the Φ around which the last trials sit."""
    study = load_study(f"journal:{PAPER}", PAPER_STUDY)
    space = SearchSpace(fixed_iss=1.0)
    dists = convergence.centers_and_spreads(study.get_trials(deepcopy=False), space)
    assert min(dists) == 2 and max(dists) >= 140
    assert 0.15 < dists[2]["lr"][1] < 2 / 6 and 0.4 < dists[2]["sr"][1] < 6 / 6
    last = dists[max(dists)]
    tail = [t for t in study.trials if t.state == TrialState.COMPLETE and t.user_attrs["generation"] == max(dists)]
    for name in ("sr", "lr"):
        assert all(abs(t.params[name] / last[name][0] - 1) < 0.01 for t in tail)


def test_a_trial_killed_while_optuna_wrote_its_optimizer_is_passed_over():
    """A process killed between two of the chunks in which Optuna stores the CMA-ES optimizer leaves a trial with
    some of them (a hex string cut mid-byte, a pickle without its end, or a gap); the spread is read from the
    generation's other trials."""
    study = load_study(f"journal:{PAPER}", PAPER_STUDY)
    trials = study.get_trials(deepcopy=True)
    space = SearchSpace(fixed_iss=1.0)
    expected = convergence.centers_and_spreads(trials, space)
    first, second = f"{convergence.OPTIMIZER_KEY}0", f"{convergence.OPTIMIZER_KEY}1"
    damaged = [t for t in trials[:90] if second in t.system_attrs][::2]  # every other trial of generations 0–14
    for k, t in enumerate(damaged):
        if k % 3 == 2:
            del t.system_attrs[first]  # a gap: the second chunk alone
        else:
            del t.system_attrs[second]
            t.system_attrs[first] = t.system_attrs[first][:2045 - k % 3]  # odd: not hex; even: a cut pickle
    assert len(damaged) == 39 and {len(t.system_attrs[first]) for t in damaged if first in t.system_attrs} == {2044, 2045}
    assert convergence.centers_and_spreads(trials, space) == expected


def test_the_replay_on_the_paper_study_stops_at_generation_32_and_copies_the_study_as_the_rule_left_it(tmp_path):
    out, copy = tmp_path / "replay", f"journal:{tmp_path / 'replay.log'}"
    run = cli("convergence", "--study", PAPER_STUDY, "--storage", f"journal:{PAPER}", "--out", out,
              "--copy-to", copy)
    assert run.returncode == 0, run.stderr
    assert f"study '{PAPER_STUDY}' converged at generation 32: 198 of its 900 completed trials (22% of the " \
           "compute)" in run.stdout
    summary = json.loads((out / "convergence.json").read_text())
    assert (summary["stop_generation"], summary["trials_to_stop"], summary["trials"]) == (32, 198, 900)
    assert summary["generations"] == 150  # 0–149, popsize 6
    assert max(summary["mean_shift_decades"].values()) < 0.01
    assert (out / "convergence.png").stat().st_size > 10_000
    header = (out / "convergence.csv").read_text().splitlines()[0]
    assert header == "generation,lr_spread_decades,sr_spread_decades,lr_mean,sr_mean"
    copied = load_study(copy, PAPER_STUDY)
    assert {t.user_attrs["generation"] for t in copied.trials} == set(range(33))
    assert len([t for t in copied.trials if t.state == TrialState.COMPLETE]) == 198
    assert copied.user_attrs["converged"] == {**copied.user_attrs["converged"], "generation": 32, "trials": 198}
    again = cli("convergence", "--study", PAPER_STUDY, "--storage", f"journal:{PAPER}", "--out", out,
                "--copy-to", copy)
    assert again.returncode == 2
    assert again.stderr.strip().endswith(f"already holds a study '{PAPER_STUDY}'; give --copy-to another storage")


def test_a_study_cut_before_it_converged_is_projected_to_converge_near_where_it_did(tmp_path):
    """The paper study cut at the first generation whose spreads are all below 0.02 decades (generation 21): the
    projection of the default rule from there lands near generation 32, where the whole study converged."""
    cut = f"journal:{tmp_path / 'cut.log'}"
    run = cli("convergence", "--study", PAPER_STUDY, "--storage", f"journal:{PAPER}", "--out", tmp_path / "a",
              "--copy-to", cut, "--converged-width", "0.02", "--converged-generations", "1")
    assert run.returncode == 0 and "converged at generation 21:" in run.stdout, run.stdout + run.stderr
    run = cli("convergence", "--study", PAPER_STUDY, "--storage", cut, "--out", tmp_path / "b")
    assert run.returncode == 0, run.stderr
    assert f"study '{PAPER_STUDY}' has not converged by the rule" in run.stdout
    complete = sum(t.state == TrialState.COMPLETE for t in load_study(cut, PAPER_STUDY).trials)
    assert f"in its 22 generations (0–21; {complete} trials)" in run.stdout
    assert json.loads((tmp_path / "b" / "convergence.json").read_text())["generations"] == 22
    said = re.search(r"at the rates of generations 12–21 \((\w+)'s spread shrinks slowest, × (0\.\d+) a generation\), "
                     r"the rule would hold at about generation (\d+), ([\d,]+) trials: within the study's limit of "
                     r"900 trials", run.stdout)
    assert said, run.stdout
    generation = int(said.group(3))
    assert 25 <= generation <= 36 and int(said.group(4).replace(",", "")) == (generation + 1) * 6
    projection = json.loads((tmp_path / "b" / "convergence.json").read_text())["projection"]
    assert (projection["window"], projection["generation"], projection["trial_limit"]) == ([12, 21], generation, 900)
    recent = json.loads((tmp_path / "b" / "convergence.json").read_text())["recent_projection"]
    assert recent["window"] == [14, 21] and 25 <= recent["generation"] <= 36  # 20 generations of spread: half 10 > 8
    assert re.search(rf"at the rates of generations 14–21 \(\w+'s spread shrinks slowest, × 0\.\d+ a generation\), the "
                     rf"rule would hold at about generation {recent['generation']}, {(recent['generation'] + 1) * 6} "
                     "trials: within", run.stdout), run.stdout
    history = json.loads((tmp_path / "b" / "convergence.json").read_text())["projection_history"]
    assert list(history) == [str(g) for g in range(12, 22)] and history["21"] == generation
    assert all(25 <= p <= 36 for p in history.values()), history  # the docstring of `project`: 25–34 from 10–32
    assert (f"the same projection made at generations 12–21: {', '.join(str(p) for p in history.values())} (it "
            "moves with the mean; read it as a range)") in run.stdout
    rho = json.loads((tmp_path / "b" / "convergence.json").read_text())["fitness_correlations"]
    assert set(rho) == {"lr", "sr"} and all(-1 <= v["rho"] <= 1 and 0 <= v["p"] <= 1 for v in rho.values())
    assert "fitness against each parameter over generations 12–21 (Spearman's ρ): lr " in run.stdout
    factor = projection["factors"][said.group(1)]
    assert 0.7 < factor < 1 and factor == pytest.approx(float(said.group(2)), abs=5e-4)
    _paces_the_cut_study_by_both_trends(cut, generation, recent["generation"])
    load_study(cut, PAPER_STUDY).set_user_attr("converged", None)  # as if evolved without --until-converged
    report = cli("report", "--study", PAPER_STUDY, "--storage", cut, "--out", tmp_path / "report")
    assert report.returncode == 0, report.stderr
    assert (f"not reached; at the rates of generations 12–21 ({said.group(1)}&#x27;s spread shrinks slowest, × "
            f"{said.group(2)} a generation), the rule would hold at about generation {generation}"
            in (tmp_path / "report" / "report.html").read_text())


def test_a_study_copied_as_it_stood_after_a_generation_selects_and_replays_like_the_original(tmp_path):
    """paper/study_so_far.py: the trials of generations 0..G of the paper study, its record and CMA-ES optimizers,
    in a new journal; an unfinished generation and a target already holding the study are refused."""
    copy = f"journal:{tmp_path / 'so-far.log'}"
    tool = Path(__file__).resolve().parents[1] / "paper" / "study_so_far.py"
    run = script(tool, "--study", PAPER_STUDY, "--storage", f"journal:{PAPER}", "--generation", "10", "--to", copy)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == f"copied 66 trials (66 complete) of generations 0–10 of '{PAPER_STUDY}' to {copy}"
    copied, original = load_study(copy, PAPER_STUDY), load_study(f"journal:{PAPER}", PAPER_STUDY)
    assert copied.user_attrs["ermrl"] == original.user_attrs["ermrl"]
    assert [(t.params, t.value) for t in copied.trials] == [(t.params, t.value) for t in original.trials[:66]]
    space = SearchSpace(fixed_iss=1.0)
    assert convergence.spreads(copied.trials, space) == {g: v for g, v in convergence.spreads(original.trials, space).items()
                                                         if g <= 10}
    again = script(tool, "--study", PAPER_STUDY, "--storage", f"journal:{PAPER}", "--generation", "10", "--to", copy)
    assert again.returncode == 2 and again.stderr.strip().endswith(
        f"{copy} already holds a study '{PAPER_STUDY}'; give --to another storage")
    late = script(tool, "--study", PAPER_STUDY, "--storage", f"journal:{PAPER}", "--generation", "150", "--to", copy)
    assert late.returncode == 2 and late.stderr.strip().endswith(
        "generation 150 of 'partial-observability-paper-cartpole-1res' has 0 of its 6 trials complete; give a "
        "generation the study has finished")


def _evolve(tmp_path, *extra):
    return cli("evolve", "--env", "CartPoleNoVel-v1", "--timesteps", "2048", "--seeds", "1", "--popsize", "2",
               "--fixed-iss", "1.0", "--trials", "40", "--study", "s", "--out", tmp_path / "s", "--quiet",
               "--no-estimate", *extra)


def test_evolve_until_converged_stops_records_why_and_a_rerun_does_nothing(tmp_path):
    """A rule that any distribution meets (10 decades, 1 generation) stops the study once the first generation
    with a stored distribution (generation 2) is complete: 6 trials of the 40 allowed."""
    rule = ("--until-converged", "--converged-width", "10", "--converged-generations", "1")
    run = _evolve(tmp_path, *rule)
    assert run.returncode == 0, run.stderr
    assert "converged at generation 2 (6 trials)" in run.stdout
    study = load_study(f"sqlite:///{tmp_path}/s/study.db", "s")
    assert len(study.trials) == 6
    assert study.user_attrs["converged"]["generation"] == 2 and study.user_attrs["converged"]["width"] == 10
    again = _evolve(tmp_path, *rule)
    assert again.returncode == 0
    assert "study 's' converged at generation 2 (6 trials): spread below 10 decades in every parameter for 1 " \
           "generations; nothing to do" in again.stdout
    assert len(load_study(f"sqlite:///{tmp_path}/s/study.db", "s").trials) == 6
    report = cli("report", "--study", "s", "--out", tmp_path / "s")
    assert report.returncode == 0
    page = (tmp_path / "s" / "report.html").read_text()
    assert "stopped: CMA-ES converged at generation 2 (6 trials)" in page and 'alt="Φ spread per generation"' in page
    assert (tmp_path / "s" / "phi_spread.png").stat().st_size > 10_000


def _paces_the_cut_study_by_both_trends(cut, generation, recent):
    """`experiment run`'s line for the cut study, resumed at a scale that stops at convergence, and the line a
    worker logs for its generation: both projections."""
    import dataclasses

    from ermrl.cli.experiment import pace_line
    from ermrl.experiments import registry, runner

    (plan,) = [p for p in runner.plan(registry.get("partial-observability"), registry.get_scale("paper"), Path("."))
               if p.study == PAPER_STUDY]
    line = pace_line(dataclasses.replace(plan, until_converged=Convergence()), load_study(cut, PAPER_STUDY))
    duration = r"(\d+ s|\d+ min|\d+ h( \d\d min)?)"
    assert re.fullmatch(rf"  {PAPER_STUDY}: {duration} a generation \(its last one\): 128 more to its trial limit, "
                        rf"about {duration}; the trend of its spread \(`ermrl convergence`\) puts the stop near "
                        rf"generation {generation}, {generation - 21} more, about {duration} \(the trend of its last 8 "
                        rf"generations: generation {recent}\)", line), line
    from ermrl.evolution.worker_config import WorkerConfig
    from ermrl.evolution.workers import Worker

    study, lines = load_study(cut, PAPER_STUDY), []
    study.sampler = optuna.samplers.CmaEsSampler()  # as `ermrl evolve` opens it
    worker = Worker(study, plan.config, WorkerConfig(until_converged=Convergence()), lines.append)
    assert not worker._converged(study.get_trials(deepcopy=False))  # as it checks before claiming
    fit = r"\(\w+'s spread shrinks slowest, × 0\.\d+ a generation\), the rule would hold at about generation"
    assert len(lines) == 1 and re.fullmatch(
        rf"generation 21: widest spread [\d.]+ decades \(\w+\), 0.01 to converge; at the rates of generations 12–21 "
        rf"{fit} {generation}; at the rates of generations 14–21 {fit} {recent}", lines[0]), lines


def test_evolve_until_converged_logs_each_generations_spread_and_the_projected_stop(tmp_path):
    """Not converged after 8 generations: one line per generation sampled from a stored distribution, logged as
    that generation starts (2 to 7), the projection from the fifth on."""
    run = _evolve(tmp_path, "--until-converged", "--trials", "16")
    assert run.returncode == 0, run.stderr
    lines = [line for line in run.stdout.splitlines() if re.match(r"generation \d+: widest spread", line)]
    assert [int(line.split()[1].rstrip(":")) for line in lines] == [2, 3, 4, 5, 6, 7], run.stdout
    assert all(re.fullmatch(r"generation \d: widest spread [\d.e-]+ decades \((lr|sr)\), 0.01 to converge", line)
               for line in lines[:3]), lines
    assert re.fullmatch(r"generation 6: widest spread [\d.e-]+ decades \((lr|sr)\), 0.01 to converge; (at the rates "
                        r"of generations 2–6 \((lr|sr)'s spread shrinks slowest, × [\d.]+ a generation\), the rule "
                        r"would hold at about generation [\d,]+|over generations 2–6, (lr|sr)'s spread did not shrink "
                        r"\(× [\d.]+ a generation\))", lines[4]), lines[4]


def test_until_converged_needs_cmaes_and_nothing_is_written(tmp_path):
    run = _evolve(tmp_path, "--until-converged", "--sampler", "random")
    assert run.returncode == 2
    assert run.stderr.strip().splitlines()[-1].endswith(
        "--until-converged reads CMA-ES's search distribution; --sampler random has none (use --sampler cmaes, or "
        "stop at --trials)")
    assert not (tmp_path / "s").exists()


def test_a_converged_scale_treats_a_converged_study_as_evolved(tmp_path):
    from ermrl.experiments import registry, runner

    shutil.copy(PAPER, tmp_path / "studies.log")
    experiment = registry.get("partial-observability")
    plans = runner.plan(experiment, registry.SCALES["converged"], tmp_path)
    p = next(p for p in plans if p.spec.name == "cartpole-1res")
    study = load_study(f"journal:{tmp_path / 'studies.log'}", PAPER_STUDY)
    assert p.until_converged == Convergence() and p.config.trials == 900
    assert runner.trials_done(p, study) == 900  # converged at generation 32: nothing left to evolve
    paper = next(q for q in runner.plan(experiment, registry.SCALES["paper"], tmp_path) if q.spec.name == "cartpole-1res")
    assert paper.until_converged is None
