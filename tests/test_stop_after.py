"""A time limit (``--stop-after``, ``WorkerConfig.stop_at``): an evolution claims no generation that would end after
it, judged by the last generation's time (generations numbered from 0, as the trials' ``generation``), and stops
between two generations with exit status 75 and one line; the rerun continues the study. ``ermrl experiment run``
starts no selection or test phase after it, and ``ermrl reproduce`` hands the time left to the commands it runs.
Each limit is set against a generation whose time is known to exceed it, so that no test depends on how fast this
machine trains."""

import dataclasses
import re
import shutil
import time

import optuna
import pytest
from optuna.trial import TrialState

from ermrl.errors import OUT_OF_TIME, OutOfTime
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.evolve import Member, evolve, evolve_together
from ermrl.evolution.record import encode_study_record
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import make_sampler, open_study
from ermrl.evolution.generations import generation_seconds
from ermrl.evolution.worker_config import WorkerConfig
from ermrl.evolution.workers import REDO_ATTR, Worker
from ermrl.experiments import registry, runner
from ermrl.experiments.reproduction.actions import Run, Step
from ermrl.experiments.reproduction.execute import run_step
from ermrl.training import TrainConfig

from cli_runs import ermrl
from smoke_study import BUDGET, EXPERIMENT, STUDY

optuna.logging.set_verbosity(optuna.logging.WARNING)

# generations of 2 Φ × 2 seeds × one iteration of 2048 steps
CONFIG = EvolveConfig(train=TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=2048),
                      space=SearchSpace(fixed_iss=1.0), trials=6, seeds=2, popsize=2)
FLAGS = ["--env", "CartPoleNoVel-v1", "--popsize", "2", "--seeds", "2", "--timesteps", "2048", "--fixed-iss", "1.0",
         "--no-estimate", "--quiet"]


def _study(path, name="s", config=CONFIG):
    return open_study(f"journal:{path}", name, make_sampler("cmaes", 2, 0), encode_study_record(config))


def _one_generation(path, name="s", config=CONFIG, pause_s=0.0):
    """A study (as ``ermrl evolve FLAGS`` makes it, for the default ``config``) with its first generation trained;
    its time in seconds. With ``pause_s``, the training pauses once that long in the progress callback, so that the
    generation takes at least that long however fast this machine trains (its program may already be compiled in
    this process) and a CLI time limit shorter than the pause is shorter than the generation."""
    paused = []

    def pause(progress):
        if pause_s and not paused:
            paused.append(progress)
            time.sleep(pause_s)

    study = _study(path, name, config)
    evolve(study, _trials(config, 2), progress_fn=pause)
    span = generation_seconds(study.get_trials(deepcopy=False), 2)
    assert span is not None and span > 0 and span >= pause_s
    return study, span


def _trials(config, n):
    return dataclasses.replace(config, trials=n)


def _states(study):
    return [(t.state, t.user_attrs.get("failure")) for t in study.get_trials(deepcopy=False)]


def test_a_limit_shorter_than_the_last_generation_stops_before_asking_and_a_longer_one_goes_on(tmp_path):
    study, span = _one_generation(tmp_path / "a.log")
    before = _states(study)
    with pytest.raises(OutOfTime) as e:
        evolve(study, CONFIG, worker=WorkerConfig(stop_at=time.time() + span / 2))
    assert re.fullmatch(r"stopped before generation 1 of study 's' \(2 of 6 trials done\): it would take about "
                        r"\d+ s \(as the last one did\) and the time limit leaves \d+ s; rerun the same command to "
                        r"continue", str(e.value)), str(e.value)
    assert _states(study) == before  # nothing asked, nothing failed

    evolve(study, CONFIG, worker=WorkerConfig(stop_at=time.time() + 1000 * span + 3600))
    assert [s for s, _ in _states(study)] == [TrialState.COMPLETE] * 6


def test_a_limit_that_has_passed_stops_even_a_new_study(tmp_path):
    study = _study(tmp_path / "a.log")
    with pytest.raises(OutOfTime, match=r"^stopped before generation 0 of study 's' \(0 of 6 trials done\): the time "
                                        r"limit has passed; rerun the same command to continue$"):
        evolve(study, CONFIG, worker=WorkerConfig(stop_at=time.time() - 1))
    assert study.get_trials(deepcopy=False) == []


def test_the_worker_judges_by_its_own_last_batch_first(tmp_path):
    study, span = _one_generation(tmp_path / "a.log")
    with Worker(study, CONFIG, WorkerConfig(stop_at=time.time() + span + 600)) as worker:
        worker.last_batch_s = 7200.0  # as if its last batch had taken two hours
        with pytest.raises(OutOfTime, match=r"it would take about 2 h 00 min \(as the last one did\) and the time "
                                            r"limit leaves (9|10) min"):
            worker.claim()
    assert len(study.get_trials(deepcopy=False)) == 2


def test_studies_evolved_together_give_back_the_round_they_claimed(tmp_path):
    """The first study (new: no time to judge by) claims its generation; the second's would not end in time: the
    first's trials are failed "interrupted", and its rerun asks their Φ again."""
    slow = EvolveConfig(train=TrainConfig(env_id="PendulumNoVel-v1", total_timesteps=3 * 2048),
                        space=SearchSpace(fixed_iss=1.0), trials=6, seeds=2, popsize=2)
    old, span = _one_generation(tmp_path / "old.log", "old", slow)
    new = _study(tmp_path / "new.log", "new")
    stop_at = time.time() + span / 2
    with pytest.raises(OutOfTime, match="^stopped before generation 1 of study 'old'"):
        evolve_together([Member(new, CONFIG, WorkerConfig(stop_at=stop_at)),
                         Member(old, slow, WorkerConfig(stop_at=stop_at))])
    assert _states(new) == [(TrialState.FAIL, "interrupted")] * 2
    given_back = [t.params for t in new.get_trials(deepcopy=False)]
    evolve(new, _trials(CONFIG, 2))
    redone = new.get_trials(deepcopy=False)[2:]
    assert [t.user_attrs[REDO_ATTR]["trial"] for t in redone] == [0, 1]
    assert [t.params for t in redone] == given_back and [t.state for t in redone] == [TrialState.COMPLETE] * 2


def test_the_command_stops_with_one_line_and_exit_status_75_and_resumes(tmp_path):
    storage = str(tmp_path / "studies.log")
    _one_generation(storage, pause_s=3.0)  # 3 s or more, against a limit of 1 s
    stopped = ermrl("evolve", *FLAGS, "--trials", "4", "--storage", storage, "--study", "s", "--stop-after", "1s")
    assert stopped.returncode == OUT_OF_TIME == 75, stopped.stderr
    last = stopped.stdout.strip().splitlines()[-1]
    assert re.fullmatch(r"ermrl evolve: stopped before generation 1 of study 's' \(2 of 4 trials done\): it would "
                        r"take about \d+ s \(as the last one did\) and the time limit leaves [01] s; rerun the same "
                        r"command to continue", last), last
    assert stopped.stderr == ""
    resumed = ermrl("evolve", *FLAGS, "--trials", "4", "--storage", storage, "--study", "s", "--stop-after", "2h")
    assert resumed.returncode == 0, resumed.stderr
    assert "best fitness" in resumed.stdout


def test_an_experiment_starts_no_test_phase_once_the_limit_has_passed(evolved, tmp_path):
    folder = tmp_path / "run"
    shutil.copytree(evolved, folder)
    shutil.rmtree(folder / STUDY / "test")
    with pytest.raises(OutOfTime, match=f"^stopped before the test phase of study '{EXPERIMENT}-smoke-{STUDY}' on "
                                        "CartPoleNoVel-v1: the time limit has passed; rerun the same command to "
                                        "continue$"):
        runner.run_experiment(registry.get(EXPERIMENT), registry.get_scale("smoke"), folder, only=(STUDY,),
                              log=lambda s: None, budget=BUDGET, stop_at=time.time() - 1)
    assert not (folder / STUDY / "test").exists() and not (folder / STUDY / "test.partial").exists()


def test_reproduce_hands_the_time_left_to_its_commands(tmp_path):
    storage = str(tmp_path / "studies.log")
    _one_generation(storage, pause_s=3.0)
    step = Step("timed", (), "an evolution under a time limit",
                (Run("ermrl", ("evolve", *FLAGS, "--trials", "4", "--storage", storage, "--study", "s")),))
    # a real `python -m ermrl.cli` process, given --stop-after 1s (the whole seconds left): it starts, then stops
    # before its second generation (which would take 3 s or more, as the first did) with exit status 75
    with pytest.raises(OutOfTime, match=r"^step timed: `ermrl evolve .*` stopped before the time limit with work "
                                        r"left; rerun the same command to continue$"):
        run_step(step, tmp_path, write=lambda s: None, stop_at=time.time() + 1.5)
    with pytest.raises(OutOfTime, match=r"^stopped before step timed's `ermrl evolve .*`: the time limit has passed"):
        run_step(step, tmp_path, write=lambda s: None, stop_at=time.time() - 1)
    study = optuna.load_study(study_name="s", storage=optuna.storages.JournalStorage(
        optuna.storages.journal.JournalFileBackend(storage)))
    assert [t.state for t in study.get_trials(deepcopy=False)] == [TrialState.COMPLETE] * 2
