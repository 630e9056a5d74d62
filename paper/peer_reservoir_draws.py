"""Peer agreement, second half: at one Φ, does the fitness gap between ermrl and the reference come from the
training stacks or from the reservoirs each draws?

ermrl's PPO (JAX, one population) trains the same Φ on two sets of reservoirs:

- ``reservoirpy``: the reference pipeline's own reservoirs (``benchmarks/reference_pipeline.py``'s ``make_env``,
  ReservoirPy's draw for seeds FIRST..FIRST+A−1, its bias too), taken out of ReservoirPy and given to ermrl as unit
  weights (W / sr, Win / iss): the very reservoirs on which SB3 scored its fitness;
- ``ermrl``: ermrl's own draw (``ermrl.reservoir.generate``) for the same seeds.

PPO's own randomness comes from the agent seed in both. Together with ``reference_pipeline.py --weights ermrl``
(SB3 on ermrl's reservoirs), this separates "the stacks learn differently" from "the draws differ". Runs in the
reference venv (it needs ReservoirPy and ermrl). Prints each agent's fitness (mean return of its last 10 training
episodes) and can write a JSON.

Example:
    .venv-ref/bin/python paper/peer_reservoir_draws.py --agents 10 --timesteps 300000 \\
        --sr 0.508 --leak-rate 0.0568 --bias bernoulli --json out.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def _reference_pipeline():
    """benchmarks/reference_pipeline.py, imported from beside this script."""
    benchmarks = str(Path(__file__).resolve().parents[1] / "benchmarks")
    if benchmarks not in sys.path:
        sys.path.insert(0, benchmarks)
    import reference_pipeline

    return reference_pipeline


def reservoirpy_unit_weights(env_id: str, seed: int, sr: float, lr: float, iss: float, bias: str):
    """ReservoirPy's reservoir for ``seed`` as the reference pipeline builds it, as ermrl unit weights (K = 1):
    W (1, N, N) / sr, Win (1, N, D) / iss, bias (1, N); float32."""
    from ermrl.reservoir import ReservoirWeights

    env = _reference_pipeline().make_env(env_id, seed, sr, lr, iss, bias=bias)
    env.reset(seed=seed)  # initializes the reservoir (its weights are drawn at its first call)
    dense = lambda m: m.toarray() if hasattr(m, "toarray") else np.asarray(m)
    W, Win = dense(env.res.W) / sr, dense(env.res.Win) / iss
    b = np.broadcast_to(np.asarray(dense(env.res.bias), np.float64).ravel(), (W.shape[0],))
    return ReservoirWeights(*(np.asarray(x, np.float32)[None] for x in (W, Win, b)))


def train(env_id: str, seeds: list[int], timesteps: int, phi: tuple[float, float, float], bias: str, draw: str):
    """ermrl's PPO on ``draw``'s reservoirs ('reservoirpy' or 'ermrl'); returns (fitness per seed, train_s)."""
    from ermrl.agent import AgentConfig, Phi
    from ermrl.reservoir import ReservoirSpec
    from ermrl.training import Population, TrainConfig, Trainer

    config = TrainConfig(env_id=env_id, total_timesteps=timesteps, agent=AgentConfig(spec=ReservoirSpec(bias=bias)),
                         backend="jax")
    trainer = Trainer(config)
    if draw == "reservoirpy":  # the reference's reservoirs replace ermrl's draw, seed by seed
        weights = {s: reservoirpy_unit_weights(env_id, s, *phi, bias) for s in seeds}
        trainer.agent.unit_weights = weights.__getitem__
    population = Population.grid(Phi(*phi), seeds, config.ppo.learning_rate, 1)
    results = trainer.run(population)
    return [float(f) for f in results.fitness()], float(results.train_s)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="CartPoleNoVel-v1", choices=("CartPoleNoVel-v1",),
                   help="environment (default: %(default)s)")
    p.add_argument("--agents", type=int, default=10, help="seeds FIRST..FIRST+A-1 (default: %(default)s)")
    p.add_argument("--first-seed", type=int, default=0, help="first seed (default: %(default)s)")
    p.add_argument("--timesteps", type=int, default=300000, help="env steps per agent (default: %(default)s)")
    reference = _reference_pipeline()
    reference.add_phi_options(p, defaults=None)
    p.add_argument("--bias", choices=("none", "bernoulli"), default="bernoulli",
                   help="the reservoir's bias (default: %(default)s)")
    p.add_argument("--draws", nargs="+", choices=("reservoirpy", "ermrl"), default=["reservoirpy", "ermrl"],
                   help="whose reservoirs to train on (default: both)")
    p.add_argument("--json", metavar="PATH", help="write the results as JSON to PATH")
    a = p.parse_args(argv)
    if a.agents < 1 or a.timesteps < 1 or a.first_seed < 0:
        p.error("--agents and --timesteps must be >= 1, --first-seed >= 0")
    reference.check_phi(p, a)
    seeds = list(range(a.first_seed, a.first_seed + a.agents))
    phi = (a.sr, a.lr, a.iss)
    out = {"env": a.env, "timesteps": a.timesteps, "phi": dict(zip(("sr", "lr", "iss"), phi)), "bias": a.bias,
           "seeds": seeds, "trainer": "ermrl (JAX)"}
    for draw in a.draws:
        t0 = time.perf_counter()
        fitness, train_s = train(a.env, seeds, a.timesteps, phi, a.bias, draw)
        out[draw] = {"fitness": fitness, "mean": float(np.mean(fitness)), "std": float(np.std(fitness)),
                     "train_s": train_s, "wall_s": time.perf_counter() - t0}
        print(f"{draw} reservoirs, ermrl PPO: {', '.join(f'{v:.1f}' for v in fitness)}; "
              f"mean {np.mean(fitness):.1f} ± {np.std(fitness):.1f} ({time.perf_counter() - t0:.0f} s)")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
