"""The paper's experiments as software: several envs with normalized scores, selection of Φ*, generalization
tests on an unseen env, the named experiments at smoke scale, and statistics in the test summaries."""

import json
import re
from pathlib import Path

import jax
import numpy as np
import optuna
import pytest
from optuna.trial import TrialState

from ermrl.evolution.record import decode_study_record, encode_study_record
from ermrl.agent import AgentConfig, Phi
from ermrl.evolution.evolve import shared_envs
from ermrl.evolution.study import load_study
from ermrl.experiments import registry, runner
from ermrl.experiments.baselines import load_table, nscore, resolve
from ermrl.experiments.evaluation import summarize
from ermrl.training import Population, TrainConfig, train

from cli_runs import ermrl as cli

optuna.logging.set_verbosity(optuna.logging.WARNING)


def test_two_env_evolution_scores_each_env_and_tests_on_a_third(tmp_path):
    table = tmp_path / "baselines.json"
    envs = ["CartPoleNoVel-v1", "PendulumNoVel-v1"]
    r = cli("evolve", "--env", envs[0], "--env", envs[1], "--trials", "2", "--popsize", "2", "--seeds", "1",
            "--timesteps", "2048", "--fixed-iss", "1.0", "--study", "g", "--out", str(tmp_path), "--baselines", str(table),
            "--allow-weak-baselines", "--quiet", "--no-estimate")
    assert r.returncode == 0, r.stderr
    assert "baselines: vanilla PPO on PendulumNoVel-v1 (1 seeds × 2,048 steps, learning rate 0.0003)" in r.stdout
    study = load_study(f"sqlite:///{tmp_path}/study.db", "g")
    assert study.user_attrs["ermrl"]["envs"] == envs
    constants = {e: resolve(e, 2048, 1, 3e-4, load_table(table)) for e in envs}
    trials = [t for t in study.trials if t.state == TrialState.COMPLETE]
    assert len(trials) == 2
    for t in trials:
        assert set(t.user_attrs["env_scores"]) == set(envs) == set(t.user_attrs["env_nscores"])
        expected = [nscore(t.user_attrs["env_scores"][e], constants[e], "episodic") for e in envs]
        assert t.user_attrs["env_nscores"] == {e: pytest.approx(v) for e, v in zip(envs, expected)}
        assert t.value == pytest.approx(np.mean(expected))
        assert t.user_attrs["env_scores"]["CartPoleNoVel-v1"] > 0 > t.user_attrs["env_scores"]["PendulumNoVel-v1"]

    # the third env: CartPole-v1, outside the evolution, with another input size and no masked dims (so no
    # full-observation baseline); its models are those that the tests on CartPole-v1 compile
    r = cli("test", "--study", "g", "--out", str(tmp_path), "--env", "CartPole-v1", "--seeds", "1",
            "--timesteps", "2048", "--quiet")
    assert r.returncode == 0, r.stderr
    rows = json.loads((tmp_path / "test-CartPole-v1" / "summary.json").read_text())
    assert [row["kind"] for row in rows] == ["ER-MRL", "PPO"]
    assert all(row["env_id"] == "CartPole-v1" and row["evolved_on"] == envs for row in rows)
    assert "evolved on CartPoleNoVel-v1, PendulumNoVel-v1; tested on CartPole-v1" in r.stdout
    assert (tmp_path / "test-CartPole-v1" / "test_phase.png").stat().st_size > 0


def test_evolution_refuses_constants_where_ppo_does_not_beat_random(tmp_path):
    table = tmp_path / "baselines.json"
    from ermrl.experiments.baselines import BaselineTable, PPOScore, save_table

    t = load_table(table)
    assert isinstance(t, BaselineTable)
    for env, mean in (("CartPoleNoVel-v1", 20.0), ("PendulumNoVel-v1", -900.0)):  # random: 23.7 and -1207.6
        t.add_ppo(env, PPOScore(1, 2048, 3e-4, mean, 0.0, (mean,)), "test")
    save_table(t, table)
    r = cli("evolve", "--env", "CartPoleNoVel-v1", "--env", "PendulumNoVel-v1", "--trials", "2", "--popsize", "2",
            "--seeds", "1", "--timesteps", "2048", "--study", "w", "--out", str(tmp_path), "--baselines", str(table),
            "--quiet", "--no-estimate")
    assert r.returncode == 2
    assert r.stderr == ("ermrl evolve: error: on CartPoleNoVel-v1, vanilla PPO (20) does not beat the random agent "
                        "(23.68) at this budget, so nScore would reward scores below random; use a larger --timesteps, "
                        "drop the env, or pass --allow-weak-baselines to go on anyway\n")
    assert not (tmp_path / "study.db").exists()


def test_an_experiment_study_whose_ppo_baseline_is_weak_is_refused_with_experiment_advice(tmp_path):
    """In `experiment run` the advice names its own flags (it has no --timesteps); nothing is evolved. The table
    holds PPO at the study's budget (Ant's floor: 200k-step trials at `small`) below the random agent's -48.05."""
    from ermrl.experiments.baselines import PPOScore, save_table

    table = tmp_path / "baselines.json"
    t = load_table(table)
    for env, mean in (("Ant-v5", -60.0), ("Swimmer-v5", 40.0)):
        t.add_ppo(env, PPOScore(2, registry.ANT_MIN_TRIAL_TIMESTEPS, 3e-4, mean, 0.0, (mean, mean)), "test")
    save_table(t, table)
    out = tmp_path / "run"
    r = cli("experiment", "run", "generalization-morphology", "--only", "to-halfcheetah", "--baselines", str(table),
            "--out", str(out), "--no-estimate", "--quiet")
    assert (r.returncode, r.stderr) == (2, "ermrl experiment: error: on Ant-v5, vanilla PPO (-60) does not beat the "
                                           "random agent (-48.05) at this budget, so nScore would reward scores below "
                                           "random; give the study longer trials (a larger --scale) or leave it out "
                                           "(--only)\n")
    storage = optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(str(out / "studies.log")))
    assert optuna.get_all_study_names(storage) == []


def test_select_reevaluates_exactly_the_top_k_and_test_uses_the_winner(tmp_path):
    base = ["--out", str(tmp_path), "--study", "s"]
    r = cli("evolve", "--trials", "4", "--popsize", "4", "--seeds", "1", "--timesteps", "2048", "--fixed-iss", "1.0",
            "--sampler", "random", "--quiet", "--no-estimate", *base)
    assert r.returncode == 0, r.stderr
    r = cli("select", "--top", "2", "--seeds", "2", "--quiet", *base)
    assert r.returncode == 0, r.stderr
    study = load_study(f"sqlite:///{tmp_path}/study.db", "s")
    ranked = sorted((t for t in study.trials if t.state == TrialState.COMPLETE), key=lambda t: -t.value)
    selection = study.user_attrs["selection"]
    assert selection["trials"] == [t.number for t in ranked[:2]]
    assert selection["seeds"] == [2000, 2001] and len(selection["per_seed"]) == 2
    assert selection["winner"] == selection["trials"][int(np.argmax(selection["values"]))]
    r = cli("select", "--top", "2", "--seeds", "2", "--quiet", *base)  # a rerun reuses it, trains nothing
    assert r.returncode == 0 and (
        f"the top 2 trials were re-evaluated on seeds 2000..2001 already ({selection['date']}); reusing that "
        "selection (--again re-evaluates them):\n") in r.stdout, r.stdout
    assert load_study(f"sqlite:///{tmp_path}/study.db", "s").user_attrs["selection"] == selection
    r = cli("select", "--top", "2", "--seeds", "2", "--again", "--quiet", *base)
    assert r.returncode == 0 and "re-evaluated the top 2 trials on seeds 2000..2001:\n" in r.stdout, r.stdout
    assert "already" not in r.stdout
    again = load_study(f"sqlite:///{tmp_path}/study.db", "s").user_attrs["selection"]
    assert again["values"] == selection["values"]  # the same seeds give the same re-evaluation
    r = cli("test", "--seeds", "1", "--timesteps", "2048", "--quiet", *base)
    assert r.returncode == 0, r.stderr
    rows = json.loads((tmp_path / "test" / "summary.json").read_text())
    assert rows[0]["phi_trial"] == selection["winner"] and "selected by `ermrl select`" in rows[0]["phi_choice"]
    assert selection["software"] == json.loads((tmp_path / "test" / "test_config.json").read_text())["software"]
    assert selection["software"]["jax"] == jax.__version__ and study.user_attrs["software"]["jax"] == jax.__version__


def test_a_diverged_seed_is_counted_not_dropped():
    results = train(TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=2048, agent=AgentConfig(reservoirs=1)),
                    Population.grid([Phi(0.95, 0.5, 1.0), Phi(1.0, 5.0, 1.0), Phi(0.5, 0.3, 1.0)], 1, 3e-4, 1))
    assert list(results.finite) == [True, False, True]
    row = summarize("ER-MRL", "ER-MRL", results)
    assert row["n_seeds"] == 3 and row["diverged"] == 1 and row["per_seed"][1] is None
    fit = results.fitness()
    assert row["final_mean"] == pytest.approx(np.mean(fit[[0, 2]]))


def test_experiment_list_names_every_experiment_of_the_paper():
    r = cli("experiment", "list")
    assert r.returncode == 0, r.stderr
    for name in ("partial-observability", "locomotion", "generalization-morphology", "generalization-humanoid",
                 "hp-map", "reservoir-sizes", "observed-units", "reservoir-count"):
        assert f"{name}: " in r.stdout
    assert ("    studies: to-ant, to-halfcheetah (trials of at least 200k steps), to-swimmer (trials of at least 200k "
            "steps)\n") in r.stdout
    gen = registry.get("generalization-morphology")
    assert {(s.envs, s.test_envs) for s in gen.studies} == {
        (("HalfCheetah-v5", "Swimmer-v5"), ("Ant-v5",)), (("Ant-v5", "Swimmer-v5"), ("HalfCheetah-v5",)),
        (("Ant-v5", "HalfCheetah-v5"), ("Swimmer-v5",))}
    assert {s.units for s in registry.get("reservoir-sizes").studies} == {25, 50, 100, 200, 500, 1000}
    assert registry.SCALES["paper"].trials == 900 and registry.SCALES["paper"].long_test_timesteps == 3_000_000


def test_unknown_experiment_and_study_are_one_line_errors(tmp_path):
    r = cli("experiment", "run", "generalisation-morphology", cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr == ("ermrl experiment: error: unknown experiment 'generalisation-morphology'; did you mean "
                        "generalization-morphology? (`ermrl experiment list` names them all)\n")
    r = cli("experiment", "run", "observed-units", "--only", "10-of-100", cwd=tmp_path)
    assert r.returncode == 2 and "has no study '10-of-100'; its studies: 100-of-100, 100-of-1000" in r.stderr
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("scale", list(registry.SCALES))
def test_every_experiment_plans_at_every_scale(scale, tmp_path):
    """Every study of every experiment builds a valid config (env ids exist, options are in range), with the
    scale's budgets, and a time estimate (without training)."""
    names = set()
    for experiment in registry.EXPERIMENTS.values():
        plans = runner.plan(experiment, registry.get_scale(scale), tmp_path)
        assert len({p.study for p in plans}) == len(plans) == len(experiment.studies)
        names |= {p.study for p in plans}
        for p in plans:
            assert p.config.trials == registry.SCALES[scale].trials
            floor = 0 if registry.SCALES[scale].wiring_only else p.spec.min_trial_timesteps
            assert p.config.train.total_timesteps == max(registry.SCALES[scale].timesteps, floor)
            assert p.config.normalized == (len(p.spec.envs) > 1)
            assert [t.env_id or p.config.env_ids[0] for t in p.tests] == list(p.spec.tested_on)
    assert len(names) == sum(len(e.studies) for e in registry.EXPERIMENTS.values())


def test_studies_that_evolve_on_ant_get_trials_long_enough_for_ppo_to_beat_random(tmp_path):
    """At 50k steps PPO scores below a random agent on Ant-v5, so an nScore evolution with Ant among its envs gets
    200k-step trials at `small` (and keeps `medium`'s 300k); `smoke` keeps its tiny trials (wiring only)."""
    steps = {scale: {p.spec.name: p.config.train.total_timesteps
                     for p in runner.plan(registry.get("generalization-morphology"), registry.get_scale(scale), tmp_path)}
             for scale in ("smoke", "small", "medium")}
    assert steps == {"smoke": {"to-ant": 2048, "to-halfcheetah": 2048, "to-swimmer": 2048},
                     "small": {"to-ant": 50_000, "to-halfcheetah": 200_000, "to-swimmer": 200_000},
                     "medium": {"to-ant": 300_000, "to-halfcheetah": 300_000, "to-swimmer": 300_000}}


def test_generalization_groups_evolve_together_and_other_agent_shapes_apart(tmp_path):
    """At `converged` every generalization group shares one env, trained alike, with each other group, so
    `experiment run` trains them together (one population per env); groups of another reservoir count (C16) or
    another budget (`small`'s 50k-step to-ant) share none."""
    def shared(experiment, scale):
        plans = runner.plan(registry.get(experiment), registry.get_scale(scale), tmp_path)
        return {(p.spec.name, q.spec.name): shared_envs(p.config, q.config)
                for p in plans for q in plans if p.spec.name < q.spec.name}

    assert shared("generalization-morphology", "converged") == {
        ("to-ant", "to-halfcheetah"): ("Swimmer-v5",), ("to-ant", "to-swimmer"): ("HalfCheetah-v5",),
        ("to-halfcheetah", "to-swimmer"): ("Ant-v5",)}
    assert shared("generalization-morphology", "small")[("to-ant", "to-swimmer")] == ()
    count = shared("reservoir-count", "small")
    assert count[("to-ant-1res", "to-ant-2res")] == () and count[("to-halfcheetah-2res", "to-swimmer-2res")] == \
        ("Ant-v5",)


def run_smoke(name, tmp_path, only=()):
    """Runs ``name`` at smoke scale, checks every study's trials, selection and test phases, then checks that a
    rerun resumes without training anything again."""
    experiment, scale = registry.get(name), registry.get_scale("smoke")
    table = tmp_path / "baselines.json"
    report = runner.run_experiment(experiment, scale, tmp_path, log=lambda s: None, baselines_table=table, only=only)
    assert report.is_file() and "<h2>Studies</h2>" in report.read_text()
    url = runner.default_storage(tmp_path)
    plans = [p for p in runner.plan(experiment, scale, tmp_path) if not only or p.spec.name in only]
    for plan in plans:
        study = load_study(url, plan.study)
        assert sum(t.state == TrialState.COMPLETE for t in study.trials) == scale.trials
        assert study.user_attrs["selection"]["winner"] in {t.number for t in study.trials}
        for env_id in plan.spec.tested_on:
            folder = plan.run_dir / ("test" if (env_id,) == plan.spec.envs else f"test-{env_id}")
            rows = json.loads((folder / "summary.json").read_text())
            assert rows[0]["env_id"] == env_id and rows[0]["evolved_on"] == list(plan.spec.envs)
    # a rerun resumes: no trial is added and no test phase is redone
    summaries = {p: p.stat().st_mtime_ns for p in tmp_path.glob("*/test*/summary.json")}
    trials = {p.study: len(load_study(url, p.study).trials) for p in plans}
    assert runner.run_experiment(experiment, scale, tmp_path, log=lambda s: None, baselines_table=table,
                                 only=only) == report
    assert {p: p.stat().st_mtime_ns for p in tmp_path.glob("*/test*/summary.json")} == summaries
    assert {p.study: len(load_study(url, p.study).trials) for p in plans} == trials
    return report


FAST_END_TO_END = ("partial-observability", "observed-units")
"""Experiments whose first study runs end to end in the default suite (JAX envs, seconds). The others' first
studies (MuJoCo host envs, two-env normalized fitness: 0.5–2 min each) run with `make test-slow`; their paths are
covered in the default suite by the plan test above and the two-env test below."""

@pytest.mark.parametrize("name", [n if n in FAST_END_TO_END else pytest.param(n, marks=pytest.mark.slow)
                                  for n in registry.EXPERIMENTS])
def test_every_experiment_runs_end_to_end_and_resumes(name, tmp_path):
    """Every experiment name runs at smoke scale (each one's first study; `make test-slow` also runs all their
    studies, below)."""
    first = registry.get(name).studies[0]
    text = run_smoke(name, tmp_path, only=(first.name,)).read_text()
    assert first.name in text and "P(improvement)" in text
    assert all(f"Test phase on {env_id}" in text for env_id in first.tested_on)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(registry.EXPERIMENTS))
def test_every_experiment_runs_at_smoke_scale(name, tmp_path):
    text = run_smoke(name, tmp_path).read_text()
    if registry.get(name).hp_map:  # the HP map across studies and its leak-rate table, one row per study
        assert "HP map across studies" in text and "leak rate against the other studies of K reservoirs" in text
        assert all(f"<td>{name}-smoke-{s.name}</td>" in text for s in registry.get(name).studies)


def test_a_finished_test_phase_is_kept_across_new_test_config_fields(tmp_path):
    """A test phase saved before a TestConfig field existed (here: recurrent_baseline), and before its learning
    rates had their names of today (then ermrl_lrs and ppo_lr), counts as done for the same settings and Φ*, so a
    resumed experiment does not redo it; other settings or another Φ* redo it."""
    import dataclasses

    from ermrl.experiments.evaluation import TestConfig

    test = TestConfig(seeds=3, timesteps=4096, learning_rates=(3e-4, 1e-4), baseline_learning_rate=3e-4,
                      env_id="Ant-v5", auc_steps=4096)
    old_names = {"learning_rates": "ermrl_lrs", "baseline_learning_rate": "ppo_lr"}
    saved = {old_names.get(k, k): v for k, v in dataclasses.asdict(test).items() if k != "recurrent_baseline"}
    assert saved["ermrl_lrs"] == (3e-4, 1e-4) and saved["ppo_lr"] == 3e-4
    (tmp_path / "test_config.json").write_text(json.dumps({**saved, "phi_trial": 7}))
    assert not runner._test_done(tmp_path, test, 7)  # no summary yet: not finished
    row = {"model": "m", "env_id": "Ant-v5", "n_seeds": 3, "final_mean": 1.0, "final_std": 0.0, "auc_mean": 1.0,
           "auc_std": 0.0}
    (tmp_path / "summary.json").write_text(json.dumps([row]))
    assert runner._test_done(tmp_path, test, 7)
    assert not runner._test_done(tmp_path, test, 8)
    assert not runner._test_done(tmp_path, dataclasses.replace(test, seeds=4), 7)
    assert not runner._test_done(tmp_path, dataclasses.replace(test, recurrent_baseline=True), 7)
    assert not runner._test_done(tmp_path, dataclasses.replace(test, learning_rates=(3e-4,)), 7)
    assert not runner._test_done(tmp_path, dataclasses.replace(test, baseline_learning_rate=1e-4), 7)


def test_a_committed_test_phase_of_an_older_version_counts_as_done():
    """docs/data's test phases were written before the learning rates' names of today: their test_config.json
    (ermrl_lrs, ppo_lr) still reads as the same settings, so an experiment resumed over them keeps them."""
    from ermrl.experiments.evaluation import TestConfig

    folder = Path(__file__).resolve().parents[1] / "docs/data/partial-observability-paper/cartpole-1res/test"
    assert {"ermrl_lrs", "ppo_lr"} <= set(json.loads((folder / "test_config.json").read_text()))
    test = TestConfig(seeds=10, timesteps=1_000_000, learning_rates=(3e-4, 1e-4, 5e-5), baseline_learning_rate=3e-4,
                      auc_steps=300_000)
    assert runner._test_done(folder, test, 43)
    assert not runner._test_done(folder, TestConfig(seeds=10, timesteps=1_000_000, learning_rates=(3e-4,),
                                                    baseline_learning_rate=3e-4, auc_steps=300_000), 43)


def test_select_says_when_trials_tie_at_its_cut(tmp_path):
    """A ceiling (CartPole's 500) ties many trials; the top K are then simply the first by trial number, and
    `select` says so before it trains, with the --top that would take them all."""
    from ermrl import storage
    from ermrl.evolution.config import EvolveConfig
    from ermrl.evolution.search_space import SearchSpace
    from ermrl.evolution.study import ATTR, make_storage

    journal = tmp_path / "studies.log"
    space = SearchSpace(1, fixed_iss=1.0)
    config = EvolveConfig(train=TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=2048), space=space,
                          trials=5, seeds=1)
    study = optuna.create_study(storage=make_storage(str(journal)), study_name="ties", direction="maximize")
    study.set_user_attr(ATTR, encode_study_record(config))
    for lr, value in ((0.5, 40.0), (0.6, 500.0), (0.7, 500.0), (0.8, 500.0), (0.9, 500.0)):
        study.add_trial(optuna.trial.create_trial(params={"sr": 0.95, "lr": lr}, distributions=space.distributions(),
                                                  value=value))
    r = cli("select", "--study", "ties", "--storage", str(journal), "--out", str(tmp_path / "run"), "--top", "2",
            "--seeds", "1", "--quiet")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("note: 2 more trials tie at the cut's fitness (500), so the top 2 are the first of "
                               "them by trial number; --top 4 re-evaluates them all\n")
    assert load_study(str(journal), "ties").user_attrs["selection"]["trials"] == [1, 2]
    r = cli("select", "--study", "ties", "--storage", str(journal), "--out", str(tmp_path / "run"), "--top", "4",
            "--seeds", "1", "--quiet")
    assert r.returncode == 0 and not r.stdout.startswith("note:"), r.stdout


def test_an_experiment_stopped_by_convergence_logs_each_generations_spread(tmp_path):
    """A scale with a convergence rule (as `converged`) logs, under its study, the widest Φ spread of each
    generation sampled from CMA-ES's distribution, as `ermrl evolve --until-converged` does."""
    import dataclasses
    import re

    from ermrl.evolution.convergence import Convergence

    scale = dataclasses.replace(registry.get_scale("smoke"), trials=10, until_converged=Convergence())
    first = registry.get("partial-observability").studies[0].name
    lines = []
    runner.run_experiment(registry.get("partial-observability"), scale, tmp_path, log=lines.append,
                          baselines_table=tmp_path / "baselines.json", only=(first,))
    spread = [line for line in lines if re.match(r" {4}generation \d+: widest spread", line)]
    assert [int(line.split()[1].rstrip(":")) for line in spread] == [2, 3, 4], lines  # as each one starts
    assert all(line.endswith("0.01 to converge") for line in spread), spread


def test_the_converged_scale_estimates_the_trial_limit_and_the_typical_convergence(tmp_path):
    """`experiment run --scale converged` prints the time to every study's trial limit, the likelier time if each
    converges after CONVERGED_TRIALS trials, and for several reservoirs that they may not converge."""
    from ermrl.cli.experiment import estimate_lines

    def lines(scale: str, only: str, done: int) -> tuple[list[str], float]:
        plans = [p for p in runner.plan(registry.get("locomotion"), registry.get_scale(scale), tmp_path)
                 if p.spec.name == only]
        return estimate_lines(plans, registry.get_scale(scale), {plans[0].study: done}, {}, {plans[0].study}, None,
                              runner.TestBudget(), None)

    (limit, typical, caveat), likelier = lines("converged", "ant-2res", 27)
    to_limit = int(limit.split()[2])
    assert limit == (f"estimated time: {to_limit} min (rough: nominal throughput, 27 trials and 0 test phases "
                     "already done) if every study runs to its trial limit")
    assert typical == (f"  about {likelier / 60:.0f} min if each study converges after about "
                       f"{registry.CONVERGED_TRIALS} trials, as the paper's 900-trial CartPoleNoVel study did")
    assert 0 < likelier / 60 < to_limit / 3  # 173 of 873 trials left, and the same selection and test phases
    assert caveat.startswith("  (a study of 2 or more reservoirs searches 6 or more parameters and may not converge")
    assert len(lines("converged", "ant-1res", 0)[0]) == 2  # one reservoir: no caveat
    paper, _ = lines("paper", "ant-2res", 27)  # a scale without convergence: the one line, no trial-limit clause
    assert len(paper) == 1 and paper[0].endswith("already done)")


def test_a_running_study_is_estimated_at_the_pace_of_its_last_generation(tmp_path):
    """Before it resumes a study, `experiment run` prints the rest of its evolution at its last generation's pace,
    and at a scale that stops at convergence, where the trend of CMA-ES's spread puts the stop."""
    import dataclasses

    from ermrl.cli.experiment import pace_line
    from ermrl.evolution.evolve import evolve
    from ermrl.evolution.study import make_sampler, open_study
    from ermrl.evolution.generations import generation_seconds

    (plan,) = [p for p in runner.plan(registry.get("partial-observability"), registry.get_scale("converged"),
                                      tmp_path) if p.spec.name == "cartpole-1res"]
    small = dataclasses.replace(plan.config, train=dataclasses.replace(plan.config.train, total_timesteps=2048),
                                seeds=1, popsize=2, trials=20)
    plan = dataclasses.replace(plan, config=small)
    study = open_study(f"journal:{tmp_path / 'studies.log'}", plan.study, make_sampler("cmaes", 2, 0),
                       encode_study_record(small))
    assert pace_line(plan, study) is None  # nothing to go by yet
    evolve(study, dataclasses.replace(small, trials=14))  # 7 generations
    took = generation_seconds(study.get_trials(deepcopy=False), 2)
    line = pace_line(plan, study)
    assert re.fullmatch(rf"  {plan.study}: \d+ s a generation \(its last one\): 3 more to its trial limit, about "
                        r"\d+ (s|min); (its spread is not shrinking \(`ermrl convergence`\), so it will likely run to "
                        r"that limit|the trend of its spread \(`ermrl convergence`\) puts the stop near generation "
                        r"\d+, (beyond that limit|\d+ more, about \d+ (s|min)))", line), line
    assert line.split(": ", 1)[1].startswith(f"{took:.0f} s a generation")
    plain = dataclasses.replace(plan, until_converged=None)  # a scale without convergence: the pace only
    assert pace_line(plain, study) == f"  {plan.study}: {took:.0f} s a generation (its last one): 3 more to its " \
                                      f"trial limit, about {3 * took:.0f} s"
    done = dataclasses.replace(plan, config=dataclasses.replace(small, trials=14))
    assert pace_line(done, study) is None  # evolved to its limit


def test_runtime_settings_reach_every_study_and_a_study_resumes_under_other_ones(tmp_path):
    """`experiment run --env-workers/--env-threads/--processes` set every study's training (before,
    --env-threads was parsed and dropped); like the env workers, none of them is part of a study's config, so a
    study started under one value resumes under another."""
    import dataclasses

    from ermrl.evolution.study import make_sampler, open_study

    plans = runner.plan(registry.get("locomotion"), registry.get_scale("smoke"), tmp_path, "auto", 0,
                        runner.TestBudget(), env_threads=1, processes=2)
    assert {(p.config.train.env_workers, p.config.train.env_threads, p.config.train.processes) for p in plans} == \
        {(0, 1, 2)}
    config = plans[0].config
    url = f"journal:{tmp_path / 'studies.log'}"
    sampler = lambda: make_sampler(config.sampler, config.generation_size, config.sampler_seed)
    open_study(url, "s", sampler(), encode_study_record(config))
    other = dataclasses.replace(config, train=dataclasses.replace(config.train, env_workers="auto",
                                                                   env_threads="auto", processes=1))
    assert open_study(url, "s", sampler(), encode_study_record(other)).study_name == "s"
