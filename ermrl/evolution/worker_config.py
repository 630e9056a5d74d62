"""How one process takes part in a study (``WorkerConfig``), and the sampler seed each worker draws with.

None of it is part of the study's config: a study resumes with other values, and its workers may differ
(docs/scaling.md). :mod:`ermrl.evolution.workers` runs a worker with it.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from ermrl.errors import ConfigError
from ermrl.evolution.convergence import Convergence
from ermrl.evolution.heartbeat import GRACE_PERIOD_S, INTERVAL_S

MAX_WAIT_S = 86_400
"""The longest heartbeat interval and grace period, in seconds (a day)."""
MAX_WORKER_INDEX = 2**31 - 1


@dataclasses.dataclass(frozen=True)
class WorkerConfig:
    """How one process takes part in a study. None of it is part of the study's config: a study resumes with
    other values, and its workers may differ. On an RDB storage the heartbeat settings that count are those the
    storage was opened with (``study.open_study``, which ``ermrl evolve`` gives these)."""

    batch: int | None = None
    """Trials this worker claims at once (trained as one population), at most; default: popsize, i.e. whole
    generations for a lone worker. With N workers on one study: ceil(popsize / N)."""
    worker_index: int = 0
    """This worker's index among the study's workers (0, 1, ...; e.g. $SLURM_ARRAY_TASK_ID). Worker 0 seeds its
    sampler with --sampler-seed, worker i > 0 with a seed drawn from (--sampler-seed, i), so that workers draw
    different candidates."""
    heartbeat_interval: int = INTERVAL_S
    """Seconds between two heartbeats of the trials this worker trains."""
    grace_period: int = GRACE_PERIOD_S
    """Seconds without a heartbeat after which other workers fail a trial (its worker is gone) and redo it."""
    until_converged: Convergence | None = None
    """Also stop once CMA-ES has converged by this rule (:mod:`ermrl.evolution.convergence`), recording it in
    the study; None: stop at the trial target only."""
    snapshots: Path | None = None
    """A folder for snapshots of the batch in training, one file per env, written every few minutes: a worker
    stopped mid-batch (Ctrl-C, SIGTERM, a lost process) and rerun on this machine asks the stopped trials' Φ again
    and continues their training from the last snapshot, to the fitness an unbroken batch gets. Without it a
    stopped batch trains again from its start."""
    snapshot_every_s: float = 300.0
    """Seconds between two snapshots of a batch in training (with ``snapshots``)."""
    stop_at: float | None = None
    """A time (``time.time()``, seconds) by which this worker stops: it claims no batch that would end after it,
    by the last batch's time (this worker's, else the study's last generation's), and raises
    :class:`~ermrl.errors.OutOfTime` instead (``--stop-after``); None: no limit."""

    def __post_init__(self):
        if self.batch is not None and self.batch < 1:
            raise ConfigError(f"`batch` must be >= 1, got {self.batch}", owner=type(self))
        if self.worker_index < 0:
            raise ConfigError(f"`worker_index` must be >= 0, got {self.worker_index}", owner=type(self))
        if self.worker_index > MAX_WORKER_INDEX:
            raise ConfigError(f"`worker_index` must be <= {MAX_WORKER_INDEX:,}, got {self.worker_index}",
                              owner=type(self))
        if self.heartbeat_interval < 1:
            raise ConfigError(f"`heartbeat_interval` must be >= 1 (seconds), got {self.heartbeat_interval}",
                              owner=type(self))
        if max(self.heartbeat_interval, self.grace_period) > MAX_WAIT_S:
            raise ConfigError(f"`heartbeat_interval` and `grace_period` must be <= {MAX_WAIT_S} seconds (a day), "
                              f"got {self.heartbeat_interval} and {self.grace_period}", owner=type(self))
        if self.stop_at is not None and not math.isfinite(self.stop_at):
            raise ConfigError(f"`stop_at` must be a finite time, got {self.stop_at}", owner=type(self))
        if not self.snapshot_every_s > 0:
            raise ConfigError(f"`snapshot_every_s` must be > 0 (seconds), got {self.snapshot_every_s}", owner=type(self))
        if self.grace_period <= self.heartbeat_interval:
            raise ConfigError(f"`grace_period` ({self.grace_period} s) must be longer than `heartbeat_interval` "
                              f"({self.heartbeat_interval} s), or live trials would be failed as lost",
                              owner=type(self))



def worker_seed(seed: int | None, index: int) -> int | None:
    """The sampler seed of worker ``index``: ``seed`` itself for worker 0 (a lone worker's draws do not change),
    else one drawn from (seed, index). Optuna's samplers draw from their own seeded generator (CmaEsSampler's
    independent sampler, RandomSampler, TPESampler), so workers with one seed would draw the same candidates."""
    if seed is None or index == 0:
        return seed
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0])
