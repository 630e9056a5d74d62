"""Parity with stable-baselines3 (optional suite: `make parity`): with no reservoir, our PPO and SB3's PPO with
the same defaults learn alike on full-observation CartPole-v1 and Pendulum-v1.

The metric is SB3's: the mean return of the last 100 episodes finished by a timestep, here 50k and 100k,
over 5 seeds. The numbers are written to docs/data/parity_sb3.json (recorded in docs/results.md)."""

import concurrent.futures as cf
import json
import multiprocessing as mp
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.reference

SEEDS = 5
CHECKPOINTS = (50_000, 100_000)
OUT = Path(__file__).resolve().parents[1] / "docs" / "data" / "parity_sb3.json"


def last_100_mean(ends: np.ndarray, returns: np.ndarray, t: int) -> float:
    """Mean return of the (at most) 100 last episodes that ended at or before step t."""
    done = returns[ends <= t]
    return float(np.mean(done[-100:])) if len(done) else float("nan")


def sb3_episodes(env_id: str, seed: int, timesteps: int) -> tuple[np.ndarray, np.ndarray]:
    """One SB3 PPO("MlpPolicy") run with default hyperparameters; (end timestep, return) of each episode."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.monitor import Monitor

    torch.set_num_threads(1)
    env = Monitor(gym.make(env_id))
    PPO("MlpPolicy", env, seed=seed).learn(timesteps)
    lengths = np.asarray(env.get_episode_lengths())
    return np.cumsum(lengths), np.asarray(env.get_episode_rewards())


def ours(env_id: str, timesteps: int) -> list[tuple[np.ndarray, np.ndarray]]:
    from ermrl.agent import AgentConfig, Phi
    from ermrl.train import Population, TrainConfig, Trainer

    config = TrainConfig(env_id=env_id, total_timesteps=timesteps, agent=AgentConfig(reservoirs=0))
    results = Trainer(config).run(Population.grid(Phi(1.0, 1.0, 1.0), SEEDS, 3e-4, 0))
    return [(e.timestep, e.ret) for e in results.episodes]


@pytest.mark.parametrize("env_id", ["CartPole-v1", "Pendulum-v1"])
def test_ppo_learns_like_sb3(env_id):
    with cf.ProcessPoolExecutor(2, mp_context=mp.get_context("spawn")) as pool:
        sb3_runs = list(pool.map(sb3_episodes, [env_id] * SEEDS, range(SEEDS), [CHECKPOINTS[-1]] * SEEDS))
    our_runs = ours(env_id, CHECKPOINTS[-1])
    record = json.loads(OUT.read_text()) if OUT.exists() else {}
    record[env_id] = {}
    for t in CHECKPOINTS:
        a = np.array([last_100_mean(e, r, t) for e, r in our_runs])
        b = np.array([last_100_mean(e, r, t) for e, r in sb3_runs])
        record[env_id][str(t)] = {"ermrl": a.tolist(), "sb3": b.tolist(), "ermrl_mean": a.mean(), "sb3_mean": b.mean(),
                                  "ermrl_std": a.std(), "sb3_std": b.std()}
        print(f"{env_id} @ {t}: ermrl {a.mean():.1f} ± {a.std():.1f}   sb3 {b.mean():.1f} ± {b.std():.1f}")
        gap = abs(a.mean() - b.mean())
        within_15 = gap <= 0.15 * max(abs(a.mean()), abs(b.mean()))
        inside_spread = gap <= max(a.std(), b.std())
        assert within_15 or inside_spread, f"{env_id} at {t}: ermrl {a.mean():.1f}±{a.std():.1f} vs sb3 {b.mean():.1f}±{b.std():.1f}"
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(record, indent=1))
