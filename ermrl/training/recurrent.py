"""The recurrent baseline's per-agent functions (PPO with an LSTM policy, ``PPOConfig.model = "lstm"``).

:func:`make_recurrent_fns` returns the same :class:`~ermrl.training.state.AgentFns` as the feedforward agent,
so the :class:`~ermrl.training.trainer.Trainer` (population, sharding, host loop, ``Results``) runs it unchanged;
the LSTM states live in the agent state's env carry. JAX backend only, and no reservoir: the LSTM sees the raw
(masked) observation, as RecurrentPPO's does.

The rollout follows sb3-contrib RecurrentPPO's ``collect_rollouts``: before each step the state is zeroed where
the step starts an episode (every env starts with one), the LSTMs step on the observation, and the state before
the step is stored for the update; on a time-limit truncation the reward gets γ·V(final observation), V taken
from the critic LSTM stepped once more from its state after the step, without a reset; the last value feeds the
next observation from the carried state (reset where an episode just ended). The rest is our PPO's: the same
action sampling (gSDE's exploration matrices too), clipping, GAE and episode bookkeeping
(:mod:`ermrl.training.rollout`); with ``PPOConfig.normalize`` the observations the LSTMs see and the rewards are
normalized as SB3's ``VecNormalize`` does (:mod:`ermrl.ppo.normalize`), the episode returns staying raw.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from ermrl import envs
from ermrl.agent import Agent
from ermrl.envs.jax_backend import JaxEnv
from ermrl.errors import ConfigError
from ermrl.ppo import normalize, recurrent_update
from ermrl.ppo.losses import bootstrapped_gae
from ermrl.ppo.recurrent import RecurrentActorCritic, RecurrentState
from ermrl.ppo.update import init_learner
from ermrl.training.rollout import draw_noise


class RecurrentCarry(NamedTuple):
    """Per-env state carried between steps; every field has a leading (n_envs,) axis."""

    env_state: Any
    obs: jax.Array
    """(n_envs, obs_dim) the observation to act on next (normalized with ``PPOConfig.normalize``)."""
    lstm: RecurrentState
    """(n_envs, H) leaves: the LSTM states after the last step (not yet reset for a new episode)."""
    episode_start: jax.Array
    """(n_envs,) bool: the next step starts an episode (the last one ended, or training just began)."""
    episode_return: jax.Array
    episode_length: jax.Array
    norm: normalize.Normalizer | None = None
    """The agent's running statistics with ``PPOConfig.normalize`` (no n_envs axis but its ``returns``'s)."""


class RecurrentStep(NamedTuple):
    """One rollout step, each field (n_envs, ...); ``scan`` stacks them to (n_steps, n_envs, ...)."""

    obs: jax.Array
    action: jax.Array
    log_prob: jax.Array
    value: jax.Array
    reward: jax.Array
    """The reward PPO learns from (normalized with ``PPOConfig.normalize``)."""
    done: jax.Array
    truncated: jax.Array
    episode_start: jax.Array
    state: RecurrentState
    """The LSTM states before the step (before its episode-start reset), as RecurrentPPO's buffer stores them."""
    final_obs: jax.Array
    """The step's final observation (before any reset), for the truncation bootstrap."""
    finished_return: jax.Array
    finished_length: jax.Array


def check(config) -> None:
    """One-line ConfigErrors for what the LSTM baseline does not support (``config`` a TrainConfig)."""
    if config.agent.reservoirs != 0:
        raise ConfigError(f"the LSTM baseline (`model` lstm) sees the raw observation: use `reservoirs` 0, "
                          f"got {config.agent.reservoirs}")
    if envs.resolve_backend(config.env_id, config.backend) != "jax":
        raise ConfigError(f"the LSTM baseline (`model` lstm) runs on the JAX backend only, and {config.env_id} would "
                          f"run on the host (backend {config.backend!r}); JAX envs: {', '.join(envs.jax_ids())}")


def start(env: JaxEnv, net: RecurrentActorCritic, key: jax.Array, n_envs: int,
          normalized: bool = False) -> RecurrentCarry:
    """Resets n_envs envs; zero LSTM states and an episode start in every env. ``normalized``: start the
    normalization statistics from the first observations."""
    obs, env_state = jax.vmap(env.reset)(jax.random.split(key, n_envs))
    norm = None
    if normalized:
        norm, obs = normalize.start(obs)
    zeros = jnp.zeros((n_envs,), jnp.float32)
    return RecurrentCarry(env_state, obs, net.initial_state((n_envs,)), jnp.ones((n_envs,), bool), zeros,
                          jnp.zeros((n_envs,), jnp.int32), norm)


def collect(env: JaxEnv, net: RecurrentActorCritic, params, carry: RecurrentCarry, key: jax.Array, n_steps: int,
            gamma: float = 0.99, sde_sample_freq: int = -1):
    """Runs n_steps steps in each env. Returns the final carry and the stacked steps (n_steps, n_envs, ...).
    The randomness is drawn as :func:`ermrl.training.rollout.collect` draws it; ``gamma`` discounts the running
    return that normalizes rewards (unused without ``carry.norm``)."""
    n_envs = carry.obs.shape[0]
    k_act, k_env = jnp.moveaxis(jax.vmap(jax.random.split)(jax.random.split(key, n_steps)), 1, 0)
    noise = draw_noise(net, k_act, n_envs, sde_sample_freq)
    key_step, restart = jax.vmap(lambda k: jax.vmap(env.draw)(jax.random.split(k, n_envs)))(k_env)
    space = net.action

    def body(carry: RecurrentCarry, drawn):
        noise, key_step, restart = drawn
        lstm, head, value, latent = net.step(params, carry.lstm, carry.obs, carry.episode_start)
        action = net.sample(params, head, noise, latent)
        env_action = action if space.discrete else jnp.clip(action, jnp.asarray(space.low), jnp.asarray(space.high))
        tr = jax.vmap(env.step_from)(key_step, carry.env_state, env_action, restart)
        done = jnp.logical_or(tr.terminated, tr.truncated)
        episode_return = carry.episode_return + tr.reward
        episode_length = carry.episode_length + 1
        obs, final_obs, reward, norm = tr.obs, tr.final_obs, tr.reward, carry.norm
        if norm is not None:
            norm, obs, final_obs, reward = normalize.step(norm, obs, final_obs, reward, done, gamma)
        step = RecurrentStep(
            obs=carry.obs, action=action, log_prob=net.log_prob(params, head, action, latent), value=value,
            reward=reward, done=done, truncated=tr.truncated, episode_start=carry.episode_start,
            state=carry.lstm, final_obs=final_obs,
            finished_return=jnp.where(done, episode_return, jnp.nan),
            finished_length=jnp.where(done, episode_length, 0),
        )
        carry = RecurrentCarry(tr.state, obs, lstm, done, jnp.where(done, 0.0, episode_return),
                               jnp.where(done, 0, episode_length), norm)
        return carry, step

    return jax.lax.scan(body, carry, (noise, key_step, restart))


def sequence_batch(steps: RecurrentStep, advantage: jax.Array, ret: jax.Array) -> recurrent_update.SequenceBatch:
    """The rollout (n_steps, n_envs, ...) as the update's env-major rows, row = env · n_steps + t."""
    env_major = lambda x: jnp.swapaxes(x, 0, 1).reshape((-1,) + x.shape[2:])
    return recurrent_update.SequenceBatch(
        env_major(steps.obs), env_major(steps.action), env_major(steps.log_prob), env_major(advantage),
        env_major(ret), env_major(steps.episode_start), jax.tree.map(env_major, steps.state))


def make_recurrent_fns(config):
    """The :class:`~ermrl.training.state.AgentFns` of the LSTM baseline for ``config`` (a TrainConfig)."""
    from ermrl.training.state import AgentFns, AgentState, IterationLog

    check(config)
    env = envs.make(config.env_id, config.backend)
    agent = Agent(config.agent, env.info)
    ppo = config.ppo
    ppo.check_actions(config.env_id, env.info.action.discrete)
    net = RecurrentActorCritic.of(env.info.action, ppo)

    def init(seed, unit_weights, phi, learning_rate, first_obs) -> AgentState:
        del unit_weights, phi, first_obs  # no reservoir; JAX envs reset themselves
        k_policy, k_env, k_next = jax.random.split(jax.random.PRNGKey(seed), 3)
        learner = init_learner(net, ppo, k_policy, env.info.obs_dim, learning_rate)
        return AgentState(learner, None, start(env, net, k_env, ppo.n_envs, ppo.normalize), k_next)

    def learn(state: AgentState, carry: RecurrentCarry, steps: RecurrentStep, k_update):
        params = state.learner.params
        # V(final observation): the critic state after step t is the one stored before step t + 1 (the carry's
        # after the last step), so all of them take one batched LSTM step rather than one per rollout step.
        after = jax.tree.map(lambda s, last: jnp.concatenate([s[1:], last[None]]), steps.state.vf, carry.lstm.vf)
        final_value = net.step_value(params, after, steps.final_obs)
        _, _, last_value, _ = net.step(params, carry.lstm, carry.obs, carry.episode_start)
        advantage, ret = bootstrapped_gae(steps.reward, steps.value, steps.done, steps.truncated, final_value,
                                          last_value, ppo.gamma, ppo.gae_lambda)
        batch = sequence_batch(steps, advantage, ret)
        learner, metrics = recurrent_update.update(state.learner, batch, k_update, net, ppo)
        leaves = jax.tree.leaves(learner.params) + list(metrics.values())
        finite = jnp.all(jnp.array([jnp.all(jnp.isfinite(x)) for x in leaves]))
        log = IterationLog(steps.finished_return, steps.finished_length, metrics, finite)
        return AgentState(learner, None, carry, state.key), log

    def rollout(state: AgentState):
        key, k_roll, k_update = jax.random.split(state.key, 3)
        carry, steps = collect(env, net, state.learner.params, state.envs, k_roll, ppo.n_steps, ppo.gamma,
                               ppo.sde_sample_freq)
        return state._replace(key=key), carry, steps, k_update

    return AgentFns(env, agent, net, init, rollout, learn)
