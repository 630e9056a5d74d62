"""The outer loop: CMA-ES over Φ, one generation at a time (paper §3, "Outer loop").

Each generation asks the sampler for popsize trials, trains all of them × seeds as ONE population through
the engine, then tells each trial its fitness (the mean over its seeds). A trial whose training diverged
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

from ermrl.results import Results
from ermrl.search_space import SearchSpace
from ermrl.runs import config_dict
from ermrl.train import Population, Progress, TrainConfig, Trainer

MAX_FAILED_GENERATIONS = 3
"""Stop when this many generations in a row have no completed trial (something is wrong with the setup)."""


@dataclasses.dataclass(frozen=True)
class EvolveConfig:
    """An evolution: what each candidate's training is, and how many candidates to try."""

    train: TrainConfig
    space: SearchSpace
    trials: int = 900
    """Completed trials to reach (the paper: 900)."""
    seeds: int = 3
    """Seeds per candidate Φ; its fitness is the mean over them (the paper: 3)."""
    sampler: str = "cmaes"
    popsize: int | None = None
    """Trials per generation; None takes CMA-ES's default 4 + ⌊3 ln n⌋."""
    sampler_seed: int | None = 0

    @property
    def generation_size(self) -> int:
        return self.popsize or self.space.default_popsize()

    def record(self) -> dict:
        """What the study stores (user attribute ``ermrl``) to resume, test and report."""
        return {
            "env_id": self.train.env_id, "reservoirs": self.space.reservoirs, "seeds": self.seeds,
            "timesteps": self.train.total_timesteps, "sampler": self.sampler, "popsize": self.generation_size,
            "learning_rate": self.train.ppo.learning_rate, "search_space": self.space.to_dict(),
            "train": config_dict(self.train), "trials": self.trials,
        }


@dataclasses.dataclass(frozen=True)
class GenerationProgress:
    """Passed to ``progress_fn`` during a generation's training and after it is told."""

    generation: int
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


def tell_generation(study, trials, results: Results, seeds: int, generation: int) -> int:
    """Tells each trial its fitness, recording per-seed fitness and a curve summary. Returns completed count."""
    fitness = results.fitness().reshape(len(trials), seeds)
    _, curves = results.curves()
    curves = curves.reshape(len(trials), seeds, -1)
    finite = results.finite.reshape(len(trials), seeds)
    done = 0
    for i, trial in enumerate(trials):
        phi = {k: v.reshape(len(trials), seeds, -1)[i, 0].tolist() for k, v in results.phi.items()}
        trial.set_user_attr("generation", generation)
        trial.set_user_attr("phi", phi)
        trial.set_user_attr("seed_fitness", [None if np.isnan(f) else float(f) for f in fitness[i]])
        with np.errstate(all="ignore"):
            final = curves[i, :, -1]
        trial.set_user_attr("curve_final", [None if np.isnan(f) else float(f) for f in final])
        if not finite[i].all():
            trial.set_user_attr("failure", f"diverged (NaN/inf) on {int((~finite[i]).sum())} of {seeds} seeds")
            study.tell(trial, state=TrialState.FAIL)
        elif np.isnan(fitness[i]).any():
            trial.set_user_attr("failure", "no episode completed within the budget")
            study.tell(trial, state=TrialState.FAIL)
        else:
            study.tell(trial, float(fitness[i].mean()))
            done += 1
    return done


def estimate_seconds(trainer: Trainer, config: EvolveConfig, remaining: int) -> float:
    """Measures one iteration of a full generation (compiling first) and scales it to the remaining trials."""
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
    generations = -(-remaining // size)
    return generations * trainer.n_iterations * per_iteration


def evolve(study: optuna.Study, config: EvolveConfig, trainer: Trainer | None = None,
           progress_fn: Callable[[GenerationProgress], None] | None = None) -> optuna.Study:
    """Runs generations until the study holds ``config.trials`` completed trials."""
    trainer = trainer or Trainer(config.train)
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

        def report(p: Progress, generation=generation, completed=completed):
            if progress_fn is not None:
                progress_fn(GenerationProgress(generation, completed, config.trials, *_best(study), p))

        results = trainer.run(population, report)
        done = tell_generation(study, trials, results, config.seeds, generation)
        failed_in_a_row = 0 if done else failed_in_a_row + 1
        if failed_in_a_row >= MAX_FAILED_GENERATIONS:
            raise RuntimeError(f"{MAX_FAILED_GENERATIONS} generations in a row had no completed trial; "
                               "see the trials' 'failure' attributes")
        if progress_fn is not None:
            progress_fn(GenerationProgress(generation, count(study, TrialState.COMPLETE), config.trials,
                                           *_best(study), None))
    return study
