"""Normalized scores for evolutions over several envs (paper §4.3 and appendix "Normalized scores").

nScore = (score − random) / (ppo − random), per env, with two constants:
- ``random``: the random agent's mean *episode return* (uniform actions in the real Gymnasium env);
- ``ppo``: vanilla PPO's fitness (the mean return of its last 10 training episodes, averaged over the
  evolution's seeds 0..S−1), with the same budget and PPO settings (learning rate, ``--gamma``, ...) as the
  evolution that uses it.

The reference code took as ``random`` the mean over episodes of the *per-step* mean reward, while its PPO
targets were episodic returns; ``normalization="reference"`` reproduces that mix.

The constants live in tables with their provenance: ``ermrl/data/baselines.json`` ships with the package, and
``runs/baselines.json`` (or any path) holds what users computed; the user's entries win.
"""

from __future__ import annotations

import dataclasses
import datetime
from pathlib import Path

import numpy as np

from ermrl.errors import ConfigError
from ermrl.evolution.scoring import NORMALIZATIONS, Baseline, nscore

__all__ = ["NORMALIZATIONS", "Baseline", "BaselineTable", "PPOScore", "RandomScore", "load_table", "nscore",
           "ppo_fitness", "ppo_settings", "random_scores", "resolve", "save_table"]

SHIPPED = Path(__file__).resolve().parent.parent / "data" / "baselines.json"
"""The table that ships with ermrl (random agents of the paper's envs, PPO at the paper's budget)."""


def default_table() -> Path:
    """The user's table, which extends the shipped one."""
    return Path("runs") / "baselines.json"


@dataclasses.dataclass(frozen=True)
class RandomScore:
    """A uniform-random agent's scores on one env."""

    episodes: int
    mean_return: float
    """Mean episode return: the constant of the correct normalization."""
    std_return: float
    mean_step_reward: float
    """Mean over episodes of the per-episode mean step reward: the reference code's constant."""


@dataclasses.dataclass(frozen=True)
class PPOScore:
    """Vanilla PPO's fitness on one env at one budget."""

    seeds: int
    timesteps: int
    learning_rate: float
    mean: float
    std: float
    per_seed: tuple[float | None, ...]
    settings: dict = dataclasses.field(default_factory=dict)
    """Its PPO settings other than SB3's defaults, the learning rate aside (:func:`ppo_settings`); {} for the
    paper's PPO."""


def ppo_settings(ppo) -> dict:
    """{field: value} of the PPOConfig ``ppo`` where it differs from SB3's defaults, the learning rate aside (a key
    of its own): {} for the paper's PPO, so the entries written before settings were recorded are those."""
    from ermrl.ppo.config import SB3_DEFAULTS

    return {f.name: list(v) if isinstance(v, tuple) else v for f in dataclasses.fields(ppo)
            if f.name != "learning_rate" and (v := getattr(ppo, f.name)) != getattr(SB3_DEFAULTS, f.name)}


def _ppo_config(learning_rate: float, settings: dict | None):
    """The PPOConfig of a table entry: SB3's defaults with its learning rate and settings."""
    from ermrl.ppo.config import SB3_DEFAULTS

    fields = {k: tuple(v) if isinstance(v, list) else v for k, v in (settings or {}).items()}
    return dataclasses.replace(SB3_DEFAULTS, learning_rate=learning_rate, **fields)


def random_scores(env_id: str, episodes: int = 100, seed: int = 0) -> RandomScore:
    """Runs ``episodes`` episodes of uniform actions (``action_space.sample``, seeded) in the Gymnasium env;
    masking deletes observation dims only, so the base env's rewards are the NoVel env's."""
    from ermrl import envs
    from ermrl.envs.host_groups import make_gymnasium

    if episodes < 1:
        raise ConfigError(f"`episodes` must be >= 1, got {episodes}", owner=random_scores)
    info = envs.describe(env_id, "host")
    env = make_gymnasium(info.base_id)
    env.action_space.seed(seed)
    returns, step_means = [], []
    try:
        for e in range(episodes):
            env.reset(seed=seed + e)
            rewards, done = [], False
            while not done:
                _, r, terminated, truncated, _ = env.step(env.action_space.sample())
                rewards.append(float(r))
                done = terminated or truncated
            returns.append(sum(rewards))
            step_means.append(float(np.mean(rewards)))
    finally:
        env.close()
    return RandomScore(episodes, float(np.mean(returns)), float(np.std(returns)), float(np.mean(step_means)))


def ppo_fitness(env_id: str, timesteps: int, seeds: int, learning_rate: float = 3e-4, backend: str = "auto",
                env_workers="auto", progress_fn=None, settings: dict | None = None, env_threads="auto",
                processes: int = 1) -> PPOScore:
    """Vanilla PPO (no reservoir) on ``env_id`` over seeds 0..seeds−1, the evolution's fitness definition, with
    SB3's PPO defaults but ``learning_rate`` and ``settings`` (:func:`ppo_settings` of the evolution's PPO).
    ``backend``, ``env_workers``, ``env_threads`` and ``processes``: how it trains (TrainConfig's fields)."""
    from ermrl.agent import AgentConfig, Phi
    from ermrl.training import Population, TrainConfig, Trainer

    if seeds < 1:
        raise ConfigError(f"`seeds` must be >= 1, got {seeds}", owner=ppo_fitness)
    config = TrainConfig(env_id=env_id, total_timesteps=timesteps, agent=AgentConfig(reservoirs=0),
                         ppo=_ppo_config(learning_rate, settings), backend=backend,
                         env_workers=env_workers, env_threads=env_threads, processes=processes)
    fit = Trainer(config).run(Population.grid(Phi(1.0, 1.0, 1.0), seeds, learning_rate, 0), progress_fn).fitness()
    if not np.isfinite(fit).any():
        raise ConfigError(f"vanilla PPO finished no episode on {env_id} in {timesteps} steps; use a larger budget")
    return PPOScore(seeds, timesteps, learning_rate, float(np.nanmean(fit)), float(np.nanstd(fit)),
                    tuple(None if not np.isfinite(v) else float(v) for v in fit), dict(settings or {}))


# -- tables ------------------------------------------------------------------------------------------------


def _provenance(command: str) -> dict:
    import ermrl
    from ermrl.provenance import software

    return {"command": command, "date": datetime.date.today().isoformat(), "ermrl_version": ermrl.__version__,
            "software": software()}


@dataclasses.dataclass
class BaselineTable:
    """Random entries by env id, PPO entries by (env id, timesteps, seeds, learning rate, other PPO settings), each
    a dict with its numbers and provenance (command, date, ermrl_version); an entry without ``settings`` has SB3's.
    ``user`` holds the entries to save."""

    random_entries: dict
    ppo_entries: list
    user: dict = dataclasses.field(default_factory=lambda: {"random": {}, "ppo": []})

    def random(self, env_id: str) -> RandomScore | None:
        e = self.random_entries.get(env_id)
        return None if e is None else RandomScore(e["episodes"], e["mean_return"], e["std_return"], e["mean_step_reward"])

    def _ppo_entry(self, entries, env_id, timesteps, seeds, learning_rate, settings):
        return next((e for e in reversed(entries) if e["env_id"] == env_id and e["timesteps"] == timesteps
                     and e["seeds"] == seeds and np.isclose(e["learning_rate"], learning_rate)
                     and e.get("settings", {}) == (settings or {})), None)

    def ppo(self, env_id: str, timesteps: int, seeds: int, learning_rate: float,
            settings: dict | None = None) -> PPOScore | None:
        e = self._ppo_entry(self.ppo_entries, env_id, timesteps, seeds, learning_rate, settings)
        return None if e is None else PPOScore(e["seeds"], e["timesteps"], e["learning_rate"], e["mean"], e["std"],
                                               tuple(e["per_seed"]), e.get("settings", {}))

    def add_random(self, env_id: str, score: RandomScore, command: str) -> None:
        entry = {**dataclasses.asdict(score), **_provenance(command)}
        self.random_entries[env_id] = self.user["random"][env_id] = entry

    def add_ppo(self, env_id: str, score: PPOScore, command: str) -> None:
        entry = {"env_id": env_id, **dataclasses.asdict(score), **_provenance(command)}
        entry["per_seed"] = list(entry["per_seed"])
        for entries in (self.ppo_entries, self.user["ppo"]):
            old = self._ppo_entry(entries, env_id, score.timesteps, score.seeds, score.learning_rate, score.settings)
            if old is not None:
                entries.remove(old)
            entries.append(entry)


def _read(path: Path) -> dict:
    import json

    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
        if not isinstance(data, dict) or not isinstance(data.get("random"), dict) or not isinstance(data.get("ppo"), list):
            raise ValueError("needs a 'random' table and a 'ppo' list")
        return data
    except (ValueError, AttributeError) as e:
        raise ConfigError(f"baselines table {path} is damaged ({str(e).splitlines()[0]}); fix it or delete it and "
                          "rerun `ermrl baselines`") from None


def load_table(path: Path | None = None) -> BaselineTable:
    """The shipped table with the user's table (``path``, default runs/baselines.json) over it."""
    shipped = _read(SHIPPED)
    path = Path(path) if path is not None else default_table()
    user = _read(path) if path.is_file() else {"random": {}, "ppo": []}
    return BaselineTable({**shipped["random"], **user["random"]}, shipped["ppo"] + user["ppo"],
                         {"random": dict(user["random"]), "ppo": list(user["ppo"])})


def save_table(table: BaselineTable, path: Path | None = None) -> Path:
    """Writes the user's entries (never the shipped ones) atomically."""
    from ermrl.storage import write_json

    return write_json(Path(path) if path is not None else default_table(), {"version": 1, **table.user})


def resolve(env_id: str, timesteps: int, seeds: int, learning_rate: float, table: BaselineTable,
            settings: dict | None = None) -> Baseline | None:
    """The Baseline of ``env_id`` at this budget and PPO setting, or None when the table lacks either constant."""
    r, p = table.random(env_id), table.ppo(env_id, timesteps, seeds, learning_rate, settings)
    if r is None or p is None:
        return None
    return Baseline(env_id, r.mean_return, r.mean_step_reward, p.mean)
