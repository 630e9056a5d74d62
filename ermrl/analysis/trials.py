"""A study's trials as the analyses read them: completed, failed, ranked by fitness, their Φ, and the study's time.

A completed trial of ``ermrl evolve`` has ``value`` = fitness (mean over seeds) and the user attribute ``phi``
({"sr"|"lr"|"iss": [K floats]}); the study keeps its configuration in ``study.user_attrs["ermrl"]``.
"""

from __future__ import annotations

import math

import optuna
from optuna.study import StudyDirection
from optuna.trial import FrozenTrial, TrialState


def maximize(study: optuna.Study) -> bool:
    """Whether the study maximizes its fitness (every ermrl study does; a foreign one may not)."""
    return study.direction != StudyDirection.MINIMIZE


def completed(study: optuna.Study) -> list[FrozenTrial]:
    """Completed trials with a finite fitness, in trial-number order."""
    return [t for t in study.get_trials(deepcopy=False)
            if t.state == TrialState.COMPLETE and t.value is not None and math.isfinite(t.value)]


def failed(study: optuna.Study) -> list[FrozenTrial]:
    """Failed trials, in trial-number order."""
    return [t for t in study.get_trials(deepcopy=False) if t.state == TrialState.FAIL]


def ranked(study: optuna.Study) -> list[FrozenTrial]:
    """Completed trials, best fitness first."""
    return sorted(completed(study), key=lambda t: t.value, reverse=maximize(study))


def running_time(study: optuna.Study) -> tuple[float, float]:
    """(running, span) in seconds over the completed trials: ``running`` is the time during which at least one of
    them ran (the union of their [start, finish] intervals; overlapping workers count once), ``span`` the time from
    the first start to the last finish. A study run in parts, with stops between them, has running < span. Failed
    trials are left out: one failed by another worker after a stop ("worker lost") would span the stop. (0, 0)
    before any trial completed."""
    spans = sorted((t.datetime_start, t.datetime_complete) for t in study.get_trials(deepcopy=False)
                   if t.state == TrialState.COMPLETE and t.datetime_start is not None
                   and t.datetime_complete is not None)
    if not spans:
        return 0.0, 0.0
    running, (start, end) = 0.0, spans[0]
    for a, b in spans[1:]:
        if a > end:
            running += (end - start).total_seconds()
            start, end = a, b
        else:
            end = max(end, b)
    running += (end - start).total_seconds()
    return running, (max(b for _, b in spans) - spans[0][0]).total_seconds()


def n_reservoirs(study: optuna.Study) -> int:
    """K, the reservoirs of each agent, from the study's record (1 when it has none)."""
    return int(study.user_attrs.get("ermrl", {}).get("reservoirs", 1))


def phi(trial: FrozenTrial, k: int) -> dict[str, list[float]]:
    """{"sr", "lr", "iss": K floats} from the trial's user_attrs, else from its params (iss may be missing)."""
    if "phi" in trial.user_attrs:
        return {name: [float(v) for v in vals] for name, vals in trial.user_attrs["phi"].items()}
    out = {}
    for name in ("sr", "lr", "iss"):
        keys = [name] if k == 1 else [f"{name}_{i}" for i in range(1, k + 1)]
        if all(key in trial.params for key in keys):
            out[name] = [float(trial.params[key]) for key in keys]
    return out
