"""The evolved genome: Φ = (sr, lr, iss) per reservoir, log-uniform within bounds (paper §3, "Outer loop").

Parameter names follow the reference code: ``sr``, ``lr``, ``iss`` for one reservoir and ``sr_1``, ``lr_1``, ...
for several. With a fixed input scaling, ``iss`` is not searched.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import optuna

from ermrl.agent import Phi
from ermrl.errors import ConfigError


@dataclasses.dataclass(frozen=True)
class SearchSpace:
    """Log-uniform bounds of Φ, shared by every reservoir."""

    reservoirs: int = 1
    sr: tuple[float, float] = (1e-4, 1e2)
    """Spectral radius bounds (the reference's defaults)."""
    lr: tuple[float, float] = (1e-2, 1.0)
    """Leak rate bounds; the upper one may not exceed 1."""
    iss: tuple[float, float] = (0.1, 10.0)
    """Input scaling bounds, unused when ``fixed_iss`` is set."""
    fixed_iss: float | None = None
    """Input scaling held fixed (the paper's partially observable runs use 1.0), or None to search it."""

    def __post_init__(self):
        if self.reservoirs < 1:
            raise ConfigError(f"evolution needs at least 1 reservoir, got {self.reservoirs}")
        for name in ("sr", "lr", "iss"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
                flag = {"lr": "leak-rate"}.get(name, name)
                raise ConfigError(f"bad {flag} bounds [{lo}, {hi}]: need 0 < `{name}[0]` < `{name}[1]` (log-uniform)",
                                  owner=type(self))
        if self.lr[1] > 1:
            raise ConfigError(f"bad leak-rate bounds [{self.lr[0]}, {self.lr[1]}]: a leak rate is at most 1; set `lr[1]` "
                              "to 1", owner=type(self))
        if self.fixed_iss is not None and not (math.isfinite(self.fixed_iss) and self.fixed_iss > 0):
            raise ConfigError(f"`fixed_iss` must be positive, got {self.fixed_iss}", owner=type(self))

    @property
    def searched(self) -> tuple[str, ...]:
        return ("sr", "lr") if self.fixed_iss is not None else ("sr", "lr", "iss")

    def names(self, hp: str) -> list[str]:
        """Optuna parameter names of hyperparameter ``hp``, one per reservoir."""
        return [hp] if self.reservoirs == 1 else [f"{hp}_{k + 1}" for k in range(self.reservoirs)]

    def distributions(self) -> dict[str, optuna.distributions.FloatDistribution]:
        return {n: optuna.distributions.FloatDistribution(*getattr(self, hp), log=True)
                for hp in self.searched for n in self.names(hp)}

    @property
    def dimension(self) -> int:
        return len(self.searched) * self.reservoirs

    def default_popsize(self) -> int:
        """CMA-ES's default population size, 4 + ⌊3 ln n⌋ (what Optuna's CmaEsSampler uses)."""
        return 4 + int(math.floor(3 * math.log(self.dimension)))

    def suggest(self, trial: optuna.Trial) -> Phi:
        """Draws Φ for ``trial``: fields of shape (K,)."""
        values = {hp: np.array([trial.suggest_float(n, *getattr(self, hp), log=True) for n in self.names(hp)], np.float32)
                  for hp in self.searched}
        if self.fixed_iss is not None:
            values["iss"] = np.full(self.reservoirs, self.fixed_iss, np.float32)
        return Phi(values["sr"], values["lr"], values["iss"])

    def phi_from_params(self, params: dict) -> Phi:
        """Φ of a finished trial, from its params."""
        get = lambda hp: np.array([params[n] for n in self.names(hp)], np.float32)
        iss = np.full(self.reservoirs, self.fixed_iss, np.float32) if self.fixed_iss is not None else get("iss")
        return Phi(get("sr"), get("lr"), iss)

    def to_dict(self) -> dict:
        """The study record's form: {"sr": [lo, hi], "lr": [lo, hi], "iss": [lo, hi] or {"fixed": v}}."""
        out = {hp: list(getattr(self, hp)) for hp in ("sr", "lr")}
        out["iss"] = {"fixed": self.fixed_iss} if self.fixed_iss is not None else list(self.iss)
        return out

    @staticmethod
    def from_dict(reservoirs: int, d: dict) -> "SearchSpace":
        """Inverse of :meth:`to_dict`."""
        fixed = d["iss"]["fixed"] if isinstance(d["iss"], dict) else None
        iss = SearchSpace.iss if fixed is not None else tuple(d["iss"])
        return SearchSpace(reservoirs, tuple(d["sr"]), tuple(d["lr"]), iss, fixed)
