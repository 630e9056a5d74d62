"""The recurrent PPO update for one agent: n_epochs passes over minibatches of whole sequences. Pure; vmap it.

Each epoch cuts the rollout (rows in env-major order, row = env · n_steps + t, as sb3-contrib's buffer flattens
it) into windows of ``lstm_seq_len`` consecutive rows, starting at a random offset as sb3-contrib's buffer
rotates its rows by a random ``split_index``; the window that passes the end wraps to the first rows. A window's
first step, and a step where another env's data begins inside it, start from the LSTM state stored during the
rollout; an episode start zeroes the state inside a window. The windows are shuffled and ``batch_size /
lstm_seq_len`` of them make a minibatch; a window is never cut or reordered inside.

Where this differs from sb3-contrib's RecurrentPPO:
- sb3-contrib's minibatch is ``batch_size`` consecutive rows of the rotated buffer, split into sequences at
  episode starts and env changes and padded to the longest; ours is ``batch_size / lstm_seq_len`` windows of
  fixed length with the resets applied inside them by masks. Resetting by mask gives the same LSTM outputs as
  splitting, and without padding every row counts in the losses and the advantage normalization, as only the
  unpadded rows count in sb3-contrib's. At batch_size = lstm_seq_len (64, our default) a minibatch holds
  exactly the rows of one sb3-contrib minibatch for the same rotation.
- sb3-contrib visits its minibatches in buffer order within an epoch; ours visits the windows in a random order.
- the state stored before a sequence is the rollout's (old parameters), and no gradient flows into it: as in
  sb3-contrib (truncated backpropagation through time).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax

from ermrl.ppo.config import PPOConfig
from ermrl.ppo.losses import Batch, ppo_loss
from ermrl.ppo.recurrent import RecurrentActorCritic, RecurrentState, Sequences
from ermrl.ppo.update import LearnerState, make_optimizer, permutation


class SequenceBatch(NamedTuple):
    """A rollout in env-major rows (B = n_envs · n_steps, row = env · n_steps + t)."""

    obs: jax.Array
    """(B, obs_dim)"""
    action: jax.Array
    """(B,) int32 or (B, action_dim) unclipped float32."""
    log_prob: jax.Array
    """(B,) log π_old(action)."""
    advantage: jax.Array
    """(B,)"""
    ret: jax.Array
    """(B,)"""
    episode_start: jax.Array
    """(B,) bool: the step started an episode."""
    state: RecurrentState
    """(B, H) leaves: the LSTM states before each step (before the episode-start reset)."""


def windows(key: jax.Array, config: PPOConfig) -> jax.Array:
    """One epoch's windows, (n_windows, lstm_seq_len) int32 row indices: consecutive rows from a random offset
    (wrapping at the end), in a random order."""
    n, t = config.buffer_size, config.lstm_seq_len
    k_offset, k_order = jax.random.split(key)
    offset = jax.random.randint(k_offset, (), 0, t)
    starts = offset + t * jnp.arange(n // t, dtype=jnp.int32)
    rows = (starts[:, None] + jnp.arange(t, dtype=jnp.int32)) % n
    return rows[permutation(k_order, n // t)]


def sequences(batch: SequenceBatch, rows: jax.Array, n_steps: int) -> Batch:
    """The minibatch of windows ``rows`` (N, T): a :class:`Batch` whose ``context`` is :class:`Sequences` and
    whose other fields are flattened to (N·T,) rows in the same order."""
    take = lambda x: x[rows]
    begin = (jnp.arange(rows.shape[1]) == 0)[None, :] | (rows % n_steps == 0)
    seq = Sequences(take(batch.obs), take(batch.episode_start), begin, jax.tree.map(take, batch.state))
    flat = lambda x: x[rows.reshape(-1)]
    return Batch(seq, flat(batch.action), flat(batch.log_prob), flat(batch.advantage), flat(batch.ret))


def update(learner: LearnerState, batch: SequenceBatch, key: jax.Array, net: RecurrentActorCritic,
           config: PPOConfig, orders: jax.Array | None = None):
    """Runs the epochs over ``batch``. Returns (learner, metrics averaged over minibatches).

    ``orders`` (n_epochs, n_windows, lstm_seq_len) int32 gives each epoch's windows instead of :func:`windows`
    (the tests use it: minibatch contents, and RecurrentPPO's order in tests/test_parity_recurrent.py)."""
    optimizer = make_optimizer(config)
    grad_fn = jax.value_and_grad(ppo_loss, has_aux=True)
    per_minibatch = config.batch_size // config.lstm_seq_len

    def minibatch_step(learner: LearnerState, rows: jax.Array):
        (_, metrics), grads = grad_fn(learner.params, net, sequences(batch, rows, config.n_steps), config)
        updates, opt_state = optimizer.update(grads, learner.opt_state, learner.params)
        params = jax.tree.map(lambda p, u: p - learner.learning_rate * u, learner.params, updates)
        metrics["grad_norm"] = optax.tree.norm(grads)
        return LearnerState(params, opt_state, learner.learning_rate), metrics

    def epoch(learner: LearnerState, rows: jax.Array):
        return jax.lax.scan(minibatch_step, learner, rows.reshape(config.n_minibatches, per_minibatch, -1))

    if orders is None:
        orders = jax.vmap(lambda k: windows(k, config))(jax.random.split(key, config.n_epochs))
    learner, metrics = jax.lax.scan(epoch, learner, jnp.asarray(orders, jnp.int32))
    return learner, jax.tree.map(jnp.mean, metrics)
