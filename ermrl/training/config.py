"""What a population's training is: its static config (:class:`TrainConfig`, one compiled program serves any
population of it) and its agents (:class:`Population`: Φ × learning rates × seeds)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ermrl.agent import AgentConfig, Phi
from ermrl.errors import ConfigError
from ermrl.ppo.config import PPOConfig
from ermrl.codec import OMIT_WHEN_DEFAULT


MAX_TIMESTEPS = 1_000_000_000
"""The longest training budget per agent that a config accepts."""
MAX_PROCESSES = 256
"""The most processes one population may be trained in (``TrainConfig.processes``)."""


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
    """'auto' (JAX when the env has a JAX version, MuJoCo's batched backend for the MuJoCo locomotion tasks, else
    Gymnasium on the host), 'jax', 'mujoco' or 'host'."""
    env_workers: int | str = "auto"
    """Host backend only: processes that step the envs (0: the main process; 'auto': one per device when an
    env step costs more than the IPC). Results do not depend on it."""
    env_threads: int | str = dataclasses.field(default="auto", metadata={OMIT_WHEN_DEFAULT: True})
    """MuJoCo backend only: threads that step the envs ('auto': one per core). Results do not depend on it."""
    processes: int = dataclasses.field(default=1, metadata={OMIT_WHEN_DEFAULT: True})
    """Host-loop backends (``mujoco``, ``host``) only: processes that train the population at once, each a
    contiguous part of its agents with its own JAX devices and envs (:mod:`ermrl.training.processes`; 1: this
    process alone; the JAX backend, whose one process already keeps every core busy, and JAX on a GPU ignore it).
    On 2 cores two train MuJoCo populations about 1.3× faster. Results do not depend on it."""

    def __post_init__(self):
        if self.total_timesteps < 1:
            raise ConfigError(f"total timesteps must be >= 1, got {self.total_timesteps}")
        if self.total_timesteps > MAX_TIMESTEPS:
            raise ConfigError(f"total timesteps must be <= {MAX_TIMESTEPS:,} per agent (about a day at 10k steps/s; "
                              f"the paper's longest run is 3M), got {self.total_timesteps:,}")
        if self.env_workers != "auto" and not (isinstance(self.env_workers, int) and self.env_workers >= 0):
            raise ConfigError(f"env workers must be 'auto' or an integer >= 0, got {self.env_workers!r}")
        if self.env_threads != "auto" and not (isinstance(self.env_threads, int) and 1 <= self.env_threads <= 4096):
            raise ConfigError(f"env threads must be 'auto' or an integer in 1..4096, got {self.env_threads!r}")
        if not (isinstance(self.processes, int) and 1 <= self.processes <= MAX_PROCESSES):
            raise ConfigError(f"processes must be an integer in 1..{MAX_PROCESSES}, got {self.processes!r}")


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
