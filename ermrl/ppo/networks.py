"""Separate actor and critic MLPs as in SB3's MlpPolicy, with SB3's orthogonal initialization.

Gains: √2 for hidden layers, 0.01 for the policy head, 1 for the value head; biases 0 (without ``ortho_init``,
torch's ``nn.Linear`` default instead: weights and biases U(±1/√fan_in)). Hidden layers are tanh (SB3's default)
or ReLU. Box actions get a Gaussian with a state-independent log std; Discrete actions a Categorical over logits.

With ``use_sde`` (SB3's gSDE, generalized State-Dependent Exploration, with its defaults ``full_std=True``,
``use_expln=False``, ``learn_features=False``) the Box policy's noise is ``z · M``: z the actor's last hidden
features (L,), M an (L, action_dim) exploration matrix drawn from N(0, exp(log_std)²) and held for several
steps; so π(·|c) = N(μ(c), z² · exp(log_std)² + 1e-6) per action dim, with z treated as a constant (no gradient
through the features into the variance).
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from ermrl.envs.spaces import ActionSpace
from ermrl.ppo import ordered


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


def torch_default_bias(fan_in: int):
    """torch ``nn.Linear``'s default bias initializer, U(±1/√fan_in) (its weights: :func:`torch_default_kernel`)."""
    bound = 1.0 / np.sqrt(fan_in)

    def init(key, shape, dtype=jnp.float32):
        return jax.random.uniform(key, shape, dtype, -bound, bound)

    return init


def torch_default_kernel():
    """torch ``nn.Linear``'s default weight initializer, kaiming_uniform(a=√5): U(±1/√fan_in)."""
    return nn.initializers.variance_scaling(1.0 / 3.0, "fan_in", "uniform")


ACTIVATIONS = {"tanh": jnp.tanh, "relu": jax.nn.relu}
"""PPOConfig.activation's names and functions."""


class MLP(nn.Module):
    """An MLP of ``activation`` hidden layers; the last layer is linear. With ``ortho_init`` (SB3's default)
    orthogonal weights, gain √2 in hidden layers and ``head_gain`` in the last, and zero biases; without it
    torch's default init for every layer."""

    hidden: Sequence[int]
    out: int
    head_gain: float
    activation: str = "tanh"
    ortho_init: bool = True

    def _dense(self, width: int, gain: float, fan_in: int) -> nn.Dense:
        if self.ortho_init:
            return nn.Dense(width, kernel_init=orthogonal(gain), bias_init=nn.initializers.zeros)
        return nn.Dense(width, kernel_init=torch_default_kernel(), bias_init=torch_default_bias(fan_in))

    @nn.compact
    def __call__(self, x, features: bool = False):
        """(..., out), or with ``features`` (output, the last hidden layer (..., hidden[-1]))."""
        act = ACTIVATIONS[self.activation]
        for width in self.hidden:
            x = act(self._dense(width, np.sqrt(2), x.shape[-1])(x))
        out = self._dense(self.out, self.head_gain, x.shape[-1])(x)
        return (out, x) if features else out


class PolicyParams(NamedTuple):
    actor: dict
    critic: dict
    log_std: jax.Array | None
    """(action_dim,) for Box; (hidden[-1], action_dim) for Box with gSDE; None for Discrete."""


class ActorCritic:
    """Pure functions over :class:`PolicyParams`. Inputs have shape (..., context_dim)."""

    SDE_EPSILON = 1e-6
    """Added to gSDE's variance (SB3's ``StateDependentNoiseDistribution.epsilon``)."""

    def __init__(self, action: ActionSpace, hidden: Sequence[int], log_std_init: float = 0.0, use_sde: bool = False,
                 activation: str = "tanh", ortho_init: bool = True):
        self.action = action
        self.log_std_init = log_std_init
        self.use_sde = use_sde and not action.discrete
        self.latent_dim = tuple(hidden)[-1]
        self.actor = MLP(tuple(hidden), action.policy_dim, 0.01, activation, ortho_init)
        self.critic = MLP(tuple(hidden), 1, 1.0, activation, ortho_init)

    @classmethod
    def of(cls, action: ActionSpace, ppo) -> "ActorCritic":
        """The network of a PPOConfig ``ppo``'s settings."""
        return cls(action, ppo.hidden, ppo.log_std_init, ppo.use_sde, ppo.activation, ppo.ortho_init)

    def init(self, key: jax.Array, context_dim: int) -> PolicyParams:
        ka, kc = jax.random.split(key)
        x = jnp.zeros((context_dim,), jnp.float32)
        shape = (self.latent_dim, self.action.dim) if self.use_sde else (self.action.dim,)
        log_std = None if self.action.discrete else jnp.full(shape, self.log_std_init, jnp.float32)
        return PolicyParams(actor=self.actor.init(ka, x), critic=self.critic.init(kc, x), log_std=log_std)

    def value(self, params: PolicyParams, context: jax.Array) -> jax.Array:
        """(...,) state values."""
        return self.critic.apply(params.critic, context)[..., 0]

    def head(self, params: PolicyParams, context: jax.Array) -> jax.Array:
        """(..., policy_dim): logits (Discrete) or Gaussian means (Box)."""
        return self.actor.apply(params.actor, context)

    def policy(self, params: PolicyParams, context: jax.Array) -> tuple[jax.Array, jax.Array | None]:
        """(:meth:`head`, the actor's last hidden features (..., latent_dim) with gSDE, else None)."""
        if not self.use_sde:
            return self.head(params, context), None
        return self.actor.apply(params.actor, context, features=True)

    def noise(self, key: jax.Array, batch_shape: tuple[int, ...]) -> jax.Array:
        """float32 sampling noise, drawn apart from :meth:`sample` so that a rollout can draw all its steps' noise in
        one batched call: (*batch_shape, policy_dim), Gumbel for Discrete (the Gumbel-max trick of
        ``jax.random.categorical``), standard normal for Box; with gSDE (*batch_shape, latent_dim, action_dim),
        standard normal, the exploration matrix before its scale exp(log_std)."""
        if self.action.discrete:
            return jax.random.gumbel(key, (*batch_shape, self.action.policy_dim), jnp.float32)
        shape = (*batch_shape, self.latent_dim, self.action.dim) if self.use_sde else (*batch_shape, self.action.dim)
        return jax.random.normal(key, shape, jnp.float32)

    def sample(self, params: PolicyParams, head: jax.Array, noise: jax.Array, latent: jax.Array | None = None):
        """An action per row from :meth:`noise`'s draw: int32 (...,) for Discrete (the same action as
        ``jax.random.categorical`` with that key), float32 (..., dim) for Box (unclipped); with gSDE
        μ + z · (exp(log_std) ⊙ ε), z = ``latent`` (..., latent_dim)."""
        if self.action.discrete:
            return jnp.argmax(noise + head, axis=-1).astype(jnp.int32)
        if self.use_sde:
            return head + jnp.einsum("...l,...ld->...d", latent, jnp.exp(params.log_std) * noise)
        return head + jnp.exp(params.log_std) * noise

    def _log_std(self, params: PolicyParams, latent: jax.Array | None) -> jax.Array:
        """(..., action_dim) or (action_dim,): the Gaussian's log std per action dim."""
        if not self.use_sde:
            return params.log_std
        z = jax.lax.stop_gradient(latent)  # SB3's learn_features=False
        variance = jnp.square(z) @ jnp.square(jnp.exp(params.log_std))
        return 0.5 * jnp.log(variance + self.SDE_EPSILON)

    def log_prob(self, params: PolicyParams, head: jax.Array, action: jax.Array,
                 latent: jax.Array | None = None) -> jax.Array:
        """(...,) log π(action); ``latent``: :meth:`policy`'s features, with gSDE."""
        if self.action.discrete:
            logp = jax.nn.log_softmax(head, axis=-1)
            return jnp.take_along_axis(logp, action[..., None].astype(jnp.int32), axis=-1)[..., 0]
        log_std = self._log_std(params, latent)
        z = (action - head) * jnp.exp(-log_std)
        return ordered.tree_sum(-0.5 * z**2 - log_std - 0.5 * jnp.log(2 * jnp.pi))

    def entropy(self, params: PolicyParams, head: jax.Array, latent: jax.Array | None = None) -> jax.Array:
        """(...,) entropy of π."""
        if self.action.discrete:
            logp = jax.nn.log_softmax(head, axis=-1)
            return -jnp.sum(jnp.exp(logp) * logp, axis=-1)
        per_dim = 0.5 + 0.5 * jnp.log(2 * jnp.pi) + self._log_std(params, latent)
        return jnp.broadcast_to(ordered.tree_sum(per_dim), head.shape[:-1])
