"""A generation stopped while it trains, then rerun: its trials' Φ are asked again, and with snapshots
(``WorkerConfig.snapshots``) their training continues where it stopped, to the fitness an unbroken run gets."""

import optuna
import pytest
from optuna.trial import TrialState

from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.evolve import evolve
from ermrl.evolution.record import encode_study_record
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import make_sampler, open_study
from ermrl.evolution.worker_config import WorkerConfig
from ermrl.evolution.workers import REDO_ATTR
from ermrl.training import TrainConfig

optuna.logging.set_verbosity(optuna.logging.WARNING)

# 3 iterations of 2048 steps: a snapshot after the first, the stop at the second; generations of 2 Φ × 2 seeds
CONFIG = EvolveConfig(train=TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=3 * 2048),
                      space=SearchSpace(fixed_iss=1.0), trials=6, seeds=2, popsize=2)


def _study(path, name):
    return open_study(f"journal:{path}", name, make_sampler("cmaes", 2, 0), encode_study_record(CONFIG))


def _stop_in_generation_1(g):
    if g.train is not None and g.generation == 1 and g.train.iteration == 2:
        raise KeyboardInterrupt


def test_a_stopped_generation_trains_its_own_candidates_again_and_continues_from_its_snapshot(tmp_path):
    unbroken = _study(tmp_path / "a.log", "a")
    evolve(unbroken, CONFIG)
    expected = {t.number: (t.params, t.value) for t in unbroken.trials}

    folder = tmp_path / "snapshots"
    worker = WorkerConfig(snapshots=folder, snapshot_every_s=1e-6)  # one after every iteration
    stopped = _study(tmp_path / "b.log", "b")
    with pytest.raises(KeyboardInterrupt):
        evolve(stopped, CONFIG, progress_fn=_stop_in_generation_1, worker=worker)
    trials = stopped.trials
    assert [(t.number, t.state, t.user_attrs.get("failure")) for t in trials] == \
        [(0, TrialState.COMPLETE, None), (1, TrialState.COMPLETE, None),
         (2, TrialState.FAIL, "interrupted"), (3, TrialState.FAIL, "interrupted")]
    assert [t.params for t in trials[2:]] == [expected[2][0], expected[3][0]]  # the same draws so far
    assert len(list((folder / "b").glob("CartPoleNoVel-v1.*.snapshot"))) == 1

    lines = []
    evolve(_study(tmp_path / "b.log", "b"), CONFIG, worker=worker, log=lines.append)
    trials = stopped.trials
    redone = trials[4:6]
    assert [t.user_attrs[REDO_ATTR] for t in redone] == [{"trial": 2, "generation": 1}, {"trial": 3, "generation": 1}]
    assert [t.user_attrs["generation"] for t in redone] == [1, 1]
    assert [t.system_attrs["cma:generation"] for t in redone] == [0, 0]  # told to CMA-ES with its generation
    assert [(t.params, t.value) for t in redone] == [expected[2], expected[3]]  # bit for bit the unbroken run's
    assert "trial 2's Φ asked again" in lines and "trial 3's Φ asked again" in lines
    assert any(line.startswith(f"resumed from {folder / 'b'}") and "at iteration 1 of 3" in line for line in lines), lines
    assert [t.state for t in trials[6:]] == [TrialState.COMPLETE] * 2 and len(trials) == 8
    assert [t.user_attrs["generation"] for t in trials[6:]] == [2, 2]
    assert not (folder / "b").exists()  # its snapshots removed once told, the study's folder once it is done


def test_without_snapshots_the_stopped_generation_still_trains_its_own_candidates(tmp_path):
    stopped = _study(tmp_path / "b.log", "b")
    with pytest.raises(KeyboardInterrupt):
        evolve(stopped, CONFIG, progress_fn=_stop_in_generation_1)
    evolve(_study(tmp_path / "b.log", "b"), CONFIG)
    trials = stopped.trials
    assert [t.params for t in trials[4:6]] == [trials[2].params, trials[3].params]
    assert sum(t.state == TrialState.COMPLETE for t in trials) == 6
