"""``ermrl convergence``: where a CMA-ES study converged, by the stopping rule of ``ermrl evolve --until-converged``,
replayed on the study's stored search distributions; with ``--copy-to``, the study as the rule would have left it."""

from __future__ import annotations

import math

from ermrl.cli import common, options
from ermrl.errors import ConfigError


def add_parser(sub, formatter) -> None:
    p = sub.add_parser("convergence", help="the Φ spread per generation of a CMA-ES study and where it converged",
                       description="Read the search distribution CMA-ES sampled each generation from (Optuna stores "
                                   "it in the study), write its spread per generation (OUT/convergence.csv, "
                                   "OUT/convergence.png) and say at which generation the stopping rule of `ermrl "
                                   "evolve --until-converged` holds, with the trials that far and the compute they "
                                   "are of all the study's trials (OUT/convergence.json). On a study that has not "
                                   "converged it says where the rule would hold if each spread kept shrinking at "
                                   "its rate of the later half of the generations (and of the last 8, once "
                                   "the later half is longer), and Spearman's ρ of fitness "
                                   "against each parameter there. --copy-to writes the study "
                                   "as the rule would have left it (its trials up to that generation) to another "
                                   "storage, where `ermrl select` and `ermrl test` run as on any study.",
                       formatter_class=formatter)
    common.study_location(p)
    options.add_options(p, "convergence", skip=("--until-converged",))
    p.add_argument("--copy-to", type=options.storage, default=None, metavar="STORAGE",
                   help="also write the trials up to the stop as a study of the same name in this storage (a "
                        "journal file or URL without that study)")
    common.config_and_quiet(p)


def cmd_convergence(args) -> int:
    import optuna
    from optuna.trial import TrialState

    from ermrl import storage
    from ermrl.evolution import record as study_record
    from ermrl.analysis import spread
    from ermrl.evolution import convergence
    from ermrl.evolution.generations import ATTR as GENERATION
    from ermrl.evolution.study import ATTR, load_study

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    rule = convergence.Convergence(args.converged_width, args.converged_generations)
    study = load_study(common.storage_url(args), args.study)
    config = study_record.decode_study_record(study.user_attrs[ATTR])
    if config.sampler != "cmaes":
        raise ConfigError(f"study {args.study!r} was sampled by {config.sampler}, which has no search distribution; "
                          "convergence is read from CMA-ES studies only")
    if args.copy_to is not None:
        _check_copy_target(args.copy_to, args.study)
    trials = study.get_trials(deepcopy=False)
    dists = convergence.centers_and_spreads(trials, config.space)
    if not dists:
        raise ConfigError(f"study {args.study!r} holds no CMA-ES search distribution yet (it needs 2 generations "
                          "told); evolve it further first")
    verdict = convergence.judge(study, config.space, config.generation_size, rule, trials)
    out = common.run_dir(args)
    storage.check_folder(out, "--out")
    out.mkdir(parents=True, exist_ok=True)
    spread.write_table(out / "convergence.csv", dists)
    spread.figure(dists, rule, verdict.generation, f"{args.study}: Φ spread per generation", out / "convergence.png")
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    total, generations = len(complete), 1 + max(int(t.user_attrs.get(GENERATION, 0)) for t in complete)
    summary = {"study": args.study, "rule": {"width": rule.width, "generations": rule.generations},
               "stop_generation": verdict.generation, "trials_to_stop": verdict.trials, "trials": total,
               "generations": generations, **spread.summary(dists, verdict.generation)}
    if verdict.generation is None:
        print(f"study {args.study!r} has not converged by the rule ({rule.describe()}) in its {generations} "
              f"generations (0–{generations - 1}; {total} trials)")
        summary["projection"] = _projection(convergence.project(verdict.spread, rule), config)
        summary["recent_projection"] = _projection(convergence.recent_projection(verdict.spread, rule), config)
        summary["projection_history"] = _history(convergence.projection_history(verdict.spread, rule))
        if summary["projection"] is not None:
            summary["fitness_correlations"] = _correlations(trials, config, summary["projection"]["window"])
    else:
        shift = spread.shift(dists, verdict.generation)
        summary["mean_shift_decades"] = shift
        print(f"study {args.study!r} converged at generation {verdict.generation}: {verdict.trials} of its {total} "
              f"completed trials ({verdict.trials / total:.0%} of the compute); {rule.describe()}")
        for name, (mean, s) in dists[verdict.generation].items():
            last_mean, last_s = dists[max(dists)][name]
            print(f"  {name}: mean {mean:.4g} ± {s:.2g} decades at the stop; {last_mean:.4g} ± {last_s:.2g} at "
                  f"generation {max(dists)} (the mean moved {shift[name]:.3g} decades after the stop)")
    storage.write_json(out / "convergence.json", summary)
    print(f"wrote {out}/ (convergence.csv, convergence.png, convergence.json)")
    if args.copy_to is not None:
        if verdict.generation is None:
            raise ConfigError("--copy-to needs a generation where the study converged; none was found")
        kept = [t for t in trials if t.state in (TrialState.COMPLETE, TrialState.FAIL)
                and int(t.user_attrs.get(GENERATION, 0)) <= verdict.generation]
        _copy(study, kept, args.copy_to, rule, verdict)
        print(f"copied {len(kept)} trials (generations 0–{verdict.generation}) to study {args.study!r} in "
              f"{args.copy_to}; next: ermrl select --study {args.study} --storage {args.copy_to}")
    return 0


def _projection(projection, config) -> dict | None:
    """Prints where the rule would hold at the spreads' recent rates, against the study's trial limit; returns it
    for convergence.json."""
    if projection is None:
        return None
    summary = {"window": list(projection.window), "factors": projection.factors, "generation": None, "trials": None,
               "trial_limit": config.trials}
    if projection.generation is None:
        print(f"  {projection.describe()}: no projection of the stop")
        return summary
    generation = math.ceil(projection.generation)
    trials = (generation + 1) * config.generation_size
    limit = (f"beyond the study's limit of {config.trials:,} trials, where it stops unconverged" if trials > config.trials
             else f"within the study's limit of {config.trials:,} trials")
    print(f"  {projection.describe()}, {trials:,} trials: {limit} (a log-linear fit per parameter; a trend, not a "
          "promise)")
    return {**summary, "generation": generation, "trials": trials}


def _history(history: dict[int, float | None]) -> dict[str, int | None]:
    """Prints the projection as it was made at each of the last generations; returns {generation: projection}."""
    said = {g: None if p is None else math.ceil(p) for g, p in history.items()}
    if len(said) > 1:
        cells = ", ".join("not shrinking" if p is None else f"{p:,}" for p in said.values())
        print(f"  the same projection made at generations {min(said)}–{max(said)}: {cells} (it moves with the mean; "
              "read it as a range)")
    return {str(g): p for g, p in said.items()}


def _correlations(trials, config, window) -> dict:
    """Prints Spearman's ρ of fitness against each parameter over the projection's generations; returns them."""
    from ermrl.evolution import convergence

    rho = convergence.fitness_correlations(trials, config.space, tuple(window))
    if rho:
        cells = ", ".join(f"{name} {r:+.2f} (p {p:.2g})" for name, (r, p) in rho.items())
        print(f"  fitness against each parameter over generations {window[0]}–{window[1]} (Spearman's ρ): {cells}")
    return {name: {"rho": r, "p": p} for name, (r, p) in rho.items()}


def _check_copy_target(url: str, name: str) -> None:
    """ConfigError when ``url`` already holds study ``name`` (nothing is written)."""
    import optuna

    from ermrl.evolution.study import check_writable, make_storage, storage_file

    path = storage_file(url)
    if path is not None and not path.exists():
        check_writable(url)
        return
    names = [s.study_name for s in optuna.get_all_study_summaries(make_storage(url, heartbeat=None))]
    if name in names:
        raise ConfigError(f"{url} already holds a study {name!r}; give --copy-to another storage")
    check_writable(url)


def _copy(study, trials, url: str, rule, verdict) -> None:
    """A new study ``study.study_name`` in ``url`` with ``study``'s record and ``trials``, marked converged by ``rule``."""
    from ermrl.evolution import convergence
    from ermrl.evolution.study import copy_trials

    convergence.record(copy_trials(study, trials, url), rule, verdict)
