"""The PPO update for one agent: n_epochs passes of shuffled minibatches. Pure; vmap it over agents."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax

from ermrl.ppo.config import PPOConfig
from ermrl.ppo.losses import Batch, ppo_loss
from ermrl.ppo.networks import ActorCritic, PolicyParams


class LearnerState(NamedTuple):
    """What PPO learns and the optimizer's memory, for one agent."""

    params: PolicyParams
    opt_state: optax.OptState
    learning_rate: jax.Array
    """() float32; traced, so agents in one population may differ."""


def make_optimizer(config: PPOConfig) -> optax.GradientTransformation:
    """Global-norm clipping then Adam's scaling. The step size is applied in :func:`update` so it can be traced."""
    return optax.chain(optax.clip_by_global_norm(config.max_grad_norm), optax.scale_by_adam(eps=config.adam_eps))


def init_learner(net: ActorCritic, config: PPOConfig, key: jax.Array, context_dim: int, learning_rate) -> LearnerState:
    params = net.init(key, context_dim)
    return LearnerState(params, make_optimizer(config).init(params), jnp.asarray(learning_rate, jnp.float32))


def update(learner: LearnerState, batch: Batch, key: jax.Array, net: ActorCritic, config: PPOConfig):
    """Runs the epochs over ``batch`` (rows (B, ...)). Returns (learner, metrics averaged over minibatches)."""
    optimizer = make_optimizer(config)
    grad_fn = jax.value_and_grad(ppo_loss, has_aux=True)

    def minibatch_step(learner: LearnerState, rows: jax.Array):
        mb = jax.tree.map(lambda x: x[rows], batch)
        (_, metrics), grads = grad_fn(learner.params, net, mb, config)
        updates, opt_state = optimizer.update(grads, learner.opt_state, learner.params)
        params = jax.tree.map(lambda p, u: p - learner.learning_rate * u, learner.params, updates)
        metrics["grad_norm"] = optax.tree.norm(grads)
        return LearnerState(params, opt_state, learner.learning_rate), metrics

    def epoch(learner: LearnerState, epoch_key: jax.Array):
        order = jax.random.permutation(epoch_key, config.buffer_size)
        return jax.lax.scan(minibatch_step, learner, order.reshape(config.n_minibatches, config.batch_size))

    learner, metrics = jax.lax.scan(epoch, learner, jax.random.split(key, config.n_epochs))
    return learner, jax.tree.map(jnp.mean, metrics)
