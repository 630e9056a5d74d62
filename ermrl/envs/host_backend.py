"""The host backend: any Gymnasium env id, its envs stepped on the host (in worker processes when a step is
costly), while the reservoirs, policy and PPO update run in JAX (see :mod:`ermrl.training.host_loop`).

Why not ``jax.pure_callback`` from inside the jitted rollout: on XLA:CPU each callback spends about 130 µs
moving its arguments into JAX arrays, several times the cost of a MuJoCo step. One jitted call per step from a
Python loop costs less, and lets the env workers run while the main process waits.
"""

from __future__ import annotations

import os
import time

import numpy as np

from ermrl.envs.host_groups import EnvGroup, EpisodeRecord, WorkerGroup, make_gymnasium
from ermrl.envs.masking import kept_dims
from ermrl.envs.spaces import ActionSpace, EnvInfo
from ermrl.errors import ConfigError

EXTRAS = {"gymnasium.envs.box2d": "box2d", "gymnasium.envs.mujoco": "mujoco"}
"""Entry-point prefix -> the ermrl extra that installs the env's simulator."""

WORKER_THRESHOLD_S = 25e-6
"""With ``workers="auto"``, envs whose step takes longer than this run in worker processes."""


def extra_for(base_id: str) -> str | None:
    """The extra ('box2d', 'mujoco') that ``base_id`` needs, or None."""
    import gymnasium as gym

    spec = gym.spec(base_id)
    entry = spec.entry_point if isinstance(spec.entry_point, str) else ""
    return next((extra for prefix, extra in EXTRAS.items() if entry.startswith(prefix)), None)


MUJOCO_GL_VALUES = ("egl", "osmesa", "glfw", "glx", "enable", "enabled", "on", "true", "1", "",
                    "disable", "disabled", "off", "false", "0")
"""What MuJoCo accepts for MUJOCO_GL on Linux; any other value makes ``import mujoco`` raise."""


def check_mujoco_gl(base_id: str) -> None:
    """A one-line ConfigError when ``base_id`` is a MuJoCo env and MUJOCO_GL holds a value MuJoCo refuses."""
    value = os.environ.get("MUJOCO_GL")
    if value is not None and value.lower().strip() not in MUJOCO_GL_VALUES and extra_for(base_id) == "mujoco":
        raise ConfigError(f"MUJOCO_GL={value!r} is not a renderer MuJoCo knows; set it to egl or osmesa (no screen) "
                          "or glfw, or unset it")


def known(base_id: str) -> bool:
    """Whether Gymnasium's registry has ``base_id``."""
    import gymnasium as gym

    return base_id in gym.registry


def describe(env_id: str, base_id: str, deleted: tuple[int, ...]) -> EnvInfo:
    """EnvInfo of a Gymnasium env, built by making one instance. Raises ConfigError with the fix."""
    import gymnasium as gym

    check_mujoco_gl(base_id)
    try:
        env = make_gymnasium(base_id)
    except gym.error.DependencyNotInstalled as error:
        extra = extra_for(base_id)
        fix = f"pip install 'ermrl[{extra}]'" if extra else f"install what it needs ({error})"
        raise ConfigError(f"env {env_id!r} needs a simulator that is not installed; run: {fix}") from None
    try:
        space = env.observation_space
        if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
            raise ConfigError(f"env {env_id!r} has observation space {space}; only 1-D Box observations are supported")
        try:
            action = ActionSpace.from_gymnasium(env.action_space)
        except NotImplementedError as error:
            raise ConfigError(f"env {env_id!r}: {error}") from None
        obs_dim = space.shape[0]
        if any(d >= obs_dim for d in deleted):
            raise ConfigError(f"env {env_id!r}: velocity dims {deleted} do not fit a {obs_dim}-dim observation")
        return EnvInfo(env_id, base_id, kept_dims(obs_dim, deleted), action, int(env.spec.max_episode_steps or 0))
    finally:
        env.close()


def step_seconds(info: EnvInfo, steps: int = 200) -> float:
    """A quick estimate of one env step's host time, in seconds (random actions)."""
    group = EnvGroup(info.base_id, info.kept_dims, info.action.discrete, 0, 1)
    group.reset(np.zeros(1, np.int64))
    space = group.envs[0].action_space
    space.seed(0)
    actions = [space.sample() for _ in range(steps)]
    t = time.perf_counter()
    for a in actions:
        group.step(np.asarray([a]))
    elapsed = (time.perf_counter() - t) / steps
    group.close()
    return elapsed


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS tells it)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def batched_step_seconds(info: EnvInfo, slots: int = 22, threads: int | None = None, steps: int = 40) -> float:
    """A quick estimate of one env step's host time on the ``mujoco`` backend, in seconds per env: ``slots``
    envs of a :class:`~ermrl.envs.mujoco_group.MujocoGroup` stepped together on ``threads`` threads (default: every
    usable core) with random actions."""
    from ermrl.envs.mujoco_group import MujocoGroup

    threads = usable_cores() if threads is None else threads
    group = MujocoGroup(info.base_id, info.kept_dims, False, 0, slots, threads=min(threads, slots))
    group.reset(np.arange(slots))
    space = group.action_space
    actions = np.random.default_rng(0).uniform(space.low, space.high, size=(steps, slots, space.shape[0]))
    t = time.perf_counter()
    for a in actions:
        group.step(a)
    elapsed = (time.perf_counter() - t) / (steps * slots)
    group.close()
    return elapsed


class HostEnv:
    """The Gymnasium envs of one population, stepped all at once from the host loop.

    Slots are numbered agent · n_envs + env. ``open`` builds them in one in-process group, or splits them
    into ``workers`` contiguous groups, each in its own process; ``step`` then sends every group its actions
    before waiting for any, so the groups step in parallel. ``batched``: one in-process
    :class:`~ermrl.envs.mujoco_group.MujocoGroup` instead, stepped by MuJoCo on ``threads`` threads (the
    ``mujoco`` backend).
    """

    def __init__(self, info: EnvInfo, workers: int | str = "auto", threads: int | str = "auto", batched: bool = False):
        self.info = info
        self.workers = workers
        self.threads, self.batched = threads, batched
        self.groups: list[EnvGroup | WorkerGroup] = []
        self._step_s: float | None = None
        """``step_seconds`` measured once, not at every ``open`` (an evolution opens once per generation)."""

    def resolved_workers(self, n_slots: int) -> int:
        """Worker processes to use: 'auto' gives one per core when a step costs more than the IPC."""
        if self.workers != "auto":
            return min(int(self.workers), n_slots)
        cores = os.cpu_count() or 1
        if cores == 1:
            return 0
        if self._step_s is None:
            self._step_s = step_seconds(self.info)
        return min(cores, n_slots) if self._step_s > WORKER_THRESHOLD_S else 0

    def open(self, n_slots: int):
        """Creates the envs of ``n_slots`` slots (closing any open ones)."""
        self.close()
        args = (self.info.base_id, self.info.kept_dims, self.info.action.discrete)
        if self.batched:
            from ermrl.envs.mujoco_group import MujocoGroup

            threads = usable_cores() if self.threads == "auto" else int(self.threads)
            self.groups = [MujocoGroup(*args, 0, n_slots, threads=min(threads, n_slots))]
            return
        workers = self.resolved_workers(n_slots)
        if workers == 0:
            self.groups = [EnvGroup(*args, 0, n_slots)]
            return
        per = -(-n_slots // workers)
        self.groups = [WorkerGroup(*args, first, min(per, n_slots - first)) for first in range(0, n_slots, per)]

    def close(self):
        for group in self.groups:
            group.close()
        self.groups = []

    def _call(self, command: str, *per_slot: np.ndarray) -> list:
        """Runs ``command`` on every group with its part of the per-slot arrays; returns the parts in order."""
        if not self.groups:
            raise RuntimeError("host envs are not open: call open() first")
        parts = [tuple(x[g.first:g.first + g.size] for x in per_slot) for g in self.groups]
        for group, args in zip(self.groups, parts):
            if isinstance(group, WorkerGroup):
                group.send(command, *args)
        return [group.receive() if isinstance(group, WorkerGroup) else getattr(group, command)(*args)
                for group, args in zip(self.groups, parts)]

    def reset(self, seeds: np.ndarray) -> np.ndarray:
        """Seeds and resets every slot; seeds (n_slots,) -> masked obs (n_slots, obs_dim) float32."""
        return np.concatenate(self._call("reset", np.asarray(seeds)))

    def snapshot(self) -> list[EpisodeRecord]:
        """Every slot's :class:`~ermrl.envs.host_groups.EpisodeRecord`, in slot order."""
        return [record for part in self._call("snapshot") for record in part]

    def restore(self, records: list[EpisodeRecord]) -> np.ndarray:
        """Rebuilds every slot from its record (the envs must be open, with as many slots); returns the masked
        observations (n_slots, obs_dim). Raises :class:`~ermrl.envs.host_groups.ReplayMismatch` when one does
        not replay exactly."""
        return np.concatenate(self._call("restore", records))

    def step(self, actions: np.ndarray) -> np.ndarray:
        """Steps every slot with actions (n_slots,) int or (n_slots, dim) float, auto-resetting ended episodes.
        Returns the packed :class:`ermrl.envs.host_groups.Stepped`, (n_slots, 2·obs_dim + 3) float32."""
        parts = self._call("step", np.asarray(actions))
        return parts[0] if len(parts) == 1 else np.concatenate(parts)
