"""A trial's fitness from its agents' fitness: the seed mean on one env, the mean nScore over several (paper §4.3)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ermrl.errors import ConfigError

NORMALIZATIONS = ("episodic", "reference")
"""'episodic': random = the random agent's mean episode return; 'reference': the reference code's mean per-step
reward of the random agent (mixed with episodic PPO scores, a bug kept behind this switch)."""


@dataclasses.dataclass(frozen=True)
class Baseline:
    """The normalization constants of one env, as an evolution stores them in its study (paper App. "Normalized
    scores"; computed by :mod:`ermrl.experiments.baselines`)."""

    env_id: str
    random_return: float
    """The random agent's mean episode return."""
    random_step_reward: float
    """The random agent's mean per-step reward (what the reference code used)."""
    ppo: float
    """Vanilla PPO's fitness at the evolution's budget, seeds and learning rate."""


def nscore(score, baseline: Baseline, normalization: str = "episodic"):
    """(score − random) / (ppo − random): 0 for the random agent, 1 for vanilla PPO. ``score`` a float or array."""
    if normalization not in NORMALIZATIONS:
        raise ConfigError(f"unknown normalization {normalization!r}; choose one of {', '.join(NORMALIZATIONS)}")
    random = baseline.random_return if normalization == "episodic" else baseline.random_step_reward
    if baseline.ppo == random:
        raise ConfigError(f"{baseline.env_id}: PPO scores the same as the random agent ({random:g}), so no score can "
                          "be normalized; recompute the baselines at a larger budget (ermrl baselines --timesteps ...)")
    return (np.asarray(score, float) - random) / (baseline.ppo - random) if np.ndim(score) else \
        (float(score) - random) / (baseline.ppo - random)


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
