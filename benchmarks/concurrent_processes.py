"""MuJoCo populations: one process, two processes at once, and one population split over two (`--processes 2`).

    .venv/bin/python benchmarks/concurrent_processes.py [--env HalfCheetah-v5] [--reservoirs 2] [--agents 27]
                                                        [--iterations 4] [--repeats 3]

Each mode starts fresh processes (the compilation cache warm), each of which trains one population of ``agents``
agents of ``reservoirs`` 100-unit reservoirs (SB3-default PPO) for ``iterations`` iterations of 2048 steps with
``Trainer.run``, and reports its rate over the training time (``Results.train_s``: compile excluded, the first
iteration's first-call costs included, the same in every mode). Modes, timed in turn, ``repeats`` times:

- ``one``: one process, ``processes=1`` (a study's generation, as ``ermrl experiment run`` trains it by default);
- ``two``: two such processes started at once (two studies side by side; their rates are summed, and their
  training overlaps up to their compile times' difference, a few seconds);
- ``processes``: one process with ``TrainConfig.processes=2`` (``--processes 2``): the population's two halves
  train at once, the second in a helper process.

Prints each mode's median rate in agent-steps/s (summed over its processes) and the ratio to ``one``. An agent
trains the same in any population and any number of processes, so the modes differ only in speed.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys


def worker(env_id: str, reservoirs: int, agents: int, iterations: int, processes: int) -> None:
    """One process: trains the population and prints {"rate": agent-steps/s over its training time}."""
    from ermrl.agent import AgentConfig, Phi
    from ermrl.compile_cache import enable as enable_cache
    from ermrl.ppo.config import PPOConfig
    from ermrl.training.config import Population, TrainConfig
    from ermrl.training.trainer import Trainer

    enable_cache()
    steps = iterations * PPOConfig().buffer_size
    config = TrainConfig(env_id=env_id, total_timesteps=steps, agent=AgentConfig(reservoirs=reservoirs),
                         processes=processes)
    population = Population.grid(Phi(0.9, 0.3, 1.0), agents, config.ppo.learning_rate, reservoirs)
    results = Trainer(config).run(population)
    print(json.dumps({"rate": agents * steps / results.train_s}), flush=True)


def run_mode(runs: list[tuple[int, int]], args) -> float:
    """Starts one process per (agents, processes) entry of ``runs`` at once; returns their summed rate."""
    procs = [subprocess.Popen([sys.executable, __file__, "--worker", "--env", args.env, "--reservoirs",
                               str(args.reservoirs), "--agents", str(agents), "--iterations", str(args.iterations),
                               "--processes", str(processes)], stdout=subprocess.PIPE, text=True)
             for agents, processes in runs]
    outputs = [p.communicate()[0] for p in procs]
    if any(p.returncode for p in procs):
        raise SystemExit("a worker process failed; see its error above")
    return sum(json.loads(out.strip().splitlines()[-1])["rate"] for out in outputs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="HalfCheetah-v5")
    parser.add_argument("--reservoirs", type=int, default=2)
    parser.add_argument("--agents", type=int, default=27)
    parser.add_argument("--iterations", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--processes", type=int, default=1, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.env, args.reservoirs, args.agents, args.iterations, args.processes)
        return
    a = args.agents
    modes = {"one": [(a, 1)], "two": [(a, 1), (a, 1)], "processes": [(a, 2)]}
    shown = {"one": f"1 × {a}", "two": f"2 × {a}", "processes": f"1 × {a}, --processes 2"}
    rates: dict[str, list[float]] = {m: [] for m in modes}
    for r in range(args.repeats):
        for mode, runs in modes.items():
            rates[mode].append(run_mode(runs, args))
            print(f"repeat {r + 1}, {mode} ({shown[mode]}): {rates[mode][-1]:,.0f} agent-steps/s", flush=True)
    one = statistics.median(rates["one"])
    print(f"\n| env | reservoirs | mode | processes × agents | agent-steps/s (median of {args.repeats}) | runs | "
          "ratio to one |\n|---|---:|---|---|---:|---|---:|")
    for mode in modes:
        median = statistics.median(rates[mode])
        runs = " · ".join(f"{x:,.0f}" for x in rates[mode])
        print(f"| {args.env} | {args.reservoirs} | {mode} | {shown[mode]} | {median:,.0f} | {runs} | "
              f"{median / one:.2f}× |")


if __name__ == "__main__":
    main()
