"""The ER-MRL agent's perception: K reservoirs fed (o_t, a_{t−1}, r_{t−1}) that give the policy its context c_t.

Paper §3 ("Inner loop"): the reservoir is fed the current observation with the previous action and reward,
and the policy sees only the context c_t, the reservoirs' states concatenated. With zero reservoirs the
same code path is plain PPO on o_t.

The reference code (ER-MRL's ReservoirWrapper) never fed the action: it fed ``one_hot(0)`` for Discrete
actions and zeros for Box at every step. ``feed_action="none"`` reproduces that; the default feeds it.
"""

from __future__ import annotations

import dataclasses
from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ermrl import reservoir
from ermrl.envs.spaces import EnvInfo
from ermrl.errors import ConfigError


MAX_RESERVOIRS = 100
"""The most reservoirs an agent may have (the paper uses 1 to 3)."""


@dataclasses.dataclass(frozen=True)
class AgentConfig:
    """Static description of an agent's perception (everything here sets shapes)."""

    reservoirs: int = 1
    """K, the number of reservoirs, each with its own Φ. 0 gives plain PPO, whose policy sees o_t."""
    spec: reservoir.ReservoirSpec = reservoir.ReservoirSpec()
    """Units, connectivity and bias of every reservoir."""
    feed_action: Literal["previous", "none"] = "previous"
    """"previous" feeds a_{t−1} (one-hot for Discrete, the clipped env action for Box);
    "none" reproduces the reference code, which fed a constant (one_hot(0), or zeros for Box)."""
    skip_connection: bool = False
    """Append the raw reservoir input u_t to the context."""
    observed_units: int | None = None
    """The policy sees only the first k units of each reservoir (None: all of them)."""

    def __post_init__(self):
        if not 0 <= self.reservoirs <= MAX_RESERVOIRS:
            raise ConfigError(f"reservoirs must be in 0..{MAX_RESERVOIRS}, got {self.reservoirs}")
        if self.feed_action not in ("previous", "none"):
            raise ConfigError(f"feed_action must be 'previous' or 'none', got {self.feed_action!r}")
        if self.observed_units is not None and not 1 <= self.observed_units <= self.spec.units:
            raise ConfigError(f"observed_units must be in [1, {self.spec.units}], got {self.observed_units}")

    @property
    def units_seen(self) -> int:
        return self.spec.units if self.observed_units is None else self.observed_units


class Phi(NamedTuple):
    """Reservoir hyperparameters for one agent, one entry per reservoir: each field (K,) float32."""

    sr: jax.Array
    """Spectral radius."""
    lr: jax.Array
    """Leak rate."""
    iss: jax.Array
    """Input scaling."""


DEFAULT_PHI = Phi(0.95, 0.5, 1.0)
"""The paper's unevolved Φ (spectral radius 0.95, leak rate 0.5, input scaling 1.0), as scalars."""


class Reservoirs(NamedTuple):
    """An agent's K scaled reservoirs: W (K, N, N), Win (K, N, input_dim), bias (K, N), leak (K,)."""

    weights: reservoir.ReservoirWeights
    leak: jax.Array


class Agent:
    """Pure functions of one env's perception. ``vmap`` adds the env and agent axes."""

    def __init__(self, config: AgentConfig, env: EnvInfo):
        self.config = config
        self.env = env
        self.input_dim = env.obs_dim + env.action.feature_dim + 1
        if config.reservoirs == 0:
            self.context_dim = env.obs_dim
        else:
            self.context_dim = config.reservoirs * config.units_seen + (self.input_dim if config.skip_connection else 0)

    # -- reservoirs ------------------------------------------------------------------------------------
    def unit_weights(self, seed: int) -> reservoir.ReservoirWeights | None:
        """Host-side draw of the K unit reservoirs of the agent with ``seed`` (reservoir k uses seed + k, as
        the reference's MultiReservoirWrapper does). Arrays (K, ...) float32; None when K = 0."""
        draws = [reservoir.generate(self.config.spec, seed + k, self.input_dim) for k in range(self.config.reservoirs)]
        if not draws:  # plain PPO: no leaves at all, since JAX drops the sharding of zero-size arrays
            return None
        return reservoir.ReservoirWeights(*(np.stack(parts) for parts in zip(*draws)))

    @staticmethod
    def build(unit: reservoir.ReservoirWeights | None, phi: Phi | None) -> Reservoirs | None:
        """Applies Φ (traced) to the unit weights."""
        if unit is None:
            return None
        return Reservoirs(jax.vmap(reservoir.scale)(unit, phi.sr, phi.iss), phi.lr)

    # -- inputs and context ----------------------------------------------------------------------------
    def _constant_action(self) -> jax.Array:
        """The action slot at episode start (zeros) or always, under feed_action="none" (reference)."""
        enc = jnp.zeros((self.env.action.feature_dim,), jnp.float32)
        if self.config.feed_action == "none" and self.env.action.discrete:
            enc = enc.at[0].set(1.0)
        return enc

    def encode_action(self, env_action: jax.Array) -> jax.Array:
        """(feature_dim,) encoding of the action the env received."""
        if self.config.feed_action == "none":
            return self._constant_action()
        if self.env.action.discrete:
            return jax.nn.one_hot(env_action, self.env.action.dim, dtype=jnp.float32)
        return env_action.astype(jnp.float32).reshape(self.env.action.dim)

    def observe(self, res: Reservoirs, state: jax.Array | None, obs, action_enc, reward):
        """Feeds u = (obs, action_enc, reward) to the reservoirs.

        state: (K, N), or None for a reset (zero) state or with no reservoir.
        Returns (new state (K, N) or None, context (context_dim,)).
        """
        if self.config.reservoirs == 0:
            return None, obs
        u = jnp.concatenate([obs, action_enc, jnp.reshape(reward, (1,)).astype(jnp.float32)])
        if state is None:
            state = jax.vmap(reservoir.first_step, in_axes=(0, 0, None))(res.weights, res.leak, u)
        else:
            state = jax.vmap(reservoir.step, in_axes=(0, 0, 0, None))(res.weights, res.leak, state, u)
        context = state[:, : self.config.units_seen].reshape(-1)
        if self.config.skip_connection:
            context = jnp.concatenate([context, u])
        return state, context

    def start_episode(self, res: Reservoirs, obs: jax.Array):
        """Reset the state to zeros, then feed (o_0, zeros, 0). Returns (state (K, N), context)."""
        return self.observe(res, None, obs, self._constant_action(), jnp.float32(0.0))
