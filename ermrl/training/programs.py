"""A TrainConfig's per-agent functions (:func:`make_agent_fns`, purejaxrl's ``make_train``) and their jitted,
sharded population programs (:class:`Programs`), kept per static config in the process (:func:`programs_for`)."""

from __future__ import annotations

import dataclasses
import functools
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ermrl import envs
from ermrl.agent import Agent, Phi
from ermrl.ppo import update as ppo_update
from ermrl.ppo.losses import Batch, bootstrapped_gae
from ermrl.ppo.networks import ActorCritic
from ermrl.training.config import TrainConfig
from ermrl.training.rollout import EnvCarry, Step, collect, start, start_from_obs
from ermrl.training.state import AgentFns, AgentState, IterationLog


def make_agent_fns(config: TrainConfig) -> AgentFns:
    """Builds the per-agent functions for ``config``'s env, agent and PPO settings (``ppo.model = "lstm"``: the
    recurrent baseline's, :func:`ermrl.training.recurrent.make_recurrent_fns`)."""
    if config.ppo.model == "lstm":
        from ermrl.training.recurrent import make_recurrent_fns

        return make_recurrent_fns(config)
    env = envs.make(config.env_id, config.backend, config.env_workers, config.env_threads)
    agent = Agent(config.agent, env.info)
    ppo = config.ppo
    ppo.check_actions(config.env_id, env.info.action.discrete)
    net = ActorCritic.of(env.info.action, ppo)

    def init(seed, unit_weights, phi: Phi, learning_rate, first_obs) -> AgentState:
        key = jax.random.PRNGKey(seed)
        k_policy, k_env, k_next = jax.random.split(key, 3)
        res = Agent.build(unit_weights, phi)
        learner = ppo_update.init_learner(net, ppo, k_policy, agent.context_dim, learning_rate)
        if first_obs is None:
            carry = start(env, agent, res, k_env, ppo.n_envs, ppo.normalize)
        else:  # host envs: the env state lives on the host
            carry = start_from_obs(agent, res, first_obs, jnp.zeros((ppo.n_envs,), jnp.int32), ppo.normalize)
        return AgentState(learner, res, carry, k_next)

    def learn(state: AgentState, carry: EnvCarry, steps: Step, k_update) -> tuple[AgentState, IterationLog]:
        params = state.learner.params
        advantage, ret = bootstrapped_gae(steps.reward, steps.value, steps.done, steps.truncated,
                                          net.value(params, steps.final_context), net.value(params, carry.context),
                                          ppo.gamma, ppo.gae_lambda)
        flat = lambda x: x.reshape((ppo.buffer_size,) + x.shape[2:])
        batch = Batch(flat(steps.context), flat(steps.action), flat(steps.log_prob), flat(advantage), flat(ret))
        learner, metrics = ppo_update.update(state.learner, batch, k_update, net, ppo)
        leaves = jax.tree.leaves(learner.params) + list(metrics.values())
        finite = jnp.all(jnp.array([jnp.all(jnp.isfinite(x)) for x in leaves]))
        log = IterationLog(steps.finished_return, steps.finished_length, metrics, finite)
        return AgentState(learner, state.reservoirs, carry, state.key), log

    def rollout(state: AgentState) -> tuple[AgentState, EnvCarry, Step, jax.Array]:
        key, k_roll, k_update = jax.random.split(state.key, 3)
        carry, steps = collect(env, agent, net, state.learner.params, state.reservoirs, state.envs, k_roll,
                               ppo.n_steps, ppo.gamma, ppo.sde_sample_freq)
        return state._replace(key=key), carry, steps, k_update

    return AgentFns(env, agent, net, init, rollout, learn)


class Programs(NamedTuple):
    """A config's jitted population functions over a device mesh, and its compiled iterations."""

    fns: AgentFns
    sharding: NamedSharding
    """Agent axis over the mesh's devices."""
    init: Callable
    """Jitted, sharded ``fns.init`` over a padded population."""
    iteration: Callable
    """Jitted, sharded rollout and update (donates its state): ``fns.rollout`` for the agents of a device at
    once (``vmap``), then ``fns.learn`` one agent after the other (``lax.map``)."""
    learn: Callable
    """Jitted, sharded ``fns.learn``, one agent after the other (donates its state)."""
    compiled: dict[int, Callable]
    """Padded population size -> the compiled iteration for it."""


def build_programs(config: TrainConfig, devices: tuple) -> Programs:
    """Jits ``config``'s per-agent functions over a population sharded over ``devices``. The rollout is
    ``vmap``-ed over each device's agents; the initialization and the update run one agent after the other
    (``lax.map``), each on its own shapes: XLA:CPU rounds a batched QR (the orthogonal init) and the update's
    reductions differently for different batch sizes, and an agent must train the same alone as inside any
    population (studies trained together; see also :mod:`ermrl.ppo.ordered`)."""
    fns = make_agent_fns(config)
    mesh = Mesh(np.array(devices), ("agents",))
    spec = PartitionSpec("agents")
    shard = lambda f: jax.shard_map(f, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False)

    def one_by_one(f):
        def each(*xs):
            return jax.lax.map(lambda x: f(*x), xs)

        each.__name__ = f.__name__  # the compiled program's name (``jit_init``, ``jit_learn``)
        return each

    def iteration(state: AgentState) -> tuple[AgentState, IterationLog]:
        return one_by_one(fns.learn)(*jax.vmap(fns.rollout)(state))

    return Programs(fns, NamedSharding(mesh, spec), jax.jit(shard(one_by_one(fns.init))),
                    jax.jit(shard(iteration), donate_argnums=0), jax.jit(shard(one_by_one(fns.learn)), donate_argnums=0),
                    {})


@functools.lru_cache(maxsize=8)
def _shared_programs(config: TrainConfig, devices: tuple) -> Programs:
    return build_programs(config, devices)


def programs_for(config: TrainConfig, devices: tuple) -> Programs:
    """The programs of ``config`` on ``devices``. On the JAX backend one set serves every Trainer of the same
    static config in the process (the last 8 configs kept), so building a Trainer again (a selection or test phase
    after an evolution, a notebook, a test) neither traces nor compiles again; ``total_timesteps`` only sets the
    number of iterations and is not part of the key. Host-backend Trainers get their own: their functions hold
    the Gymnasium envs that the Trainer opens and closes."""
    backend = envs.resolve_backend(config.env_id, config.backend)
    if backend in envs.HOST_BACKENDS:
        return build_programs(config, devices)
    return _shared_programs(dataclasses.replace(config, total_timesteps=1, backend=backend, env_workers=0), devices)
