"""How workers share CMA-ES generations (the race rule of ``generations.Ledger``) and draw different candidates
(``worker_config.worker_seed``): unit tests on plain Optuna studies."""

import warnings

import optuna
from optuna.trial import TrialState

from ermrl.evolution.generations import Ledger
from ermrl.evolution.study import make_sampler
from ermrl.evolution.worker_config import worker_seed


def test_a_trial_fits_while_its_generation_has_room():
    """The race rule: a trial fits when fewer than popsize trials of its generation with smaller numbers are
    running or complete; undecided while a smaller trial's generation is unknown (it is being asked)."""
    study = optuna.create_study(direction="maximize")
    dist = {"x": optuna.distributions.FloatDistribution(0, 1)}

    def add(state, tag=None, label=None):
        study.add_trial(optuna.trial.create_trial(
            state=state, params={"x": 0.5}, distributions=dist, value=1.0 if state == TrialState.COMPLETE else None,
            system_attrs={} if tag is None else {"cma:generation": tag},
            user_attrs={} if label is None else {"generation": label}))
        return study.get_trials(deepcopy=False)[-1]

    ledger = Ledger(popsize=2, cma=True)
    for _ in range(2):
        add(TrialState.COMPLETE, label=0)  # the random startup generation
    add(TrialState.COMPLETE, tag=0)
    add(TrialState.FAIL, tag=0)
    mine = add(TrialState.RUNNING, tag=0)
    assert ledger.place(mine, study.get_trials(deepcopy=False)) == 1  # the failed trial's slot
    late = add(TrialState.RUNNING, tag=0)
    assert ledger.place(late, study.get_trials(deepcopy=False)) == -1  # lost the race for it
    assert ledger.next_slots(study.get_trials(deepcopy=False)).free == 0
    asking = add(TrialState.RUNNING)
    after = add(TrialState.RUNNING, tag=1)
    assert ledger.place(after, study.get_trials(deepcopy=False)) is None  # trial 6 might be of generation 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        study._storage.set_trial_user_attr(asking._trial_id, "generation", 0)
    assert ledger.place(after, study.get_trials(deepcopy=False)) == 2


def test_worker_seeds():
    assert worker_seed(7, 0) == 7 and worker_seed(None, 3) is None  # a lone worker draws as before
    seeds = [worker_seed(7, i) for i in range(8)]
    assert len(set(seeds)) == 8
    a, b = (make_sampler("random", 4, s) for s in seeds[:2])
    study = optuna.create_study()
    dist = optuna.distributions.FloatDistribution(0, 1)
    t = study.ask()
    assert a.sample_independent(study, t._cached_frozen_trial, "x", dist) != \
        b.sample_independent(study, t._cached_frozen_trial, "x", dist)
