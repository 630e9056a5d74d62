"""What `ermrl experiment run` estimates before it starts: the selection until one of the current top trials is
stored, the reservoir's size, and PPO baselines shared through a store (counted once) or already stored (not at
all). The runs it prices are conftest's smoke study of CartPoleNoVel (``evolved``) and the registry's plans."""

import dataclasses

import pytest

from ermrl.evolution.study import load_study
from ermrl.experiments import evaluation, registry, runner
from smoke_study import BUDGET, EXPERIMENT, FLAGS, RUN, STUDY, cli


def test_the_estimate_counts_the_reservoir_size(tmp_path):
    """Every step reads each agent's whole (units, units) W, so 1000-unit reservoirs train ≈ 8× slower than 100-unit
    ones here (docs/benchmarks.md, "Reservoir size"): the estimate says so for the evolution and the ER-MRL test
    models, not for the PPO baselines, and counts the reservoir's units, not those the policy observes."""
    plans = {p.spec.name: p for p in runner.plan(registry.get("observed-units"), registry.get_scale("small"), tmp_path)}
    evolution = {name: runner.estimate_seconds([p], left={p.study: ()}) - runner.COMPILE_S
                 for name, p in plans.items()}
    assert 5 < evolution["1000-of-1000"] / evolution["100-of-100"] < 20
    assert evolution["100-of-1000"] == evolution["1000-of-1000"]
    p = plans["1000-of-1000"]
    (t,) = p.tests
    whole = runner.estimate_seconds([p], {p.study: p.config.trials})
    ppo_only = runner.estimate_seconds([dataclasses.replace(p, tests=(dataclasses.replace(t, learning_rates=()),))],
                                       {p.study: p.config.trials})
    ppo_seconds = 2 * t.seeds * t.timesteps / runner.JAX_RATE  # PPO on the same and on the full observation
    assert ppo_only == pytest.approx(runner.COMPILE_S + ppo_seconds)
    assert 5 < (whole - ppo_only) / (t.seeds * t.timesteps / runner.JAX_RATE) < 20


def test_the_estimate_counts_the_selection_until_one_of_the_current_top_is_stored(evolved, tmp_path):
    """The selection re-evaluates the top trials on new seeds at the evolution's budget (at `small`, 3 trials × 3
    seeds of 50k steps beside the evolution's 18 × 2): the estimate counts it until the study stores a selection of
    its current top with the scale's number of seeds, and again when one was made with another number; the CLI
    asks the storage, so a rerun with everything done estimates 0."""
    (p,) = [p for p in runner.plan(registry.get(EXPERIMENT), registry.get_scale("small"), tmp_path)
            if p.spec.name == STUDY]
    assert (p.config.trials, p.config.seeds, p.select_top, p.select_seeds) == (18, 2, 3, 3)
    run_s = p.config.train.total_timesteps / runner.JAX_RATE
    assert runner.estimate_seconds([p], left={p.study: ()}) == pytest.approx(runner.COMPILE_S + (36 + 9) * run_s)
    evolved_only = {p.study: p.config.trials}
    assert runner.estimate_seconds([p], evolved_only, {p.study: ()}, unselected={p.study}) == pytest.approx(
        runner.COMPILE_S + 9 * run_s)
    assert runner.estimate_seconds([p], evolved_only, {p.study: ()}, unselected=set()) == 0
    (q,) = [q for q in runner.plan(registry.get(EXPERIMENT), registry.get_scale("smoke"), evolved)
            if q.spec.name == STUDY]
    study = load_study(runner.default_storage(evolved), q.study)
    assert not runner.selection_left(q, study)
    assert runner.selection_left(dataclasses.replace(q, select_seeds=q.select_seeds + 1), study)
    assert runner.selection_left(q, None)
    r = cli(*[a for a in RUN if a != "--no-estimate"], "--out", str(evolved), *FLAGS)  # a rerun: all done
    assert r.returncode == 0, r.stderr
    assert f"experiment {EXPERIMENT} at smoke scale: 1 study in " in r.stdout
    assert "estimated time: 0 min (rough: nominal throughput, 2 trials and 1 test phase already done)" in r.stdout


def test_the_estimate_counts_a_shared_baseline_once_and_a_stored_one_not_at_all(evolved, tmp_path):
    """With a baseline store, a PPO baseline that two test phases share is estimated once, and one that a real
    test phase has already stored (found under the same identity as training uses) costs nothing; without a
    store, every test phase trains its own."""
    (p,) = [p for p in runner.plan(registry.get(EXPERIMENT), registry.get_scale("smoke"), evolved, budget=BUDGET)
            if p.spec.name == STUDY]
    twins = [p, dataclasses.replace(p, study=p.study + "-twin", run_dir=tmp_path / "twin")]
    done = {q.study: q.config.trials for q in twins}
    (t,) = p.tests
    model_s = t.seeds * t.timesteps / runner.JAX_RATE
    ermrl_s = len(t.learning_rates) * model_s  # 100-unit reservoirs: no extra cost
    store = tmp_path / "store"
    assert runner.estimate_seconds(twins, done) == pytest.approx(2 * (runner.COMPILE_S + ermrl_s + 2 * model_s))
    assert runner.estimate_seconds(twins, done, store=store) == pytest.approx(
        2 * (runner.COMPILE_S + ermrl_s) + 2 * model_s)  # PPO on the same and on the full observation, once each
    study = load_study(runner.default_storage(evolved), p.study)
    evaluation.run_test_phase(study, tmp_path / "test", t, save_agents=False, baseline_store=store)
    assert sorted(f.parent.name for f in store.glob("*/*.npz")) == ["CartPole-v1", "CartPoleNoVel-v1"]
    assert runner.estimate_seconds(twins, done, store=store) == pytest.approx(2 * (runner.COMPILE_S + ermrl_s))
    assert runner.estimate_seconds(twins, done) == pytest.approx(2 * (runner.COMPILE_S + ermrl_s + 2 * model_s))


def test_test_phases_of_any_reservoir_size_share_their_baselines(tmp_path):
    """A PPO baseline has no reservoir, so its identity in a store does not carry the study's units or observed
    units: C15's three studies (100 of 100, 1000 of 1000, 100 of 1000 units) and C14's six CartPole sizes share
    one PPO on the same observation and one on the full observation."""
    from ermrl.experiments.evaluation import baseline_files

    budget = runner.TestBudget(seeds=10, timesteps=1_000_000)
    plans = [p for name in ("observed-units", "reservoir-sizes")
             for p in runner.plan(registry.get(name), registry.get_scale("small"), tmp_path, budget=budget)
             if p.config.env_ids == ("CartPoleNoVel-v1",)]
    assert len(plans) == 9
    files = {tuple(baseline_files(p.config, p.tests[0], tmp_path)) for p in plans}
    assert len(files) == 1
    assert [f.parent.name for f in next(iter(files))] == ["CartPoleNoVel-v1", "CartPole-v1"]


def test_an_estimate_on_a_busy_machine_says_it_may_be_several_times_too_short():
    """The estimates assume free cores; a load average above 0.75 per core (another training: ≈ 2 on 2 cores)
    adds a one-line note, an idle machine none."""
    from ermrl.cli.common import busy_note

    assert busy_note(load=2.1, cores=2) == ("note: the machine looks busy (load average 2.1 on 2 cores); the estimate "
                                           "assumes free cores, and training beside another job can take several "
                                           "times longer")
    assert busy_note(load=1.5, cores=2) is None and busy_note(load=0.2, cores=2) is None
    assert busy_note(load=2.1, cores=4) is None


def test_the_estimate_counts_the_normalization_baselines_a_new_study_over_several_envs_trains_first(tmp_path):
    """A study whose fitness is the mean nScore over several envs first trains vanilla PPO on each env at the
    evolution's budget where the baselines table lacks it (``baseline_runs.ensure``): the estimate counts it once
    per env and budget, not when the table has it, and not for a study that exists already (it keeps its
    constants). JAX envs here, so that the rate is the nominal one."""
    from ermrl.experiments import baselines

    envs = ("CartPoleNoVel-v1", "PendulumNoVel-v1")
    experiment = registry.Experiment("pair", "two JAX envs", "test", (), (
        registry.StudySpec("a", envs), registry.StudySpec("b", envs)))
    plans = runner.plan(experiment, registry.get_scale("small"), tmp_path)
    c = plans[0].config
    assert c.normalized and c.env_ids == envs
    per_env = c.seeds * c.train.total_timesteps / runner.JAX_RATE
    table = baselines.load_table(tmp_path / "baselines.json")  # the shipped table only
    assert all(table.ppo(e, c.train.total_timesteps, c.seeds, 3e-4) is None for e in envs)
    without = runner.estimate_seconds(plans)
    assert runner.estimate_seconds(plans, table=table) == pytest.approx(without + 2 * per_env)  # shared by a and b
    table.add_ppo(envs[0], baselines.PPOScore(c.seeds, c.train.total_timesteps, 3e-4, 100.0, 1.0, (99.0, 101.0)), "x")
    assert runner.estimate_seconds(plans, table=table) == pytest.approx(without + per_env)
    started = {p.study: 0 for p in plans}
    assert runner.estimate_seconds(plans, started, table=table) == pytest.approx(runner.estimate_seconds(plans, started))
