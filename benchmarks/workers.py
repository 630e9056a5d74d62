"""One worker against several on one study: the wall time of the same evolution run by N `ermrl evolve` processes
at once (docs/scaling.md). Each N gets a fresh study in the storage; worker i runs with --worker-index i and
--batch ceil(popsize / N).

    python benchmarks/workers.py --storage postgresql://USER@HOST/DB --workers 1 2 \
        --trials 24 --popsize 6 --seeds 2 --timesteps 20000

Without --storage the study lives in a fresh SQLite file (fine for workers on one machine). --cpu-devices sets
ERMRL_CPU_DEVICES for every worker (default: one JAX device per core in each). Prints a Markdown table; each row
is one run from the workers' start (Python and JAX start-up and compiles included) to the last one's exit.
"""

from __future__ import annotations

import argparse
import collections
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import optuna
from optuna.trial import TrialState

from ermrl.evolution.study import load_study


def run(storage: str, study: str, n: int, args, folder: Path) -> dict:
    batch = -(-args.popsize // n)
    env = dict(os.environ)
    if args.cpu_devices:
        env["ERMRL_CPU_DEVICES"] = str(args.cpu_devices)
    command = [sys.executable, "-m", "ermrl.cli", "evolve", "--env", args.env, "--trials", str(args.trials),
               "--popsize", str(args.popsize), "--seeds", str(args.seeds), "--timesteps", str(args.timesteps),
               "--fixed-iss", "1.0", "--storage", storage, "--study", study, "--batch", str(batch),
               "--quiet", "--no-estimate"]
    start = time.perf_counter()
    procs = [subprocess.Popen([*command, "--worker-index", str(i)], env=env, cwd=folder,
                              stdout=open(folder / f"{study}-w{i}.log", "w"), stderr=subprocess.STDOUT)
             for i in range(n)]
    codes = [p.wait() for p in procs]
    wall = time.perf_counter() - start
    if any(codes):
        raise SystemExit(f"a worker failed (exit codes {codes}); see {folder}")
    trials = load_study(storage, study).trials
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    failed = collections.Counter(t.user_attrs.get("failure", "?") for t in trials if t.state == TrialState.FAIL)
    per_worker = collections.Counter(t.user_attrs["worker"]["index"] for t in complete)
    return {"workers": n, "batch": batch, "wall_s": wall, "complete": len(complete), "failed": dict(failed),
            "per_worker": [per_worker[i] for i in range(n)],
            "best": max(t.value for t in complete)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--storage", default=None, help="an Optuna storage URL (default: a fresh SQLite file)")
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--env", default="CartPoleNoVel-v1")
    p.add_argument("--trials", type=int, default=24)
    p.add_argument("--popsize", type=int, default=6)
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--timesteps", type=int, default=20000)
    p.add_argument("--cpu-devices", type=int, default=None, help="ERMRL_CPU_DEVICES of each worker")
    args = p.parse_args()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    folder = Path(tempfile.mkdtemp(prefix="ermrl-workers-bench-"))
    storage = args.storage or f"sqlite:///{folder / 'study.db'}"
    tag = time.strftime("%Y%m%d-%H%M%S")
    print(f"{args.trials} trials, popsize {args.popsize}, {args.env}, {args.seeds} seeds × {args.timesteps:,} steps; "
          f"{os.cpu_count()} cores; load average before: {os.getloadavg()[0]:.1f}; logs in {folder}")
    print("| workers | batch | wall time | trials/min | trials per worker | failed trials | best |")
    print("|---|---|---|---|---|---|---|")
    for n in args.workers:
        r = run(storage, f"bench-{tag}-{n}w", n, args, folder)
        failed = ", ".join(f"{v} {k}" for k, v in r["failed"].items()) or "none"
        print(f"| {n} | {r['batch']} | {r['wall_s']:.0f} s | {60 * r['complete'] / r['wall_s']:.1f} | "
              f"{' + '.join(map(str, r['per_worker']))} | {failed} | {r['best']:.1f} |", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
