"""The outer loop: CMA-ES over Φ, one generation at a time (paper §3, "Outer loop").

Each generation asks the sampler for popsize trials, trains all of them × seeds as ONE population through
the engine (one population per env when the fitness spans several envs), then tells each trial its fitness
(see :mod:`ermrl.evolution.scoring`). A trial whose training diverged
(NaN/inf) or finished no episode is told as failed, with the reason in its user attributes.

Resuming: completed trials count toward ``trials``; trials left RUNNING by an interrupted process (a
generation cut off mid-way) are marked failed with reason "interrupted", and their generation is redone.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Callable

import numpy as np
import optuna
from optuna.trial import TrialState

from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.scoring import score
from ermrl.training import Population, Progress, Results, Trainer

MAX_FAILED_GENERATIONS = 3
"""Stop when this many generations in a row have no completed trial (something is wrong with the setup)."""


@dataclasses.dataclass(frozen=True)
class GenerationProgress:
    """Passed to ``progress_fn`` during a generation's training and after it is told."""

    generation: int
    env_id: str
    """The env whose population is training (the evolution's first env between generations)."""
    completed: int
    """Completed trials in the study."""
    trials: int
    best_value: float | None
    best_params: dict | None
    train: Progress | None
    """The engine's progress inside the generation (None between generations)."""


def count(study: optuna.Study, state: TrialState) -> int:
    return len(study.get_trials(deepcopy=False, states=(state,)))


def fail_interrupted(study: optuna.Study) -> int:
    """Marks trials left RUNNING by a killed process as failed. Returns how many."""
    stale = study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
    for t in stale:
        study._storage.set_trial_user_attr(t._trial_id, "failure", "interrupted")
        study._storage.set_trial_state_values(t._trial_id, TrialState.FAIL)
    return len(stale)


def next_generation(study: optuna.Study) -> int:
    gens = [t.user_attrs.get("generation", -1) for t in study.get_trials(deepcopy=False)]
    return max(gens, default=-1) + 1


def _best(study: optuna.Study):
    try:
        return study.best_value, study.best_params
    except ValueError:
        return None, None


def _floats(values) -> list[float | None]:
    return [None if not np.isfinite(v) else float(v) for v in np.ravel(values)]


def tell_generation(study, trials, results: dict[str, Results], config: EvolveConfig, generation: int) -> int:
    """Tells each trial its fitness (see :mod:`ermrl.evolution.scoring`) and records, per trial: its Φ, the
    per-seed fitness, the final curve values and, with several envs, every env's raw score and nScore.
    Returns how many trials completed."""
    n, seeds = len(trials), config.seeds
    env_fitness = {e: r.fitness().reshape(n, seeds) for e, r in results.items()}
    scores = score(config, env_fitness)
    first = results[config.env_ids[0]]
    finite = np.all([r.finite.reshape(n, seeds) for r in results.values()], axis=0)
    finals = {}
    for e, r in results.items():
        with np.errstate(all="ignore"):
            finals[e] = r.curves()[1].reshape(n, seeds, -1)[:, :, -1]
    done = 0
    for i, trial in enumerate(trials):
        trial.set_user_attr("generation", generation)
        trial.set_user_attr("phi", {k: v.reshape(n, seeds, -1)[i, 0].tolist() for k, v in first.phi.items()})
        trial.set_user_attr("seed_fitness", _floats(scores.per_seed[i]))
        trial.set_user_attr("curve_final", _floats(finals[config.env_ids[0]][i]))
        if config.normalized:
            trial.set_user_attr("env_scores", {e: _floats(np.mean(f[i]))[0] for e, f in env_fitness.items()})
            trial.set_user_attr("env_nscores", {e: _floats(v[i])[0] for e, v in scores.env_nscore.items()})
            trial.set_user_attr("env_seed_fitness", {e: _floats(f[i]) for e, f in env_fitness.items()})
        if not finite[i].all():
            trial.set_user_attr("failure", f"diverged (NaN/inf) on {int((~finite[i]).sum())} of {seeds} seeds")
            study.tell(trial, state=TrialState.FAIL)
        elif np.isnan(scores.per_seed[i]).any():
            trial.set_user_attr("failure", "no episode completed within the budget")
            study.tell(trial, state=TrialState.FAIL)
        else:
            study.tell(trial, float(scores.value[i]))
            done += 1
    return done


def generation_seconds(trainer: Trainer, config: EvolveConfig) -> float:
    """Seconds one generation takes on ``trainer``'s env: one measured iteration (after compiling), scaled."""
    size = config.generation_size
    phis = [config.space.phi_from_params({n: d.low for n, d in config.space.distributions().items()})] * size
    population = Population.grid(phis, config.seeds, config.train.ppo.learning_rate, config.space.reservoirs)
    state = trainer.init(population)
    compiled = trainer.compiled(state)
    start = time.perf_counter()
    _, log = compiled(state)
    np.asarray(log.finite)
    per_iteration = time.perf_counter() - start
    trainer.close()
    return trainer.n_iterations * per_iteration


def estimate_seconds(trainers: dict[str, Trainer], config: EvolveConfig, remaining: int) -> float:
    """The remaining trials' time: every env's generation measured once, times the generations left."""
    generations = -(-remaining // config.generation_size)
    return generations * sum(generation_seconds(t, config) for t in trainers.values())


def make_trainers(config: EvolveConfig) -> dict[str, Trainer]:
    """One trainer (one compile per population size) for each env of the evolution."""
    return {e: Trainer(config.train_for(e)) for e in config.env_ids}


def evolve(study: optuna.Study, config: EvolveConfig, trainers: dict[str, Trainer] | None = None,
           progress_fn: Callable[[GenerationProgress], None] | None = None) -> optuna.Study:
    """Runs generations until the study holds ``config.trials`` completed trials. Within a generation, every
    env's population (the generation's Φ × seeds) trains before the trials are told."""
    trainers = trainers or make_trainers(config)
    fail_interrupted(study)
    failed_in_a_row = 0
    while (completed := count(study, TrialState.COMPLETE)) < config.trials:
        n = min(config.generation_size, config.trials - completed)
        generation = next_generation(study)
        trials = [study.ask() for _ in range(n)]
        for t in trials:
            t.set_user_attr("generation", generation)
        phis = [config.space.suggest(t) for t in trials]
        population = Population.grid(phis, config.seeds, config.train.ppo.learning_rate, config.space.reservoirs)

        results = {}
        for env_id, trainer in trainers.items():
            def report(p: Progress, generation=generation, completed=completed, env_id=env_id):
                if progress_fn is not None:
                    progress_fn(GenerationProgress(generation, env_id, completed, config.trials, *_best(study), p))

            results[env_id] = trainer.run(population, report)
        done = tell_generation(study, trials, results, config, generation)
        failed_in_a_row = 0 if done else failed_in_a_row + 1
        if failed_in_a_row >= MAX_FAILED_GENERATIONS:
            raise RuntimeError(f"{MAX_FAILED_GENERATIONS} generations in a row had no completed trial; "
                               "see the trials' 'failure' attributes")
        if progress_fn is not None:
            progress_fn(GenerationProgress(generation, config.env_ids[0], count(study, TrialState.COMPLETE), config.trials,
                                           *_best(study), None))
    return study
