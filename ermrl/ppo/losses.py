"""GAE and the clipped PPO loss, as stable-baselines3 computes them."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ermrl.ppo.config import PPOConfig
from ermrl.ppo.networks import ActorCritic, PolicyParams


class Batch(NamedTuple):
    """Rollout data flattened to (B,) rows, B = n_steps × n_envs."""

    context: jax.Array
    """(B, context_dim) what the policy saw."""
    action: jax.Array
    """(B,) int32 or (B, action_dim) unclipped float32 actions."""
    log_prob: jax.Array
    """(B,) log π_old(action)."""
    advantage: jax.Array
    """(B,)"""
    ret: jax.Array
    """(B,) advantage + value (the value target)."""


def gae(reward, value, done, last_value, gamma: float, lam: float):
    """Generalized advantage estimation over a rollout.

    reward, value, done: (T, n_envs); done[t] is True when step t ended an episode (the reward already holds
    the time-limit bootstrap). last_value: (n_envs,) V of the observation after the rollout.
    Returns (advantage, return), each (T, n_envs).
    """

    def body(carry, xs):
        next_adv, next_value = carry
        r, v, d = xs
        nonterminal = 1.0 - d.astype(r.dtype)
        delta = r + gamma * next_value * nonterminal - v
        adv = delta + gamma * lam * nonterminal * next_adv
        return (adv, v), adv

    _, adv = jax.lax.scan(body, (jnp.zeros_like(last_value), last_value), (reward, value, done), reverse=True)
    return adv, adv + value


def bootstrapped_gae(reward, value, done, truncated, final_value, last_value, gamma: float, lam: float):
    """Advantages and returns of a rollout as SB3 computes them, time limits included.

    On a time-limit truncation SB3's ``collect_rollouts`` adds γ·V(final observation) to the step's reward
    (the episode did not really end); then :func:`gae` treats every episode end alike. reward, value, done,
    truncated, final_value: (T, n_envs), final_value being V of the context built from the step's final
    observation. last_value: (n_envs,). Returns (advantage, return), each (T, n_envs)."""
    return gae(reward + gamma * final_value * truncated, value, done, last_value, gamma, lam)


def ppo_loss(params: PolicyParams, net: ActorCritic, batch: Batch, config: PPOConfig):
    """Clipped surrogate + vf_coef·MSE − ent_coef·entropy on one minibatch. Returns (loss, metrics)."""
    head, latent = net.policy(params, batch.context)
    log_prob = net.log_prob(params, head, batch.action, latent)
    entropy = net.entropy(params, head, latent)
    value = net.value(params, batch.context)

    adv = batch.advantage
    if config.normalize_advantage and adv.shape[0] > 1:
        adv = (adv - adv.mean()) / (jnp.std(adv, ddof=1) + 1e-8)
    ratio = jnp.exp(log_prob - batch.log_prob)
    clipped = jnp.clip(ratio, 1.0 - config.clip_range, 1.0 + config.clip_range)
    policy_loss = -jnp.mean(jnp.minimum(adv * ratio, adv * clipped))
    value_loss = jnp.mean((batch.ret - value) ** 2)
    entropy_loss = -jnp.mean(entropy)
    loss = policy_loss + config.ent_coef * entropy_loss + config.vf_coef * value_loss
    metrics = {
        "policy_loss": policy_loss,
        "value_loss": value_loss,
        "entropy": -entropy_loss,
        "approx_kl": jnp.mean((ratio - 1.0) - (log_prob - batch.log_prob)),
        "clip_fraction": jnp.mean((jnp.abs(ratio - 1.0) > config.clip_range).astype(jnp.float32)),
    }
    return loss, metrics
