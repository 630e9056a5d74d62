"""``ermrl evolve``: CMA-ES over Φ (the outer loop), resumable, on one or several workers, optionally until it has
converged."""

from __future__ import annotations

from ermrl.cli import common, configs, options
from ermrl.errors import ConfigError

MAX_SAMPLER_SEED = 2**32 - 1
"""NumPy's seeds, which Optuna's samplers take."""


def add_parser(sub, formatter) -> None:
    from ermrl.evolution.config import EvolveConfig  # lazily, like the options' dataclasses

    p = sub.add_parser("evolve", help="evolve reservoir hyperparameters Φ with CMA-ES (the outer loop)",
                       description="Evolve Φ = (sr, leak rate, iss) with Optuna. Each generation (popsize trials × "
                                   "seeds) trains as one population per env. With several --env, a trial's fitness is the "
                                   "mean normalized score over the envs (paper §4.3), from the baselines table. "
                                   "Rerunning the same command resumes the study; several processes or machines "
                                   "may work on one study at once, each with its own --worker-index "
                                   "(docs/scaling.md).", formatter_class=formatter)
    options.sets(p.add_argument("--env", action="append", default=None, metavar="ID",
                                help="env id; repeat for a fitness over several envs (default CartPoleNoVel-v1)"),
                 "envs", EvolveConfig)
    p.add_argument("--seeds", type=int, default=3, help="seeds per trial; its fitness is their mean")
    options.add_options(p, "env", "agent", "ppo", "search", "workers", "stop", "convergence")
    p.add_argument("--baselines", type=options.path, default=None, metavar="TABLE",
                   help="baselines table (default runs/baselines.json over the shipped one); several envs only")
    options.sets(p.add_argument("--allow-weak-baselines", action="store_true",
                                help="go on when vanilla PPO does not beat the random agent on an env at this "
                                     "budget (nScore is then meaningless there); for wiring checks only"),
                 "allow_weak")  # baseline_runs.with_baselines's
    common.study_location(p, required=False)
    p.add_argument("--no-estimate", action="store_true", help="skip the warm-up that estimates the total time")
    common.config_and_quiet(p)


def cmd_evolve(args) -> int:
    import dataclasses
    import time

    import optuna

    from ermrl import storage
    from ermrl.evolution import record as study_record
    from ermrl.cli.progress import EvolutionBar
    from ermrl.model_labels import param_name
    from ermrl.evolution.config import EvolveConfig
    from ermrl.evolution.evolve import count, estimate_seconds, evolve, make_trainers
    from ermrl.evolution.study import (ATTR, SAMPLERS, check_resumable, check_writable, make_sampler, open_study,
                                       shown_url)
    from ermrl.evolution.worker_config import WorkerConfig, worker_seed
    from ermrl.experiments import baseline_runs
    from ermrl.training import memory

    stop_at = None if args.stop_after is None else time.time() + args.stop_after  # from the command's start
    if args.sampler not in SAMPLERS:
        raise ConfigError(f"unknown sampler {args.sampler!r}; choose one of {', '.join(SAMPLERS)}")
    env_ids = tuple(args.env or ["CartPoleNoVel-v1"])
    infos = [configs.describe_env(args, env_id) for env_id in env_ids]
    if args.sampler_seed is not None and not 0 <= args.sampler_seed <= MAX_SAMPLER_SEED:
        raise ConfigError(f"--sampler-seed must be in 0..{MAX_SAMPLER_SEED} (NumPy's seeds), got {args.sampler_seed}")
    config = EvolveConfig(train=configs.train_config(args, env_ids[0]), space=configs.search_space(args),
                          trials=args.trials, seeds=args.seeds, sampler=args.sampler, popsize=args.popsize,
                          sampler_seed=args.sampler_seed, envs=env_ids if len(env_ids) > 1 else (),
                          normalization=args.normalization, seed_schedule=args.seed_schedule)
    worker = WorkerConfig(args.batch, args.worker_index, args.heartbeat_interval, args.grace_period,
                          configs.convergence_rule(args), args.snapshots, stop_at=stop_at)
    if args.snapshots is not None:
        storage.check_folder(args.snapshots, "--snapshots")
    agents = min(worker.batch or config.generation_size, config.trials) * config.seeds  # trained at once, per env
    for env_id, info in zip(env_ids, infos):
        memory.check(config.train_for(env_id), agents, info.obs_dim, info.action.feature_dim, "a generation")
    common.check_study_name(args.study)
    name = args.study or "+".join(env_ids).replace("/", "-") + f"-{args.reservoirs}res-{args.timesteps // 1000}k"
    args.study = name
    if config.normalized:  # a damaged table or a folder given as one fails now, not after the baselines run
        from ermrl.experiments import baselines as bl

        bl.load_table(storage.check_file(args.baselines or bl.default_table(), "--baselines", "baselines.json"))
    storage_url = common.storage_url(args)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    check_writable(storage_url)  # a read-only storage, and a resumption with other settings, fail before any work
    check_resumable(storage_url, name, study_record.encode_study_record(config))
    if config.normalized:
        config = baseline_runs.with_baselines(config, args.baselines, storage_url, name, print,
                                              allow_weak=args.allow_weak_baselines)
    sampler = make_sampler(args.sampler, config.generation_size, worker_seed(args.sampler_seed, worker.worker_index))
    study = open_study(storage_url, name, sampler, study_record.encode_study_record(config),
                       heartbeat=(worker.heartbeat_interval, worker.grace_period))
    stored = study_record.decode_study_record(study.user_attrs[ATTR])
    config = dataclasses.replace(config, baselines=stored.baselines)  # a resumed study keeps its constants
    done = count(study, optuna.trial.TrialState.COMPLETE)
    print(f"study {name!r} in {shown_url(storage_url)}: {done}/{args.trials} trials done, "
          f"{config.generation_size} per generation × {args.seeds} seeds × {args.timesteps:,} steps"
          + (f" on {len(env_ids)} envs" if config.normalized else ""))
    if worker.until_converged is not None and (stop := _converged(study, config, worker.until_converged)):
        print(stop + "; nothing to do (give a smaller --converged-width or more --converged-generations to go on)")
        return 0
    trainers = make_trainers(config)
    if done < args.trials and not args.no_estimate:
        batch = min(worker.batch or config.generation_size, args.trials - done)
        eta = estimate_seconds(trainers, config, args.trials - done, batch)
        print(f"estimated time{' (at most; convergence may stop it sooner)' if worker.until_converged else ''}: "
              f"{eta / 60:.1f} min ({-(-(args.trials - done) // batch)} "
              + ("generations" if batch == config.generation_size else f"batches of {batch} trials, for this worker "
                 "alone") + ", from one measured iteration per env)")
        if eta >= 60 and (note := common.busy_note()):
            print(note)
    with EvolutionBar(args.trials, config.generation_size, len(env_ids), enabled=not args.quiet) as bar:
        evolve(study, config, trainers, bar.update, worker, lambda line: print(line, flush=True))
    if worker.until_converged is not None and (stop := _converged(study, config, worker.until_converged)):
        print(stop)
    best = study.best_trial
    print(f"best fitness {best.value:.4g} at trial {best.number}: "
          + ", ".join(f"{param_name(k)} {v:.4g}" for k, v in best.params.items()))
    if config.normalized:
        print("  per env: " + ", ".join(f"{e} {best.user_attrs['env_scores'][e]:.4g} (nScore "
                                         f"{best.user_attrs['env_nscores'][e]:.3g})" for e in env_ids))
    print(f"next: ermrl select --study {name}{common.storage_flag(args)} ; ermrl test --study {name}{common.storage_flag(args)} ; "
          f"ermrl report --study {name}{common.storage_flag(args)}")
    return 0


def _converged(study, config, rule) -> str | None:
    """'study NAME converged at generation G (N trials): RULE', or None while it has not."""
    from ermrl.evolution import convergence

    verdict = convergence.judge(study, config.space, config.generation_size, rule)
    if verdict.generation is None:
        return None
    if convergence.recorded(study, rule) is None:
        convergence.record(study, rule, verdict)
    return (f"study {study.study_name!r} converged at generation {verdict.generation} ({verdict.trials} trials): "
            f"{rule.describe()}")
