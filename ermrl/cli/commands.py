"""The study pipeline's commands: train, evolve, select, test, report, plot, baselines."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from ermrl.cli import common, configs, evolve, options
from ermrl.errors import ConfigError
from ermrl.model_labels import PHI_NAMES

# -- parsers ---------------------------------------------------------------------------------------------


def add_parsers(sub, formatter) -> None:
    p = sub.add_parser("train", help="train ER-MRL agents (or plain PPO, or PPO-LSTM) at a fixed Φ over several seeds",
                       description="Train one Φ on several seeds as one vectorized population, then write the "
                                   "effective config (JSON), episodes and curves (CSV), a summary and a learning-curve "
                                   "PNG into the run folder.", formatter_class=formatter)
    p.add_argument("--env", default="CartPoleNoVel-v1", help="env id; *NoVel-* ids delete the velocity dims")
    from ermrl.agent import DEFAULT_PHI

    flags = {"sr": ("--sr", "--spectral-radius"), "lr": ("--leak-rate",), "iss": ("--iss", "--input-scaling")}
    metavars = {"sr": "SR", "lr": "LEAK", "iss": "ISS"}  # not "LR": in RL that is a learning rate
    for name, default in DEFAULT_PHI._asdict().items():
        p.add_argument(*flags[name], dest=name, type=float, nargs="+", default=[default], metavar=metavars[name],
                       help=f"{PHI_NAMES[name]}, one value or one per reservoir")
    options.refuse_lr(p, "--lr", "--leak-rate")
    p.add_argument("--seeds", type=int, default=3, help="number of seeds (FIRST..FIRST+N-1)")
    p.add_argument("--first-seed", type=int, default=0, metavar="FIRST",
                   help="the first seed: e.g. 1000 trains on seeds no evolution used (they use 0..S-1)")
    p.add_argument("--no-reservoir", action="store_true", help="plain PPO: the policy sees the observation")
    options.add_options(p, "env", "agent", "ppo", "model", "tensorboard", "agents")
    p.add_argument("--out", type=options.path, default=None,
                   help="run folder (default runs/train-ENV-TIME). With --out, the run's state is kept in "
                        "OUT.snapshot while it trains, and the same command run again after a stop resumes from "
                        "it, to the same results")
    p.add_argument("--snapshot-every", type=float, default=300.0, metavar="SECONDS",
                   help="with --out: seconds between snapshots (default 300)")
    common.config_and_quiet(p)

    evolve.add_parser(sub, formatter)

    p = sub.add_parser("select", help="re-evaluate the top trials on fresh seeds and pick a robust Φ*",
                       description="Re-evaluate the K best trials of a study on S new seeds (the evolution's envs, "
                                   "budget and fitness), record every re-evaluation and the winner in the study. "
                                   "`ermrl test` then uses the winner.", formatter_class=formatter)
    common.study_location(p)
    p.add_argument("--top", type=int, default=5, help="how many of the best trials to re-evaluate")
    p.add_argument("--seeds", type=int, default=5, help="fresh seeds per trial (2000, 2001, ...)")
    p.add_argument("--again", action="store_true", help="re-evaluate even when the study records a selection of "
                   "these top trials on as many seeds (by default a rerun reuses it and trains nothing)")
    common.config_and_quiet(p)

    p = sub.add_parser("test", help="test phase: train Φ* on new seeds against PPO baselines",
                       description="Train Φ* (the selected trial, else the best) on new seeds, plus vanilla PPO on "
                                   "the same observation and PPO with full observations (and PPO-LSTM with "
                                   "--recurrent-baseline); write curves (CSV), a "
                                   "summary with IQM and bootstrap CIs, and the paper-style figure. --env tests on an "
                                   "env outside the evolution (generalization).", formatter_class=formatter)
    common.study_location(p)
    options.add_options(p, "test", "tensorboard", "agents")
    p.add_argument("--env-workers", type=options.workers, default=None, metavar="N|auto",
                   help="host envs: processes that step them (0: the main process; default: the evolution's "
                        "setting); results do not depend on it")
    p.add_argument("--processes", type=options.processes, default=None, metavar="N",
                   help="host-loop backends: processes that train each model's agents at once (default: the "
                        "evolution's setting); results do not depend on it")
    common.config_and_quiet(p)

    p = sub.add_parser("report", help="write a self-contained HTML report of a study",
                       description="Write report.html (images embedded): results first (best Φ, test phases with "
                                   "statistics), then fitness over trials, the HP map and the configuration.",
                       formatter_class=formatter)
    common.study_location(p)
    common.config_and_quiet(p, quiet=False)

    p = sub.add_parser("plot", help="plot several run folders' learning curves together",
                       description="Read the curves.csv of each run folder (from `ermrl train` or `ermrl test`) and "
                                   "draw every model in one figure, mean ± std over seeds.", formatter_class=formatter)
    p.add_argument("runs", type=options.path, nargs="+", help="run folders holding curves.csv")
    p.add_argument("--out", type=options.path, required=True, help="figure path (.png; .svg is written beside it too)")
    p.add_argument("--title", default="", help="figure title (default: the env id of the first run)")
    common.config_and_quiet(p, quiet=False)

    p = sub.add_parser("baselines", help="compute the random and PPO scores that normalize several envs' fitness",
                       description="For each env: the random agent's mean episode return (uniform actions) and "
                                   "vanilla PPO's fitness with the evolution's definition, seeds and budget; stored "
                                   "with their provenance in the baselines table, which `ermrl evolve` reads for "
                                   "several envs.", formatter_class=formatter)
    p.add_argument("--env", action="append", required=True, metavar="ID", help="env id; repeat for several")
    p.add_argument("--seeds", type=int, default=3, help="PPO seeds (0..N-1, the evolution's)")
    p.add_argument("--random-episodes", type=int, default=100, help="random-agent episodes per env")
    options.add_options(p, "env", "agent", "ppo", skip=())
    p.add_argument("--table", type=options.path, default=None, help="table to update (default runs/baselines.json)")
    p.add_argument("--recompute", action="store_true", help="recompute entries that the table already has")
    common.config_and_quiet(p)


MAX_SEED = 2**31 - 1
"""The largest agent seed: seeds are int32 in a population."""
MAX_RANDOM_EPISODES = 1_000_000
MAX_SCALE = 1e6
"""The largest spectral radius or input scaling a reservoir takes."""


# -- train and plot --------------------------------------------------------------------------------------


FLAGS = {"sr": "--sr", "lr": "--leak-rate", "iss": "--iss"}
"""The flag that sets each field of Φ in ``ermrl train``."""


def _phi_values(name: str, values: list[float], k: int) -> list[float]:
    if len(values) == 1:
        return values * k
    if len(values) != k:
        raise ConfigError(f"{FLAGS[name]} got {len(values)} values for {k} reservoirs; give one value or {k}")
    return values


def _check_phi(phi) -> None:
    import numpy as np

    for name, v in zip(("sr", "lr", "iss"), phi):
        if not np.all(np.isfinite(v)) or np.any(v <= 0):
            raise ConfigError(f"{FLAGS[name]} must be positive and finite, got {v.tolist()}")
    if np.any(phi.lr > 1):
        raise ConfigError(f"--leak-rate must be in (0, 1], got {phi.lr.tolist()}")
    for name, v in (("sr", phi.sr), ("iss", phi.iss)):
        if np.any(v > MAX_SCALE):
            raise ConfigError(f"{FLAGS[name]} must be <= {MAX_SCALE:g} (the reservoir's float32 sums stay finite), got "
                              f"{v.tolist()}")


def cmd_train(args) -> int:
    import numpy as np

    from ermrl import agent_files, storage
    from ermrl.agent import Phi
    from ermrl.analysis import tensorboard
    from ermrl.analysis.plots import learning_curves
    from ermrl.cli.progress import TrainingBar
    from ermrl.training import Population, Trainer, memory

    k = 0 if args.no_reservoir or args.model == "lstm" else args.reservoirs
    info = configs.describe_env(args, args.env)  # fail fast: an unknown id, a missing extra, settings it cannot take
    if args.tensorboard is not None:
        tensorboard.check_logdir(args.tensorboard)
    if args.seeds < 1:
        raise ConfigError(f"--seeds must be >= 1, got {args.seeds}")
    if args.first_seed < 0:
        raise ConfigError(f"--first-seed must be >= 0, got {args.first_seed}")
    if args.first_seed + args.seeds - 1 > MAX_SEED:
        raise ConfigError(f"--first-seed + --seeds - 1 must be <= {MAX_SEED} (seeds are 32-bit integers), got "
                          f"{args.first_seed + args.seeds - 1}")
    if not args.snapshot_every >= 0:
        raise ConfigError(f"--snapshot-every must be >= 0 seconds, got {args.snapshot_every}")
    if args.skip_connection and k == 0:
        raise ConfigError("--skip-connection feeds the observation beside a reservoir's context, but "
                          + ("--model lstm" if args.model == "lstm" else "--no-reservoir")
                          + " has no reservoir and already sees the observation; drop --skip-connection")
    config = configs.train_config(args, args.env, k)
    if config.ppo.model == "lstm":
        from ermrl.training import recurrent

        recurrent.check(config)
    phi = Phi(*(np.array(_phi_values(n, getattr(args, n), max(k, 1))[: max(k, 1)], np.float32) for n in ("sr", "lr", "iss")))
    _check_phi(phi)
    population = Population.grid(phi, list(range(args.first_seed, args.first_seed + args.seeds)),
                                 config.ppo.learning_rate, k)
    memory.check(config, population.size, info.obs_dim, info.action.feature_dim)
    label = "PPO-LSTM" if args.model == "lstm" else \
        "PPO" if k == 0 else f"ER-MRL ({k} reservoir{'s' if k > 1 else ''})"
    out = args.out or Path("runs") / f"train-{args.env}-{time.strftime('%Y%m%d-%H%M%S')}"
    storage.check_folder(storage.check_rerun_folder(out, "train"))

    # with --out, a stopped run resumes from OUT.snapshot when run again (written every few minutes)
    snapshot = common.own_snapshot(Path(f"{out}.snapshot")) if args.out else None
    with TrainingBar(f"{args.env} × {args.seeds} seeds", enabled=not args.quiet) as bar:
        results = Trainer(config).run(population, bar.update, snapshot=snapshot, snapshot_every_s=args.snapshot_every,
                                      log=print)
    with storage.staged_folder(out, stale=agent_files.AGENT_FILES) as stage:  # all or nothing: summary.json last
        run = storage.write_train_run(stage, config, results, label, configs.effective(args))
        if args.save_agents:
            agent_files.write_agents(run.folder / agent_files.AGENTS_DIR, config, results, label)
        learning_curves({label: results.curves()}, f"{results.env_id}: {label}", run.figure)
    if snapshot is not None:
        snapshot.unlink(missing_ok=True)
    if args.tensorboard is not None:
        tensorboard.write_results(args.tensorboard, results, label)
    fit = results.fitness()
    for seed, f in zip(results.seeds, fit):
        print(f"seed {seed}: fitness {f:.2f} (mean return of the last 10 training episodes)")
    mean = (f"mean fitness {np.nanmean(fit):.2f} ± {np.nanstd(fit):.2f}" if np.isfinite(fit).any()
            else "no fitness: no episode finished (train for longer than one episode)")
    print(f"{mean} | {results.agent_steps_per_s():,.0f} agent-steps/s, compile {results.compile_s:.1f}s, "
          f"train {results.train_s:.1f}s")
    if not results.finite.all():
        print(f"warning: {int((~results.finite).sum())} agent(s) diverged (NaN/inf); their fitness is NaN", file=sys.stderr)
    print(f"wrote {out}/ (config.json, episodes.csv, curves.csv, summary.json, learning_curve.png"
          + (", agents/" if args.save_agents else "") + ")")
    if args.tensorboard is not None:
        print(f"TensorBoard: tensorboard --logdir {args.tensorboard}")
    return 0


def cmd_plot(args) -> int:
    from ermrl import storage
    from ermrl.analysis.plots import learning_curves

    storage.check_file(args.out)
    curves = {}
    for run in args.runs:
        if not (run / "curves.csv").is_file():
            raise ConfigError(f"{run} has no curves.csv; give folders written by `ermrl train` or `ermrl test`")
        curves.update(storage.read_curves_csv(run / "curves.csv"))
    title = args.title or storage.run_env_id(args.runs[0]) or ""
    for path in learning_curves(curves, title, args.out, ("png", "svg")):
        print(f"wrote {path}")
    return 0


# -- evolve, select, test, report ------------------------------------------------------------------------


def cmd_select(args) -> int:
    from ermrl import storage
    from ermrl.evolution import record as study_record
    from ermrl.evolution.selection import ranked_trials, recorded_selection, select, ties_at_cut
    from ermrl.evolution.study import ATTR, check_writable, load_study

    if args.top < 1 or args.seeds < 1:
        raise ConfigError(f"--top and --seeds must be >= 1, got {args.top} and {args.seeds}")
    study = load_study(common.storage_url(args), args.study)
    check_writable(common.storage_url(args))  # the selection is recorded in the study
    config = study_record.decode_study_record(study.user_attrs[ATTR])
    for env_id in config.env_ids:
        common.check_memory(config.train_for(env_id), min(args.top, len(study.trials)) * args.seeds,
                            "the selection")
    ranked = ranked_trials(study)
    tied = ties_at_cut(ranked, args.top)
    if tied:
        print(f"note: {tied} more trials tie at the cut's fitness ({ranked[args.top - 1].value:.4g}), so the top "
              f"{args.top} are the first of them by trial number; --top {args.top + tied} re-evaluates them all")
    s = None if args.again else recorded_selection(study, args.top, args.seeds)
    if s is not None:
        print(f"the top {len(s.trials)} trials were re-evaluated on seeds {s.seeds[0]}..{s.seeds[-1]} already "
              f"({s.date}); reusing that selection (--again re-evaluates them):")
    else:
        progress, close = common.bars(args.quiet)
        try:
            s = select(study, config, args.top, args.seeds, progress)
        finally:
            close()
        print(f"re-evaluated the top {len(s.trials)} trials on seeds {s.seeds[0]}..{s.seeds[-1]}:")
    for number, before, after in zip(s.trials, s.evolution_values, s.values):
        mark = "  <- selected" if number == s.winner else ""
        print(f"  trial {number:>4}: evolution {before:9.4g}   fresh seeds {after if after is not None else float('nan'):9.4g}{mark}")
    print(f"Φ* = trial {s.winner}; `ermrl test --study {args.study}{common.storage_flag(args)}` now tests it")
    return 0


def cmd_test(args) -> int:
    from ermrl import storage
    from ermrl.evolution import record as study_record
    from ermrl.analysis import tensorboard
    from ermrl.analysis.statistics import format_ci
    from ermrl.evolution.study import ATTR, load_study
    from ermrl.experiments.evaluation import run_test_phase, test_dir

    if args.tensorboard is not None:
        tensorboard.check_logdir(args.tensorboard)
    test = configs.test_config(args)
    if args.agents_per_run is not None and args.agents_per_run < 1:
        raise ConfigError(f"--agents-per-run must be >= 1, got {args.agents_per_run}")
    if args.baseline_store is not None:
        storage.check_folder(args.baseline_store, "--baseline-store")
    if test.env_id is not None:
        from ermrl import envs

        envs.describe(test.env_id)  # an unknown id or a missing simulator, before opening the study
    study = load_study(common.storage_url(args), args.study)
    config = study_record.decode_study_record(study.user_attrs[ATTR])
    tested = config.train_for(test.env_id or config.env_ids[0])
    common.check_memory(tested, test.seeds * max(1, len(test.learning_rates)), "the test phase")
    out = storage.check_folder(test_dir(common.run_dir(args), study.user_attrs[ATTR], test.env_id))
    progress, close = common.bars(args.quiet)
    models: list = []  # (label, Results) of every model, for TensorBoard
    try:
        rows = run_test_phase(study, out, test, progress, save_agents=args.save_agents, log=print,
                              on_results=lambda label, results: models.append((label, results)),
                              agents_per_run=args.agents_per_run, env_workers=args.env_workers,
                              baseline_store=args.baseline_store, processes=args.processes)
    finally:
        close()
    if args.tensorboard is not None:
        for label, results in models:
            tensorboard.write_results(args.tensorboard, results, label)
    print(f"Φ*: {rows[0]['phi_choice']}; evolved on {', '.join(rows[0]['evolved_on'])}; tested on {rows[0]['env_id']}")
    for r in rows:
        div = f"  ({r['diverged']} diverged)" if r["diverged"] else ""
        print(f"{r['model']:<44} final {_pm(r['final_mean'], r['final_std'])}  IQM "
              f"{format_ci(r['final_iqm'], r['final_iqm_low'], r['final_iqm_high'])}  AUC {_pm(r['auc_mean'], r['auc_std'])}{div}")
        for baseline, (p, lo, hi) in r.get("improvement", {}).items():
            print(f"    P(better than {baseline}) = {p:.2f} [{lo:.2f}, {hi:.2f}]")
    print(f"wrote {out}/ (curves.csv, summary.json, summary.csv, test_phase.png, test_phase.svg"
          + (", agents/" if args.save_agents else "") + ")")
    if args.tensorboard is not None:
        print(f"TensorBoard: tensorboard --logdir {args.tensorboard}")
    return 0


def _pm(mean, std) -> str:
    return "—" if mean is None else f"{mean:8.1f} ± {std:6.1f}"


def cmd_report(args) -> int:
    from ermrl.analysis.report import write_report
    from ermrl.evolution.study import load_study

    study = load_study(common.storage_url(args), args.study)
    path = write_report(study, common.run_dir(args))
    print(f"report: {path.resolve()}")
    return 0


def cmd_baselines(args) -> int:
    from ermrl.experiments import baseline_runs, baselines

    for env_id in args.env:
        configs.describe_env(args, env_id)
    if args.seeds < 1 or args.random_episodes < 1:
        raise ConfigError(f"--seeds and --random-episodes must be >= 1, got {args.seeds} and {args.random_episodes}")
    if args.random_episodes > MAX_RANDOM_EPISODES:
        raise ConfigError(f"--random-episodes must be <= {MAX_RANDOM_EPISODES:,}, got {args.random_episodes}")
    for env_id in args.env:
        common.check_memory(configs.train_config(args, env_id, 0), args.seeds, "the PPO baseline")
    ppo = configs.ppo_config(args)
    rate = ppo.learning_rate
    progress, close = common.bars(args.quiet)
    try:  # vanilla PPO trains with every PPO setting given (--gamma, --preset, ...), as the evolution's agents
        found = baseline_runs.ensure(args.env, args.timesteps, args.seeds, rate, args.table, print, progress,
                                     args.backend, args.env_workers, args.random_episodes, args.recompute,
                                     baselines.ppo_settings(ppo), args.env_threads, args.processes)
    finally:
        close()
    for env_id, b in found.items():
        print(f"{env_id}: random {b.random_return:.4g} per episode ({b.random_step_reward:.4g} per step), "
              f"PPO {b.ppo:.4g} ({args.seeds} seeds × {args.timesteps:,} steps, learning rate {rate:g})")
    print(f"table: {args.table or baselines.default_table()} (over the shipped table {baselines.SHIPPED})")
    return 0


COMMANDS = {"train": cmd_train, "evolve": evolve.cmd_evolve, "select": cmd_select, "test": cmd_test,
            "report": cmd_report, "plot": cmd_plot, "baselines": cmd_baselines}
