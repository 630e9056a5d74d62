"""What an evolution is: the candidates' training, the search space, the budget and the fitness (paper §3).

With one env, a trial's fitness is the mean over its seeds of each agent's fitness (the mean return of its last
10 training episodes). With several envs (paper §4.3, generalization), it is the mean over the envs of the
normalized score nScore = (score − random) / (ppo − random) of each env's seed-averaged fitness.
"""

from __future__ import annotations

import dataclasses

from ermrl.errors import ConfigError
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.scoring import NORMALIZATIONS, Baseline
from ermrl.training.config import TrainConfig


SEED_SCHEDULES = ("fixed", "generation")
GENERATION_SEEDS = 100_000
"""The first seed of the 'generation' schedule, far from the test phases' (1000…) and selection's (2000…)."""


MAX_TRIALS = 100_000
"""The most trials a study may have."""


@dataclasses.dataclass(frozen=True)
class EvolveConfig:
    """An evolution: what each candidate's training is, and how many candidates to try."""

    train: TrainConfig
    """Every candidate's training; with several envs, its ``env_id`` is replaced by each env in turn."""
    space: SearchSpace
    trials: int = 900
    """Completed trials to reach (the paper: 900)."""
    seeds: int = 3
    """Seeds per candidate Φ; its fitness is the mean over them (the paper: 3)."""
    sampler: str = "cmaes"
    popsize: int | None = None
    """Trials per generation; None takes CMA-ES's default 4 + ⌊3 ln n⌋."""
    sampler_seed: int | None = 0
    """Seed of the sampler's draws (worker i > 0 of a study draws from this seed and i); the same seed and trials
    give the same candidates."""
    seed_schedule: str = "fixed"
    """Which seeds (reservoir draws, policy inits, envs) evaluate a trial: 'fixed', seeds 0..S−1 for every trial
    (the paper's code), or 'generation', new seeds for each generation, shared by its trials so that CMA-ES still
    ranks them on the same draws (generation g: GENERATION_SEEDS + g·S .. + S−1), which keeps the evolution from
    fitting Φ to S particular draws."""
    envs: tuple[str, ...] = ()
    """The envs the fitness is averaged over; empty means just ``train.env_id``."""
    normalization: str = "episodic"
    """With several envs: 'episodic' (random = the random agent's mean episode return) or 'reference'
    (the reference code's mean per-step reward of the random agent, mixed with episodic PPO scores)."""
    baselines: tuple[Baseline, ...] = ()
    """With several envs: the random and PPO constants of each env, in ``env_ids`` order."""

    def __post_init__(self):
        for name in ("trials", "seeds"):
            if getattr(self, name) < 1:
                raise ConfigError(f"`{name}` must be >= 1, got {getattr(self, name)}", owner=type(self))
        if self.trials > MAX_TRIALS:
            raise ConfigError(f"`trials` must be <= {MAX_TRIALS:,} (the paper's studies have 900), got {self.trials}",
                              owner=type(self))
        if self.popsize is not None and self.popsize < 2:
            raise ConfigError(f"`popsize` must be >= 2 (CMA-ES needs at least 2 candidates a generation), got "
                              f"{self.popsize}", owner=type(self))
        if self.seed_schedule not in SEED_SCHEDULES:
            raise ConfigError(f"unknown seed schedule {self.seed_schedule!r}; choose one of {', '.join(SEED_SCHEDULES)}")
        if self.normalization not in NORMALIZATIONS:
            raise ConfigError(f"unknown normalization {self.normalization!r}; choose one of {', '.join(NORMALIZATIONS)}")
        if len(set(self.env_ids)) != len(self.env_ids):
            raise ConfigError(f"`envs` lists an env twice: {', '.join(self.env_ids)}; give each env once",
                              owner=type(self))
        if self.baselines and tuple(b.env_id for b in self.baselines) != self.env_ids:
            raise ConfigError("baselines must list the evolution's envs in order")

    @property
    def env_ids(self) -> tuple[str, ...]:
        return self.envs or (self.train.env_id,)

    @property
    def normalized(self) -> bool:
        """Whether the fitness is a mean of normalized scores (several envs)."""
        return len(self.env_ids) > 1

    def train_for(self, env_id: str) -> TrainConfig:
        return dataclasses.replace(self.train, env_id=env_id)

    def trial_seeds(self, generation: int) -> list[int]:
        """The S seeds of a trial of ``generation`` (see ``seed_schedule``)."""
        if self.seed_schedule == "fixed":
            return list(range(self.seeds))
        start = GENERATION_SEEDS + generation * self.seeds
        return list(range(start, start + self.seeds))

    @property
    def generation_size(self) -> int:
        return self.popsize or self.space.default_popsize()
