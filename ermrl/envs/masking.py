"""Velocity removal: the partially observable ``NoVel`` variants of the paper's control tasks (paper §4.1).

Masking *deletes* the velocity dimensions of the observation (as the reference's DeletedVelocityWrapper and
rl-zoo's NoVel ids do), it does not zero them.
"""

from __future__ import annotations

import re

from ermrl.errors import ConfigError

VELOCITY_DIMS: dict[str, tuple[int, ...]] = {
    "CartPole-v1": (1, 3),
    "Pendulum-v1": (2,),
    "MountainCar-v0": (1,),
    "MountainCarContinuous-v0": (1,),
    "LunarLander-v3": (2, 3, 5),
    "LunarLanderContinuous-v3": (2, 3, 5),
}
"""Base env id -> indices of the velocity dimensions that the NoVel variant deletes."""

_NOVEL = re.compile(r"^(?P<name>.+)NoVel-(?P<version>v\d+)$")


def novel_id(base_id: str) -> str:
    """'CartPole-v1' -> 'CartPoleNoVel-v1'."""
    name, version = base_id.rsplit("-", 1)
    return f"{name}NoVel-{version}"


def parse(env_id: str) -> tuple[str, tuple[int, ...]]:
    """Splits an env id into (base id, deleted dims). Plain ids delete nothing.

    Raises ConfigError for a NoVel id whose base env has no known velocity dims.
    """
    match = _NOVEL.match(env_id)
    if match is None:
        return env_id, ()
    base_id = f"{match['name']}-{match['version']}"
    if base_id not in VELOCITY_DIMS:
        known = ", ".join(novel_id(b) for b in VELOCITY_DIMS)
        raise ConfigError(f"no velocity mask is known for {base_id!r} (from {env_id!r}); NoVel ids are: {known}")
    return base_id, VELOCITY_DIMS[base_id]


def kept_dims(obs_dim: int, deleted: tuple[int, ...]) -> tuple[int, ...]:
    """Indices of the observation dims that survive masking, in order."""
    return tuple(i for i in range(obs_dim) if i not in set(deleted))
