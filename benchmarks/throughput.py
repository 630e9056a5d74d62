"""Agent-steps/s of population training, against the reference pipeline (SB3 + ReservoirPy).

Each population size A runs in a fresh subprocess (so peak memory is its own): it compiles once (timed
separately), runs ``--iterations`` rollout+update cycles (SB3 defaults: 2048 steps, 10 epochs of 32
minibatches) and reports the median agent-steps/s over the cycles after the first. Then, unless
``--no-reference``, it times the reference pipeline, one process per agent and two at a time, with the
Python given by ``--reference-python`` (a venv with `make reference`'s packages), and prints the ratio.

    python benchmarks/throughput.py --sizes 1 3 21 --reference-python .venv-ref/bin/python
    python benchmarks/throughput.py --env HalfCheetah-v5 --sizes 6 21 --reference-agents 2

Envs without a JAX version (MuJoCo, Box2D) run on the host backend; their rows also give the env-only
ceiling: Gymnasium stepping the same envs with the same workers and no learning at all.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def measure(env_id: str, size: int, iterations: int, units: int) -> dict:
    """Runs in the child process: trains ``size`` agents for ``iterations`` cycles and times them."""
    import jax
    import numpy as np

    from ermrl import devices

    devices.setup()  # one JAX CPU device per core
    from ermrl.agent import AgentConfig, Phi
    from ermrl.reservoir import ReservoirSpec
    from ermrl.training import Population, TrainConfig, Trainer

    config = TrainConfig(env_id=env_id, total_timesteps=iterations * 2048,
                         agent=AgentConfig(reservoirs=1, spec=ReservoirSpec(units=units)))
    seeds = np.arange(size)
    population = Population.grid(Phi(0.95, 0.5, 1.0), list(seeds), 3e-4, 1)
    t0 = time.perf_counter()
    trainer = Trainer(config)
    state = trainer.init(population)
    compiled = trainer.compiled(state)
    compile_s = time.perf_counter() - t0
    times = []
    for _ in range(iterations):
        t = time.perf_counter()
        state, log = compiled(state)
        jax.block_until_ready(log.finite)
        times.append(time.perf_counter() - t)
    steady = times[1:] if len(times) > 1 else times
    per_iter = statistics.median(steady)
    row = {
        "env": env_id, "agents": size, "devices": len(jax.devices()), "backend": "host" if trainer.host else "jax",
        "compile_s": compile_s, "iteration_s_median": per_iter, "agent_steps_per_s": size * 2048 / per_iter,
        "agent_steps_per_s_all": [size * 2048 / t for t in steady],
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }
    if trainer.host:
        row["env_workers"] = len(trainer.env.groups) if len(trainer.env.groups) > 1 else 0
        row["env_only_steps_per_s"] = env_only(trainer.env, sum(g.size for g in trainer.env.groups))
        row["worker_peak_rss_mb"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        trainer.close()
    return row


def env_only(env, size: int, steps: int = 300) -> float:
    """The ceiling: Gymnasium stepping alone, the same ``size`` open slots (the population padded to a
    multiple of the devices) and workers, actions like an untrained policy's (N(0, 1) clipped to the bounds)."""
    import numpy as np

    space = env.info.action
    rng = np.random.default_rng(0)
    if space.discrete:
        actions = rng.integers(0, space.dim, (steps, size))
    else:
        actions = np.clip(rng.normal(size=(steps, size, space.dim)), space.low, space.high).astype(np.float32)
    t = time.perf_counter()
    for a in actions:
        env.step(a)
    return steps * size / (time.perf_counter() - t)


def run_child(env_id: str, size: int, iterations: int, units: int) -> dict:
    cmd = [sys.executable, __file__, "--child", env_id, str(size), str(iterations), str(units)]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_reference(python: str, env_id: str, agents: int, timesteps: int) -> dict:
    out_json = Path("/tmp") / f"ermrl-reference-{env_id}.json"
    cmd = [python, str(HERE / "reference_pipeline.py"), "--env", env_id, "--agents", str(agents),
           "--timesteps", str(timesteps), "--procs", "2", "--json", str(out_json)]
    subprocess.run(cmd, check=True)
    return json.loads(out_json.read_text())


def main(argv=None) -> int:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(measure(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]))))
        return 0
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="CartPoleNoVel-v1", help="env id (default: %(default)s)")
    p.add_argument("--sizes", type=int, nargs="+", default=[1, 3, 21], help="population sizes A (default: 1 3 21)")
    p.add_argument("--iterations", type=int, default=6, help="rollout+update cycles per size (default: %(default)s)")
    p.add_argument("--units", type=int, default=100, help="reservoir units (default: %(default)s)")
    p.add_argument("--repeats", type=int, default=1, help="fresh processes per size; the median is reported")
    p.add_argument("--reference-python", default=".venv-ref/bin/python",
                   help="Python with torch, SB3 and ReservoirPy for the reference pipeline")
    p.add_argument("--reference-agents", type=int, default=4)
    p.add_argument("--reference-timesteps", type=int, default=10 * 2048)
    p.add_argument("--no-reference", action="store_true", help="skip the reference pipeline")
    p.add_argument("--json", metavar="PATH", help="write all results as JSON")
    a = p.parse_args(argv)

    rows = []
    for size in a.sizes:
        runs = [run_child(a.env, size, a.iterations, a.units) for _ in range(a.repeats)]
        best = sorted(runs, key=lambda r: r["agent_steps_per_s"])[len(runs) // 2]
        best["agent_steps_per_s_repeats"] = [r["agent_steps_per_s"] for r in runs]
        rows.append(best)
        extra = ""
        if best["backend"] == "host":
            extra = (f"  [host: {best['env_workers']} env workers (peak RSS {best['worker_peak_rss_mb']:.0f} MB each), "
                     f"Gymnasium alone {best['env_only_steps_per_s']:,.0f} steps/s]")
        print(f"A={size:3d}: {best['agent_steps_per_s']:9,.0f} agent-steps/s  compile {best['compile_s']:.1f}s  "
              f"peak RSS {best['peak_rss_mb']:.0f} MB  ({best['devices']} devices){extra}", flush=True)
    result = {"jax": rows}
    if not a.no_reference:
        if not Path(a.reference_python).exists():
            print(f"reference skipped: {a.reference_python} not found (run `make reference`)", file=sys.stderr)
        else:
            ref = run_reference(a.reference_python, a.env, a.reference_agents, a.reference_timesteps)
            result["reference"] = ref
            print(f"reference: {ref['agent_steps_per_s']:,.0f} agent-steps/s "
                  f"({a.reference_agents} agents, 2 processes at a time)")
            for row in rows:
                print(f"ratio A={row['agents']}: {row['agent_steps_per_s'] / ref['agent_steps_per_s']:.1f}x")
    if a.json:
        Path(a.json).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
