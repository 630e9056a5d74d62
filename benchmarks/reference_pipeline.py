"""The reference ER-MRL pipeline (SB3 PPO + ReservoirPy): its throughput, and its fitness for a given Φ.

Each agent is a stable-baselines3 ``PPO("MlpPolicy", env, seed=seed)`` with default
hyperparameters, trained with ``model.learn(timesteps)`` on a Gymnasium env whose
observation is replaced by the state of a ReservoirPy reservoir fed with
concat(obs, action encoding, reward) at every step. One process per agent (seeds
0..A-1, or from ``--first-seed``), at most ``--procs`` at a time. Prints agent-steps/s and each
agent's fitness (the mean return of its last 10 training episodes, as ermrl's), and can write a JSON.
``--sr/--leak-rate/--iss`` set the reservoir's Φ (default: the paper's sr 0.95, lr 0.5, iss 1.0), so that a Φ*
evolved by ermrl can be trained by the reference stack (peer agreement, docs/paper.md); ``--bias bernoulli``
gives the reservoir ReservoirPy 0.3's bias (the paper's era and ermrl's default), which 0.4 dropped.

Examples:
    python benchmarks/reference_pipeline.py --env CartPoleNoVel-v1 --agents 4 \\
        --timesteps 20000 --procs 2 --json out.json
    python benchmarks/reference_pipeline.py --agents 4 --timesteps 300000 --sr 0.756 --leak-rate 0.0886 --iss 1.0 \\
        --bias bernoulli
    python benchmarks/reference_pipeline.py --agents 10 --first-seed 1000 --timesteps 300000 --sr 0.508 \\
        --leak-rate 0.0568 --bias bernoulli --weights ermrl      # SB3 on the reservoirs ermrl trained with those seeds
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import multiprocessing as mp
import os
import sys
import time

ENVS = ("CartPoleNoVel-v1", "HalfCheetah-v5", "Humanoid-v5")
FIX = "run `make reference` (or `pip install torch==2.13.0 && pip install -e .[reference]`)"


def check_deps() -> None:
    """Exit with code 2 and a one-line hint if the reference stack is missing."""
    missing = []
    for mod in ("torch", "stable_baselines3", "reservoirpy"):
        try:
            __import__(mod)
        except ImportError:
            missing.append(mod)
    if missing:
        print(f"error: missing {', '.join(missing)}; {FIX}", file=sys.stderr)
        sys.exit(2)


def make_env(name: str, seed: int, sr: float = 0.95, lr: float = 0.5, iss: float = 1.0, bias: str = "none",
             weights: str = "reservoirpy"):
    """Build the reservoir-wrapped env: CartPole-v1 without velocities, or a Gymnasium id as it is.

    ``weights="ermrl"`` gives the reservoir ermrl's draw for ``seed`` (``ermrl.reservoir.generate``, scaled by sr and
    iss) instead of ReservoirPy's, so that both stacks train on the very same reservoir (a paired peer check)."""
    import gymnasium as gym
    import numpy as np
    from reservoirpy.nodes import Reservoir

    class ReservoirWrapper(gym.Wrapper):
        """Observation := state of a 100-unit reservoir driven by (obs, action, reward)."""

        def __init__(self, env):
            super().__init__(env)
            self.discrete = isinstance(env.action_space, gym.spaces.Discrete)
            b = 0.0
            if bias == "bernoulli":  # ReservoirPy 0.3's default (the paper's): ±1 on 10% of the units
                rng = np.random.default_rng(seed)
                b = np.zeros(100)
                b[rng.choice(100, size=10, replace=False)] = rng.choice([-1.0, 1.0], size=10)
            if weights == "ermrl":  # ermrl's reservoir for this seed: (obs, one-hot or Box action, reward) inputs
                from ermrl.reservoir import ReservoirSpec, generate

                n_act = env.action_space.n if self.discrete else env.action_space.shape[0]
                unit = generate(ReservoirSpec(bias=bias), seed, env.observation_space.shape[0] + n_act + 1)
                self.res = Reservoir(lr=lr, W=sr * np.asarray(unit.W, np.float64),
                                     Win=iss * np.asarray(unit.Win, np.float64), bias=np.asarray(unit.bias, np.float64))
            else:
                self.res = Reservoir(units=100, lr=lr, sr=sr, input_scaling=iss, bias=b, seed=seed)
            self.observation_space = gym.spaces.Box(-1.0, 1.0, (100,), np.float32)

        def _encode(self, action):
            if self.discrete:
                return np.eye(self.env.action_space.n)[int(action)]
            return np.asarray(action, dtype=np.float64).ravel()

        def _feed(self, obs, act_enc, reward):
            x = np.concatenate([np.ravel(obs), act_enc, [float(reward)]])
            # ReservoirPy 0.4: Node.__call__ is a single step on a 1-D (features,) vector;
            # the (1, features) input of 0.3 is rejected.
            return self.res(x).astype(np.float32)

        def reset(self, *, seed=None, options=None):
            if self.res.initialized:  # 0.4: reset() before the first call raises
                self.res.reset()
            obs, info = self.env.reset(seed=seed, options=options)
            zeros = np.zeros(self.env.action_space.n if self.discrete else self.env.action_space.shape[0])
            return self._feed(obs, zeros, 0.0), info

        def step(self, action):
            obs, reward, terminated, truncated, info = self.env.step(action)
            return self._feed(obs, self._encode(action), reward), reward, terminated, truncated, info

    if name == "CartPoleNoVel-v1":
        env = gym.make("CartPole-v1")
        keep = [0, 2]  # cart position, pole angle; drop the velocities (dims 1, 3)
        box = env.observation_space
        env = gym.wrappers.TransformObservation(
            env, lambda o: o[keep], gym.spaces.Box(box.low[keep], box.high[keep], dtype=box.dtype)
        )
    else:
        env = gym.make(name)
    return ReservoirWrapper(env)


def train_one(env_name: str, seed: int, timesteps: int, phi: tuple[float, float, float],
              bias: str = "none", weights: str = "reservoirpy") -> tuple[float, float, int]:
    """Worker: train one PPO agent on a reservoir with ``phi`` = (sr, lr, iss); return its wall time in seconds
    (learn() only), its fitness (mean return of its last 10 training episodes) and its episode count."""
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    from stable_baselines3.common.monitor import Monitor

    env = Monitor(make_env(env_name, seed, *phi, bias=bias, weights=weights))
    model = PPO("MlpPolicy", env, seed=seed, device="cpu", verbose=0)
    t0 = time.perf_counter()
    model.learn(total_timesteps=timesteps)
    wall = time.perf_counter() - t0
    returns = env.get_episode_rewards()
    return wall, float(sum(returns[-10:]) / max(len(returns[-10:]), 1)), len(returns)


def add_phi_options(p: argparse.ArgumentParser, defaults: tuple[float, float] | None) -> None:
    """--sr, --leak-rate (dest ``lr``) and --iss; sr and leak rate required where ``defaults`` is None."""
    sr, leak = defaults or (None, None)
    shown = " (default: %(default)s)"
    p.add_argument("--sr", type=float, default=sr, required=sr is None, help="spectral radius" + shown * bool(defaults))
    p.add_argument("--leak-rate", dest="lr", type=float, default=leak, required=leak is None,
                   help="leak rate" + shown * bool(defaults))
    p.add_argument("--iss", type=float, default=1.0, help="input scaling" + shown)


def check_phi(p: argparse.ArgumentParser, a: argparse.Namespace) -> None:
    """Exits through ``p.error`` where Φ is out of its range."""
    if not (a.sr > 0 and 0 < a.lr <= 1 and a.iss > 0):
        p.error(f"Φ out of range: sr {a.sr} and iss {a.iss} must be > 0, lr {a.lr} in (0, 1]")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", choices=ENVS, default="CartPoleNoVel-v1", help="environment (default: %(default)s)")
    p.add_argument("--agents", type=int, default=4, help="independent trainings, seeds 0..A-1 (default: %(default)s)")
    p.add_argument("--timesteps", type=int, default=20000, help="model.learn() budget per agent (default: %(default)s)")
    p.add_argument("--procs", type=int, default=2, help="max worker processes at a time (default: %(default)s)")
    p.add_argument("--first-seed", type=int, default=0, help="seed of the first agent (default: %(default)s)")
    add_phi_options(p, defaults=(0.95, 0.5))
    p.add_argument("--bias", choices=("none", "bernoulli"), default="none",
                   help="the reservoir's bias: none (ReservoirPy 0.4) or bernoulli (0.3, the paper's, and ermrl's "
                        "default) (default: %(default)s)")
    p.add_argument("--weights", choices=("reservoirpy", "ermrl"), default="reservoirpy",
                   help="whose reservoir draw for each seed: ReservoirPy's, or ermrl's (the same reservoir ermrl "
                        "trains on with that seed: a paired check of the two stacks) (default: %(default)s)")
    p.add_argument("--json", metavar="PATH", help="write the results as JSON to PATH")
    a = p.parse_args(argv)
    if a.agents < 1 or a.timesteps < 1 or a.procs < 1:
        p.error("--agents, --timesteps and --procs must be >= 1")
    check_phi(p, a)
    check_deps()
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"  # inherited by the spawned workers before numpy/torch load

    t0 = time.perf_counter()
    with cf.ProcessPoolExecutor(max_workers=a.procs, mp_context=mp.get_context("spawn")) as pool:
        seeds = list(range(a.first_seed, a.first_seed + a.agents))
        jobs = [pool.submit(train_one, a.env, s, a.timesteps, (a.sr, a.lr, a.iss), a.bias, a.weights)
                for s in seeds]
        per_agent, fitness, episodes = zip(*(j.result() for j in jobs))
    wall = time.perf_counter() - t0

    # SB3 rounds learn() up to whole rollouts (n_steps=2048); report the requested budget.
    res = {
        "env": a.env, "agents": a.agents, "timesteps": a.timesteps, "procs": a.procs, "wall_s": wall,
        "agent_steps_per_s": a.agents * a.timesteps / wall,
        "per_agent_steps_per_s": [a.timesteps / t for t in per_agent],
        "phi": {"sr": a.sr, "lr": a.lr, "iss": a.iss}, "bias": a.bias, "weights": a.weights, "seeds": seeds,
        "fitness": list(fitness), "episodes": list(episodes),
    }
    print(f"{a.env}: {a.agents} agents x {a.timesteps} steps, {a.procs} procs, wall {wall:.1f}s")
    print(f"total: {res['agent_steps_per_s']:.0f} agent-steps/s (incl. process start-up)")
    print("per process: " + ", ".join(f"{v:.0f}" for v in res["per_agent_steps_per_s"]) + " steps/s (learn() only)")
    mean = sum(fitness) / len(fitness)
    print(f"fitness (mean of the last 10 episodes) per seed: {', '.join(f'{v:.1f}' for v in fitness)}; mean {mean:.1f}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
