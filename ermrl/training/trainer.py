"""Trains a population of ER-MRL agents as one jitted program (paper §3, "Inner loop").

Each of the A agents has its own Φ, seed, reservoirs, policy, optimizer and envs. One call of the jitted
``iteration`` runs, for every agent at once (``vmap``), a rollout of n_steps and a PPO update; the agent
axis is sharded over the machine's devices (both CPU cores here) with ``shard_map``. The host loop over
iterations only reports progress and gathers finished episodes.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from pathlib import Path
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ermrl import envs, provenance
from ermrl.agent import Agent, AgentConfig, Phi, Reservoirs
from ermrl.errors import ConfigError
from ermrl.training.host_loop import HostIteration
from ermrl.ppo import update as ppo_update
from ermrl.ppo.config import PPOConfig
from ermrl.ppo.losses import Batch, bootstrapped_gae
from ermrl.ppo.networks import ActorCritic
from ermrl.training.results import WALL_S, Policies, Results
from ermrl.envs import HostEnv, JaxEnv
from ermrl.envs.host_groups import ReplayMismatch
from ermrl.training import snapshots
from ermrl.training.rollout import EnvCarry, Step, collect, start, start_from_obs


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
    """'auto' (JAX when the env has a JAX version, else Gymnasium on the host), 'jax' or 'host'."""
    env_workers: int | str = "auto"
    """Host backend only: processes that step the envs (0: the main process; 'auto': one per device when an
    env step costs more than the IPC). Results do not depend on it."""

    def __post_init__(self):
        if self.total_timesteps < 1:
            raise ConfigError(f"total timesteps must be >= 1, got {self.total_timesteps}")
        if self.env_workers != "auto" and not (isinstance(self.env_workers, int) and self.env_workers >= 0):
            raise ConfigError(f"env workers must be 'auto' or an integer >= 0, got {self.env_workers!r}")


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
    def grid(phis: list[Phi] | Phi, seeds: int | list[int], learning_rate: float | list[float],
             reservoirs: int) -> "Population":
        """Every Φ crossed with every learning rate and every seed: agent i = (phis[i // (L·S)],
        learning_rates[i // S % L], seeds[i % S]). Φ fields are scalars or (K,)."""
        phis = [phis] if isinstance(phis, Phi) else list(phis)
        seed_list = list(range(seeds)) if isinstance(seeds, int) else list(seeds)
        lrs = [learning_rate] if np.ndim(learning_rate) == 0 else list(learning_rate)
        as_k = lambda v: np.broadcast_to(np.asarray(v, np.float32), (reservoirs,))
        rows = [(p, lr, s) for p in phis for lr in lrs for s in seed_list]
        return Population(
            seeds=np.array([s for _, _, s in rows], np.int64),
            phi=Phi(*(np.stack([as_k(getattr(p, f)) for p, _, _ in rows]) for f in Phi._fields)),
            learning_rate=np.array([lr for _, lr, _ in rows], np.float32),
        )


    @staticmethod
    def concat(parts: list["Population"]) -> "Population":
        """The agents of ``parts``, in order, as one population (Φ with the same K in every part)."""
        return Population(seeds=np.concatenate([p.seeds for p in parts]),
                          phi=Phi(*(np.concatenate([getattr(p.phi, f) for p in parts]) for f in Phi._fields)),
                          learning_rate=np.concatenate([p.learning_rate for p in parts]))


class AgentState(NamedTuple):
    """Everything one agent carries between iterations."""

    learner: ppo_update.LearnerState
    reservoirs: Reservoirs
    envs: EnvCarry
    key: jax.Array


def _kept_leaves(state: AgentState) -> list:
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


class AgentFns(NamedTuple):
    """The pure per-agent functions of a TrainConfig (purejaxrl's ``make_train``); ``vmap`` adds the agent axis."""

    env: JaxEnv | HostEnv
    agent: Agent
    net: ActorCritic
    init: Callable
    """(seed, unit_weights, phi, learning_rate, first_obs) -> AgentState. ``first_obs`` (n_envs, obs_dim) are
    the reset observations of host envs; None on the JAX backend, which resets its own envs."""
    iteration: Callable
    """AgentState -> (AgentState, IterationLog): rollout and update, JAX backend only."""
    learn: Callable
    """(AgentState, final EnvCarry, Step (n_steps, n_envs, ...), key) -> (AgentState, IterationLog)."""


def make_agent_fns(config: TrainConfig) -> AgentFns:
    """Builds the per-agent functions for ``config``'s env, agent and PPO settings (``ppo.model = "lstm"``: the
    recurrent baseline's, :func:`ermrl.training.recurrent.make_recurrent_fns`)."""
    if config.ppo.model == "lstm":
        from ermrl.training.recurrent import make_recurrent_fns

        return make_recurrent_fns(config)
    env = envs.make(config.env_id, config.backend, config.env_workers)
    agent = Agent(config.agent, env.info)
    net = ActorCritic(env.info.action, config.ppo.hidden, config.ppo.log_std_init)
    ppo = config.ppo

    def init(seed, unit_weights, phi: Phi, learning_rate, first_obs) -> AgentState:
        key = jax.random.PRNGKey(seed)
        k_policy, k_env, k_next = jax.random.split(key, 3)
        res = Agent.build(unit_weights, phi)
        learner = ppo_update.init_learner(net, ppo, k_policy, agent.context_dim, learning_rate)
        if first_obs is None:
            carry = start(env, agent, res, k_env, ppo.n_envs)
        else:  # host envs: the env state lives on the host
            carry = start_from_obs(agent, res, first_obs, jnp.zeros((ppo.n_envs,), jnp.int32))
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

    def iteration(state: AgentState) -> tuple[AgentState, IterationLog]:
        key, k_roll, k_update = jax.random.split(state.key, 3)
        carry, steps = collect(env, agent, net, state.learner.params, state.reservoirs, state.envs, k_roll,
                               ppo.n_steps)
        return learn(state._replace(key=key), carry, steps, k_update)

    return AgentFns(env, agent, net, init, iteration, learn)


def _pad(x: np.ndarray, size: int) -> np.ndarray:
    """Pads the leading axis to ``size`` by repeating the first row (padded agents are discarded)."""
    extra = size - x.shape[0]
    return x if extra == 0 else np.concatenate([x, np.repeat(x[:1], extra, axis=0)])


class Programs(NamedTuple):
    """A config's jitted population functions over a device mesh, and its compiled iterations."""

    fns: AgentFns
    sharding: NamedSharding
    """Agent axis over the mesh's devices."""
    init: Callable
    """Jitted, sharded ``fns.init`` over a padded population."""
    iteration: Callable
    """Jitted, sharded ``fns.iteration`` (donates its state)."""
    learn: Callable
    """Jitted, sharded ``fns.learn`` (donates its state)."""
    compiled: dict[int, Callable]
    """Padded population size -> the compiled iteration for it."""


def build_programs(config: TrainConfig, devices: tuple) -> Programs:
    """Jits ``config``'s per-agent functions, ``vmap``-ed over agents and sharded over ``devices``."""
    fns = make_agent_fns(config)
    mesh = Mesh(np.array(devices), ("agents",))
    spec = PartitionSpec("agents")
    shard = lambda f: jax.shard_map(jax.vmap(f), mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False)
    return Programs(fns, NamedSharding(mesh, spec), jax.jit(shard(fns.init)),
                    jax.jit(shard(fns.iteration), donate_argnums=0), jax.jit(shard(fns.learn), donate_argnums=0), {})


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
    if backend == "host":
        return build_programs(config, devices)
    return _shared_programs(dataclasses.replace(config, total_timesteps=1, backend=backend, env_workers=0), devices)


class Trainer:
    """Trains any population of one TrainConfig with its compiled population program (:func:`programs_for`)."""

    def __init__(self, config: TrainConfig, devices=None):
        self.config = config
        self.devices = list(devices if devices is not None else jax.devices())
        self.programs = programs_for(config, tuple(self.devices))
        self.fns, self.sharding = self.programs.fns, self.programs.sharding
        self.env, self.agent = self.fns.env, self.fns.agent
        self.host = isinstance(self.env, HostEnv)
        self.n_iterations = config.ppo.iterations(config.total_timesteps)

    def _padded_size(self, n: int) -> int:
        d = len(self.devices)
        return -(-n // d) * d

    def init(self, population: Population) -> AgentState:
        """Initial states for the (padded) population, sharded over devices. On the host backend this opens
        the population's envs (slot agent · n_envs + env, seeded from the agent's seed) and resets them."""
        size = self._padded_size(population.size)
        seeds = _pad(population.seeds.astype(np.uint32), size)
        units = [self.agent.unit_weights(int(s)) for s in population.seeds]
        unit = None if units[0] is None else jax.tree.map(lambda *xs: _pad(np.stack(xs), size), *units)
        phi = None if unit is None else Phi(*(_pad(np.asarray(f, np.float32), size) for f in population.phi))
        first_obs = None
        if self.host:
            n_envs = self.config.ppo.n_envs
            self.env.open(size * n_envs)
            env_seeds = [np.random.SeedSequence([int(s), e]).generate_state(1)[0] for s in seeds for e in range(n_envs)]
            first_obs = self.env.reset(np.array(env_seeds)).reshape(size, n_envs, -1)
        args = (seeds, unit, phi, _pad(np.asarray(population.learning_rate, np.float32), size), first_obs)
        return self.programs.init(*jax.device_put(args, self.sharding))

    def compiled(self, state: AgentState) -> Callable:
        """The iteration compiled for ``state``'s population size; one compile per size, reused by later runs."""
        size = jax.tree.leaves(state)[0].shape[0]
        compiled = self.programs.compiled
        if size not in compiled:
            if self.host:
                iteration = HostIteration(self.fns, self.config.ppo, self.programs.learn, self.sharding,
                                          self.devices[0])
                iteration.warm_up(state)
                compiled[size] = iteration
            else:
                compiled[size] = self.programs.iteration.lower(state).compile()
        return compiled[size]

    def close(self):
        """Closes the host envs (and their worker processes); ``init`` reopens them. No-op on the JAX backend."""
        if self.host:
            self.env.close()

    def step(self, state: AgentState) -> tuple[AgentState, IterationLog]:
        """One rollout + PPO update for every agent (donates ``state``)."""
        return self.compiled(state)(state)

    def _loop(self, compiled, state: AgentState, n: int, compile_s: float, progress_fn,
              resumed: snapshots.Snapshot | None, saver: Callable | None):
        """The host loop over iterations: gathers finished episodes and metrics of the first n agents; returns
        them with the final state and the train time. ``resumed`` continues a stopped run; ``saver(snapshot)``
        is called after every iteration (it writes one when its interval is up)."""
        steps_per_iter = self.config.ppo.buffer_size
        if resumed is None:
            first, finished, metrics, finite, before = 0, [], [], np.ones(n, bool), 0.0
        else:
            first, before = resumed.iteration, resumed.train_s
            finished, metrics, finite = list(resumed.finished), list(resumed.metrics), resumed.finite.copy()
        t1 = time.perf_counter()
        for it in range(first, self.n_iterations):
            state, log = compiled(state)
            ret, length = np.asarray(log.finished_return)[:n], np.asarray(log.finished_length)[:n]
            finished.append((ret, length))
            finite &= np.asarray(log.finite)[:n]
            elapsed = before + time.perf_counter() - t1  # after the transfers above: this update is done
            metrics.append({**{k: np.asarray(v)[:n] for k, v in log.metrics.items()}, WALL_S: np.full(n, elapsed)})
            if progress_fn is not None:
                progress_fn(Progress(it + 1, self.n_iterations, (it + 1) * steps_per_iter * n,
                                     self.n_iterations * steps_per_iter * n, elapsed, compile_s))
            if saver is not None and it + 1 < self.n_iterations:
                saver(lambda: snapshots.Snapshot(
                    it + 1, jax.device_get(_kept_leaves(state)), self.env.snapshot() if self.host else None,
                    finished, metrics, finite, compile_s, before + time.perf_counter() - t1))
        return finished, metrics, finite, state, before + time.perf_counter() - t1

    def _resume(self, state: AgentState, snap: snapshots.Snapshot) -> AgentState | None:
        """``state`` (just initialized, envs open) brought to ``snap``; None when the snapshot does not fit it
        or its envs do not replay exactly (the run then starts over)."""
        whole = len(snap.leaves) == len(jax.tree.leaves(state))  # a snapshot written with its reservoirs (before
        kept = state if whole else state._replace(reservoirs=None)  # 2026-11-24): restored as it is
        fresh = jax.tree.leaves(kept)
        if len(fresh) != len(snap.leaves) or any(a.shape != b.shape or a.dtype != b.dtype
                                                 for a, b in zip(fresh, snap.leaves)):
            return None
        if self.host:
            try:
                self.env.restore(snap.envs)
            except ReplayMismatch:
                return None
        leaves = [jax.device_put(x, like.sharding) for x, like in zip(snap.leaves, fresh)]
        restored = jax.tree.unflatten(jax.tree.structure(kept), leaves)
        return restored if whole else restored._replace(reservoirs=state.reservoirs)

    def run(self, population: Population, progress_fn: Callable[[Progress], None] | None = None,
            snapshot: Path | None = None, snapshot_every_s: float = 300.0,
            log: Callable[[str], None] | None = None) -> Results:
        """Trains every agent of ``population`` for ``total_timesteps``; returns curves, fitness and every
        agent's final policy (``Results.policies``).

        With ``snapshot`` (a file path), the run's state is written there every ``snapshot_every_s`` seconds,
        and a run that finds a snapshot of the same config and population there continues from it, to the same
        Results as an unbroken run (:mod:`ermrl.training.snapshots`). The caller removes the file once it has
        kept the Results. ``log`` gets a line when a run resumes or cannot."""
        ppo = self.config.ppo
        n = population.size
        t0 = time.perf_counter()
        ident = None if snapshot is None else snapshots.identity(self.config, population, len(self.devices))
        try:
            state = self.init(population)
            resumed = None if snapshot is None else snapshots.read(snapshot, ident)
            if resumed is not None:
                restored = self._resume(state, resumed)
                if restored is None:
                    state = self.init(population)  # the failed replay moved the envs: reset them again
                    if log:
                        log(f"{snapshot} does not replay exactly on this machine; training from the start")
                    resumed = None
                else:
                    state = restored
                    if log:
                        changed = provenance.differences(resumed.software or {})
                        log(f"resumed from {snapshot} at iteration {resumed.iteration} of {self.n_iterations}"
                            + (f"; it was written under other versions ({', '.join(changed)}), so the rest of the "
                               "run is not bit for bit what they would compute" if changed else ""))
            compiled = self.compiled(state)
            compile_s = time.perf_counter() - t0 if resumed is None else resumed.compile_s
            saver = None if snapshot is None else _Saver(Path(snapshot), ident, snapshot_every_s)
            finished, metrics, finite, state, train_s = self._loop(compiled, state, n, compile_s, progress_fn,
                                                                        resumed, saver)
            # the final policies, in one transfer after the loop (the first n agents; padding dropped)
            policies = Policies.from_params(self.env.info, jax.device_get(state.learner.params), n)
        finally:
            self.close()
        return Results.from_iterations(
            config=self.config, population=population, finished=finished, metrics=metrics, finite=finite,
            n_envs=ppo.n_envs, compile_s=compile_s, train_s=train_s, policies=policies,
        )


class _Saver:
    """Writes a snapshot when ``every_s`` seconds have passed since the last (or since the start)."""

    def __init__(self, path: Path, ident: dict, every_s: float):
        self.path, self.ident, self.every_s = path, ident, every_s
        self.last = time.perf_counter()

    def __call__(self, make: Callable[[], snapshots.Snapshot]) -> None:
        if time.perf_counter() - self.last >= self.every_s:
            snapshots.write(self.path, self.ident, make())
            self.last = time.perf_counter()


def train(config: TrainConfig, population: Population, progress_fn=None) -> Results:
    """Compiles and trains in one call."""
    return Trainer(config).run(population, progress_fn)
