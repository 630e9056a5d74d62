"""JAX environments (gymnax), stepped inside the jitted training program.

gymnax 1.0 already separates ``terminated`` from ``truncated`` and returns the final observation of an
episode before its auto-reset, which is what the time-limit bootstrap needs.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from ermrl.envs.spaces import ActionSpace, EnvInfo

GYMNAX_IDS: dict[str, str] = {
    "CartPole-v1": "CartPole-v1",
    "Pendulum-v1": "Pendulum-v1",
    "MountainCar-v0": "MountainCar-v0",
    "MountainCarContinuous-v0": "MountainCarContinuous-v0",
    "Acrobot-v1": "Acrobot-v1",
}
"""Gymnasium id -> gymnax id, for the envs that have a JAX version."""


class Transition(NamedTuple):
    """One env step. Shapes are per env; vmap adds leading axes."""

    obs: jax.Array
    """(obs_dim,) masked observation to act on next (the reset observation if the episode ended)."""
    state: Any
    """The gymnax state after the step (already reset if the episode ended)."""
    reward: jax.Array
    """() float32."""
    terminated: jax.Array
    """() bool: the MDP reached a terminal state."""
    truncated: jax.Array
    """() bool: the time limit cut the episode (and it did not terminate)."""
    final_obs: jax.Array
    """(obs_dim,) masked observation reached by this step, before any reset."""


class Restart(NamedTuple):
    """Where an env starts again if a step ends its episode: gymnax's reset output, drawn ahead."""

    obs: jax.Array
    """(raw obs_dim,) unmasked observation."""
    state: Any


class JaxEnv:
    """A gymnax env with velocity masking. ``reset`` and ``step`` are pure and vmappable."""

    def __init__(self, info: EnvInfo):
        import gymnax

        self.info = info
        self._env, self._params = gymnax.make(GYMNAX_IDS[info.base_id])

    @staticmethod
    def describe(env_id: str, base_id: str, kept: tuple[int, ...] | None) -> EnvInfo:
        """EnvInfo for a gymnax-backed id (kept=None keeps every dim)."""
        import gymnax

        env, params = gymnax.make(GYMNAX_IDS[base_id])
        obs_dim = env.observation_space(params).shape[0]
        space = env.action_space(params)
        if hasattr(space, "n"):
            action = ActionSpace(True, int(space.n))
        else:
            dim = space.shape[0] if space.shape else 1
            low = tuple(float(v) for v in jnp.broadcast_to(space.low, (dim,)))
            high = tuple(float(v) for v in jnp.broadcast_to(space.high, (dim,)))
            action = ActionSpace(False, dim, low, high)
        kept = tuple(range(obs_dim)) if kept is None else kept
        return EnvInfo(env_id, base_id, kept, action, int(params.max_steps_in_episode))

    def reset(self, key: jax.Array) -> tuple[jax.Array, Any]:
        """Returns (masked obs (obs_dim,), state)."""
        obs, state = self._env.reset(key, self._params)
        return self.info.mask(obs.astype(jnp.float32)), state

    def draw(self, key: jax.Array) -> tuple[jax.Array, Restart]:
        """The randomness of one ``step(key, ...)``, drawn ahead: gymnax splits a step's key into one for the
        dynamics and one for the reset that follows if the episode ends. Returns (dynamics key, Restart)."""
        key_step, key_reset = jax.random.split(key)
        return key_step, Restart(*self._env.reset_env(key_reset, self._params))

    def step_from(self, key_step: jax.Array, state: Any, action: jax.Array, restart: Restart) -> Transition:
        """:meth:`step` with its randomness drawn ahead by :meth:`draw`: the env steps and, if the episode
        ended, starts again from ``restart``. Same result as ``step(key, ...)`` for ``draw(key)``."""
        obs, next_state, reward, terminated, _ = self._env.step_env(key_step, state, action, self._params)
        time_limit = self._env.is_truncated(next_state, self._params)
        done = jnp.logical_or(terminated, time_limit)
        pick = lambda reset_leaf, step_leaf: jax.lax.select(done, reset_leaf, step_leaf)
        return Transition(
            obs=self.info.mask(pick(restart.obs, obs).astype(jnp.float32)),
            state=jax.tree.map(pick, restart.state, next_state),
            reward=jnp.asarray(reward, jnp.float32).reshape(()),
            terminated=jnp.asarray(terminated).reshape(()),
            truncated=jnp.logical_and(time_limit, jnp.logical_not(terminated)).reshape(()),
            final_obs=self.info.mask(obs.astype(jnp.float32)),
        )

    def step(self, key: jax.Array, state: Any, action: jax.Array) -> Transition:
        """Steps with an env action (an int for Discrete, a clipped (dim,) array for Box), auto-resetting
        as gymnax's ``step`` does."""
        key_step, restart = self.draw(key)
        return self.step_from(key_step, state, action, restart)
