"""Where one step of the host backend's rollout goes, for A agents: the Gymnasium envs' step, the jitted
per-step call (feed the reservoirs, choose the next actions) and the wait for its outputs.

    .venv/bin/python benchmarks/host_step_cost.py --env LunarLanderNoVel-v3 --reservoirs 2 --agents 2 6 10

Prints one line per agent count: medians over the steps after a warm-up, in microseconds. The PPO update is
not included (see docs/benchmarks.md, "Host backend, few cheap envs").

``--overlap`` adds a column: the same step with the envs' ``step`` running on a helper thread while the main
thread makes the jitted call and waits for it (both release the GIL: MuJoCo's ``mj_step`` and XLA). Fed the
previous step's outputs, so it measures only whether the two can share the cores, not a training loop.

    .venv/bin/python benchmarks/host_step_cost.py --env HalfCheetah-v5 --backend mujoco --reservoirs 1 --agents 21 --overlap
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np


def step_costs(env_id: str, reservoirs: int, agents: int, workers: int | str, steps: int, backend: str = "host",
               overlap: bool = False) -> dict[str, float]:
    """Median seconds per rollout step of ``agents`` agents: {'env', 'call', 'wait'}, and with ``overlap``
    'overlapped' (the env step on a helper thread during the call and its wait)."""
    from ermrl.agent import AgentConfig, Phi
    from ermrl.training import Population, TrainConfig, Trainer

    config = TrainConfig(env_id=env_id, total_timesteps=2048, agent=AgentConfig(reservoirs=reservoirs),
                         backend=backend, env_workers=workers)
    trainer = Trainer(config)
    k = max(reservoirs, 1)
    phi = Phi(np.full(k, 0.9, np.float32), np.full(k, 0.3, np.float32), np.ones(k, np.float32))
    state = trainer.init(Population.grid(phi, agents, 3e-4, reservoirs))
    loop = trainer.compiled(state)
    _, params, res, carry, noise, _ = loop._start(state)
    chosen = loop._choose(params, carry.context, noise[0])
    times: dict[str, list[float]] = {"env": [], "call": [], "wait": []}
    try:
        for t in range(1, steps):
            t0 = time.perf_counter()
            actions = np.asarray(chosen.env_action)
            flat = actions.reshape((-1,) if loop.env.info.action.discrete else (-1, loop.env.info.action.dim))
            packed = loop.env.step(flat)
            packed = packed.reshape(actions.shape[:2] + packed.shape[1:])
            t1 = time.perf_counter()
            carry, step, chosen = loop._advance_choose(params, res, carry, chosen, packed, noise[t % len(noise)])
            t2 = time.perf_counter()
            np.asarray(step), np.asarray(chosen.env_action)
            t3 = time.perf_counter()
            for name, dt in zip(("env", "call", "wait"), (t1 - t0, t2 - t1, t3 - t2)):
                times[name].append(dt)
        if overlap:
            times["overlapped"] = []
            with ThreadPoolExecutor(1) as helper:
                for t in range(1, steps):
                    t0 = time.perf_counter()
                    physics = helper.submit(loop.env.step, flat)
                    out = loop._advance_choose(params, res, carry, chosen, packed, noise[t % len(noise)])
                    np.asarray(out[1]), np.asarray(out[2].env_action)
                    physics.result()
                    times["overlapped"].append(time.perf_counter() - t0)
    finally:
        trainer.close()
    warm = steps // 5
    return {name: float(np.median(v[warm:])) for name, v in times.items()}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="LunarLanderNoVel-v3")
    p.add_argument("--reservoirs", type=int, default=2)
    p.add_argument("--agents", type=int, nargs="+", default=[2, 6, 10])
    p.add_argument("--env-workers", default="0", help="0, N or auto")
    p.add_argument("--steps", type=int, default=1500)
    p.add_argument("--backend", default="host", choices=("host", "mujoco"))
    p.add_argument("--overlap", action="store_true", help="also time the env step overlapped with the call")
    args = p.parse_args()
    workers = args.env_workers if args.env_workers == "auto" else int(args.env_workers)
    extra = (" overlapped (µs) |", "---|") if args.overlap else ("", "")
    print("| agents | env step (µs) | jitted call (µs) | wait (µs) | total (µs) |" + extra[0]
          + " agent-steps/s, rollout only |")
    print("|---|---|---|---|---|" + extra[1] + "---|")
    for a in args.agents:
        c = step_costs(args.env, args.reservoirs, a, workers, args.steps, args.backend, args.overlap)
        total = c["env"] + c["call"] + c["wait"]
        cell = f" {c['overlapped'] * 1e6:.0f} |" if args.overlap else ""
        print(f"| {a} | {c['env'] * 1e6:.0f} | {c['call'] * 1e6:.0f} | {c['wait'] * 1e6:.0f} | {total * 1e6:.0f} |"
              f"{cell} {a / total:,.0f} |")


if __name__ == "__main__":
    main()
