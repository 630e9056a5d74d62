"""Separate actor and critic MLPs as in SB3's MlpPolicy, with SB3's orthogonal initialization.

Gains: √2 for hidden layers, 0.01 for the policy head, 1 for the value head; biases 0. Box actions get a
Gaussian with a state-independent log std; Discrete actions a Categorical over logits.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from ermrl.envs.spaces import ActionSpace


def orthogonal(gain: float, iterations: int = 60):
    """Orthogonal initializer (as torch's ``orthogonal_``, which SB3 uses) without a LAPACK call.

    It returns gain × the orthogonal polar factor of a Gaussian matrix, found by Newton–Schulz iteration. For a
    Gaussian matrix that factor is Haar-distributed, like the sign-corrected QR factor, so the distribution is
    the same. We avoid ``jnp.linalg.qr``: on XLA:CPU, batched QRs running at once deadlocked the thread pool.
    """

    def init(key, shape, dtype=jnp.float32):
        a = jax.random.normal(key, shape, jnp.float32)
        x = a / jnp.linalg.norm(a)  # every singular value now <= 1, where the iteration converges

        def body(_, x):
            return 1.5 * x - 0.5 * x @ (x.T @ x)

        return (gain * jax.lax.fori_loop(0, iterations, body, x)).astype(dtype)

    return init


class MLP(nn.Module):
    """tanh MLP with orthogonal init; the last layer is linear with gain ``head_gain``."""

    hidden: Sequence[int]
    out: int
    head_gain: float

    @nn.compact
    def __call__(self, x):
        for width in self.hidden:
            x = nn.Dense(width, kernel_init=orthogonal(np.sqrt(2)), bias_init=nn.initializers.zeros)(x)
            x = jnp.tanh(x)
        return nn.Dense(self.out, kernel_init=orthogonal(self.head_gain), bias_init=nn.initializers.zeros)(x)


class PolicyParams(NamedTuple):
    actor: dict
    critic: dict
    log_std: jax.Array | None
    """(action_dim,) for Box; None for Discrete."""


class ActorCritic:
    """Pure functions over :class:`PolicyParams`. Inputs have shape (..., context_dim)."""

    def __init__(self, action: ActionSpace, hidden: Sequence[int], log_std_init: float = 0.0):
        self.action = action
        self.log_std_init = log_std_init
        self.actor = MLP(tuple(hidden), action.policy_dim, 0.01)
        self.critic = MLP(tuple(hidden), 1, 1.0)

    def init(self, key: jax.Array, context_dim: int) -> PolicyParams:
        ka, kc = jax.random.split(key)
        x = jnp.zeros((context_dim,), jnp.float32)
        log_std = None if self.action.discrete else jnp.full((self.action.dim,), self.log_std_init, jnp.float32)
        return PolicyParams(actor=self.actor.init(ka, x), critic=self.critic.init(kc, x), log_std=log_std)

    def value(self, params: PolicyParams, context: jax.Array) -> jax.Array:
        """(...,) state values."""
        return self.critic.apply(params.critic, context)[..., 0]

    def head(self, params: PolicyParams, context: jax.Array) -> jax.Array:
        """(..., policy_dim): logits (Discrete) or Gaussian means (Box)."""
        return self.actor.apply(params.actor, context)

    def noise(self, key: jax.Array, batch_shape: tuple[int, ...]) -> jax.Array:
        """(*batch_shape, policy_dim) float32 sampling noise: Gumbel for Discrete (the Gumbel-max trick of
        ``jax.random.categorical``), standard normal for Box. Drawn apart from :meth:`sample` so that a
        rollout can draw all its steps' noise in one batched call."""
        shape = (*batch_shape, self.action.policy_dim)
        if self.action.discrete:
            return jax.random.gumbel(key, shape, jnp.float32)
        return jax.random.normal(key, shape, jnp.float32)

    def sample(self, params: PolicyParams, head: jax.Array, noise: jax.Array) -> jax.Array:
        """An action per row from :meth:`noise`'s draw: int32 (...,) for Discrete (the same action as
        ``jax.random.categorical`` with that key), float32 (..., dim) for Box (unclipped)."""
        if self.action.discrete:
            return jnp.argmax(noise + head, axis=-1).astype(jnp.int32)
        return head + jnp.exp(params.log_std) * noise

    def log_prob(self, params: PolicyParams, head: jax.Array, action: jax.Array) -> jax.Array:
        """(...,) log π(action)."""
        if self.action.discrete:
            logp = jax.nn.log_softmax(head, axis=-1)
            return jnp.take_along_axis(logp, action[..., None].astype(jnp.int32), axis=-1)[..., 0]
        log_std = params.log_std
        z = (action - head) * jnp.exp(-log_std)
        return jnp.sum(-0.5 * z**2 - log_std - 0.5 * jnp.log(2 * jnp.pi), axis=-1)

    def entropy(self, params: PolicyParams, head: jax.Array) -> jax.Array:
        """(...,) entropy of π."""
        if self.action.discrete:
            logp = jax.nn.log_softmax(head, axis=-1)
            return -jnp.sum(jnp.exp(logp) * logp, axis=-1)
        per_dim = 0.5 + 0.5 * jnp.log(2 * jnp.pi) + params.log_std
        return jnp.broadcast_to(jnp.sum(per_dim), head.shape[:-1])
