"""Backend-independent description of an environment's interface."""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class ActionSpace:
    """Discrete(n) when ``discrete``, else Box(low, high) of shape (dim,)."""

    discrete: bool
    dim: int
    """n for Discrete, the action dimension for Box."""
    low: tuple[float, ...] = ()
    high: tuple[float, ...] = ()

    @property
    def feature_dim(self) -> int:
        """Width of the action's encoding in the reservoir input: one-hot n, or the raw Box dim."""
        return self.dim

    @property
    def policy_dim(self) -> int:
        """Width of the policy head: logits (n) or Gaussian means (dim)."""
        return self.dim

    @staticmethod
    def from_gymnasium(space) -> "ActionSpace":
        import gymnasium as gym

        if isinstance(space, gym.spaces.Discrete):
            return ActionSpace(True, int(space.n))
        if isinstance(space, gym.spaces.Box) and len(space.shape) == 1:
            return ActionSpace(False, int(space.shape[0]), tuple(map(float, space.low)), tuple(map(float, space.high)))
        raise NotImplementedError(f"unsupported action space {space}: only Discrete and 1-D Box are supported")


@dataclasses.dataclass(frozen=True)
class EnvInfo:
    """What the agent needs to know about an env id, whatever backend steps it."""

    env_id: str
    """The id the user asked for, e.g. 'CartPoleNoVel-v1'."""
    base_id: str
    """The underlying Gymnasium id, e.g. 'CartPole-v1'."""
    kept_dims: tuple[int, ...]
    """Observation dims that survive velocity masking."""
    action: ActionSpace
    max_episode_steps: int

    @property
    def obs_dim(self) -> int:
        return len(self.kept_dims)

    def mask(self, obs):
        """Deletes the masked dims from obs (..., full_obs_dim) -> (..., obs_dim). Works on NumPy and JAX arrays."""
        return obs[..., np.asarray(self.kept_dims)]
