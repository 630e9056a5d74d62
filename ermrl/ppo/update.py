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


_PACKED_INDEX_BITS = 16
"""Above 2**16 rows the packed keys keep too few random bits; :func:`permutation` then uses JAX's own."""


def permutation(key: jax.Array, n: int) -> jax.Array:
    """A random ordering of range(n), (n,) int32, for shuffling the rollout buffer into minibatches.

    ``jax.random.permutation`` sorts (random key, index) pairs, which XLA:CPU does about 7× slower than a sort
    of one uint32 array; at SB3's settings that sort was 12% of the PPO update. Here each uint32 holds random
    high bits and the index in its low ``b = ceil(log2 n)`` bits, so one plain sort orders the indices by
    random keys. Equal random bits (about one pair per 2048 rows) would leave that pair in index order, so a
    second such sort, whose ties fall back on positions in the first ordering, shuffles the first:
    ``order = first[second]``. A pair is then biased only if it ties in both sorts (probability ~2**-42 at
    2048 rows), and a tied pair is adjacent, so it nearly always lands in the same minibatch anyway.
    """
    bits = max(1, (n - 1).bit_length())
    if bits > _PACKED_INDEX_BITS:
        return jax.random.permutation(key, n).astype(jnp.int32)
    mask = jnp.uint32((1 << bits) - 1)
    index = jnp.arange(n, dtype=jnp.uint32)

    def by_random_keys(k):
        return jax.lax.sort((jax.random.bits(k, (n,), jnp.uint32) & ~mask) | index) & mask

    first, second = (by_random_keys(k) for k in jax.random.split(key))
    return first[second].astype(jnp.int32)


def update(learner: LearnerState, batch: Batch, key: jax.Array, net: ActorCritic, config: PPOConfig,
           orders: jax.Array | None = None):
    """Runs the epochs over ``batch`` (rows (B, ...)). Returns (learner, metrics averaged over minibatches).

    Each epoch visits the rows in a fresh :func:`permutation` drawn from ``key``, split into minibatches of
    ``batch_size``. ``orders`` (n_epochs, B) int32 gives those orders instead (to replay another library's
    shuffles, as the SB3 parity test does)."""
    optimizer = make_optimizer(config)
    grad_fn = jax.value_and_grad(ppo_loss, has_aux=True)

    def minibatch_step(learner: LearnerState, rows: jax.Array):
        mb = jax.tree.map(lambda x: x[rows], batch)
        (_, metrics), grads = grad_fn(learner.params, net, mb, config)
        updates, opt_state = optimizer.update(grads, learner.opt_state, learner.params)
        params = jax.tree.map(lambda p, u: p - learner.learning_rate * u, learner.params, updates)
        metrics["grad_norm"] = optax.tree.norm(grads)
        return LearnerState(params, opt_state, learner.learning_rate), metrics

    def epoch(learner: LearnerState, order: jax.Array):
        return jax.lax.scan(minibatch_step, learner, order.reshape(config.n_minibatches, config.batch_size))

    if orders is None:
        orders = jax.vmap(lambda k: permutation(k, config.buffer_size))(jax.random.split(key, config.n_epochs))
    learner, metrics = jax.lax.scan(epoch, learner, jnp.asarray(orders, jnp.int32))
    return learner, jax.tree.map(jnp.mean, metrics)
