"""Several studies evolved together (one population per env) against one after another: the same trials, timed.

    .venv/bin/python benchmarks/joint_studies.py [--env CartPoleNoVel-v1] [--studies 3] [--generations 2]
                                                 [--timesteps 20480] [--repeats 2]
    .venv/bin/python benchmarks/joint_studies.py --groups HalfCheetah-v5 Swimmer-v5 Ant-v5 --reservoirs 2 ...

Each study is CMA-ES over (sr, lr) with iss fixed at 1.0 (with ``--reservoirs K`` > 1: over all 3K
parameters), CMA-ES's default popsize, 3 seeds a trial, ``timesteps`` steps per agent, its own sampler seed
(0, 1, ...), for ``generations`` generations after the random startup. Every study evolves on ``--env``; with
``--groups E1 E2 E3`` study k instead evolves on two of them as a generalization group does (nScore; the one left
out is Ek), so each env is shared by two studies. Mode ``apart`` evolves the studies one after the other
(``evolve``); mode ``together`` evolves them together (``evolve_together``); both in a fresh process with the
compilation cache warm (one untimed run of each mode first), the modes timed in turn, ``repeats`` times. Prints
the median wall time of each mode, the ratio, and whether both modes gave the same trials.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time


def _space(reservoirs: int):
    """The search space: (sr, lr) with iss fixed at 1.0 for one reservoir, all 3K parameters for K > 1."""
    from ermrl.evolution.search_space import SearchSpace

    return SearchSpace(reservoirs=reservoirs, fixed_iss=1.0 if reservoirs == 1 else None)


def run_mode(mode: str, args) -> list:
    """Evolves the studies in ``mode`` in this process; returns every study's (params, value) per trial."""
    import optuna

    from ermrl.agent import AgentConfig
    from ermrl.compile_cache import enable
    from ermrl.evolution.config import EvolveConfig
    from ermrl.evolution.evolve import Member, evolve, evolve_together
    from ermrl.evolution.study import make_sampler, open_study
    from ermrl.evolution.record import encode_study_record
    from ermrl.evolution.scoring import Baseline
    from ermrl.training import TrainConfig

    enable()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    space = _space(args.reservoirs)
    popsize = space.default_popsize()
    if args.groups:  # study k leaves env k out and evolves on the others; the constants only scale the nScore
        envs = [tuple(e for e in args.groups if e != held) for held in args.groups]
        extra = [{"envs": e, "baselines": tuple(Baseline(x, 0.0, 0.0, 1.0) for x in e)} for e in envs]
    else:
        envs, extra = [(args.env,)] * args.studies, [{}] * args.studies
    configs = [EvolveConfig(train=TrainConfig(env_id=e[0], total_timesteps=args.timesteps,
                                              agent=AgentConfig(reservoirs=args.reservoirs)),
                            space=space, trials=popsize * (args.generations + 1), seeds=3, sampler_seed=k, **x)
               for k, (e, x) in enumerate(zip(envs, extra))]
    folder = tempfile.mkdtemp()
    studies = [open_study(f"sqlite:///{folder}/s{k}.db", f"s{k}", make_sampler("cmaes", popsize, k),
                          encode_study_record(c))
               for k, c in enumerate(configs)]
    if mode == "together":
        evolve_together([Member(s, c) for s, c in zip(studies, configs)])
    else:
        for s, c in zip(studies, configs):
            evolve(s, c)
    return [[(t.params, t.value) for t in s.trials] for s in studies]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="CartPoleNoVel-v1")
    parser.add_argument("--studies", type=int, default=3)
    parser.add_argument("--generations", type=int, default=2)
    parser.add_argument("--timesteps", type=int, default=20480)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--groups", nargs=3, metavar="ENV", help="three envs: study k evolves on the two besides env k")
    parser.add_argument("--reservoirs", type=int, default=1)
    parser.add_argument("--mode", choices=("apart", "together"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.mode:
        print(json.dumps(run_mode(args.mode, args)))
        return
    flags = ["--env", args.env, "--studies", str(args.studies), "--generations", str(args.generations),
             "--timesteps", str(args.timesteps), "--reservoirs", str(args.reservoirs),
             *(["--groups", *args.groups] if args.groups else [])]
    times: dict[str, list[float]] = {"apart": [], "together": []}
    trials = {}
    for repeat in range(args.repeats + 1):
        for mode in ("apart", "together"):
            start = time.perf_counter()
            out = subprocess.run([sys.executable, __file__, *flags, "--mode", mode], check=True, capture_output=True,
                                 text=True).stdout
            if repeat:  # the first round warms the compilation cache
                times[mode].append(time.perf_counter() - start)
            trials[mode] = json.loads(out.strip().splitlines()[-1])
    apart, together = (statistics.median(times[m]) for m in ("apart", "together"))
    agents = 3 * _space(args.reservoirs).default_popsize()
    studies, envs = (3, 2) if args.groups else (args.studies, 1)
    agent_steps = studies * envs * (args.generations + 1) * agents * args.timesteps
    work = (f"3 groups × {args.generations + 1} generations × 2 envs × {agents} agents" if args.groups else
            f"{args.studies} × {args.generations + 1} generations × {agents} agents")
    print(f"| {' + '.join(args.groups) if args.groups else args.env} | {work} × {args.timesteps:,} | "
          f"{apart:.1f} s ({agent_steps / apart:,.0f}/s) | {together:.1f} s ({agent_steps / together:,.0f}/s) | "
          f"{apart / together:.2f}× | {'same' if trials['apart'] == trials['together'] else 'DIFFERENT'} |")


if __name__ == "__main__":
    main()
