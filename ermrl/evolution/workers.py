"""One worker of a study: how it claims trials, waits for them, and gives them back (docs/scaling.md).

Any number of ``ermrl evolve`` processes, on one machine or many, may work on one study in a shared storage
(PostgreSQL for many machines). Each one loops: fail the trials of workers that are gone (``heartbeat``), claim
at most ``batch`` free slots of the shared generation (``generations``), train them as one population, tell
them. It asks no more trials than the study still needs (``trials`` minus those completed or running), and
waits, polling, while the generation is full or the last trials run elsewhere, until ``trials`` completed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import signal
import sys
import threading
import time
import warnings
from typing import Callable, Iterator

import optuna
from optuna.exceptions import UpdateFinishedTrialError
from optuna.trial import FrozenTrial, TrialState

from ermrl.agent import Phi
from ermrl.errors import TERMINATED, OutOfTime, raise_terminated
from ermrl.evolution import convergence
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.generations import ATTR, CMA_GENERATION, FULL, Ledger, duration_text, generation_seconds
from ermrl.evolution.heartbeat import (INTERRUPTED, LOST_PREFIX, WORKER_ATTR, Heartbeat, WorkerId, fail_lost, fail_trial,
                                       optuna_heartbeat)
from ermrl.evolution.journal_file import JournalChanged
from ermrl.evolution.worker_config import WorkerConfig

POLL_S = 1.0
"""Seconds between two looks at the study while waiting for a free slot."""
PLACE_POLL_S = 0.1
"""Seconds between two looks while another worker is asking a trial numbered below one of ours."""


REDO_ATTR = "redo_of"
"""The user attribute of a trial asked again with the Φ of a trial that a stopped or lost worker left failed:
{"trial": its number, "generation": its generation}."""
STALE_REDO = "its generation ended before it was redone"
"""The failure reason of a trial asked again whose generation other workers finished meanwhile (CMA-ES)."""
TWICE_REDONE = "another worker asked the same Φ again first"
"""The failure reason of a trial asked again for a stopped trial that a lower-numbered trial, not failed, is
already asked again for: two workers that saw the stopped trial at once each enqueued its Φ."""


def _suggest(space, trial: optuna.Trial) -> Phi:
    """``space.suggest(trial)``, where the sampler's relative sampling runs. cmaes at popsize 2 (μ = 1) has no rank-μ
    update: one of the bounds it takes the minimum of divides by its zero learning rate (the minimum stays
    finite), a numpy warning that users need not see. A trial asked again (``REDO_ATTR``) has every parameter
    given, where Optuna skips the relative sampling; it runs here all the same, so that CMA-ES tags the trial with
    its generation (and tells it with that generation), and the given Φ is kept."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="divide by zero encountered in scalar divide", category=RuntimeWarning)
        if REDO_ATTR in trial.user_attrs:
            trial.relative_params  # noqa: B018 (the property samples and tags)
        return space.suggest(trial)


def _redo_of(t: FrozenTrial | optuna.Trial) -> dict | None:
    """``t``'s ``REDO_ATTR`` ({"trial", "generation"}) when it was asked again for a stopped trial, else None."""
    return redo if isinstance(redo := t.user_attrs.get(REDO_ATTR), dict) else None


def _stopped(t: FrozenTrial) -> bool:
    """Whether ``t`` failed because its worker stopped or was lost, not because of its Φ."""
    reason = t.user_attrs.get("failure")
    return t.state == TrialState.FAIL and isinstance(reason, str) and (reason == INTERRUPTED
                                                                        or reason.startswith(LOST_PREFIX))


@dataclasses.dataclass(frozen=True)
class Claim:
    """Trials this worker holds: asked, sampled and placed in their generation, to train as one population."""

    trials: list[optuna.Trial]
    phis: list[Phi]
    generation: int
    """The (lowest) generation of the trials."""
    generations: list[int]
    """Each trial's generation."""
    completed: int
    """Completed trials in the study when they were claimed."""


class Worker:
    """Claims trials of ``study`` for ``config`` (``claim``), keeps them alive while they train, and fails the
    ones it still holds when it stops early (reason "interrupted": Ctrl-C, SIGTERM; else the error's type). As a
    context manager in the main thread, it turns SIGTERM (where nothing else handles it) into ``SystemExit(143)``
    for its lifetime, and remembers it (``terminated``): Python drops an exception raised where nobody can catch
    it (a garbage collector's callback, a ``__del__``), and a library's clean-up may replace it with its own error,
    so ``claim``, ``check_terminated`` and the way out raise it again."""

    def __init__(self, study: optuna.Study, config: EvolveConfig, worker: WorkerConfig,
                 log: Callable[[str], None] = lambda line: None):
        self.study, self.config, self.worker, self.log = study, config, worker, log
        self.ledger = Ledger(config.generation_size, cma=isinstance(study.sampler, optuna.samplers.CmaEsSampler))
        self.batch = worker.batch or config.generation_size
        self.me = WorkerId.here(worker.worker_index)
        # an RDB storage has Optuna's heartbeats with the settings it was opened with (study.open_study)
        self.interval_s, self.grace_s = optuna_heartbeat(study._storage) or (worker.heartbeat_interval,
                                                                              worker.grace_period)
        self.heartbeat = Heartbeat(study, self.interval_s, log)
        self._warned_index = False
        self._spread_logged: int | None = None
        self.terminated = self._deferring = False
        self.last_batch_s: float | None = None
        """Seconds from claiming this worker's last told batch to telling it (its training, mostly)."""
        self._claimed_at: float | None = None

    def __enter__(self) -> "Worker":
        self._sigterm = None
        if threading.current_thread() is threading.main_thread() and \
                signal.getsignal(signal.SIGTERM) in (signal.SIG_DFL, raise_terminated):
            self._sigterm = signal.signal(signal.SIGTERM, self._terminate)  # e.g. slurm's time limit or scancel
        self.heartbeat.start()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            # a rewritten journal takes no write: its next run fails the trials still held ("interrupted")
            if self.heartbeat.trial_ids and not isinstance(exc, JournalChanged):
                stopped = self.terminated or exc_type is None or issubclass(exc_type, (KeyboardInterrupt, SystemExit))
                self.release(INTERRUPTED if stopped else f"worker error ({exc_type.__name__})")
        finally:
            self.heartbeat.stop()
            if self._sigterm is not None:
                signal.signal(signal.SIGTERM, self._sigterm)
        if self.terminated and not isinstance(exc, SystemExit):  # dropped, or replaced by a clean-up's error
            raise SystemExit(TERMINATED) from exc

    def _terminate(self, signum, frame) -> None:
        """SIGTERM as an exception, so that the worker fails its trials on the way out (exit 143); inside
        ``_uninterrupted``, at its end."""
        self.terminated = True
        if not self._deferring:
            raise SystemExit(TERMINATED)

    @contextlib.contextmanager
    def _uninterrupted(self) -> Iterator[None]:
        """A block that SIGTERM does not cut: between creating a trial and beating for it, a worker stopped would
        leave it RUNNING with no heartbeat, for the others to fail only after the grace period."""
        self._deferring = True
        try:
            yield
        finally:
            self._deferring = False
        self.check_terminated()

    def check_terminated(self) -> None:
        """Raises ``SystemExit(143)`` if SIGTERM came, even where its first exception was dropped, and the
        heartbeat thread's :class:`~ermrl.evolution.journal_file.JournalChanged` if it found the journal
        rewritten (called at each progress report, so a run stops within an iteration, not at its batch's end)."""
        if self.terminated:
            raise SystemExit(TERMINATED)
        if self.heartbeat.fatal is not None:
            raise self.heartbeat.fatal

    def release(self, reason: str) -> None:
        """Fails every trial this worker still holds, so that nobody waits for them."""
        for trial_id in sorted(self.heartbeat.trial_ids):
            try:
                fail_trial(self.study, trial_id, reason)
            except Exception as e:  # the storage is unreachable: the heartbeats stop, others fail them later
                self.log(f"could not fail trial id {trial_id} ({type(e).__name__}); others will once its "
                         "heartbeat is stale")
            self.heartbeat.remove(trial_id)

    def finished(self, trials: list[optuna.Trial]) -> None:
        """Stops the heartbeats of told trials, and times the batch (``last_batch_s``)."""
        for t in trials:
            self.heartbeat.remove(t._trial_id)
        if self._claimed_at is not None:
            self.last_batch_s = time.monotonic() - self._claimed_at
            self._claimed_at = None

    def claim(self) -> Claim | None:
        """The next trials to train, or None once the study holds ``config.trials`` completed trials. With
        ``WorkerConfig.stop_at``, :class:`~ermrl.errors.OutOfTime` instead of trials that would not be trained by
        then, judged by the time this worker's last batch took (``last_batch_s``), else the study's last
        generation's (:func:`generation_seconds`); with neither (a new study), while any time is left."""
        waiting = None
        while True:
            self.check_terminated()
            trials = self._trials()
            completed = sum(t.state == TrialState.COMPLETE for t in trials)
            if completed >= self.config.trials or self._converged(trials):
                return None
            running = sum(t.state == TrialState.RUNNING for t in trials)
            need = self.config.trials - completed - running
            slots = self.ledger.next_slots(trials)
            n = min(self.batch, need, slots.free if self.ledger.cma else self.batch)
            if n > 0:
                self._check_time(trials, slots.generation, completed)
                self._redo(trials, slots.generation, n)
                claim = self._ask(n, completed)
                if claim is not None:
                    self._claimed_at = time.monotonic()
                    self._log_new_spread()
                    return claim
                continue
            reason = (f"generation {slots.generation} is full ({slots.running} of its trials are running in other "
                      "workers)" if need > 0 else f"the last {running} trials are running in other workers")
            if reason != waiting:
                self.log(f"waiting: {reason}")
                waiting = reason
            time.sleep(POLL_S)

    def _check_time(self, trials: list[FrozenTrial], generation: int, completed: int) -> None:
        """Raises OutOfTime when the batch about to be claimed would end after ``WorkerConfig.stop_at``."""
        stop_at = self.worker.stop_at
        if stop_at is None:
            return
        expected_s = self.last_batch_s if self.last_batch_s is not None else \
            generation_seconds(trials, self.config.generation_size)
        left = stop_at - time.time()
        if left > (expected_s or 0.0):
            return
        why = "the time limit has passed" if left <= 0 or not expected_s else (
            f"it would take about {duration_text(expected_s)} (as the last one did) and the time limit leaves "
            f"{duration_text(left)}")
        raise OutOfTime(f"stopped before generation {generation} of study {self.study.study_name!r} ({completed} of "
                        f"{self.config.trials} trials done): {why}; rerun the same command to continue")

    def _redo(self, trials: list[FrozenTrial], generation: int, n: int) -> None:
        """Enqueues, for the next asks, the Φ of at most ``n`` trials of ``generation`` that a stopped or lost
        worker left failed and that nobody asked again yet (in number order), so that the generation trains the
        candidates drawn for it, and a snapshot of their training (``WorkerConfig.snapshots``) fits them."""
        names = set(self.config.space.distributions())
        taken = {redo["trial"] for redo in map(_redo_of, trials) if redo is not None}
        todo = [t for t in trials if _stopped(t) and t.number not in taken and set(t.params) == names
                and self.ledger.label(t) == generation][:n]
        for t in todo:
            self.study.enqueue_trial(t.params, user_attrs={REDO_ATTR: {"trial": t.number, "generation": generation}})
            self.log(f"trial {t.number}'s Φ asked again")

    def _converged(self, trials: list[FrozenTrial]) -> bool:
        """Whether the study has converged by ``until_converged`` (recorded in the study and logged once)."""
        rule = self.worker.until_converged
        if rule is None or not self.ledger.cma:
            return False
        verdict = convergence.judge(self.study, self.config.space, self.config.generation_size, rule, trials)
        if verdict.generation is None:
            self._log_spread(verdict, rule)
            return False
        if convergence.recorded(self.study, rule) is None:
            convergence.record(self.study, rule, verdict)
            self.log(f"converged at generation {verdict.generation} ({verdict.trials} trials): {rule.describe()}")
        return True

    def _log_new_spread(self) -> None:
        """Logs the spread of the distribution that the trials just asked were sampled from, as their generation
        starts (CMA-ES stores it when it samples a generation's first trial)."""
        rule = self.worker.until_converged
        if rule is not None and self.ledger.cma:
            self._log_spread(convergence.judge(self.study, self.config.space, self.config.generation_size, rule), rule)

    def _log_spread(self, verdict: convergence.Verdict, rule: convergence.Convergence) -> None:
        """Logs, once per generation sampled from a new distribution, its widest spread and the projected stops."""
        if not verdict.spread or max(verdict.spread) == self._spread_logged:
            return
        self._spread_logged = latest = max(verdict.spread)
        name, widest = max(verdict.spread[latest].items(), key=lambda kv: kv[1])
        projections = (convergence.project(verdict.spread, rule), convergence.recent_projection(verdict.spread, rule))
        self.log(f"generation {latest}: widest spread {widest:.3g} decades ({name}), {rule.width:g} to converge"
                 + "".join(f"; {projection.describe()}" for projection in projections if projection is not None))

    def _trials(self) -> list[FrozenTrial]:
        """The study's trials, after failing those of workers that are gone."""
        trials = self.study.get_trials(deepcopy=False)
        if fail_lost(self.study, trials, self.me, self.grace_s, self.log):
            trials = self.study.get_trials(deepcopy=False)
        if not self._warned_index:
            for t in trials:
                w = t.user_attrs.get(WORKER_ATTR)
                if t.state == TrialState.RUNNING and isinstance(w, dict) and w.get("index") == self.me.index \
                        and not self.me.owns(t):
                    print(f"warning: another worker (pid {w.get('pid')} on {w.get('host')}) also runs with "
                          f"worker index {self.me.index}; give each worker its own index, or their sampler "
                          "draws repeat", file=sys.stderr, flush=True)
                    self._warned_index = True
                    break
        return trials

    def _ask(self, n: int, completed: int) -> Claim | None:
        """Asks ``n`` trials, samples their Φ and places each in its generation; fails those that do not fit.
        None when none fits."""
        asked = []
        for _ in range(n):
            with self._uninterrupted(), warnings.catch_warnings():
                warnings.filterwarnings("ignore", message="Heartbeat of storage")  # meant for Study.optimize
                trial = self.study.ask()
                if self._survives(trial, self._adopt):
                    asked.append(trial)
        asked = self._first_redos(asked)
        phis = {}
        for t in asked:
            if self._survives(t, lambda t: phis.__setitem__(t.number, _suggest(self.config.space, t))) \
                    and self.ledger.cma:  # the sampler chose the generation: record it at once, others wait for it
                tag = self.study._storage.get_trial_system_attrs(t._trial_id).get(CMA_GENERATION)
                if not self._survives(t, lambda t: t.set_user_attr(ATTR, 0 if tag is None else int(tag) + 1)):
                    del phis[t.number]
        placed = self._place([t for t in asked if t.number in phis])
        for t in asked:  # a trial asked again in a later generation than its own: its Φ is not of this distribution
            redo = _redo_of(t) if placed.get(t.number, -1) >= 0 else None
            if redo is not None and self.ledger.cma and placed[t.number] != redo["generation"]:
                placed[t.number] = -1
                if fail_trial(self.study, t._trial_id, STALE_REDO):
                    self.log(f"trial {t.number} failed: {STALE_REDO}")
        kept = [t for t in asked if placed.get(t.number, -1) >= 0]
        for t in asked:
            if t not in kept:
                self.heartbeat.remove(t._trial_id)
        if not self.ledger.cma:
            kept = [t for t in kept if self._survives(t, lambda t: t.set_user_attr(ATTR, placed[t.number]))]
        if not kept:
            return None
        return Claim(kept, [phis[t.number] for t in kept], min(placed[t.number] for t in kept),
                     [placed[t.number] for t in kept], completed)

    def _first_redos(self, asked: list[optuna.Trial]) -> list[optuna.Trial]:
        """``asked`` less the trials asked again for a stopped trial that a lower-numbered trial, not failed, is
        asked again for; those are failed (``TWICE_REDONE``). Two workers reading the study at once may both
        enqueue a stopped trial's Φ; the lower number wins (enqueued first, its loser's worker always sees it)."""
        redos = {t.number: _redo_of(t) for t in asked}
        if not any(redos.values()):
            return asked
        first: dict[int, int] = {}
        for t in sorted(self.study.get_trials(deepcopy=False), key=lambda t: t.number):
            redo = _redo_of(t)
            if redo is not None and t.state != TrialState.FAIL:
                first.setdefault(redo["trial"], t.number)
        kept = []
        for t in asked:
            redo = redos[t.number]
            if redo is not None and first.get(redo["trial"], t.number) != t.number:
                self.heartbeat.remove(t._trial_id)
                if fail_trial(self.study, t._trial_id, TWICE_REDONE):
                    self.log(f"trial {t.number} failed: {TWICE_REDONE} (trial {first[redo['trial']]})")
            else:
                kept.append(t)
        return kept

    def _adopt(self, trial: optuna.Trial) -> None:
        """Beats for a trial just asked, then names this worker in it (in this order: see
        ``heartbeat.WorkerId.lost_reason``)."""
        self.heartbeat.add(trial._trial_id)
        trial.set_user_attr(WORKER_ATTR, self.me.record())

    def _survives(self, trial: optuna.Trial, step: Callable[[optuna.Trial], object]) -> bool:
        """Runs ``step(trial)`` on a trial just asked; False (with a log line, the trial dropped) when another
        worker failed it meanwhile: this worker stood still longer than the grace period (a paused VM, swapping)."""
        try:
            step(trial)
            return True
        except UpdateFinishedTrialError:
            self.heartbeat.remove(trial._trial_id)
            reason = self.study._storage.get_trial(trial._trial_id).user_attrs.get("failure", "failed")
            self.log(f"trial {trial.number} was failed meanwhile ({reason}); dropped")
            return False

    def _place(self, asked: list[optuna.Trial]) -> dict[int, int]:
        """{number: generation} of the asked trials that fit, in number order; fails those that do not (CMA-ES)
        and drops those another worker failed meanwhile (-1)."""
        placed: dict[int, int] = {}
        rejected: set[int] = set()
        todo = sorted(t.number for t in asked)
        ids = {t.number: t._trial_id for t in asked}
        while todo:
            trials = [t for t in self._trials() if t.number not in rejected]
            by_number = {t.number: t for t in trials}
            while todo:
                number = todo[0]
                frozen = by_number[number]
                if frozen.state != TrialState.RUNNING:  # failed meanwhile (its heartbeat was late)
                    placed[number] = -1
                    todo.pop(0)
                    self.log(f"trial {number} was failed meanwhile ({frozen.user_attrs.get('failure', 'failed')}); "
                             "dropped")
                    continue
                generation = self.ledger.place(frozen, trials, placed)
                if generation is None:
                    break
                todo.pop(0)
                placed[number] = generation
                if generation < 0:
                    rejected.add(number)
                    trials = [t for t in trials if t.number != number]
                    if fail_trial(self.study, ids[number], FULL):
                        self.log(f"trial {number} failed: {FULL} (another worker took the last slot)")
                    else:
                        reason = self.study._storage.get_trial(ids[number]).user_attrs.get("failure", "failed")
                        self.log(f"trial {number} was failed meanwhile ({reason}); dropped")
            if todo:
                time.sleep(PLACE_POLL_S)
        return placed
