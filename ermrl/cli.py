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
    _backend_args(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _workers(value: str):
    if value == "auto":
        return value
    try:
        n = int(value)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(f"must be 'auto' or an integer >= 0, got {value!r}")
    return n


def _backend_args(p) -> None:
    p.add_argument("--backend", choices=["auto", "jax", "host"], default="auto",
                   help="auto: JAX (gymnax) when the env has a JAX version, else Gymnasium on the host; "
                        "host runs any Gymnasium id")
    p.add_argument("--env-workers", type=_workers, default="auto", metavar="N|auto",
                   help="host backend: processes that step the envs (0: the main process; auto: one per core "
                        "when an env step is costly). Results do not depend on it")


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
    envs.describe(args.env, args.backend)  # fail fast on an unknown id or a missing extra
    ppo = PRESETS[args.preset]
    if args.ppo_lr is not None:
        ppo = dataclasses.replace(ppo, learning_rate=args.ppo_lr)
    if args.seeds < 1:
        raise ConfigError(f"--seeds must be >= 1, got {args.seeds}")
    spec = ReservoirSpec(units=args.units, bias=args.bias)
    agent = AgentConfig(reservoirs=k, spec=spec, feed_action=args.feed_action, skip_connection=args.skip_connection,
                        observed_units=args.observed_units)
    config = TrainConfig(env_id=args.env, total_timesteps=args.timesteps, agent=agent, ppo=ppo, backend=args.backend,
                         env_workers=args.env_workers)
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


def _add_evolve(sub) -> None:
    p = sub.add_parser(
        "evolve", help="evolve reservoir hyperparameters Φ with CMA-ES (the outer loop)",
        description="Evolve Φ = (sr, lr, iss) with Optuna. Each generation (popsize trials × seeds) trains as one "
                    "population. Rerunning the same command resumes the study: completed trials count toward "
                    "--trials and a generation cut off mid-way is redone.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--env", default="CartPoleNoVel-v1", help="env id")
    p.add_argument("--trials", type=int, default=900, help="completed trials to reach")
    p.add_argument("--seeds", type=int, default=3, help="seeds per trial; fitness is their mean")
    p.add_argument("--timesteps", type=int, default=300_000, help="env steps per agent")
    p.add_argument("--reservoirs", type=int, default=1, help="number of reservoirs K, each with its own Φ")
    p.add_argument("--units", type=int, default=100, help="neurons per reservoir")
    p.add_argument("--fixed-iss", type=float, default=None, help="hold the input scaling fixed (e.g. 1.0) instead of searching it")
    p.add_argument("--sampler", default="cmaes", help="cmaes (Optuna's CmaEsSampler), random or tpe")
    p.add_argument("--popsize", type=int, default=None, help="trials per generation (default: CMA-ES's 4 + 3 ln n)")
    p.add_argument("--sampler-seed", type=int, default=0, help="seed of the sampler")
    for hp, lo, hi in (("sr", 1e-4, 1e2), ("lr", 1e-2, 1.0), ("iss", 0.1, 10.0)):
        p.add_argument(f"--min-{hp}", type=float, default=lo, help=f"lower log-uniform bound of {hp}")
        p.add_argument(f"--max-{hp}", type=float, default=hi, help=f"upper log-uniform bound of {hp}")
    p.add_argument("--ppo-lr", type=float, default=None, help="PPO learning rate (default 3e-4, as in the paper's evolution)")
    p.add_argument("--feed-action", choices=["previous", "none"], default="previous",
                   help="'none' reproduces the reference code, which never fed the previous action")
    p.add_argument("--study", default=None, help="study name (default ENV-Kres-STEPSk)")
    p.add_argument("--storage", default=None, help="Optuna storage URL or journal file (default sqlite in the run folder)")
    p.add_argument("--out", type=Path, default=None, help="run folder (default runs/STUDY)")
    p.add_argument("--no-estimate", action="store_true", help="skip the warm-up that estimates the total time")
    _backend_args(p)
    p.add_argument("--quiet", action="store_true", help="no progress display")


def _add_test(sub) -> None:
    p = sub.add_parser(
        "test", help="test phase: train the best Φ on new seeds against PPO baselines",
        description="Train Φ* (the study's best trial) on new seeds, plus vanilla PPO on the same observation and PPO "
                    "with full observations; write curves (CSV), a summary table and the paper-style figure.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    _study_args(p)
    p.add_argument("--seeds", type=int, default=10, help="new seeds per model")
    p.add_argument("--timesteps", type=int, default=1_000_000, help="env steps per agent (paper: 1M, LunarLander 3M)")
    p.add_argument("--ppo-lr", type=float, default=None,
                   help="PPO learning rate of every model (default: the evolution's; the paper tests NoVel tasks at 1e-4)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_report(sub) -> None:
    p = sub.add_parser("report", help="write a self-contained HTML report of a study",
                       description="Write report.html (images embedded) with the study config, fitness over trials, "
                                   "the HP map, the best Φ and the test phase if one was run; plots also as PNG.",
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    _study_args(p)


def _add_plot(sub) -> None:
    p = sub.add_parser("plot", help="plot several run folders' learning curves together",
                       description="Read the curves.csv of each run folder (from `ermrl train` or `ermrl test`) and draw "
                                   "every model in one figure, mean ± std over seeds.",
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("runs", type=Path, nargs="+", help="run folders holding curves.csv")
    p.add_argument("--out", type=Path, required=True, help="figure path (.png; .svg is written beside it too)")
    p.add_argument("--title", default="", help="figure title (default: the env id of the first run)")


def cmd_plot(args) -> int:
    import json

    from ermrl.analysis.plots import learning_curves
    from ermrl.runs import read_curves_csv

    curves = {}
    for run in args.runs:
        if not (run / "curves.csv").is_file():
            raise ConfigError(f"{run} has no curves.csv; give folders written by `ermrl train` or `ermrl test`")
        curves.update(read_curves_csv(run / "curves.csv"))
    title = args.title
    if not title and (args.runs[0] / "config.json").is_file():
        title = json.loads((args.runs[0] / "config.json").read_text())["train"]["env_id"]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    for path in learning_curves(curves, title, args.out, ("png", "svg")):
        print(f"wrote {path}")
    return 0


def _study_args(p) -> None:
    p.add_argument("--study", required=True, help="study name, as given to or printed by `ermrl evolve`")
    p.add_argument("--storage", default=None, help="storage URL (default sqlite in runs/STUDY)")
    p.add_argument("--out", type=Path, default=None, help="run folder (default runs/STUDY)")


def _run_dir(args) -> Path:
    return args.out or Path("runs") / args.study


def cmd_evolve(args) -> int:
    import dataclasses

    import optuna

    from ermrl import envs
    from ermrl.agent import AgentConfig
    from ermrl.evolve import EvolveConfig, count, estimate_seconds, evolve
    from ermrl.ppo.config import SB3_DEFAULTS
    from ermrl.progress import EvolutionBar
    from ermrl.reservoir import ReservoirSpec
    from ermrl.search_space import SearchSpace
    from ermrl.study import SAMPLERS, default_storage, make_sampler, open_study
    from ermrl.train import TrainConfig, Trainer

    if args.sampler not in SAMPLERS:
        raise ConfigError(f"unknown sampler {args.sampler!r}; choose one of {', '.join(SAMPLERS)}")
    envs.describe(args.env, args.backend)
    for name in ("trials", "seeds"):
        if getattr(args, name) < 1:
            raise ConfigError(f"--{name} must be >= 1, got {getattr(args, name)}")
    space = SearchSpace(args.reservoirs, (args.min_sr, args.max_sr), (args.min_lr, args.max_lr),
                        (args.min_iss, args.max_iss), args.fixed_iss)
    ppo = SB3_DEFAULTS if args.ppo_lr is None else dataclasses.replace(SB3_DEFAULTS, learning_rate=args.ppo_lr)
    agent = AgentConfig(reservoirs=args.reservoirs, spec=ReservoirSpec(units=args.units), feed_action=args.feed_action)
    config = EvolveConfig(train=TrainConfig(args.env, args.timesteps, agent, ppo, args.backend,
                                                   args.env_workers), space=space, trials=args.trials,
                          seeds=args.seeds, sampler=args.sampler, popsize=args.popsize, sampler_seed=args.sampler_seed)
    name = args.study or f"{args.env}-{args.reservoirs}res-{args.timesteps // 1000}k"
    run_dir = args.out or Path("runs") / name
    storage = args.storage or default_storage(run_dir)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = open_study(storage, name, make_sampler(args.sampler, config.generation_size, args.sampler_seed), config.record())
    done = count(study, optuna.trial.TrialState.COMPLETE)
    print(f"study {name!r} in {storage}: {done}/{args.trials} trials done, {config.generation_size} per generation "
          f"× {args.seeds} seeds × {args.timesteps:,} steps")
    trainer = Trainer(config.train)
    if done < args.trials and not args.no_estimate:
        eta = estimate_seconds(trainer, config, args.trials - done)
        print(f"estimated time: {eta / 60:.1f} min ({-(-(args.trials - done) // config.generation_size)} generations, "
              "from one measured iteration)")
    with EvolutionBar(args.trials, config.generation_size, enabled=not args.quiet) as bar:
        evolve(study, config, trainer, bar.update)
    best = study.best_trial
    print(f"best fitness {best.value:.2f} at trial {best.number}: "
          + ", ".join(f"{k} {v:.4g}" for k, v in best.params.items()))
    print(f"next: ermrl test --study {name}{_storage_flag(args)} ; ermrl report --study {name}{_storage_flag(args)}")
    return 0


def _storage_flag(args) -> str:
    out = f" --storage {args.storage}" if args.storage else ""
    return out + (f" --out {args.out}" if args.out else "")


def cmd_test(args) -> int:
    from ermrl.experiments.test_phase import run_test_phase
    from ermrl.progress import TrainingBar
    from ermrl.study import default_storage, load_study

    if args.seeds < 1:
        raise ConfigError(f"--seeds must be >= 1, got {args.seeds}")
    run_dir = _run_dir(args)
    study = load_study(args.storage or default_storage(run_dir), args.study)
    bars = []

    def progress(label):
        bar = TrainingBar(f"{label}", enabled=not args.quiet)
        bar.__enter__()
        bars.append(bar)
        return bar.update

    try:
        rows = run_test_phase(study, run_dir / "test", args.seeds, args.timesteps, progress, args.ppo_lr)
    finally:
        for bar in bars:
            bar.__exit__(None, None, None)
    for r in rows:
        print(f"{r['model']:<40} final {r['final_mean']:8.1f} ± {r['final_std']:6.1f}   AUC {r['auc_mean']:8.1f} ± {r['auc_std']:6.1f}")
    print(f"wrote {run_dir / 'test'}/ (curves.csv, summary.json, summary.csv, test_phase.png, test_phase.svg)")
    return 0


def cmd_report(args) -> int:
    from ermrl.analysis.report import write_report
    from ermrl.study import default_storage, load_study

    run_dir = _run_dir(args)
    study = load_study(args.storage or default_storage(run_dir), args.study)
    path = write_report(study, run_dir)
    print(f"report: {path.resolve()}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ermrl", description="Evolving Reservoirs for Meta Reinforcement Learning (ER-MRL), vectorized in JAX.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_train(sub)
    _add_evolve(sub)
    _add_test(sub)
    _add_report(sub)
    _add_plot(sub)
    return parser


COMMANDS = {"train": cmd_train, "evolve": cmd_evolve, "test": cmd_test, "report": cmd_report, "plot": cmd_plot}


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
