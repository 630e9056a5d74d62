"""Robust selection of Φ* (beyond the paper).

The best trial of a study is the best of many noisy few-seed estimates, so its fitness overstates what its Φ
gives on new seeds (the winner's curse). ``select`` re-evaluates the top K trials on S fresh seeds, with the
evolution's fitness, and records every re-evaluation and the winner in the study (user attribute
``selection``). The test phase then uses the winner, and says so.
"""

from __future__ import annotations

import dataclasses
import datetime
from typing import Callable

import numpy as np
import optuna
from optuna.trial import FrozenTrial, TrialState

from ermrl import provenance
from ermrl.agent import Phi
from ermrl.errors import ConfigError
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.scoring import score
from ermrl.training import Population, Trainer

ATTR = "selection"
"""The study user attribute holding the last selection."""
FIRST_SELECTION_SEED = 2000
"""Selection seeds start here: new to the evolution (0, 1, ...) and to the test phase (1000, ...)."""


@dataclasses.dataclass(frozen=True)
class Selection:
    """A re-evaluation of a study's top trials on fresh seeds."""

    trials: tuple[int, ...]
    """Trial numbers re-evaluated, best evolution fitness first."""
    seeds: tuple[int, ...]
    evolution_values: tuple[float, ...]
    """Each trial's fitness in the evolution."""
    values: tuple[float | None, ...]
    """Each trial's fitness on the fresh seeds (None: diverged on some seed)."""
    per_seed: tuple[tuple[float | None, ...], ...]
    winner: int
    """Trial number with the best re-evaluated fitness."""
    date: str
    software: dict | None = None
    """The versions the re-evaluations ran with (:mod:`ermrl.provenance`); None in selections made before."""


def ranked_trials(study: optuna.Study) -> list[FrozenTrial]:
    """Completed trials, best fitness first."""
    done = [t for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
            if t.value is not None and np.isfinite(t.value)]
    return sorted(done, key=lambda t: t.value, reverse=True)


def ties_at_cut(trials: list[FrozenTrial], top: int) -> int:
    """How many of ``trials`` (ranked, best first) past the first ``top`` have the same fitness as the ``top``-th:
    trials a re-evaluation of the top ``top`` leaves out only because their trial number is larger (a ceiling, such
    as CartPole's 500, makes many)."""
    if len(trials) <= top:
        return 0
    return sum(1 for t in trials[top:] if t.value == trials[top - 1].value)


def load_selection(study: optuna.Study) -> Selection | None:
    data = study.user_attrs.get(ATTR)
    if not data:
        return None
    return Selection(**{k: tuple(tuple(v) if isinstance(v, list) else v for v in data[k])
                        if isinstance(data[k], list) else data[k] for k in data})


def recorded_selection(study: optuna.Study, top: int, seeds: int) -> Selection | None:
    """The study's recorded selection when it re-evaluated exactly what ``select(study, ..., top, seeds)`` would
    (the same top trials, as many seeds), else None: the evolution went on since, or other settings."""
    sel = load_selection(study)
    if sel is None or len(sel.seeds) != seeds or sel.trials != tuple(t.number for t in ranked_trials(study)[:top]):
        return None
    return sel


def chosen_trial(study: optuna.Study, config: EvolveConfig, number: int | None = None) -> tuple[FrozenTrial, Phi, str]:
    """(trial, Φ, how it was chosen) of the Φ* to test: trial ``number`` when given, else the selected one,
    else the best trial."""
    trials = ranked_trials(study)
    if not trials:
        raise ConfigError(f"study {study.study_name!r} has no completed trial yet; run `ermrl evolve` first")
    selection = load_selection(study)
    if number is not None:
        by_number = {t.number: t for t in trials}
        if number not in by_number:
            raise ConfigError(f"trial {number} of study {study.study_name!r} is not a completed trial; "
                              f"completed trials include {', '.join(str(t.number) for t in trials[:5])}")
        trial, how = by_number[number], f"trial {number}, as asked"
    elif selection is not None:
        trial = next(t for t in trials if t.number == selection.winner)
        how = (f"trial {trial.number}, selected by `ermrl select` (top {len(selection.trials)} re-evaluated "
               f"on {len(selection.seeds)} new seeds)")
    else:
        trial, how = trials[0], f"trial {trials[0].number}, the best of the evolution (no `ermrl select` yet)"
    return trial, config.space.phi_from_params(trial.params), how


def select(study: optuna.Study, config: EvolveConfig, top: int, seeds: int,
           progress_fn: Callable[[str], Callable] | None = None) -> Selection:
    """Re-evaluates the ``top`` best trials on ``seeds`` fresh seeds (every env of the evolution, its budget
    and fitness) as one population per env; records and returns the selection."""
    if top < 1 or seeds < 1:
        raise ConfigError(f"`top` and `seeds` must be >= 1, got {top} and {seeds}", owner=select)
    trials = ranked_trials(study)[:top]
    if not trials:
        raise ConfigError(f"study {study.study_name!r} has no completed trial yet; run `ermrl evolve` first")
    seed_list = list(range(FIRST_SELECTION_SEED, FIRST_SELECTION_SEED + seeds))
    phis = [config.space.phi_from_params(t.params) for t in trials]
    population = Population.grid(phis, seed_list, config.train.ppo.learning_rate, config.space.reservoirs)
    fitness = {}
    for env_id in config.env_ids:
        fn = progress_fn(f"select on {env_id}") if progress_fn else None
        results = Trainer(config.train_for(env_id)).run(population, fn)
        fit = results.fitness().reshape(len(trials), seeds)
        fit[~results.finite.reshape(len(trials), seeds)] = np.nan
        fitness[env_id] = fit
    scores = dataclasses.replace(config, seeds=seeds)
    s = score(scores, fitness)
    values = [None if not np.isfinite(v) else float(v) for v in s.value]
    finite = [v if v is not None else -np.inf for v in values]
    selection = Selection(
        trials=tuple(t.number for t in trials), seeds=tuple(seed_list),
        evolution_values=tuple(float(t.value) for t in trials), values=tuple(values),
        per_seed=tuple(tuple(None if not np.isfinite(v) else float(v) for v in row) for row in s.per_seed),
        winner=trials[int(np.argmax(finite))].number, date=datetime.datetime.now().isoformat(timespec="seconds"),
        software=provenance.software())
    study.set_user_attr(ATTR, dataclasses.asdict(selection))
    return selection
