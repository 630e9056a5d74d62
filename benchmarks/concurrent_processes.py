"""Populations on the MuJoCo backend: one process alone against two processes at once on the same machine.

    .venv/bin/python benchmarks/concurrent_processes.py [--env HalfCheetah-v5] [--reservoirs 2] [--agents 27]
                                                        [--iterations 4] [--repeats 3]

Each mode starts fresh processes, each of which builds one population (``agents`` agents of ``reservoirs``
100-unit reservoirs, SB3-default PPO, the compilation cache warm), compiles it, runs one untimed iteration, waits
for a start time common to all processes of the mode (``--start-delay`` after its launch), and then times
``iterations`` whole iterations (2048 steps of every agent and one PPO update). Modes, timed in turn,
``repeats`` times:

- ``one``: one process of ``agents`` agents (a study's generation, trained as ``ermrl experiment run`` does);
- ``two``: two such processes at once (two studies run side by side);
- ``split``: two processes of half the agents each (one generation split over two processes).

Prints each mode's median total rate in agent-steps/s (the sum over its processes) and the ratio to ``one``.
An agent trains the same in any population, so the modes differ only in speed.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time



def worker(env_id: str, reservoirs: int, agents: int, iterations: int, start_at: float) -> None:
    """One process: prints {"rate": agent-steps/s over the timed iterations, "late": s past start_at}."""
    import jax

    from ermrl.agent import AgentConfig, Phi
    from ermrl.compile_cache import enable as enable_cache
    from ermrl.training.config import Population, TrainConfig
    from ermrl.training.trainer import Trainer

    enable_cache()
    config = TrainConfig(env_id=env_id, total_timesteps=10 ** 6, agent=AgentConfig(reservoirs=reservoirs))
    trainer = Trainer(config)
    state = trainer.init(Population.grid(Phi(0.9, 0.3, 1.0), agents, config.ppo.learning_rate, reservoirs))
    iteration = trainer.compiled(state)
    state, log = iteration(state)  # untimed: first-call costs
    jax.block_until_ready(log)
    late = time.time() - start_at
    time.sleep(max(0.0, -late))
    t = time.perf_counter()
    for _ in range(iterations):
        state, log = iteration(state)
    jax.block_until_ready(log)
    rate = iterations * config.ppo.buffer_size * agents / (time.perf_counter() - t)
    trainer.close()
    print(json.dumps({"rate": rate, "late": late}), flush=True)


def run_mode(sizes: list[int], args) -> float:
    """Starts one process per entry of ``sizes`` (its agents) at once; returns their summed rate."""
    start_at = time.time() + args.start_delay
    procs = [subprocess.Popen([sys.executable, __file__, "--worker", "--env", args.env, "--reservoirs",
                               str(args.reservoirs), "--agents", str(size), "--iterations", str(args.iterations),
                               "--start-at", repr(start_at)], stdout=subprocess.PIPE, text=True)
             for size in sizes]
    results = [json.loads(p.communicate()[0].strip().splitlines()[-1]) for p in procs]
    if any(p.returncode for p in procs):
        raise SystemExit("a worker process failed; see its error above")
    late = max(r["late"] for r in results)
    if late > 0:
        print(f"  warning: a process was ready {late:.0f} s after the common start; raise --start-delay",
              file=sys.stderr)
    return sum(r["rate"] for r in results)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="HalfCheetah-v5")
    parser.add_argument("--reservoirs", type=int, default=2)
    parser.add_argument("--agents", type=int, default=27)
    parser.add_argument("--iterations", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--start-delay", type=float, default=60.0,
                        help="seconds from a mode's launch to its common start (its processes compile and warm up)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--start-at", type=float, default=0.0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.env, args.reservoirs, args.agents, args.iterations, args.start_at)
        return
    half = args.agents // 2
    modes = {"one": [args.agents], "two": [args.agents, args.agents], "split": [args.agents - half, half]}
    rates: dict[str, list[float]] = {m: [] for m in modes}
    for r in range(args.repeats):
        for mode, sizes in modes.items():
            rates[mode].append(run_mode(sizes, args))
            print(f"repeat {r + 1}, {mode} ({' + '.join(map(str, sizes))} agents): {rates[mode][-1]:,.0f} "
                  "agent-steps/s", flush=True)
    one = statistics.median(rates["one"])
    print(f"\n| env | reservoirs | mode | processes × agents | agent-steps/s (median of {args.repeats}) | "
          "ratio to one |\n|---|---:|---|---|---:|---:|")
    for mode, sizes in modes.items():
        median = statistics.median(rates[mode])
        print(f"| {args.env} | {args.reservoirs} | {mode} | {len(sizes)} × {'/'.join(map(str, sizes))} | "
              f"{median:,.0f} | {median / one:.2f}× |")


if __name__ == "__main__":
    main()
