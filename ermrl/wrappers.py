"""A Gymnasium wrapper that gives any env's agent the ER-MRL context, for users of SB3 or other libraries.

The wrapper uses the same reservoirs (:func:`ermrl.agent.Agent.unit_weights` for the seed, Φ applied as in
training) and the same input convention as the JAX trainer: the reservoirs are reset and fed
(o_0, zeros, 0) at ``reset``, then (o_t, a_{t−1}, r_{t−1}) at every ``step``; the observation returned is the
context c_t.
"""

from __future__ import annotations

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np

from ermrl.agent import Agent, AgentConfig, DEFAULT_PHI, Phi
from ermrl.envs.spaces import ActionSpace, EnvInfo
from ermrl.errors import ConfigError


class ReservoirObservation(gym.Wrapper):
    """Replaces the observation of ``env`` by the context of K reservoirs generated from Φ and ``seed``.

    sr, lr, iss: one value, or one per reservoir. The observation space is Box(-1, 1, (K·units,)), or
    unbounded with ``agent.skip_connection``.
    """

    def __init__(self, env: gym.Env, sr=DEFAULT_PHI.sr, lr=DEFAULT_PHI.lr, iss=DEFAULT_PHI.iss, seed: int = 0,
                 agent: AgentConfig = AgentConfig()):
        super().__init__(env)
        if agent.reservoirs < 1:
            raise ConfigError("ReservoirObservation needs at least one reservoir")
        if not isinstance(env.observation_space, gym.spaces.Box) or len(env.observation_space.shape) != 1:
            raise ConfigError(f"ReservoirObservation needs a 1-D Box observation space, got {env.observation_space}")
        action = ActionSpace.from_gymnasium(env.action_space)
        obs_dim = env.observation_space.shape[0]
        env_id = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
        info = EnvInfo(env_id, env_id, tuple(range(obs_dim)), action, 0)
        self.agent = Agent(agent, info)
        k = agent.reservoirs
        as_k = lambda v: np.broadcast_to(np.asarray(v, np.float32), (k,)).copy()
        self.phi = Phi(as_k(sr), as_k(lr), as_k(iss))
        self.reservoirs = Agent.build(self.agent.unit_weights(seed), self.phi)
        bound = np.inf if agent.skip_connection else 1.0
        self.observation_space = gym.spaces.Box(-bound, bound, (self.agent.context_dim,), np.float32)
        self._start = jax.jit(self.agent.start_episode)
        self._observe = jax.jit(lambda res, state, obs, action, reward:
                                self.agent.observe(res, state, obs, self.agent.encode_action(action), reward))
        self._state = None

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._state, context = self._start(self.reservoirs, jnp.asarray(obs, jnp.float32))
        return np.asarray(context), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        enc = jnp.asarray(action, jnp.int32 if self.agent.env.action.discrete else jnp.float32)
        self._state, context = self._observe(self.reservoirs, self._state, jnp.asarray(obs, jnp.float32), enc,
                                             jnp.float32(reward))
        return np.asarray(context), reward, terminated, truncated, info
