"""Generations shared by several workers: where the next trial goes, and whether a trial just asked fits.

CMA-ES (Optuna's ``CmaEsSampler``) tags every trial it samples with its CMA generation (the trial system
attribute ``cma:generation``). Before sampling, it tells the optimizer the first ``popsize`` COMPLETE trials (by
trial number) of the current generation once there are that many, and moves on to the next generation; any
further trial of a generation is never told. So that every completed trial informs the search, at most
``popsize`` trials of a generation may be RUNNING or COMPLETE at any time: the workers share one generation,
each claiming some of its free slots, and a trial asked beyond ``popsize`` by a race is failed at once
("generation already full"). Failed trials free their slot, which the next ask fills in the same generation.

A trial fits when fewer than ``popsize`` trials of its generation with a smaller number are RUNNING or
COMPLETE. Numbers grow with asking and states never return to RUNNING, so the verdict, once every smaller
trial's generation is known, is final: of two trials racing for the last slot, the smaller number wins.

ermrl's generation of a trial (its user attribute ``generation``) is its CMA generation + 1. Generation 0 is the
sampler's startup: while no trial has completed, CMA-ES has nothing to tell and the independent sampler draws at
random, untagged; those trials never reach CMA-ES (Optuna's design). Other samplers have no generations: there
ermrl groups trials ``popsize`` at a time for the record, and a trial that does not fit joins the next group.
"""

from __future__ import annotations

import dataclasses

from optuna.trial import FrozenTrial, TrialState

CMA_GENERATION = "cma:generation"
"""The system attribute in which Optuna's CmaEsSampler records a trial's CMA generation."""
ATTR = "generation"
"""The trial user attribute holding ermrl's generation; set as soon as the trial's generation is known."""
FULL = "generation already full"
"""The failure reason of a CMA-ES trial asked beyond popsize in its generation (a race between workers)."""

_ALIVE = (TrialState.RUNNING, TrialState.COMPLETE)


@dataclasses.dataclass(frozen=True)
class Slots:
    """The generation the next trial should join and how many of its slots are free."""

    generation: int
    free: int
    running: int
    """Trials of that generation RUNNING now (with those whose generation is not known yet)."""


@dataclasses.dataclass(frozen=True)
class Ledger:
    """The generations of one study. ``cma``: the sampler is CMA-ES (its generations are the sampler's)."""

    popsize: int
    cma: bool

    def label(self, t: FrozenTrial, placed: dict[int, int] | None = None) -> int | None:
        """ermrl's generation of ``t``; None while it is being asked (neither sampled nor placed yet)."""
        tag = t.system_attrs.get(CMA_GENERATION) if self.cma else None
        if tag is not None:
            return int(tag) + 1
        if placed and t.number in placed:
            return placed[t.number]
        if ATTR in t.user_attrs:
            return 0 if self.cma else int(t.user_attrs[ATTR])
        return None

    def next_slots(self, trials: list[FrozenTrial]) -> Slots:
        """The generation the next asked trial will (most likely) join, and its free slots. The verdict on each
        trial comes after asking, from ``place``; this only says how many to ask."""
        alive = [t for t in trials if t.state in _ALIVE]
        unknown = sum(t.state == TrialState.RUNNING and self.label(t) is None for t in alive)
        if self.cma:
            if not any(t.state == TrialState.COMPLETE for t in trials):
                generation = 0  # the sampler's startup: random draws until a trial completes
            else:
                tags = [int(t.system_attrs[CMA_GENERATION]) for t in trials if CMA_GENERATION in t.system_attrs]
                last = max(tags, default=-1)
                done = sum(t.state == TrialState.COMPLETE and t.system_attrs.get(CMA_GENERATION) == last
                           for t in trials)
                generation = (last if last >= 0 and done < self.popsize else last + 1) + 1
        else:
            generation = max((g for t in alive if (g := self.label(t)) is not None), default=0)
            if sum(self.label(t) == generation for t in alive) + unknown >= self.popsize:
                generation += 1
        members = sum(self.label(t) == generation for t in alive)
        running = sum(self.label(t) == generation and t.state == TrialState.RUNNING for t in alive) + unknown
        return Slots(generation, max(0, self.popsize - members - unknown), running)

    def place(self, trial: FrozenTrial, trials: list[FrozenTrial], placed: dict[int, int] | None = None) -> int | None:
        """The generation ``trial`` (just asked and sampled) belongs to, or -1 when it does not fit (CMA-ES: its
        generation already has popsize trials running or complete), or None while some trial with a smaller
        number is still being asked (ask again shortly). ``placed``: generations decided but not yet stored
        ({number: generation}), for a worker placing several trials in number order."""
        lower = [t for t in trials if t.number < trial.number and t.state in _ALIVE]
        labels = [self.label(t, placed) for t in lower]
        if any(g is None for g in labels):
            return None
        if self.cma:
            if CMA_GENERATION not in trial.system_attrs and "fixed_params" in trial.system_attrs:
                return 0  # an enqueued trial with every parameter given: outside the sampler's generations
            generation = self.label(trial, {trial.number: 0})
            return generation if labels.count(generation) < self.popsize else -1
        generation = max(labels, default=0)
        while labels.count(generation) >= self.popsize:
            generation += 1
        return generation


def generation_seconds(trials: list[FrozenTrial], size: int) -> float | None:
    """The wall time of the study's last generation whose ``size`` trials all completed: from its first trial's
    start to its last one's end (with several workers, about one batch's time); None when there is none."""
    by: dict[int, list[FrozenTrial]] = {}
    for t in trials:
        if t.state == TrialState.COMPLETE and isinstance(t.user_attrs.get(ATTR), int) \
                and t.datetime_start is not None and t.datetime_complete is not None:
            by.setdefault(t.user_attrs[ATTR], []).append(t)
    full = [g for g, ts in by.items() if len(ts) >= size]
    if not full:
        return None
    last = by[max(full)]
    return (max(t.datetime_complete for t in last) - min(t.datetime_start for t in last)).total_seconds()


def duration_text(seconds: float) -> str:
    """A duration as the messages show it: '40 s', '41 min', '2 h 05 min', '19 h'."""
    if seconds < 60:
        return f"{seconds:.0f} s"
    m = round(seconds / 60)
    if m >= 600:
        return f"{round(seconds / 3600)} h"
    return f"{m} min" if m < 60 else f"{m // 60} h {m % 60:02d} min"
