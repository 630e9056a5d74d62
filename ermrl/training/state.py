"""One agent's functions and what they carry (a TrainConfig's :class:`AgentFns`, built by
:func:`ermrl.training.programs.make_agent_fns` or, for the LSTM baseline, :mod:`ermrl.training.recurrent`)."""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax

from ermrl.agent import Agent, Reservoirs
from ermrl.envs import HostEnv, JaxEnv
from ermrl.ppo import update as ppo_update
from ermrl.ppo.networks import ActorCritic
from ermrl.training.rollout import EnvCarry


class AgentState(NamedTuple):
    """Everything one agent carries between iterations."""

    learner: ppo_update.LearnerState
    reservoirs: Reservoirs
    envs: EnvCarry
    key: jax.Array


def kept_leaves(state: AgentState) -> list:
    """The leaves of ``state`` that a snapshot keeps: all but the reservoirs' weights, which never change during
    training and are drawn again from the seeds and Φ on resume (at 1000 units they are 4 MB an agent)."""
    return jax.tree.leaves(state._replace(reservoirs=None))


class IterationLog(NamedTuple):
    """What one iteration reports per agent."""

    finished_return: jax.Array
    """(n_steps, n_envs) returns of the episodes that ended at each step, NaN elsewhere."""
    finished_length: jax.Array
    """(n_steps, n_envs) lengths, 0 elsewhere."""
    metrics: dict
    """Scalars averaged over the update's minibatches."""
    finite: jax.Array
    """() bool: parameters and losses are all finite."""


class AgentFns(NamedTuple):
    """The pure per-agent functions of a TrainConfig (purejaxrl's ``make_train``); ``vmap`` adds the agent axis."""

    env: JaxEnv | HostEnv
    agent: Agent
    net: ActorCritic
    init: Callable
    """(seed, unit_weights, phi, learning_rate, first_obs) -> AgentState. ``first_obs`` (n_envs, obs_dim) are
    the reset observations of host envs; None on the JAX backend, which resets its own envs."""
    rollout: Callable
    """AgentState -> (AgentState with its next key, final EnvCarry, Step (n_steps, n_envs, ...), update key): the
    rollout half of an iteration on the JAX backend, whose outputs ``learn`` takes."""
    learn: Callable
    """(AgentState, final EnvCarry, Step (n_steps, n_envs, ...), key) -> (AgentState, IterationLog)."""
