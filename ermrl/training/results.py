"""Training results: per-agent episodes, learning curves and fitness (paper §3, "Outer loop").

Fitness is the mean return of the last 10 completed *training* episodes of an agent, as the reference's
RewardsSavingWrapper computes it; a Φ's fitness is the mean over its seeds.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ermrl.envs.spaces import EnvInfo

FITNESS_EPISODES = 10
"""Episodes averaged for an agent's fitness (paper: "the final 10 episodes")."""
CURVE_WINDOW = 100
"""Episodes averaged per curve point, like SB3's ``rollout/ep_rew_mean`` that the paper's curves plot."""
WALL_S = "wall_s"
"""The ``Results.metrics`` name of the training wall time at each update (for TensorBoard's ``time/fps``)."""


@dataclasses.dataclass
class Episodes:
    """The completed training episodes of one agent, in order of completion."""

    timestep: np.ndarray
    """(E,) int: the agent's env-step count when the episode ended (summed over its envs)."""
    ret: np.ndarray
    """(E,) float: undiscounted return."""
    length: np.ndarray
    """(E,) int."""


@dataclasses.dataclass
class Policies:
    """The final policies of a population, fetched from the devices once after training. Every array has a
    leading agent axis (A, ...); padding agents are dropped."""

    env: EnvInfo
    """The env the policies act in (masked observation dims, action space)."""
    actor: dict
    """Flax params of the actor MLP, {"params": {"Dense_i": {"kernel": (A, in, out), "bias": (A, out)}}};
    its output is the logits (Discrete) or the Gaussian means (Box). PPO-LSTM (``ppo.model = "lstm"``):
    {"lstm": {"kernel_x", "kernel_h", "bias_ih", "bias_hh"}, "mlp": those MLP params} (see
    :mod:`ermrl.ppo.recurrent`)."""
    critic: dict
    """The same for the critic (its last layer has one output, the value)."""
    log_std: np.ndarray | None
    """(A, action_dim) state-independent log std for Box actions; None for Discrete."""
    context_norm: dict | None = None
    """With ``PPOConfig.normalize``: {"mean": (A, context_dim), "var": (A, context_dim)}, the final running
    statistics the policy's input is standardized with (:func:`ermrl.ppo.normalize.normalize`; for PPO-LSTM the
    observation's, (A, obs_dim), what its LSTMs see); else None."""

    @staticmethod
    def from_params(env: EnvInfo, params, n: int, norm=None) -> "Policies":
        """From a :class:`~ermrl.ppo.networks.PolicyParams` of NumPy arrays (padded agents first dropped) and the
        agents' :class:`~ermrl.ppo.normalize.Normalizer` (None without normalization)."""
        take = lambda x: np.asarray(x)[:n]
        return Policies(env, _map(take, params.actor), _map(take, params.critic),
                        None if params.log_std is None else take(params.log_std),
                        None if norm is None else {"mean": take(norm.context.mean), "var": take(norm.context.var)})

    def select(self, idx) -> "Policies":
        take = lambda x: x[np.asarray(idx)]
        return Policies(self.env, _map(take, self.actor), _map(take, self.critic),
                        None if self.log_std is None else take(self.log_std),
                        None if self.context_norm is None else _map(take, self.context_norm))


def _map(fn, tree):
    """``fn`` over the leaves of a nested dict."""
    return {k: _map(fn, v) if isinstance(v, dict) else fn(v) for k, v in tree.items()}


def _zip_map(fn, trees: list[dict]):
    """``fn(*leaves)`` over the same leaf of every nested dict of ``trees`` (dicts of one structure)."""
    return {k: _zip_map(fn, [t[k] for t in trees]) if isinstance(trees[0][k], dict) else fn(*(t[k] for t in trees))
            for k in trees[0]}


def fitness(episodes: Episodes, last: int = FITNESS_EPISODES) -> float:
    """Mean return of the last ``last`` completed episodes; NaN when none completed."""
    if len(episodes.ret) == 0:
        return float("nan")
    return float(np.mean(episodes.ret[-last:]))


@dataclasses.dataclass
class Results:
    """What a population's training returns. Agent i has seed ``seeds[i]`` and Φ ``phi[:, i]``."""

    env_id: str
    total_timesteps: int
    timesteps_per_iteration: int
    seeds: np.ndarray
    """(A,)"""
    phi: dict
    """{"sr", "lr", "iss"} -> (A, K) arrays."""
    learning_rate: np.ndarray
    episodes: list[Episodes]
    """One per agent."""
    finite: np.ndarray
    """(A,) bool: False when the agent's parameters or losses became NaN/inf (diverged)."""
    metrics: dict
    """name -> (A, n_iterations) PPO diagnostics, and ``WALL_S``: the training seconds (compile excluded) at the
    end of each update, the same for the agents that trained together (absent from results saved before it)."""
    compile_s: float
    train_s: float
    policies: Policies | None = None
    """Every agent's final policy (None when the results were built without one)."""

    @staticmethod
    def from_iterations(config, population, finished, metrics, finite, n_envs, compile_s, train_s,
                        policies: Policies | None = None) -> "Results":
        """Assembles per-iteration logs: ``finished`` is a list of (returns, lengths), each (A, n_steps, n_envs)."""
        per_iter = config.ppo.buffer_size
        episodes = []
        for i in range(population.size):
            ts, rets, lens = [], [], []
            for it, (ret, length) in enumerate(finished):
                steps, envs_ = np.nonzero(length[i] > 0)
                ts.append(it * per_iter + steps * n_envs + envs_ + 1)
                rets.append(ret[i][steps, envs_])
                lens.append(length[i][steps, envs_])
            episodes.append(Episodes(np.concatenate(ts).astype(np.int64), np.concatenate(rets).astype(np.float64),
                                     np.concatenate(lens).astype(np.int64)))
        stacked = {k: np.stack([m[k] for m in metrics], axis=1) for k in (metrics[0] if metrics else {})}
        return Results(
            env_id=config.env_id, total_timesteps=len(finished) * per_iter, timesteps_per_iteration=per_iter,
            seeds=np.asarray(population.seeds), phi={f: np.asarray(v) for f, v in population.phi._asdict().items()},
            learning_rate=np.asarray(population.learning_rate), episodes=episodes, finite=np.asarray(finite),
            metrics=stacked, compile_s=compile_s, train_s=train_s, policies=policies,
        )

    @property
    def size(self) -> int:
        return len(self.seeds)

    def fitness(self) -> np.ndarray:
        """(A,) per-agent fitness; NaN for an agent that diverged or finished no episode."""
        out = np.array([fitness(e) for e in self.episodes])
        out[~self.finite] = np.nan
        return out

    def curves(self, window: int = CURVE_WINDOW) -> tuple[np.ndarray, np.ndarray]:
        """Learning curves on the update grid: (timesteps (I,), values (A, I)).

        values[a, i] is the mean return of agent a's last ``window`` episodes completed by timesteps[i]
        (NaN before its first episode), as SB3 logs ``rollout/ep_rew_mean``.
        """
        n_iter = self.total_timesteps // self.timesteps_per_iteration
        grid = (np.arange(n_iter) + 1) * self.timesteps_per_iteration
        values = np.full((self.size, n_iter), np.nan)
        for a, ep in enumerate(self.episodes):
            done_by = np.searchsorted(ep.timestep, grid, side="right")
            csum = np.concatenate([[0.0], np.cumsum(ep.ret)])
            lo = np.maximum(done_by - window, 0)
            with np.errstate(invalid="ignore", divide="ignore"):
                values[a] = np.where(done_by > 0, (csum[done_by] - csum[lo]) / (done_by - lo), np.nan)
        return grid, values

    def select(self, agents) -> "Results":
        """The results of a subset of agents (indices into the agent axis), e.g. one model of a population."""
        idx = np.asarray(agents)
        return dataclasses.replace(
            self, seeds=self.seeds[idx], phi={k: v[idx] for k, v in self.phi.items()},
            learning_rate=self.learning_rate[idx], episodes=[self.episodes[i] for i in idx], finite=self.finite[idx],
            metrics={k: v[idx] for k, v in self.metrics.items()},
            policies=None if self.policies is None else self.policies.select(idx))

    @staticmethod
    def concat(parts: list["Results"]) -> "Results":
        """The results of populations trained apart (same env, budget and settings) as one, agents in order:
        the inverse of :meth:`select` over consecutive groups. Compile and training times add up."""
        first = parts[0]
        for p in parts[1:]:
            if (p.env_id, p.total_timesteps, p.timesteps_per_iteration) != \
                    (first.env_id, first.total_timesteps, first.timesteps_per_iteration):
                raise ValueError("cannot join results of different envs or budgets")
        cat = lambda *xs: np.concatenate(xs)
        policies = None
        if all(p.policies is not None for p in parts):
            ps = [p.policies for p in parts]
            policies = Policies(first.policies.env, _zip_map(cat, [q.actor for q in ps]),
                                _zip_map(cat, [q.critic for q in ps]),
                                None if ps[0].log_std is None else cat(*(q.log_std for q in ps)),
                                None if ps[0].context_norm is None else _zip_map(cat, [q.context_norm for q in ps]))
        return dataclasses.replace(
            first, seeds=cat(*(p.seeds for p in parts)), phi={k: cat(*(p.phi[k] for p in parts)) for k in first.phi},
            learning_rate=cat(*(p.learning_rate for p in parts)), episodes=[e for p in parts for e in p.episodes],
            finite=cat(*(p.finite for p in parts)),
            metrics={k: cat(*(p.metrics[k] for p in parts)) for k in first.metrics if all(k in p.metrics for p in parts)},
            compile_s=sum(p.compile_s for p in parts), train_s=sum(p.train_s for p in parts), policies=policies)

    def agent_steps_per_s(self) -> float:
        return self.size * self.total_timesteps / self.train_s if self.train_s > 0 else float("nan")
