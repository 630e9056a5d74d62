"""Heartbeats: a worker keeps the trials it trains alive in the storage, and fails the trials of workers that
are gone so that others redo them (docs/scaling.md, "Heartbeats").

On an RDB storage (PostgreSQL, SQLite, ...) opened with a ``heartbeat_interval`` (``study.make_storage``), the
heartbeats are Optuna's own: ``RDBStorage.record_heartbeat`` and the stale trials it finds with the database's
clock. Optuna's ``fail_stale_trials`` is not used because it cannot record why a trial failed (a finished trial
takes no more attributes). Journal files and in-memory storages have no heartbeats in Optuna; there a heartbeat
is the trial system attribute ``ermrl:heartbeat`` (Unix time), and since a journal only grows, a worker beats for
one of its trials per interval (the oldest it trains), whose heartbeat stands for all trials naming the same worker.
With ask/tell nothing beats by itself: ``Heartbeat`` is a thread that beats for the worker's trials while it trains
them.

A RUNNING trial of another worker is failed
- at once when its worker ran on this machine and its process is gone (reason "interrupted");
- when its last heartbeat is older than the grace period (reason "worker lost (no heartbeat for N s)");
- when it has no heartbeat and started more than the grace period ago: a worker killed while asking, or a trial
  left by an ermrl version without heartbeats (same reason).
"""

from __future__ import annotations

import dataclasses
import datetime
import os
import socket
import threading
import time
import uuid
from pathlib import Path
from typing import Callable

import optuna
from optuna.exceptions import UpdateFinishedTrialError
from optuna.storages._heartbeat import is_heartbeat_enabled
from optuna.trial import FrozenTrial, TrialState

from ermrl import provenance
from ermrl.evolution.journal_file import JournalChanged

HEARTBEAT_ATTR = "ermrl:heartbeat"
"""The trial system attribute holding the last heartbeat (Unix time) where Optuna has no heartbeats."""
WORKER_ATTR = "worker"
"""The trial user attribute naming the worker that trains it (``WorkerId.record``)."""
INTERRUPTED = "interrupted"
LOST_PREFIX = "worker lost"
"""How the failure reason of a trial whose worker stopped beating begins."""
INTERVAL_S = 10
"""Seconds between two heartbeats, by default."""
GRACE_PERIOD_S = 60
"""Seconds without a heartbeat after which a trial's worker counts as gone, by default."""


def _machine() -> str:
    """This process's machine, as far as process ids are comparable: the boot and the pid namespace."""
    parts = []
    for read in (lambda: Path("/proc/sys/kernel/random/boot_id").read_text().strip(),
                 lambda: os.readlink("/proc/self/ns/pid")):
        try:
            parts.append(read())
        except OSError:
            parts.append("?")
    return "/".join(parts)


def _stat(pid: int) -> list[str] | None:
    """The fields of /proc/PID/stat after the command name (state first); None where there is no /proc."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def _started(pid: int) -> int | None:
    """When process ``pid`` started (clock ticks since boot), to tell it from a later process with its id."""
    stat = _stat(pid)
    return int(stat[19]) if stat and len(stat) > 19 else None


def process_gone(pid: int, started: int | None) -> bool:
    """Whether process ``pid`` of this machine, started at ``started``, has exited: no such process, a zombie
    (exited, not yet reaped), or another process that was given the same id later."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:  # it exists, under another user
        pass
    stat = _stat(pid)
    if stat is None:
        return False
    return stat[0] == "Z" or (started is not None and len(stat) > 19 and int(stat[19]) != started)


@dataclasses.dataclass(frozen=True)
class WorkerId:
    """Who trains a trial: the host name, the machine (boot and pid namespace), the process (id and start) and
    the worker index; ``token`` is unique to this process, even where process ids repeat (containers). ``cpu``
    (:func:`ermrl.provenance.cpu`, "x86_64 AVX2") tells which instruction set the trial's numbers were computed
    with, where the study's ``software`` record names only the first run's."""

    host: str
    machine: str
    pid: int
    started: int | None
    index: int
    token: str
    cpu: str

    @classmethod
    def here(cls, index: int) -> "WorkerId":
        return cls(socket.gethostname(), _machine(), os.getpid(), _started(os.getpid()), index, uuid.uuid4().hex,
                   provenance.cpu())

    def record(self) -> dict:
        return dataclasses.asdict(self)

    def owns(self, t: FrozenTrial) -> bool:
        w = t.user_attrs.get(WORKER_ATTR)
        return isinstance(w, dict) and w.get("token") == self.token

    def same_machine(self, w: dict) -> bool:
        return w.get("host") == self.host and w.get("machine") == self.machine and "?" not in self.machine

    def lost_reason(self, t: FrozenTrial, stale_ids: set[int], grace_s: int, optuna_beats: bool,
                    now: float, worker_beats: dict[str, float] | None = None) -> str | None:
        """Why ``t`` (RUNNING, another worker's) is to be failed; None while its worker may be alive.
        ``worker_beats`` ({worker token: last heartbeat}, ``worker_beats``) counts a heartbeat of any trial of
        ``t``'s worker as ``t``'s own, where heartbeats are trial attributes."""
        w = t.user_attrs.get(WORKER_ATTR)
        lost = f"{LOST_PREFIX} (no heartbeat for {grace_s} s)"
        if isinstance(w, dict) and self.same_machine(w) and isinstance(w.get("pid"), int) \
                and process_gone(w["pid"], w.get("started")):
            return INTERRUPTED
        beat = t.system_attrs.get(HEARTBEAT_ATTR)
        if optuna_beats and isinstance(w, dict) and beat is None:  # it beat before naming itself: Optuna knows
            return lost if t._trial_id in stale_ids else None
        last = float(beat) if isinstance(beat, (int, float)) else _timestamp(t.datetime_start)
        shared = (worker_beats or {}).get(w.get("token")) if isinstance(w, dict) else None
        if shared is not None:
            last = shared if last is None else max(last, shared)
        return lost if last is not None and now - last > grace_s else None


def worker_beats(trials: list[FrozenTrial]) -> dict[str, float]:
    """{worker token: its latest heartbeat} over ``trials`` whose heartbeat is the attribute ``ermrl:heartbeat``."""
    latest: dict[str, float] = {}
    for t in trials:
        w, beat = t.user_attrs.get(WORKER_ATTR), t.system_attrs.get(HEARTBEAT_ATTR)
        if isinstance(w, dict) and isinstance(w.get("token"), str) and isinstance(beat, (int, float)):
            latest[w["token"]] = max(latest.get(w["token"], beat), float(beat))
    return latest


def _timestamp(when: datetime.datetime | None) -> float | None:
    return None if when is None else when.timestamp()  # naive datetimes are local time, as Optuna writes them


def optuna_heartbeat(storage: optuna.storages.BaseStorage) -> tuple[int, int] | None:
    """(interval, grace period) of Optuna's heartbeats on ``storage``; None where it has none (journal files,
    memory, or an RDB storage opened without ``heartbeat_interval``)."""
    if not is_heartbeat_enabled(storage):
        return None
    interval = storage.get_heartbeat_interval()
    backend = getattr(storage, "_backend", storage)  # Optuna wraps an RDBStorage in a _CachedStorage
    return interval, getattr(backend, "grace_period", None) or 2 * interval  # Optuna's default grace: 2 intervals


def fail_trial(study: optuna.Study, trial_id: int, reason: str) -> bool:
    """Fails a RUNNING trial with ``reason``; False when it had finished meanwhile (told or failed by another)."""
    storage = study._storage
    try:
        storage.set_trial_user_attr(trial_id, "failure", reason)
        return bool(storage.set_trial_state_values(trial_id, TrialState.FAIL))
    except UpdateFinishedTrialError:
        return False


def fail_lost(study: optuna.Study, trials: list[FrozenTrial], me: WorkerId, grace_s: int,
              log: Callable[[str], None]) -> int:
    """Fails the RUNNING trials in ``trials`` whose worker is gone (see the module docstring). Returns how many."""
    running = [t for t in trials if t.state == TrialState.RUNNING and not me.owns(t)]
    if not running:
        return 0
    optuna_beats = is_heartbeat_enabled(study._storage)
    stale = set(study._storage._get_stale_trial_ids(study._study_id)) if optuna_beats else set()
    shared = None if optuna_beats else worker_beats(trials)
    failed, now = 0, time.time()
    for t in running:
        reason = me.lost_reason(t, stale, grace_s, optuna_beats, now, shared)
        if reason is not None and fail_trial(study, t._trial_id, reason):
            failed += 1
            log(f"trial {t.number} failed: {reason}; it will be redone")
    return failed


class Heartbeat:
    """Beats for a set of trials every ``interval_s`` seconds in a background thread, from ``start`` to
    ``stop``: for each of them with Optuna's heartbeats (one row per trial, updated in place), for the oldest one
    on a journal file (one line per interval, whatever the batch). ``add`` beats at once for a new trial (before
    anyone could find it without a heartbeat)."""

    def __init__(self, study: optuna.Study, interval_s: float, log: Callable[[str], None] = lambda line: None):
        self.study, self.interval_s, self.log = study, interval_s, log
        self.optuna_beats = is_heartbeat_enabled(study._storage)
        self._ids: set[int] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._failures = 0
        self.fatal: JournalChanged | None = None
        """The error that stopped the beats for good: the journal was rewritten under the run. The worker's
        main thread raises it at its next progress report (``Worker.check_terminated``)."""

    @property
    def trial_ids(self) -> set[int]:
        with self._lock:
            return set(self._ids)

    def add(self, trial_id: int) -> None:
        self._beat(trial_id)
        with self._lock:
            self._ids.add(trial_id)

    def remove(self, trial_id: int) -> None:
        with self._lock:
            self._ids.discard(trial_id)

    def start(self) -> "Heartbeat":
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="ermrl-heartbeat", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def __enter__(self) -> "Heartbeat":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _beat(self, trial_id: int) -> None:
        storage = self.study._storage
        if self.optuna_beats:
            storage.record_heartbeat(trial_id)
        else:
            storage.set_trial_system_attr(trial_id, HEARTBEAT_ATTR, time.time())

    def _run(self) -> None:
        while not self._stop.wait(self.interval_s):
            for trial_id in sorted(self.trial_ids):
                try:
                    self._beat(trial_id)
                    if not self.optuna_beats:
                        break  # this beat stands for all this worker's trials (WorkerId.lost_reason)
                except UpdateFinishedTrialError:  # failed meanwhile by another worker; the tell will say so
                    self.remove(trial_id)
                except JournalChanged as e:  # no write can succeed now; the main thread stops the run
                    self.fatal = e
                    return
                except Exception as e:  # a database hiccup must not kill training; the next beat retries
                    self._failures += 1
                    if self._failures in (1, 10, 100):
                        first = (str(e).strip().splitlines() or [""])[0]
                        self.log(f"heartbeat failed ({type(e).__name__}: {first}); retrying")
