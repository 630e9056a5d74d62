"""Where an iteration's time goes on the host loop (``mujoco`` or ``host`` backend), and the learning-only rate.

    .venv/bin/python benchmarks/host_loop_split.py [--env HalfCheetah-v5] [--agents 21] [--backend mujoco]
                                                   [--iterations 3]

Builds one population of ``agents`` agents (one 100-unit reservoir, SB3-default PPO), compiles it, then times
``iterations`` whole iterations (n_steps steps of every env and one PPO update), split into the envs' ``step``
calls, the rest of the rollout (the per-step jitted calls and transfers) and the PPO update. It then times the
same iterations with ``step`` returning one fixed packed array, so that no physics runs: the rate the learning
alone allows on this loop. Prints medians, in agent-steps/s, as one Markdown row:

    | env | backend | A | whole | physics in the loop (env-steps/s) | learning only | bound 1/(1/p + 1/l) | whole / bound |
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="HalfCheetah-v5")
    parser.add_argument("--agents", type=int, default=21)
    parser.add_argument("--backend", default="mujoco", choices=("mujoco", "host"))
    parser.add_argument("--iterations", type=int, default=3)
    args = parser.parse_args()

    import jax

    from ermrl.agent import Phi
    from ermrl.compile_cache import enable as enable_cache
    from ermrl.training.config import Population, TrainConfig
    from ermrl.training.trainer import Trainer

    enable_cache()
    config = TrainConfig(env_id=args.env, total_timesteps=10 ** 6, backend=args.backend)
    trainer = Trainer(config)
    state = trainer.init(Population.grid(Phi(0.9, 0.3, 1.0), args.agents, config.ppo.learning_rate, 1))
    iteration = trainer.compiled(state)
    env, real_step = iteration.env, iteration.env.step
    spent = [0.0]

    def timed_step(actions):
        t = time.perf_counter()
        out = real_step(actions)
        spent[0] += time.perf_counter() - t
        return out

    agent_steps = config.ppo.buffer_size * args.agents
    slots = sum(group.size for group in env.groups)  # padded agents x n_envs
    env_steps = config.ppo.n_steps * slots
    whole, physics = [], []
    env.step = timed_step
    state, _ = iteration(state)  # one untimed iteration: first-call costs
    for _ in range(args.iterations):
        spent[0] = 0.0
        t = time.perf_counter()
        state, log = iteration(state)
        jax.block_until_ready(log)
        whole.append(agent_steps / (time.perf_counter() - t))
        physics.append(env_steps / spent[0])
    space = env.info.action
    fixed = real_step(np.zeros(slots, np.int64) if space.discrete else np.zeros((slots, space.dim), np.float32))
    env.step = lambda actions: fixed
    learning = []
    for _ in range(args.iterations):
        t = time.perf_counter()
        state, log = iteration(state)
        jax.block_until_ready(log)
        learning.append(agent_steps / (time.perf_counter() - t))
    trainer.close()
    w, p, l = (statistics.median(x) for x in (whole, physics, learning))
    bound = 1.0 / (1.0 / p + 1.0 / l)
    print(f"| {args.env} | {args.backend} | {args.agents} | {w:,.0f} | {p:,.0f} | {l:,.0f} | {bound:,.0f} | "
          f"{w / bound:.0%} |")


if __name__ == "__main__":
    main()
