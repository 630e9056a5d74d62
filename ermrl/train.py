"""Trains a population of ER-MRL agents as one jitted program (paper §3, "Inner loop").

Each of the A agents has its own Φ, seed, reservoirs, policy, optimizer and envs. One call of the jitted
``iteration`` runs, for every agent at once (``vmap``), a rollout of n_steps and a PPO update; the agent
axis is sharded over the machine's devices (both CPU cores here) with ``shard_map``. The host loop over
iterations only reports progress and gathers finished episodes.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ermrl import envs
from ermrl.agent import Agent, AgentConfig, Phi, Reservoirs
from ermrl.errors import ConfigError
from ermrl.ppo import update as ppo_update
from ermrl.ppo.config import PPOConfig
from ermrl.ppo.losses import Batch, gae
from ermrl.ppo.networks import ActorCritic
from ermrl.results import Results
from ermrl.rollout import EnvCarry, collect, start


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything static about a population's training (one compile serves any Φ, seeds and learning rates)."""

    env_id: str = "CartPoleNoVel-v1"
    """Gymnasium-style id; NoVel ids delete the velocity dims."""
    total_timesteps: int = 300_000
    """Env steps per agent; like SB3, training stops at the first update boundary at or past it."""
    agent: AgentConfig = AgentConfig()
    ppo: PPOConfig = PPOConfig()
    backend: str = "auto"
    """'auto' (JAX when the env has a JAX version) or 'jax'."""

    def __post_init__(self):
        if self.total_timesteps < 1:
            raise ConfigError(f"total timesteps must be >= 1, got {self.total_timesteps}")


@dataclasses.dataclass(frozen=True)
class Population:
    """Per-agent inputs, each with a leading agent axis of length A."""

    seeds: np.ndarray
    """(A,) int: seeds reservoir weights (seed + k for reservoir k), policy init and envs."""
    phi: Phi
    """Fields (A, K) float32."""
    learning_rate: np.ndarray
    """(A,) float32 PPO step sizes."""

    @property
    def size(self) -> int:
        return len(self.seeds)

    @staticmethod
    def grid(phis: list[Phi] | Phi, seeds: int | list[int], learning_rate: float, reservoirs: int) -> "Population":
        """Every Φ crossed with every seed: agent i = (phis[i // S], seeds[i % S]). Φ fields are scalars or (K,)."""
        phis = [phis] if isinstance(phis, Phi) else list(phis)
        seed_list = list(range(seeds)) if isinstance(seeds, int) else list(seeds)
        as_k = lambda v: np.broadcast_to(np.asarray(v, np.float32), (reservoirs,))
        rows = [(p, s) for p in phis for s in seed_list]
        return Population(
            seeds=np.array([s for _, s in rows], np.int64),
            phi=Phi(*(np.stack([as_k(getattr(p, f)) for p, _ in rows]) for f in Phi._fields)),
            learning_rate=np.full(len(rows), learning_rate, np.float32),
        )


class AgentState(NamedTuple):
    """Everything one agent carries between iterations."""

    learner: ppo_update.LearnerState
    reservoirs: Reservoirs
    envs: EnvCarry
    key: jax.Array


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


@dataclasses.dataclass(frozen=True)
class Progress:
    """Passed to ``progress_fn`` after every iteration."""

    iteration: int
    n_iterations: int
    agent_steps: int
    """Env steps done, summed over agents."""
    total_agent_steps: int
    elapsed_s: float
    """Wall time since training started, compile excluded."""
    compile_s: float


def make_agent_fns(config: TrainConfig):
    """Builds the pure per-agent ``init`` and ``iteration`` functions (purejaxrl's ``make_train``)."""
    env = envs.make(config.env_id, config.backend)
    agent = Agent(config.agent, env.info)
    net = ActorCritic(env.info.action, config.ppo.hidden, config.ppo.log_std_init)
    ppo = config.ppo

    def init(seed, unit_weights, phi: Phi, learning_rate) -> AgentState:
        key = jax.random.PRNGKey(seed)
        k_policy, k_env, k_next = jax.random.split(key, 3)
        res = Agent.build(unit_weights, phi)
        learner = ppo_update.init_learner(net, ppo, k_policy, agent.context_dim, learning_rate)
        return AgentState(learner, res, start(env, agent, res, k_env, ppo.n_envs), k_next)

    def iteration(state: AgentState) -> tuple[AgentState, IterationLog]:
        key, k_roll, k_update = jax.random.split(state.key, 3)
        params = state.learner.params
        carry, steps = collect(env, agent, net, params, state.reservoirs, state.envs, k_roll, ppo.n_steps)
        final_value = net.value(params, steps.final_context)
        reward = steps.reward + ppo.gamma * final_value * steps.truncated
        advantage, ret = gae(reward, steps.value, steps.done, net.value(params, carry.context), ppo.gamma, ppo.gae_lambda)
        flat = lambda x: x.reshape((ppo.buffer_size,) + x.shape[2:])
        batch = Batch(flat(steps.context), flat(steps.action), flat(steps.log_prob), flat(advantage), flat(ret))
        learner, metrics = ppo_update.update(state.learner, batch, k_update, net, ppo)
        leaves = jax.tree.leaves(learner.params) + list(metrics.values())
        finite = jnp.all(jnp.array([jnp.all(jnp.isfinite(x)) for x in leaves]))
        log = IterationLog(steps.finished_return, steps.finished_length, metrics, finite)
        return AgentState(learner, state.reservoirs, carry, key), log

    return agent, init, iteration


def _pad(x: np.ndarray, size: int) -> np.ndarray:
    """Pads the leading axis to ``size`` by repeating the first row (padded agents are discarded)."""
    extra = size - x.shape[0]
    return x if extra == 0 else np.concatenate([x, np.repeat(x[:1], extra, axis=0)])


class Trainer:
    """Compiles the population program for one TrainConfig; ``run`` trains any population with it."""

    def __init__(self, config: TrainConfig, devices=None):
        self.config = config
        self.agent, init, iteration = make_agent_fns(config)
        self.devices = list(devices if devices is not None else jax.devices())
        self.mesh = Mesh(np.array(self.devices), ("agents",))
        self.sharding = NamedSharding(self.mesh, PartitionSpec("agents"))
        spec = PartitionSpec("agents")
        shard = lambda f: jax.shard_map(jax.vmap(f), mesh=self.mesh, in_specs=spec, out_specs=spec, check_vma=False)
        self._init = jax.jit(shard(init))
        self._iteration = jax.jit(shard(iteration), donate_argnums=0)
        self.n_iterations = config.ppo.iterations(config.total_timesteps)
        self._compiled: dict[int, jax.stages.Compiled] = {}

    def _padded_size(self, n: int) -> int:
        d = len(self.devices)
        return -(-n // d) * d

    def init(self, population: Population) -> AgentState:
        """Initial states for the (padded) population, sharded over devices."""
        size = self._padded_size(population.size)
        units = [self.agent.unit_weights(int(s)) for s in population.seeds]
        unit = None if units[0] is None else jax.tree.map(lambda *xs: _pad(np.stack(xs), size), *units)
        phi = None if unit is None else Phi(*(_pad(np.asarray(f, np.float32), size) for f in population.phi))
        args = (
            _pad(population.seeds.astype(np.uint32), size),
            unit,
            phi,
            _pad(np.asarray(population.learning_rate, np.float32), size),
        )
        return self._init(*jax.device_put(args, self.sharding))

    def compiled(self, state: AgentState):
        """The iteration compiled for ``state``'s population size; one compile per size, reused by later runs."""
        size = jax.tree.leaves(state)[0].shape[0]
        if size not in self._compiled:
            self._compiled[size] = self._iteration.lower(state).compile()
        return self._compiled[size]

    def step(self, state: AgentState) -> tuple[AgentState, IterationLog]:
        """One rollout + PPO update for every agent (donates ``state``)."""
        return self._iteration(state)

    def run(self, population: Population, progress_fn: Callable[[Progress], None] | None = None) -> Results:
        """Trains every agent of ``population`` for ``total_timesteps``; returns curves and fitness."""
        ppo = self.config.ppo
        n = population.size
        t0 = time.perf_counter()
        state = self.init(population)
        compiled = self.compiled(state)
        compile_s = time.perf_counter() - t0
        steps_per_iter = ppo.buffer_size
        finished: list[tuple[np.ndarray, np.ndarray]] = []
        metrics, finite = [], np.ones(n, bool)
        t1 = time.perf_counter()
        for it in range(self.n_iterations):
            state, log = compiled(state)
            ret, length = np.asarray(log.finished_return)[:n], np.asarray(log.finished_length)[:n]
            finished.append((ret, length))
            metrics.append({k: np.asarray(v)[:n] for k, v in log.metrics.items()})
            finite &= np.asarray(log.finite)[:n]
            if progress_fn is not None:
                progress_fn(Progress(it + 1, self.n_iterations, (it + 1) * steps_per_iter * n,
                                     self.n_iterations * steps_per_iter * n, time.perf_counter() - t1, compile_s))
        train_s = time.perf_counter() - t1
        return Results.from_iterations(
            config=self.config, population=population, finished=finished, metrics=metrics, finite=finite,
            n_envs=ppo.n_envs, compile_s=compile_s, train_s=train_s,
        )


def train(config: TrainConfig, population: Population, progress_fn=None) -> Results:
    """Compiles and trains in one call."""
    return Trainer(config).run(population, progress_fn)
