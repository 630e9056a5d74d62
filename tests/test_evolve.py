"""Evolution, resumption, divergence, the test phase and the report, at tiny budgets."""

import dataclasses
import json
import shutil
import signal
import subprocess
import time
import warnings
from pathlib import Path

import numpy as np
import optuna
import pytest
from optuna.trial import TrialState

from ermrl.agent import AgentConfig, Phi
from ermrl.errors import RunFailed
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.evolve import evolve
from ermrl.evolution.record import decode_study_record, encode_study_record
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import load_study, make_sampler, open_study
from ermrl.training import Population, TrainConfig, train

from cli_runs import COMMAND, ermrl as cli

optuna.logging.set_verbosity(optuna.logging.WARNING)


def tiny(trials, sampler="cmaes", popsize=None, space=SearchSpace(fixed_iss=1.0)):
    return EvolveConfig(train=TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=2048), space=space,
                        trials=trials, seeds=2, sampler=sampler, popsize=popsize)


def test_two_cmaes_generations_store_every_trial(tmp_path):
    config = tiny(trials=12)
    assert config.generation_size == 6  # CMA-ES default for 2 parameters: 4 + ⌊3 ln 2⌋
    study = open_study(f"sqlite:///{tmp_path}/s.db", "s", make_sampler("cmaes", 6, 0), encode_study_record(config))
    evolve(study, config)
    trials = study.trials
    assert [t.state for t in trials] == [TrialState.COMPLETE] * 12
    assert sorted(t.user_attrs["generation"] for t in trials) == [0] * 6 + [1] * 6
    for t in trials:
        assert t.distributions == {"sr": optuna.distributions.FloatDistribution(1e-4, 1e2, log=True),
                                   "lr": optuna.distributions.FloatDistribution(1e-2, 1.0, log=True)}
        assert t.user_attrs["phi"]["sr"] == [pytest.approx(t.params["sr"], rel=1e-6)]
        assert t.user_attrs["phi"]["iss"] == [1.0]
        assert len(t.user_attrs["seed_fitness"]) == 2 and len(t.user_attrs["curve_final"]) == 2
        assert t.value == pytest.approx(np.mean(t.user_attrs["seed_fitness"]))
    assert study.user_attrs["ermrl"]["popsize"] == 6 and study.user_attrs["ermrl"]["search_space"]["iss"] == {"fixed": 1.0}


@pytest.mark.filterwarnings("error::RuntimeWarning")  # cmaes's warnings at popsize 2 do not reach users
@pytest.mark.parametrize("schedule", ["fixed", "generation"])
def test_the_seed_schedule_sets_each_trials_seeds_and_its_fitness_is_theirs(schedule, tmp_path):
    """'fixed': seeds 0, 1 for every trial (the paper's code); 'generation': new seeds each generation, shared by
    its trials. A trial's per-seed fitness is what its Φ scores when trained again alone on its recorded seeds.
    Generations of 2 (the random startup, then CMA-ES's first): 2 trials × 2 seeds, a population size that other
    tests compile too."""
    config = dataclasses.replace(tiny(trials=4, popsize=2), seed_schedule=schedule)
    study = open_study(f"sqlite:///{tmp_path}/s.db", "s", make_sampler("cmaes", 2, 0), encode_study_record(config))
    evolve(study, config)
    trials = study.trials
    assert [t.state for t in trials] == [TrialState.COMPLETE] * 4
    base = {"fixed": lambda g: [0, 1], "generation": lambda g: [100_000 + 2 * g, 100_001 + 2 * g]}[schedule]
    assert [t.user_attrs["seeds"] for t in trials] == [base(t.user_attrs["generation"]) for t in trials]
    assert sorted({t.user_attrs["generation"] for t in trials}) == [0, 1]
    assert decode_study_record(study.user_attrs["ermrl"]).seed_schedule == schedule
    last = trials[-1]
    phi = Phi(*(np.asarray(last.user_attrs["phi"][k], np.float32) for k in ("sr", "lr", "iss")))
    alone = train(config.train, Population.grid(phi, last.user_attrs["seeds"], config.train.ppo.learning_rate, 1))
    np.testing.assert_allclose(alone.fitness(), last.user_attrs["seed_fitness"], rtol=1e-5)


def test_divergent_candidate_is_failed_and_the_study_goes_on(tmp_path):
    config = tiny(trials=4, sampler="random", popsize=2, space=SearchSpace())
    study = open_study(f"sqlite:///{tmp_path}/s.db", "s", make_sampler("random", 2, 0), encode_study_record(config))
    with warnings.catch_warnings():  # a leak rate of 5 is outside the search space: x grows ×4 per step
        warnings.simplefilter("ignore", UserWarning)
        study.enqueue_trial({"sr": 1.0, "lr": 5.0, "iss": 1.0})
        evolve(study, config)
    failed = [t for t in study.trials if t.state == TrialState.FAIL]
    assert len(failed) == 1 and failed[0].params["lr"] == 5.0
    assert failed[0].user_attrs["failure"] == "diverged (NaN/inf) on 2 of 2 seeds"
    assert sum(t.state == TrialState.COMPLETE for t in study.trials) == 4


def test_three_batches_without_a_completed_trial_stop_the_run_with_a_reason(tmp_path):
    """Every trial of three batches in a row diverges: the worker stops with RunFailed (one line, exit code 1 in the
    CLI, not an "unexpected" bug) and keeps the failed trials with their reasons."""
    config = tiny(trials=8, sampler="random", popsize=2, space=SearchSpace())
    study = open_study(f"sqlite:///{tmp_path}/s.db", "s", make_sampler("random", 2, 0), encode_study_record(config))
    with warnings.catch_warnings():  # a leak rate of 5 is outside the search space: x grows ×4 per step
        warnings.simplefilter("ignore", UserWarning)
        for _ in range(6):
            study.enqueue_trial({"sr": 1.0, "lr": 5.0, "iss": 1.0})
        with pytest.raises(RunFailed) as e:
            evolve(study, config)
    assert str(e.value) == ("3 batches in a row of study 's' had no completed trial; see the trials' 'failure' "
                            "attributes (`ermrl report`), fix the cause, then rerun to resume")
    assert [(t.state, t.user_attrs["failure"]) for t in study.trials] == \
        [(TrialState.FAIL, "diverged (NaN/inf) on 2 of 2 seeds")] * 6


def test_extreme_but_valid_phi_stays_finite():
    """sr = 100 and iss = 10 are the search space's corners; tanh keeps the states bounded and PPO finite."""
    res = train(TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=4096, agent=AgentConfig(reservoirs=1)),
                Population.grid([Phi(100.0, 1.0, 10.0), Phi(100.0, 0.01, 10.0)], 1, 3e-4, 1))
    assert res.finite.all() and np.isfinite(res.fitness()).all()


@pytest.mark.slow  # the default suite kills evolutions at 10 random points: test_crash_safety.py
def test_resume_after_kill_loses_and_duplicates_nothing(tmp_path):
    args = ["evolve", "--env", "CartPoleNoVel-v1", "--trials", "12", "--seeds", "2", "--timesteps", "61440",
            "--fixed-iss", "1.0", "--study", "r", "--out", str(tmp_path), "--quiet", "--no-estimate"]
    proc = subprocess.Popen([*COMMAND, *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    url = f"sqlite:///{tmp_path}/study.db"
    first, seen = [], []
    deadline = time.time() + 600
    while time.time() < deadline and proc.poll() is None:
        time.sleep(0.1)
        try:
            trials = load_study(url, "r").trials
        except Exception:  # the database is created or written to right now
            continue
        counts = (sum(t.state == TrialState.COMPLETE for t in trials), sum(t.state == TrialState.RUNNING for t in trials))
        seen.append(counts)
        # Kill while generation 1 trains: generation 0 told, generation 1 asked and not yet told (its tells come
        # in a burst at the end, so 7-11 complete means the window has passed).
        if counts[0] == 6 and counts[1] > 0:
            first = [(t.number, t.value) for t in trials if t.state == TrialState.COMPLETE]
            proc.send_signal(signal.SIGKILL)
            break
    proc.wait()
    assert len(first) == 6, f"the first run was not caught mid-generation; (complete, running) seen: {seen[-20:]}"
    r = cli(*args)
    assert r.returncode == 0, r.stderr
    trials = load_study(url, "r").trials
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    assert len(complete) == 12
    assert set(first) <= {(t.number, t.value) for t in complete}  # nothing lost
    assert len({t.number for t in complete}) == 12  # nothing duplicated
    interrupted = [t for t in trials if t.state == TrialState.FAIL]
    assert interrupted and all(t.user_attrs["failure"] == "interrupted" for t in interrupted)


def test_test_phase_and_report_from_a_tiny_study(tmp_path):
    r = cli("evolve", "--trials", "6", "--seeds", "2", "--timesteps", "2048", "--fixed-iss", "1.0", "--study", "t",
            "--out", str(tmp_path), "--quiet", "--no-estimate")
    assert r.returncode == 0, r.stderr
    assert "best fitness" in r.stdout
    r = cli("test", "--study", "t", "--out", str(tmp_path), "--seeds", "2", "--timesteps", "2048", "--quiet")
    assert r.returncode == 0, r.stderr
    rows = json.loads((tmp_path / "test" / "summary.json").read_text())
    assert [row["model"].split(" (")[0] for row in rows] == ["ER-MRL", "PPO", "PPO"]
    assert rows[2]["env_id"] == "CartPole-v1" and all(row["n_seeds"] == 2 for row in rows)
    for name in ("curves.csv", "summary.csv", "test_phase.png", "test_phase.svg"):
        assert (tmp_path / "test" / name).stat().st_size > 0
    r = cli("report", "--study", "t", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    html = (tmp_path / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 3  # fitness, HP map, test phase
    assert (tmp_path / "hp_map.png").exists() and (tmp_path / "fitness_over_trials.png").exists()


@pytest.mark.parametrize("args, message", [
    (["--min-sr", "10", "--max-sr", "1"], "ermrl evolve: error: bad sr bounds [10.0, 1.0]: need 0 < --min-sr < --max-sr"),
    (["--max-leak-rate", "2"], "ermrl evolve: error: bad leak-rate bounds [0.01, 2.0]: a leak rate is at most 1"),
    (["--sampler", "nsga"], "ermrl evolve: error: unknown sampler 'nsga'; choose one of cmaes, random, tpe"),
    (["--env", "Nope-v0"], "ermrl evolve: error: unknown env id 'Nope-v0'"),
    (["--storage", "postgresql://u:p@127.0.0.1:9/db"], "ermrl evolve: error: cannot open storage 'postgresql://u:***@127.0.0.1:9/db'"),
    (["--storage", "nosuchdb://x"], "ermrl evolve: error: cannot open storage 'nosuchdb://x'"),
])
def test_bad_evolve_flags(args, message, tmp_path):
    r = cli("evolve", "--trials", "2", "--timesteps", "2048", *args, cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.startswith(message), r.stderr
    assert r.stderr.count("\n") == 1


def test_test_and_report_need_an_existing_study(tmp_path):
    for command in ("test", "report"):
        r = cli(command, "--study", "missing", "--out", str(tmp_path))
        assert r.returncode == 2
        assert r.stderr.startswith(f"ermrl {command}: error: no study 'missing': "), r.stderr
        assert not (tmp_path / "study.db").exists()  # looking does not create a database
    journal = tmp_path / "missing.log"
    for command in ("select", "test", "report"):
        r = cli(command, "--study", "missing", "--storage", str(journal))
        assert r.returncode == 2
        assert r.stderr == (f"ermrl {command}: error: no study 'missing': {journal} does not exist; "
                            "run `ermrl evolve` first or pass --storage/--out\n"), r.stderr
        assert not journal.exists()  # nor an empty journal file


def test_journal_storage_persists_a_study(tmp_path):
    config = tiny(trials=1)
    url = str(tmp_path / "journal.log")
    study = open_study(url, "j", make_sampler("random", 6, 0), encode_study_record(config))
    trial = study.ask()
    config.space.suggest(trial)
    study.tell(trial, 12.5)
    again = load_study(url, "j")
    assert [t.value for t in again.trials] == [12.5]
    size = Path(url).stat().st_size
    open_study(url, "j", make_sampler("random", 6, 0), encode_study_record(config))  # resuming writes nothing
    assert Path(url).stat().st_size == size
    assert again.user_attrs["ermrl"]["env_id"] == "CartPoleNoVel-v1"
    with pytest.raises(Exception, match="already exists with another config"):
        open_study(url, "j", make_sampler("random", 6, 0), encode_study_record(tiny(trials=1, space=SearchSpace())))


def test_a_study_from_before_a_config_field_existed_still_resumes(tmp_path):
    """A record written before a field was added (here: without ppo.log_std_init and the reservoir bias) resumes with the
    same config, since missing fields take their defaults; a real change is still refused. The committed journals
    under docs/data/ open without error."""
    url = f"journal:{tmp_path / 'old.log'}"
    config = tiny(trials=1)
    record = encode_study_record(config)
    del record["train"]["ppo"]["log_std_init"], record["train"]["agent"]["spec"]["bias"]
    open_study(url, "old", make_sampler("random", 6, 0), record)
    open_study(url, "old", make_sampler("random", 6, 0), encode_study_record(config))  # resumes
    with pytest.raises(Exception, match="already exists with another config"):
        open_study(url, "old", make_sampler("random", 6, 0), encode_study_record(tiny(trials=1, space=SearchSpace())))
    journal = tmp_path / "committed.log"
    shutil.copy(Path(__file__).parent.parent / "docs" / "data" / "generalization-morphology-small" / "studies.log", journal)
    study = load_study(f"journal:{journal}", "generalization-morphology-small-to-ant")
    stored = decode_study_record(study.user_attrs["ermrl"])
    open_study(f"journal:{journal}", study.study_name, make_sampler("cmaes", 9, 0), encode_study_record(stored))


def test_search_space_for_several_reservoirs():
    space = SearchSpace(reservoirs=2, fixed_iss=None)
    assert list(space.distributions()) == ["sr_1", "sr_2", "lr_1", "lr_2", "iss_1", "iss_2"]
    assert space.default_popsize() == 4 + 5  # 4 + ⌊3 ln 6⌋
    phi = space.phi_from_params({"sr_1": 1.0, "sr_2": 2.0, "lr_1": 0.1, "lr_2": 0.2, "iss_1": 3.0, "iss_2": 4.0})
    np.testing.assert_allclose(phi.sr, [1.0, 2.0])
    np.testing.assert_allclose(phi.iss, [3.0, 4.0])
