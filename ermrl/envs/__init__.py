"""One registry for every env id: ``describe(env_id)`` and ``make(env_id)``.

Two backends sit behind it: ``jax`` (gymnax, stepped inside the jitted program) and ``host`` (Gymnasium,
stepped on the host; issue 4). Velocity masking and the NoVel ids live in :mod:`ermrl.envs.masking`.
"""

from __future__ import annotations

from ermrl.envs import masking
from ermrl.envs.jax_backend import GYMNAX_IDS, JaxEnv
from ermrl.envs.spaces import ActionSpace, EnvInfo
from ermrl.errors import ConfigError

BACKENDS = ("auto", "jax")


def jax_ids() -> list[str]:
    """Every id the JAX backend runs, NoVel variants included."""
    ids = list(GYMNAX_IDS)
    ids += [masking.novel_id(b) for b in GYMNAX_IDS if b in masking.VELOCITY_DIMS]
    return sorted(ids)


def resolve_backend(env_id: str, backend: str = "auto") -> str:
    """The backend that will run ``env_id``: 'jax' when it has a JAX version."""
    if backend not in BACKENDS:
        raise ConfigError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    base_id, _ = masking.parse(env_id)
    if base_id in GYMNAX_IDS:
        return "jax"
    raise ConfigError(f"unknown env id {env_id!r}; the JAX backend runs: {', '.join(jax_ids())}")


def describe(env_id: str, backend: str = "auto") -> EnvInfo:
    """Observation and action layout of ``env_id`` after masking."""
    resolve_backend(env_id, backend)
    base_id, deleted = masking.parse(env_id)
    full = JaxEnv.describe(env_id, base_id, None)
    return JaxEnv.describe(env_id, base_id, masking.kept_dims(full.obs_dim, deleted))


def make(env_id: str, backend: str = "auto") -> JaxEnv:
    """An env for ``env_id`` on the chosen backend."""
    return JaxEnv(describe(env_id, backend))


__all__ = ["ActionSpace", "EnvInfo", "JaxEnv", "describe", "make", "jax_ids", "resolve_backend", "BACKENDS"]
