"""One training iteration on the host backend: a Python loop over steps around Gymnasium envs.

The JAX backend runs a whole iteration as one program. With Gymnasium envs, every step has to come back to
the host, so an iteration here is:

1. for each of the n_steps steps, one jitted call for all A agents that feeds the previous step's outcome
   to the reservoirs (:func:`ermrl.training.rollout.advance`) and samples the next actions (:func:`ermrl.training.rollout.act`),
   then ``HostEnv.step`` for all A · n_envs envs (in worker processes when a step is costly);
2. the PPO update, the same jitted ``learn`` as on the JAX backend, sharded over devices.

The per-step functions are the JAX backend's own, so episode boundaries, the time-limit bootstrap, fitness and
curves have the same meaning on both backends. Keys are drawn the same way too, though the envs' own
randomness differs (Gymnasium's seeding, not gymnax's).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ermrl.envs.host_backend import HostEnv
from ermrl.envs.host_groups import Stepped
from ermrl.envs.jax_backend import Transition
from ermrl.ppo.config import PPOConfig
from ermrl.training.rollout import EnvCarry, Step, act, advance, draw_noise


def pack_step(step: Step) -> jax.Array:
    """Concatenates a Step's fields (..., ·) into one float32 array (..., width): one output per call
    instead of eleven (each JAX output costs more than the arithmetic here). Ints and bools are exact."""
    col = lambda x, lead: x.astype(jnp.float32).reshape(lead + (-1,))
    lead = step.reward.shape
    return jnp.concatenate([col(x, lead) for x in step], axis=-1)


def unpack_steps(packed: jax.Array, like: Step) -> Step:
    """Inverse of :func:`pack_step`, with ``like`` (a Step of ShapeDtypeStructs, no leading axes beyond
    those of ``packed[..., 0]``) giving each field's width and dtype."""
    lead = packed.shape[:-1]
    fields, at = [], 0
    for x in like:
        width = int(np.prod(x.shape[len(lead):], dtype=int))
        part = packed[..., at:at + width].reshape(lead + x.shape[len(lead):])
        fields.append(part > 0.5 if x.dtype == jnp.bool_ else part.astype(x.dtype))
        at += width
    return Step(*fields)


class HostIteration:
    """Callable like a compiled JAX iteration: ``state -> (state, log)``. Per-step work runs on one device
    (it is a few small matmuls per agent); the update runs sharded, through ``learn``."""

    def __init__(self, fns, ppo: PPOConfig, learn, sharding, device):
        self.env: HostEnv = fns.env
        self.ppo = ppo
        self.sharding = sharding
        self.device = device
        net, agent = fns.net, fns.agent
        d = self.env.info.obs_dim
        self.step_like: Step | None = None

        def begin(key):
            """(next key, action noise (n_steps, n_envs, ...), update key): the JAX backend's keys."""
            key, k_roll, k_update = jax.random.split(key, 3)
            k_act = jax.vmap(lambda k: jax.random.split(k)[0])(jax.random.split(k_roll, ppo.n_steps))
            return key, draw_noise(net, k_act, ppo.n_envs, ppo.sde_sample_freq), k_update

        choose = functools.partial(act, net)  # (params, context, noise) -> Act

        def advance_packed(res, carry, chosen, packed):
            out = Stepped.unpack(packed, d)
            tr = Transition(out.obs, carry.env_state, out.reward, out.terminated, out.truncated, out.final_obs)
            return advance(agent, res, carry, chosen, tr, ppo.gamma)

        def advance_choose(params, res, carry, chosen, packed, noise):
            carry, step = advance_packed(res, carry, chosen, packed)
            return carry, pack_step(step), choose(params, carry.context, noise)

        def advance_last(res, carry, chosen, packed):
            carry, step = advance_packed(res, carry, chosen, packed)
            return carry, pack_step(step)

        def learn_packed(state, carry, packed_steps, k_update):
            return learn(state, carry, unpack_steps(packed_steps, self.step_like), k_update)

        self._begin = jax.jit(jax.vmap(begin))
        self._choose = jax.jit(jax.vmap(choose))
        self._advance_choose = jax.jit(jax.vmap(advance_choose))
        self._advance_last = jax.jit(jax.vmap(advance_last))
        self._advance_shape = jax.vmap(advance_packed)
        self._learn = jax.jit(learn_packed, donate_argnums=0)

    def rollout(self, params, res, carry: EnvCarry, noise: np.ndarray) -> tuple[EnvCarry, np.ndarray]:
        """n_steps steps of every agent, with action noise (n_steps, A, n_envs, policy_dim) drawn ahead.
        Returns the final carry (on ``device``) and the packed steps, (A, n_steps, n_envs, width) float32."""
        n_steps = self.ppo.n_steps
        space = self.env.info.action
        buffer = None
        chosen = self._choose(params, carry.context, noise[0])
        for t in range(n_steps):
            actions = np.asarray(chosen.env_action)
            packed = self.env.step(actions.reshape((-1,) if space.discrete else (-1, space.dim)))
            packed = packed.reshape(actions.shape[:2] + packed.shape[1:])
            if t + 1 < n_steps:
                carry, step, chosen = self._advance_choose(params, res, carry, chosen, packed, noise[t + 1])
            else:
                carry, step = self._advance_last(res, carry, chosen, packed)
            if buffer is None:
                buffer = np.empty((step.shape[0], n_steps) + step.shape[1:], np.float32)
            buffer[:, t] = step
        return carry, buffer

    def _start(self, state):
        """Keys for the iteration, and the rollout's inputs on ``device``: (next key, params, reservoirs,
        carry, action noise (n_steps, A, n_envs, policy_dim) NumPy, update key)."""
        key, noise, k_update = self._begin(jax.device_put(state.key, self.device))
        params, res, carry = jax.device_put((state.learner.params, state.reservoirs, state.envs), self.device)
        return key, params, res, carry, np.ascontiguousarray(np.asarray(noise).swapaxes(0, 1)), k_update

    def warm_up(self, state):
        """Compiles every function for ``state``'s shapes without stepping any env."""
        _, params, res, carry, noise, k_update = self._start(state)
        chosen = self._choose(params, carry.context, noise[0])
        packed = np.zeros(carry.context.shape[:2] + (2 * self.env.info.obs_dim + 3,), np.float32)
        _, self.step_like = jax.eval_shape(self._advance_shape, res, carry, chosen, packed)
        self._advance_choose(params, res, carry, chosen, packed, noise[min(1, self.ppo.n_steps - 1)])
        final, step = self._advance_last(res, carry, chosen, packed)
        size, n_envs, width = step.shape
        steps = jax.ShapeDtypeStruct((size, self.ppo.n_steps, n_envs, width), jnp.float32, sharding=self.sharding)
        self.step_like = jax.tree.map(lambda x: jax.ShapeDtypeStruct((size, self.ppo.n_steps) + x.shape[1:], x.dtype),
                                      self.step_like)
        args = jax.device_put((final, k_update), self.sharding)
        self._learn = self._learn.lower(state, args[0], steps, args[1]).compile()

    def collect(self, state):
        """The rollout half of an iteration. Returns (next key, final carry, packed steps
        (A, n_steps, n_envs, width) NumPy, update key); ``unpack_steps(steps, self.step_like)`` reads them."""
        key, params, res, carry, noise, k_update = self._start(state)
        carry, steps = self.rollout(params, res, carry, noise)
        return key, carry, steps, k_update

    def __call__(self, state):
        key, carry, steps, k_update = self.collect(state)
        carry, steps, key, k_update = jax.device_put((carry, steps, key, k_update), self.sharding)
        return self._learn(state._replace(key=key), carry, steps, k_update)
