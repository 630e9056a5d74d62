"""Trains a population of ER-MRL agents as one jitted program (paper §3, "Inner loop").

Each of the A agents has its own Φ, seed, reservoirs, policy, optimizer and envs. One call of the jitted
``iteration`` (:mod:`ermrl.training.programs`) runs, for every agent at once (``vmap``), a rollout of n_steps and a
PPO update; the agent axis is sharded over the machine's devices (both CPU cores here) with ``shard_map``. The host
loop over iterations here only reports progress, keeps snapshots and gathers finished episodes.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Callable

import jax
import numpy as np

from ermrl import devices as cpu_devices
from ermrl import provenance
from ermrl.agent import Phi
from ermrl.envs import HostEnv
from ermrl.envs.host_groups import ReplayMismatch
from ermrl.training import memory, snapshots
from ermrl.training.config import Population, TrainConfig
from ermrl.training.host_loop import HostIteration
from ermrl.training.programs import programs_for
from ermrl.training.state import AgentState, IterationLog, kept_leaves
from ermrl.training.results import WALL_S, Policies, Results


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


def _pad(x: np.ndarray, size: int) -> np.ndarray:
    """Pads the leading axis to ``size`` by repeating the first row (padded agents are discarded)."""
    extra = size - x.shape[0]
    return x if extra == 0 else np.concatenate([x, np.repeat(x[:1], extra, axis=0)])


class Trainer:
    """Trains any population of one TrainConfig with its compiled population program (:func:`programs_for`)."""

    def __init__(self, config: TrainConfig, devices=None):
        self.config = config
        if devices is None:
            cpu_devices.setup()  # one CPU device per core, unless the process started JAX's backends before
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
            if saver is not None:  # the last one too: a caller stopped before keeping the Results need not retrain
                saver(final=it + 1 == self.n_iterations, make=lambda: snapshots.Snapshot(
                    it + 1, jax.device_get(kept_leaves(state)), self.env.snapshot() if self.host else None,
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

        With ``snapshot`` (a file path), the run's state is written there every ``snapshot_every_s`` seconds
        and after the last iteration, and a run that finds a snapshot of the same config and population there
        continues from it (or, from the last one, trains no more), to the same Results as an unbroken run
        (:mod:`ermrl.training.snapshots`). The caller removes the file once it has kept the Results. ``log`` gets a line when a run resumes or cannot.

        With ``config.processes`` > 1 on a host-loop backend and JAX on the CPU, the agents train in that many
        processes at once (:mod:`ermrl.training.processes`), to the same Results."""
        memory.check(self.config, population.size, self.env.info.obs_dim, self.env.info.action.feature_dim)
        if self.config.processes > 1 and self.host and population.size > 1:
            from ermrl.training.processes import run_split

            if self.devices[0].platform != "cpu":  # each process would claim the accelerator's memory
                if log:
                    log(f"processes = {self.config.processes} is for CPU machines; training in this process on "
                        f"the {self.devices[0].platform.upper()}")
                return self._run_here(population, progress_fn, snapshot, snapshot_every_s, log)
            return run_split(self._run_here, self.config, population, self.config.processes, progress_fn, snapshot,
                             snapshot_every_s, log)
        return self._run_here(population, progress_fn, snapshot, snapshot_every_s, log)

    def _run_here(self, population: Population, progress_fn: Callable[[Progress], None] | None = None,
                  snapshot: Path | None = None, snapshot_every_s: float = 300.0,
                  log: Callable[[str], None] | None = None) -> Results:
        """``run`` in this process alone."""
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
            params, norm = jax.device_get((state.learner.params, state.envs.norm))  # norm: None unless normalized
            policies = Policies.from_params(self.env.info, params, n, norm)
        finally:
            self.close()
        return Results.from_iterations(
            config=self.config, population=population, finished=finished, metrics=metrics, finite=finite,
            n_envs=ppo.n_envs, compile_s=compile_s, train_s=train_s, policies=policies,
        )


class _Saver:
    """Writes a snapshot when ``every_s`` seconds have passed since the last (or since the start), and after the
    final iteration."""

    def __init__(self, path: Path, ident: dict, every_s: float):
        self.path, self.ident, self.every_s = path, ident, every_s
        self.last = time.perf_counter()

    def __call__(self, make: Callable[[], snapshots.Snapshot], final: bool = False) -> None:
        if final or time.perf_counter() - self.last >= self.every_s:
            snapshots.write(self.path, self.ident, make())
            self.last = time.perf_counter()


def train(config: TrainConfig, population: Population, progress_fn=None) -> Results:
    """Compiles and trains in one call."""
    return Trainer(config).run(population, progress_fn)
