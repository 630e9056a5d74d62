"""A trial's fitness from its agents' fitness: the seed mean on one env, the mean nScore over several (paper §4.3)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ermrl.experiments.baselines import nscore


@dataclasses.dataclass(frozen=True)
class TrialScores:
    """Scores of n candidates, each trained on S seeds in every env of the evolution."""

    value: np.ndarray
    """(n,) the objective: the seed-mean fitness (one env) or the mean over envs of its nScore (several)."""
    per_seed: np.ndarray
    """(n, S) the objective per seed (fitness, or that seed's nScore averaged over the envs)."""
    env_fitness: dict[str, np.ndarray]
    """env id -> (n, S) raw fitness (mean return of the last 10 training episodes)."""
    env_nscore: dict[str, np.ndarray]
    """env id -> (n,) nScore of the seed-mean fitness; empty with one env."""


def score(config, env_fitness: dict[str, np.ndarray]) -> TrialScores:
    """``config`` is an EvolveConfig; ``env_fitness`` maps each of its envs to (n, S) fitness (NaN: diverged)."""
    if not config.normalized:
        (fit,) = env_fitness.values()
        return TrialScores(fit.mean(axis=1), fit, env_fitness, {})
    baselines = {b.env_id: b for b in config.baselines}
    per_seed = np.mean([nscore(env_fitness[e], baselines[e], config.normalization) for e in config.env_ids], axis=0)
    env_nscore = {e: nscore(env_fitness[e].mean(axis=1), baselines[e], config.normalization) for e in config.env_ids}
    return TrialScores(per_seed.mean(axis=1), per_seed, env_fitness, env_nscore)
