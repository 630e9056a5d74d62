"""Running normalization of what the policy sees and of the reward, as stable-baselines3's ``VecNormalize``
(rl-baselines3-zoo's ``normalize: True``), for one agent's n_envs envs.

With ER-MRL the normalized "observation" is the context c_t, the policy's input: the composition an SB3 user
gets from ``VecNormalize`` over envs wrapped in :class:`ermrl.wrappers.ReservoirObservation`. The reservoir
itself is fed the raw (o_t, a_{t-1}, r_{t-1}), as in the paper. For plain PPO the context is the observation.

SB3's semantics, step by step (``VecNormalize.step_wait``), with the statistics updated before they are used:
- the new contexts (n_envs, D), after any reset, update the context statistics, then are normalized:
  ``clip((c - mean) / sqrt(var + 1e-8), ±10)``; an episode's final context (the time-limit bootstrap's) is
  normalized with the same statistics;
- the running discounted return ``R = γ·R + r`` updates the return statistics, and the reward becomes
  ``clip(r / sqrt(var_R + 1e-8), ±10)``; R is reset to 0 where the episode ended;
- at the start (``reset``), the n_envs first contexts update the statistics, then are normalized.
The statistics are SB3's ``RunningMeanStd`` (Chan et al.'s parallel update; mean 0, var 1 and count 1e-4 at
first), in float32 here (float64 in SB3). Episode returns and fitness stay the raw rewards' (SB3's ``Monitor``
sits below ``VecNormalize``).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

CLIP_OBS = 10.0
"""Bound of a normalized context value (SB3's ``clip_obs``)."""
CLIP_REWARD = 10.0
"""Bound of a normalized reward (SB3's ``clip_reward``)."""
EPSILON = 1e-8
"""Added to the variance before its square root (SB3's ``epsilon``)."""
COUNT_INIT = 1e-4
"""The statistics' initial count (``RunningMeanStd(epsilon=1e-4)``)."""


class RunningMeanStd(NamedTuple):
    """Mean and (population) variance of a stream of arrays of one shape, and how many went in."""

    mean: jax.Array
    """(*shape,)"""
    var: jax.Array
    """(*shape,)"""
    count: jax.Array
    """() float32"""


def rms_init(shape: tuple[int, ...]) -> RunningMeanStd:
    return RunningMeanStd(jnp.zeros(shape, jnp.float32), jnp.ones(shape, jnp.float32), jnp.float32(COUNT_INIT))


def rms_update(rms: RunningMeanStd, batch: jax.Array) -> RunningMeanStd:
    """The statistics after a batch (B, *shape) of new values (SB3's ``update_from_moments``)."""
    batch_mean, batch_var, n = jnp.mean(batch, axis=0), jnp.var(batch, axis=0), batch.shape[0]
    delta = batch_mean - rms.mean
    total = rms.count + n
    m2 = rms.var * rms.count + batch_var * n + jnp.square(delta) * rms.count * n / total
    return RunningMeanStd(rms.mean + delta * n / total, m2 / total, total)


def normalize(rms: RunningMeanStd, x: jax.Array) -> jax.Array:
    """x (..., *shape) standardized by ``rms`` and clipped to ±CLIP_OBS."""
    return jnp.clip((x - rms.mean) / jnp.sqrt(rms.var + EPSILON), -CLIP_OBS, CLIP_OBS)


class Normalizer(NamedTuple):
    """One agent's normalization state (no n_envs axis but ``returns``'s)."""

    context: RunningMeanStd
    """Statistics of the contexts, shape (context_dim,)."""
    ret: RunningMeanStd
    """Statistics of the running discounted returns, shape ()."""
    returns: jax.Array
    """(n_envs,) each env's running discounted return of raw rewards."""


def start(contexts: jax.Array) -> tuple[Normalizer, jax.Array]:
    """The normalizer after the envs' first contexts (n_envs, D), and those contexts normalized."""
    stats = rms_update(rms_init(contexts.shape[1:]), contexts)
    fresh = Normalizer(stats, rms_init(()), jnp.zeros(contexts.shape[:1], jnp.float32))
    return fresh, normalize(stats, contexts)


def step(norm: Normalizer, contexts: jax.Array, final_contexts: jax.Array, reward: jax.Array, done: jax.Array,
         gamma: float) -> tuple[Normalizer, jax.Array, jax.Array, jax.Array]:
    """One env step of n_envs envs: ``contexts`` (n_envs, D) what the policy sees next (the reset context where
    an episode ended), ``final_contexts`` (n_envs, D) each step's context before any reset, ``reward`` and
    ``done`` (n_envs,). Returns (normalizer, contexts, final contexts, rewards), the last three normalized."""
    stats = rms_update(norm.context, contexts)
    returns = norm.returns * gamma + reward
    ret = rms_update(norm.ret, returns)
    reward_n = jnp.clip(reward / jnp.sqrt(ret.var + EPSILON), -CLIP_REWARD, CLIP_REWARD)  # scaled, not centred
    return (Normalizer(stats, ret, jnp.where(done, 0.0, returns)), normalize(stats, contexts),
            normalize(stats, final_contexts), reward_n)
