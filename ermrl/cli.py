"""The ``ermrl`` command line. Thin: it parses arguments, builds configs and calls the library."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ermrl.errors import ConfigError


def _add_train(sub) -> None:
    p = sub.add_parser(
        "train", help="train ER-MRL agents (or plain PPO) at a fixed Φ over several seeds",
        description="Train one Φ on several seeds as one vectorized population, then write the config (JSON), "
                    "episodes and curves (CSV), a summary and a learning-curve PNG into the run folder.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--env", default="CartPoleNoVel-v1", help="env id; *NoVel-* ids delete the velocity dims")
    p.add_argument("--units", type=int, default=100, help="neurons per reservoir")
    p.add_argument("--reservoirs", type=int, default=1, help="number of reservoirs K (their states are concatenated)")
    p.add_argument("--sr", type=float, nargs="+", default=[0.95], help="spectral radius, one value or one per reservoir")
    p.add_argument("--lr", type=float, nargs="+", default=[0.5], help="leak rate, one value or one per reservoir")
    p.add_argument("--iss", type=float, nargs="+", default=[1.0], help="input scaling, one value or one per reservoir")
    p.add_argument("--seeds", type=int, default=3, help="number of seeds (0..N-1)")
    p.add_argument("--timesteps", type=int, default=300_000, help="env steps per agent")
    p.add_argument("--no-reservoir", action="store_true", help="plain PPO: the policy sees the observation")
    p.add_argument("--ppo-lr", type=float, default=None, help="PPO learning rate (default 3e-4; the paper uses 1e-4 on NoVel tasks)")
    p.add_argument("--preset", choices=["sb3", "fast"], default="sb3",
                   help="PPO settings: 'sb3' = stable-baselines3 defaults (the paper); 'fast' = 8 envs, 4 epochs")
    p.add_argument("--feed-action", choices=["previous", "none"], default="previous",
                   help="'none' reproduces the reference code, which never fed the previous action")
    p.add_argument("--skip-connection", action="store_true", help="the policy also sees the raw reservoir input")
    p.add_argument("--observed-units", type=int, default=None, help="the policy sees only the first k units of each reservoir")
    p.add_argument("--bias", choices=["bernoulli", "none"], default="bernoulli",
                   help="reservoir bias: ReservoirPy 0.3's ±1 on 10%% of units (the paper) or none (0.4)")
    p.add_argument("--out", type=Path, default=None, help="run folder (default runs/train-ENV-TIME)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _phi_values(name: str, values: list[float], k: int) -> list[float]:
    if len(values) == 1:
        return values * k
    if len(values) != k:
        raise ConfigError(f"--{name} got {len(values)} values for {k} reservoirs; give one value or {k}")
    return values


def cmd_train(args) -> int:
    import numpy as np

    from ermrl import envs
    from ermrl.agent import AgentConfig, Phi
    from ermrl.ppo.config import PRESETS
    from ermrl.reservoir import ReservoirSpec
    from ermrl.progress import TrainingBar
    from ermrl.runs import write_train_run
    from ermrl.train import Population, TrainConfig, Trainer
    import dataclasses

    k = 0 if args.no_reservoir else args.reservoirs
    envs.describe(args.env)  # fail fast on an unknown id
    ppo = PRESETS[args.preset]
    if args.ppo_lr is not None:
        ppo = dataclasses.replace(ppo, learning_rate=args.ppo_lr)
    if args.seeds < 1:
        raise ConfigError(f"--seeds must be >= 1, got {args.seeds}")
    spec = ReservoirSpec(units=args.units, bias=args.bias)
    agent = AgentConfig(reservoirs=k, spec=spec, feed_action=args.feed_action, skip_connection=args.skip_connection,
                        observed_units=args.observed_units)
    config = TrainConfig(env_id=args.env, total_timesteps=args.timesteps, agent=agent, ppo=ppo)
    phi = Phi(*(np.array(_phi_values(n, getattr(args, n), max(k, 1))[: max(k, 1)], np.float32) for n in ("sr", "lr", "iss")))
    _check_phi(phi)
    population = Population.grid(phi, args.seeds, ppo.learning_rate, k)
    label = "PPO" if k == 0 else f"ER-MRL ({k} reservoir{'s' if k > 1 else ''})"
    out = args.out or Path("runs") / f"train-{args.env}-{time.strftime('%Y%m%d-%H%M%S')}"

    trainer = Trainer(config)
    with TrainingBar(f"{args.env} × {args.seeds} seeds", enabled=not args.quiet) as bar:
        results = trainer.run(population, bar.update)
    files = write_train_run(out, config, results, label)
    fit = results.fitness()
    for seed, f in zip(results.seeds, fit):
        print(f"seed {seed}: fitness {f:.2f} (mean return of the last 10 training episodes)")
    print(f"mean fitness {np.nanmean(fit):.2f} ± {np.nanstd(fit):.2f} | {results.agent_steps_per_s():,.0f} agent-steps/s, "
          f"compile {results.compile_s:.1f}s, train {results.train_s:.1f}s")
    if not results.finite.all():
        print(f"warning: {int((~results.finite).sum())} agent(s) diverged (NaN/inf); their fitness is NaN", file=sys.stderr)
    print(f"wrote {out}/ ({', '.join(p.name for p in files.values())})")
    return 0


def _check_phi(phi) -> None:
    import numpy as np

    for name, v in zip(("sr", "lr", "iss"), phi):
        if not np.all(np.isfinite(v)) or np.any(v <= 0):
            raise ConfigError(f"--{name} must be positive and finite, got {v.tolist()}")
    if np.any(phi.lr > 1):
        raise ConfigError(f"--lr (leak rate) must be in (0, 1], got {phi.lr.tolist()}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ermrl", description="Evolving Reservoirs for Meta Reinforcement Learning (ER-MRL), vectorized in JAX.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_train(sub)
    return parser


COMMANDS = {"train": cmd_train}


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except ConfigError as e:
        print(f"ermrl {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
