"""The outer loop: CMA-ES over Φ, one generation at a time (paper §3, "Outer loop").

A worker claims trials of the study's current generation (a lone worker: the whole generation, popsize trials;
see :mod:`ermrl.evolution.workers` for several), trains all of them × seeds as ONE population through the
engine (one population per env when the fitness spans several envs), then tells each trial its fitness (see
:mod:`ermrl.evolution.scoring`). A trial whose training diverged (NaN/inf) or finished no episode is told as
failed, with the reason in its user attribute ``failure``.

Resuming: completed trials count toward ``trials``. Trials left RUNNING by a worker that is gone (killed, its
machine lost) are failed once found so (its process gone from this machine: "interrupted"; else its heartbeat
stale: "worker lost ..."; see :mod:`ermrl.evolution.heartbeat`) and their slots are trained again, with their
Φ asked again (:meth:`ermrl.evolution.workers.Worker.claim`). A worker stopped by Ctrl-C or SIGTERM fails its own
trials on the way out ("interrupted"). With ``WorkerConfig.snapshots``, the batch's training is snapshotted
every few minutes (:func:`batch_snapshot`), and the rerun that asks the same trials again continues it. With
``WorkerConfig.stop_at``, a worker stops between two batches (:class:`~ermrl.errors.OutOfTime`) once the next one
would not end in time.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import time
from pathlib import Path
from typing import Callable

import numpy as np
import optuna
from optuna.exceptions import UpdateFinishedTrialError
from optuna.trial import TrialState

from ermrl.errors import OutOfTime, RunFailed
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.scoring import score
from ermrl.evolution.heartbeat import INTERRUPTED
from ermrl.evolution.worker_config import WorkerConfig
from ermrl.evolution.workers import Worker
from ermrl.training import Population, Progress, Results, Trainer

MAX_FAILED_BATCHES = 3
"""Stop when this many of a worker's batches in a row have no completed trial (something is wrong with the
setup)."""


@dataclasses.dataclass(frozen=True)
class GenerationProgress:
    """Passed to ``progress_fn`` during a generation's training and after it is told."""

    generation: int
    env_id: str
    """The env whose population is training (the evolution's first env between generations)."""
    completed: int
    """Completed trials in the study."""
    trials: int
    best_value: float | None
    best_params: dict | None
    train: Progress | None
    """The engine's progress inside the generation (None between generations)."""


def count(study: optuna.Study, state: TrialState) -> int:
    return len(study.get_trials(deepcopy=False, states=(state,)))


def _best(study: optuna.Study):
    try:
        return study.best_value, study.best_params
    except ValueError:
        return None, None


def _floats(values) -> list[float | None]:
    return [None if not np.isfinite(v) else float(v) for v in np.ravel(values)]


def tell_batch(study: optuna.Study, trials: list[optuna.Trial], results: dict[str, Results], config: EvolveConfig,
               log: Callable[[str], None] = lambda line: None) -> tuple[int, int]:
    """Tells each trial its fitness (see :mod:`ermrl.evolution.scoring`) and records, per trial: its Φ, the
    per-seed fitness, the final curve values and, with several envs, every env's raw score and nScore. A trial
    that another worker failed meanwhile (this worker's heartbeat came too late) is skipped with a log line.
    Returns (completed, failed) among the trials told."""
    n, seeds = len(trials), config.seeds
    env_fitness = {e: r.fitness().reshape(n, seeds) for e, r in results.items()}
    scores = score(config, env_fitness)
    first = results[config.env_ids[0]]
    finite = np.all([r.finite.reshape(n, seeds) for r in results.values()], axis=0)
    finals = {}
    for e, r in results.items():
        with np.errstate(all="ignore"):
            finals[e] = r.curves()[1].reshape(n, seeds, -1)[:, :, -1]
    done = failed = 0
    for i, trial in enumerate(trials):
        try:
            trial.set_user_attr("phi", {k: v.reshape(n, seeds, -1)[i, 0].tolist() for k, v in first.phi.items()})
            trial.set_user_attr("seeds", [int(v) for v in first.seeds.reshape(n, seeds)[i]])
            trial.set_user_attr("seed_fitness", _floats(scores.per_seed[i]))
            trial.set_user_attr("curve_final", _floats(finals[config.env_ids[0]][i]))
            if config.normalized:
                trial.set_user_attr("env_scores", {e: _floats(np.mean(f[i]))[0] for e, f in env_fitness.items()})
                trial.set_user_attr("env_nscores", {e: _floats(v[i])[0] for e, v in scores.env_nscore.items()})
                trial.set_user_attr("env_seed_fitness", {e: _floats(f[i]) for e, f in env_fitness.items()})
            if not finite[i].all():
                trial.set_user_attr("failure", f"diverged (NaN/inf) on {int((~finite[i]).sum())} of {seeds} seeds")
                study.tell(trial, state=TrialState.FAIL)
                failed += 1
            elif np.isnan(scores.per_seed[i]).any():
                trial.set_user_attr("failure", "no episode completed within the budget")
                study.tell(trial, state=TrialState.FAIL)
                failed += 1
            else:
                study.tell(trial, float(scores.value[i]))
                done += 1
        except (UpdateFinishedTrialError, ValueError):  # ValueError: "Cannot tell a FAIL trial."
            now = study._storage.get_trial(trial._trial_id)
            if now.state == TrialState.RUNNING:
                raise
            log(f"trial {trial.number} was failed meanwhile ({now.user_attrs.get('failure', now.state.name)}); "
                "its result is dropped")
    return done, failed


def generation_seconds(trainer: Trainer, config: EvolveConfig, size: int | None = None) -> float:
    """Seconds one batch of ``size`` trials (default: a generation) takes on ``trainer``'s env: one measured
    iteration (after compiling, which the training then reuses), scaled."""
    size = size or config.generation_size
    phis = [config.space.phi_from_params({n: d.low for n, d in config.space.distributions().items()})] * size
    population = Population.grid(phis, config.seeds, config.train.ppo.learning_rate, config.space.reservoirs)
    state = trainer.init(population)
    compiled = trainer.compiled(state)
    start = time.perf_counter()
    _, log = compiled(state)
    np.asarray(log.finite)
    per_iteration = time.perf_counter() - start
    trainer.close()
    return trainer.n_iterations * per_iteration


def estimate_seconds(trainers: dict[str, Trainer], config: EvolveConfig, remaining: int,
                     batch: int | None = None) -> float:
    """The remaining trials' time for one worker alone: every env's batch (default: a generation) measured
    once, times the batches left."""
    batch = min(batch or config.generation_size, remaining)
    return -(-remaining // batch) * sum(generation_seconds(t, config, batch) for t in trainers.values())


def batch_snapshot(folder: Path, studies: list[str], env_id: str, population: Population) -> Path:
    """The snapshot file of a batch's training on ``env_id``: FOLDER/STUDY/ENV.DIGEST.snapshot, in the folder of
    its first study, with a digest of the studies and the population (Φ, seeds, learning rates), so that a rerun
    asking the same trials again finds it, and no other batch does."""
    key = json.dumps({"studies": studies, "env": env_id, "seeds": np.asarray(population.seeds).tolist(),
                      "learning_rates": np.asarray(population.learning_rate).tolist(),
                      "phi": [np.asarray(v).tolist() for v in population.phi]})
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    return Path(folder) / studies[0] / f"{env_id.replace('/', '-')}.{digest}.snapshot"


def make_trainers(*configs: EvolveConfig) -> dict[str, Trainer]:
    """One trainer (one compile per population size) for each env of the evolution, or of several evolutions
    trained together (each env trained as the first of them that evolves on it: they must agree, see
    :func:`evolve_together`)."""
    env_ids = dict.fromkeys(e for c in configs for e in c.env_ids)
    return {e: Trainer(next(c for c in configs if e in c.env_ids).train_for(e)) for e in env_ids}


def evolve(study: optuna.Study, config: EvolveConfig, trainers: dict[str, Trainer] | None = None,
           progress_fn: Callable[[GenerationProgress], None] | None = None, worker: WorkerConfig | None = None,
           log: Callable[[str], None] | None = None) -> optuna.Study:
    """Works on the study until it holds ``config.trials`` completed trials (or has converged by
    ``worker.until_converged``), alone or beside other workers (``worker``: batch, index, heartbeats). Each
    claimed batch trains every env's population (the batch's Φ × seeds) before its trials are told. ``log``
    receives one line per event: waiting for a generation, a lost worker's trial failed, a trial failed meanwhile."""
    evolve_together([Member(study, config, worker or WorkerConfig())], trainers, progress_fn, log)
    return study


@dataclasses.dataclass(frozen=True)
class Member:
    """One study of :func:`evolve_together`, with its evolution's config and this process's worker settings."""

    study: optuna.Study
    config: EvolveConfig
    worker: WorkerConfig = WorkerConfig()


def shared_envs(a: EvolveConfig, b: EvolveConfig) -> tuple[str, ...]:
    """The envs on which two studies' populations can train as one: those both evolve on, when each of them has
    the same training (agent shape, PPO settings, budget) in both; none when the studies share no env or train
    one of their shared envs differently."""
    shared = tuple(e for e in a.env_ids if e in b.env_ids)
    return shared if all(a.train_for(e) == b.train_for(e) for e in shared) else ()


def evolve_together(members: list[Member], trainers: dict[str, Trainer] | None = None,
                    progress_fn: Callable[[GenerationProgress], None] | None = None,
                    log: Callable[[str], None] | None = None) -> None:
    """Works on several studies at once until each is done: every round, each unfinished study claims its next
    batch (a generation, for a lone worker), the claims train as ONE population per env (every study that evolves
    on that env adds its agents: studies of one shape share every env, a generalization group shares one env with
    each other group), and each study is told its own trials. An agent trains the same inside any population
    (:mod:`ermrl.training.programs`), so each study's trials are those it gets evolved alone. The studies must
    train each env they share alike (:func:`shared_envs`). Progress is reported for the first study of a round;
    ``log`` receives each worker's events (as :func:`evolve`), each line led by its study's name when several
    evolve together."""
    env_ids = tuple(dict.fromkeys(e for m in members for e in m.config.env_ids))
    for e in env_ids:
        if len({m.config.train_for(e) for m in members if e in m.config.env_ids}) > 1:
            raise ValueError(f"studies trained together must train each env they share alike; {e} differs")
    trainers = trainers or make_trainers(*(m.config for m in members))
    log = log or (lambda line: None)
    failed_in_a_row = [0] * len(members)
    with contextlib.ExitStack() as stack:
        workers = [stack.enter_context(Worker(m.study, m.config, m.worker, log if len(members) == 1 else
                                              lambda line, name=m.study.study_name: log(f"{name}: {line}")))
                   for m in members]
        active = list(range(len(members)))
        while True:
            claims = []
            try:
                for i in list(active):
                    claim = workers[i].claim()
                    if claim is None:
                        active.remove(i)
                    else:
                        claims.append((i, claim))
            except OutOfTime:  # another study's batch would not end in time: the round's claims are given back
                for i, _ in claims:
                    workers[i].release(INTERRUPTED)  # their Φ are asked again by the rerun
                raise
            if not claims:
                for m in members:  # snapshots of batches whose trials were never asked again
                    if m.worker.snapshots is not None and (old := m.worker.snapshots / m.study.study_name).is_dir():
                        for path in old.glob("*.snapshot*"):
                            path.unlink(missing_ok=True)
                        with contextlib.suppress(OSError):  # not empty: someone else's files
                            old.rmdir()
                return
            parts = [Population.concat([
                Population.grid(phi, members[i].config.trial_seeds(g), members[i].config.train.ppo.learning_rate,
                                members[i].config.space.reservoirs) for phi, g in zip(claim.phis, claim.generations)])
                for i, claim in claims]
            first, lead = members[claims[0][0]], claims[0][1]
            results: list[dict[str, Results]] = [{} for _ in claims]
            kept: list[Path | None] = []  # the batch's snapshots, removed once its trials are told
            for env_id in env_ids:
                takers = [k for k, (i, _) in enumerate(claims) if env_id in members[i].config.env_ids]
                if not takers:
                    continue

                def report(p: Progress, env_id=env_id):
                    for w in workers:
                        w.check_terminated()
                    if progress_fn is not None:
                        progress_fn(GenerationProgress(lead.generation, env_id, lead.completed, first.config.trials,
                                                       *_best(first.study), p))

                population = Population.concat([parts[k] for k in takers])
                where = members[claims[takers[0]][0]].worker
                path = None if where.snapshots is None else batch_snapshot(
                    where.snapshots, [members[claims[k][0]].study.study_name for k in takers], env_id, population)
                trained = trainers[env_id].run(population, report, snapshot=path,
                                               snapshot_every_s=where.snapshot_every_s, log=log)
                kept.append(path)
                at = 0
                for k in takers:
                    results[k][env_id] = trained.select(np.arange(at, at + parts[k].size))
                    at += parts[k].size
            for (i, claim), result in zip(claims, results):
                m = members[i]
                done, failed = tell_batch(m.study, claim.trials, {e: result[e] for e in m.config.env_ids},
                                          m.config, log)
                workers[i].finished(claim.trials)
                failed_in_a_row[i] = failed_in_a_row[i] + 1 if failed and not done else 0
                if failed_in_a_row[i] >= MAX_FAILED_BATCHES:
                    raise RunFailed(f"{MAX_FAILED_BATCHES} batches in a row of study {m.study.study_name!r} had no "
                                    "completed trial; see the trials' 'failure' attributes (`ermrl report`), fix the "
                                    "cause, then rerun to resume")
                if progress_fn is not None and i == claims[0][0]:
                    progress_fn(GenerationProgress(claim.generation, m.config.env_ids[0],
                                                   count(m.study, TrialState.COMPLETE), m.config.trials,
                                                   *_best(m.study), None))
            for path in kept:
                if path is not None:
                    path.unlink(missing_ok=True)
