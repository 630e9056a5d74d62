"""One registry for every env id: ``describe(env_id)`` and ``make(env_id)``.

Three backends sit behind it: ``jax`` (gymnax, stepped inside the jitted program), ``mujoco`` (the MuJoCo
locomotion tasks, stepped in batches by MuJoCo's C library on threads, exact to Gymnasium v5:
:mod:`ermrl.envs.mujoco_group`) and ``host`` (any Gymnasium env, stepped one by one). The last two are stepped on
the host between the jitted program's calls (:data:`HOST_BACKENDS`). Velocity masking and the NoVel ids live in
:mod:`ermrl.envs.masking`.
"""

from __future__ import annotations

import difflib

from ermrl.envs import host_backend, masking
from ermrl.envs.host_backend import HostEnv
from ermrl.envs.jax_backend import GYMNAX_IDS, JaxEnv
from ermrl.envs.spaces import ActionSpace, EnvInfo
from ermrl.errors import ConfigError

BACKENDS = ("auto", "jax", "mujoco", "host")
HOST_BACKENDS = ("mujoco", "host")
"""The backends whose envs are stepped on the host (:class:`HostEnv`)."""


def jax_ids() -> list[str]:
    """Every id the JAX backend runs, NoVel variants included."""
    ids = list(GYMNAX_IDS)
    ids += [masking.novel_id(b) for b in GYMNAX_IDS if b in masking.VELOCITY_DIMS]
    return sorted(ids)


def _unknown(env_id: str, base_id: str) -> ConfigError:
    import gymnasium as gym

    close = difflib.get_close_matches(base_id, sorted(set(gym.registry) | set(jax_ids())), n=3)
    hint = f"; did you mean {', '.join(close)}?" if close else "; any Gymnasium id works, or a NoVel id of " + \
        ", ".join(masking.VELOCITY_DIMS)
    return ConfigError(f"unknown env id {env_id!r}: Gymnasium has no {base_id!r}{hint}")


def resolve_backend(env_id: str, backend: str = "auto") -> str:
    """The backend that will run ``env_id``: 'jax' when it has a JAX version, 'mujoco' for the MuJoCo tasks of
    :data:`~ermrl.envs.mujoco_tasks.TASKS`, else 'host' (Gymnasium)."""
    from ermrl.envs.mujoco_tasks import TASKS as TASK_IDS

    if backend not in BACKENDS:
        raise ConfigError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    base_id, _ = masking.parse(env_id)
    if backend in ("auto", "jax") and base_id in GYMNAX_IDS:
        return "jax"
    if backend == "jax":
        raise ConfigError(f"env {env_id!r} has no JAX version; use `backend` host or auto "
                          f"(the JAX backend runs: {', '.join(jax_ids())})", owner=resolve_backend)
    if backend in ("auto", "mujoco") and base_id in TASK_IDS:
        return "mujoco"
    if backend == "mujoco":
        raise ConfigError(f"env {env_id!r} has no batched MuJoCo version; use `backend` host or auto (the MuJoCo "
                          f"backend runs: {', '.join(sorted(TASK_IDS))})", owner=resolve_backend)
    if not host_backend.known(base_id):
        raise _unknown(env_id, base_id)
    return "host"


def describe(env_id: str, backend: str = "auto") -> EnvInfo:
    """Observation and action layout of ``env_id`` after masking."""
    base_id, deleted = masking.parse(env_id)
    if resolve_backend(env_id, backend) in HOST_BACKENDS:
        return host_backend.describe(env_id, base_id, deleted)
    full = JaxEnv.describe(env_id, base_id, None)
    return JaxEnv.describe(env_id, base_id, masking.kept_dims(full.obs_dim, deleted))


def make(env_id: str, backend: str = "auto", workers: int | str = "auto",
         threads: int | str = "auto") -> JaxEnv | HostEnv:
    """An env for ``env_id`` on the chosen backend (``workers``: Gymnasium env processes, ``threads``: MuJoCo
    stepping threads; each 'auto' or a count)."""
    info = describe(env_id, backend)
    resolved = resolve_backend(env_id, backend)
    if resolved == "mujoco":
        return HostEnv(info, threads=threads, batched=True)
    if resolved == "host":
        return HostEnv(info, workers)
    return JaxEnv(info)


__all__ = ["ActionSpace", "EnvInfo", "HostEnv", "JaxEnv", "describe", "make", "jax_ids", "resolve_backend",
           "BACKENDS", "HOST_BACKENDS"]
