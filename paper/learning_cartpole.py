"""Learning on masked CartPole at full size: ER-MRL (sr 0.95, lr 0.5) against plain PPO on the same masked
observation and PPO with full observations; 3 seeds × 300k steps each, SB3-default PPO (lr 3e-4).

    python paper/learning_cartpole.py --out docs/figures/cartpole_novel

Prints a Markdown table (final fitness, mean ± std over seeds) and writes the figure as PNG.
"""

from __future__ import annotations

import argparse
from pathlib import Path


from ermrl import devices

devices.setup()  # one JAX CPU device per core
from ermrl.agent import AgentConfig, Phi
from ermrl.analysis.plots import learning_curves
from ermrl.training import Population, TrainConfig, train

MODELS = {
    "ER-MRL (1 reservoir, sr 0.95, lr 0.5)": ("CartPoleNoVel-v1", 1),
    "PPO, masked observation": ("CartPoleNoVel-v1", 0),
    "PPO, full observation": ("CartPole-v1", 0),
}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--timesteps", type=int, default=300_000)
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--learning-rate", type=float, default=3e-4)
    p.add_argument("--out", type=Path, default=Path("docs/figures/cartpole_novel"))
    a = p.parse_args()
    curves = {}
    print("| model | env | fitness (last 10 episodes), mean ± std | per seed | agent-steps/s |")
    print("|---|---|---|---|---|")
    for label, (env_id, k) in MODELS.items():
        config = TrainConfig(env_id=env_id, total_timesteps=a.timesteps, agent=AgentConfig(reservoirs=k))
        res = train(config, Population.grid(Phi(0.95, 0.5, 1.0), a.seeds, a.learning_rate, k))
        fit = res.fitness()
        curves[label] = res.curves()
        per_seed = ", ".join(f"{v:.1f}" for v in fit)
        print(f"| {label} | {env_id} | {fit.mean():.1f} ± {fit.std():.1f} | {per_seed} | {res.agent_steps_per_s():,.0f} |",
              flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    learning_curves(curves, f"CartPole without velocities, {a.seeds} seeds", a.out)


if __name__ == "__main__":
    main()
