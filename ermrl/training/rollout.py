"""One agent's rollout on the JAX backend: n_steps of acting, stepping and feeding the reservoirs.

Semantics follow stable-baselines3's ``collect_rollouts`` with the reference's reservoir wrapper:
- Box actions are sampled unclipped, clipped to the bounds for the env, and stored unclipped for the loss;
- on a time-limit truncation the reward gets ``γ·V(c_final)``, the value of the context built from the
  episode's final observation (SB3's ``TimeLimit.truncated`` bootstrap);
- at an episode's end the reservoir state is reset and fed (o_0, zeros, 0);
- with ``PPOConfig.normalize`` the contexts and rewards PPO sees are normalized as SB3's ``VecNormalize`` does
  (:mod:`ermrl.ppo.normalize`); the reservoirs and the episode returns see the raw values.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from ermrl.agent import Agent, Reservoirs
from ermrl.envs.jax_backend import JaxEnv, Transition
from ermrl.ppo import normalize
from ermrl.ppo.networks import ActorCritic, PolicyParams


class EnvCarry(NamedTuple):
    """Per-env state carried between steps; every field but ``norm`` has a leading (n_envs,) axis."""

    env_state: Any
    res_state: jax.Array | None
    """(n_envs, K, N) reservoir states; None with no reservoir."""
    context: jax.Array
    """(n_envs, context_dim) what the policy sees now."""
    episode_return: jax.Array
    """(n_envs,) undiscounted return of the running episode."""
    episode_length: jax.Array
    """(n_envs,) int32 steps of the running episode."""
    norm: normalize.Normalizer | None = None
    """The agent's running statistics with ``PPOConfig.normalize`` (``context`` is then normalized); else None."""


class Step(NamedTuple):
    """One rollout step, each field (n_envs, ...); ``scan`` stacks them to (n_steps, n_envs, ...)."""

    context: jax.Array
    action: jax.Array
    log_prob: jax.Array
    value: jax.Array
    reward: jax.Array
    """The reward PPO learns from (normalized with ``PPOConfig.normalize``)."""
    done: jax.Array
    truncated: jax.Array
    final_context: jax.Array
    """Context built from the step's final observation (before any reset), for the truncation bootstrap
    (normalized with ``PPOConfig.normalize``)."""
    finished_return: jax.Array
    """Return (of raw rewards) of the episode this step ended, NaN when it ended none."""
    finished_length: jax.Array
    """Length of the episode this step ended, 0 when it ended none."""


class Act(NamedTuple):
    """The policy's choice in n_envs envs: each field (n_envs, ...)."""

    action: jax.Array
    """Sampled action (unclipped for Box), stored for the loss."""
    env_action: jax.Array
    """What the env receives: the action, clipped to the Box bounds."""
    log_prob: jax.Array
    value: jax.Array


def start(env: JaxEnv, agent: Agent, res: Reservoirs, key: jax.Array, n_envs: int, normalized: bool) -> EnvCarry:
    """Resets n_envs envs and their reservoirs."""
    obs, env_state = jax.vmap(env.reset)(jax.random.split(key, n_envs))
    return start_from_obs(agent, res, obs, env_state, normalized)


def start_from_obs(agent: Agent, res: Reservoirs, obs: jax.Array, env_state: Any, normalized: bool) -> EnvCarry:
    """The carry for envs just reset to ``obs`` (n_envs, obs_dim): reservoirs reset and fed (o_0, zeros, 0);
    ``normalized``: start the normalization statistics from these first contexts."""
    n_envs = obs.shape[0]
    res_state, context = jax.vmap(agent.start_episode, in_axes=(None, 0))(res, obs)
    norm = None
    if normalized:
        norm, context = normalize.start(context)
    zeros = jnp.zeros((n_envs,), jnp.float32)
    return EnvCarry(env_state, res_state, context, zeros, jnp.zeros((n_envs,), jnp.int32), norm)


def act(net: ActorCritic, params: PolicyParams, context: jax.Array, noise: jax.Array) -> Act:
    """Samples actions for contexts (n_envs, context_dim) with ``net.noise``'s draw (n_envs, ...)."""
    action_space = net.action
    head, latent = net.policy(params, context)
    action = net.sample(params, head, noise, latent)
    if action_space.discrete:
        env_action = action
    else:
        env_action = jnp.clip(action, jnp.asarray(action_space.low), jnp.asarray(action_space.high))
    return Act(action, env_action, net.log_prob(params, head, action, latent), net.value(params, context))


def draw_noise(net: ActorCritic, step_keys: jax.Array, n_envs: int, sde_sample_freq: int) -> jax.Array:
    """Every step's action noise, (n_steps, n_envs, ...), one draw per step from its key in ``step_keys``
    (n_steps, 2). With gSDE each env keeps its exploration matrix for ``sde_sample_freq`` steps (-1: the whole
    rollout), as SB3's ``reset_noise`` at a rollout's start and every ``sde_sample_freq`` steps."""
    n_steps = step_keys.shape[0]
    noise = jax.vmap(lambda k: net.noise(k, (n_envs,)))(step_keys)
    if net.use_sde:
        block = jnp.arange(n_steps) // sde_sample_freq * sde_sample_freq if sde_sample_freq > 0 else \
            jnp.zeros(n_steps, jnp.int32)
        noise = noise[block]
    return noise


def advance(agent: Agent, res: Reservoirs, carry: EnvCarry, chosen: Act, tr: Transition,
            gamma: float) -> tuple[EnvCarry, Step]:
    """Feeds one env step's outcome to the reservoirs and episode bookkeeping; every field (n_envs, ...).
    ``gamma`` discounts the running return that normalizes rewards (unused without ``carry.norm``)."""
    action_enc = jax.vmap(agent.encode_action)(chosen.env_action)
    observe = jax.vmap(agent.observe, in_axes=(None, 0, 0, 0, 0))
    res_final, final_context = observe(res, carry.res_state, tr.final_obs, action_enc, tr.reward)
    res_start, start_context = jax.vmap(agent.start_episode, in_axes=(None, 0))(res, tr.obs)

    done = jnp.logical_or(tr.terminated, tr.truncated)
    pick = lambda a, b: jax.tree.map(lambda x, y: jnp.where(done.reshape((-1,) + (1,) * (x.ndim - 1)), x, y), a, b)
    episode_return = carry.episode_return + tr.reward
    episode_length = carry.episode_length + 1
    context, reward, norm = pick(start_context, final_context), tr.reward, carry.norm
    if norm is not None:
        norm, context, final_context, reward = normalize.step(norm, context, final_context, reward, done, gamma)
    step = Step(
        context=carry.context, action=chosen.action, log_prob=chosen.log_prob, value=chosen.value,
        reward=reward, done=done, truncated=tr.truncated, final_context=final_context,
        finished_return=jnp.where(done, episode_return, jnp.nan),
        finished_length=jnp.where(done, episode_length, 0),
    )
    carry = EnvCarry(
        env_state=tr.state,
        res_state=pick(res_start, res_final),
        context=context,
        episode_return=jnp.where(done, 0.0, episode_return),
        episode_length=jnp.where(done, 0, episode_length),
        norm=norm,
    )
    return carry, step


def collect(
    env: JaxEnv, agent: Agent, net: ActorCritic, params: PolicyParams, res: Reservoirs, carry: EnvCarry,
    key: jax.Array, n_steps: int, gamma: float, sde_sample_freq: int = -1,
) -> tuple[EnvCarry, Step]:
    """Runs n_steps steps in each env. Returns the final carry and the stacked steps (n_steps, n_envs, ...)."""
    n_envs = carry.context.shape[0]
    # Every step's randomness is drawn before the scan, in a few batched calls: XLA:CPU runs each threefry call
    # as a small loop of its own, and five of them per step cost more than the rest of the step. The draws are
    # the ones a per-step split would give: noise (n_steps, n_envs, policy_dim), key_step (n_steps, n_envs, 2),
    # restart fields (n_steps, n_envs, ...).
    k_act, k_env = jnp.moveaxis(jax.vmap(jax.random.split)(jax.random.split(key, n_steps)), 1, 0)
    noise = draw_noise(net, k_act, n_envs, sde_sample_freq)
    key_step, restart = jax.vmap(lambda k: jax.vmap(env.draw)(jax.random.split(k, n_envs)))(k_env)

    def body(carry: EnvCarry, drawn):
        noise, key_step, restart = drawn
        chosen = act(net, params, carry.context, noise)
        tr = jax.vmap(env.step_from)(key_step, carry.env_state, chosen.env_action, restart)
        return advance(agent, res, carry, chosen, tr, gamma)

    return jax.lax.scan(body, carry, (noise, key_step, restart))
