"""``ermrl experiment list|run``: the paper's experiments by name."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from ermrl.cli import options
from ermrl.errors import ConfigError


if TYPE_CHECKING:
    from ermrl.experiments.registry import Scale


def add_parser(sub, formatter) -> None:
    from ermrl.experiments.runner import TestBudget  # lazily, like the options' dataclasses

    p = sub.add_parser("experiment", help="the paper's experiments by name: list them, or run one at a scale",
                       description="`ermrl experiment list` names every experiment of the paper and its appendix; "
                                   "`ermrl experiment run NAME --scale smoke|small|medium|converged|paper` runs its evolutions, "
                                   "selections, test phases and one combined report. Rerunning resumes.",
                       formatter_class=formatter)
    esub = p.add_subparsers(dest="experiment_command", required=True, metavar="list|run")
    lst = esub.add_parser("list", help="name every experiment, its studies and claims", formatter_class=formatter)
    lst.add_argument("--config", type=options.path, default=None, help=argparse_hidden())
    run = esub.add_parser("run", help="run (or resume) one experiment", formatter_class=formatter)
    run.add_argument("name", help="experiment name (see `ermrl experiment list`)")
    run.add_argument("--scale", default="small", choices=["smoke", "small", "medium", "converged", "paper"],
                     help="budgets: smoke (seconds a study, for tests), small (a first answer here), medium (the "
                          "paper's trial budget, 60 trials), converged (the paper's trial budget until CMA-ES has "
                          "converged, at most 900 trials), paper (`ermrl experiment list` gives each one's numbers)")
    run.add_argument("--only", nargs="+", default=(), metavar="STUDY", help="run only these studies of the experiment")
    options.sets(run.add_argument("--storage", type=options.storage, default=None,
                                  help="Optuna storage URL or journal file for every study (default a journal file "
                                       "in the folder)"), "storage_url")
    run.add_argument("--out", type=options.path, default=None, help="folder (default runs/experiments/NAME-SCALE)")
    run.add_argument("--baselines", type=options.path, default=None, metavar="TABLE",
                     help="baselines table for studies over several envs (default runs/baselines.json over the shipped one)")
    run.add_argument("--baseline-store", type=options.path, default=None, metavar="DIR", help=options.BASELINE_STORE_HELP)
    run.add_argument("--no-estimate", action="store_true", help="do not measure env step costs for the estimate")
    for flag, field, kwargs in (("--test-seeds", "seeds", {"type": int, "metavar": "N"}),
                                ("--test-timesteps", "timesteps", {"type": int, "metavar": "N"}),
                                ("--test-learning-rates", "learning_rates",
                                 {"type": float, "nargs": "+", "metavar": "RATE"}),
                                ("--test-agents-per-run", "agents_per_run", {"type": int, "metavar": "N"})):
        options.Option(flag, TestBudget, field, kwargs=kwargs).add_to(run)
    options.refuse_renamed(run, "--test-lrs", "--test-learning-rates", "ER-MRL's learning rates in every test phase")
    options.add_options(run, "env", "stop", skip=("--timesteps",))
    options.add_config_option(run)
    run.add_argument("--quiet", action="store_true", help="no progress display")


def argparse_hidden():
    import argparse

    return argparse.SUPPRESS


def run_command(args) -> int:
    from ermrl.experiments import registry

    if args.experiment_command == "list":
        for e in registry.EXPERIMENTS.values():
            print(f"{e.name}: {e.title}")
            print(f"    paper: {e.paper}; claims {', '.join(e.claims)}")
            print(f"    studies: {', '.join(_study_label(s) for s in e.studies)}")
        print("scales: " + "; ".join(f"{s.name} = {s.description}" for s in registry.SCALES.values()))
        return 0
    return _run(args)


def _count(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun`` in the number it takes: "1 study", "2 studies"."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


def _study_label(spec) -> str:
    """A study's name, with the floor of its trial budget where it has one."""
    floor = spec.min_trial_timesteps
    return f"{spec.name} (trials of at least {floor // 1000}k steps)" if floor else spec.name


def _run(args) -> int:
    import time

    import optuna

    from ermrl import envs, storage
    from ermrl.cli.common import bars, busy_note
    from ermrl.evolution.study import check_writable, make_storage, shown_url
    from ermrl.experiments import registry, runner

    stop_at = None if args.stop_after is None else time.time() + args.stop_after  # from the command's start
    experiment, scale = registry.get(args.name), registry.get_scale(args.scale)
    budget = runner.TestBudget(args.test_seeds, args.test_timesteps,
                               None if args.test_learning_rates is None else tuple(args.test_learning_rates),
                               args.test_agents_per_run)
    names = {s.name for s in experiment.studies}
    unknown = [n for n in args.only if n not in names]
    if unknown:
        import difflib

        close = difflib.get_close_matches(unknown[0], names, n=1)
        hint = f"; did you mean {close[0]}?" if close else ""
        raise ConfigError(f"experiment {experiment.name} has no study {unknown[0]!r}; its studies: "
                          f"{', '.join(sorted(names))}{hint}")
    folder = storage.check_folder(args.out or runner.experiment_dir(experiment, scale))
    if args.baseline_store is not None:
        storage.check_folder(args.baseline_store, "--baseline-store")
    plans = [p for p in runner.plan(experiment, scale, folder, args.backend, args.env_workers, budget, args.env_threads,
                                    args.processes)
             if not args.only or p.spec.name in args.only]
    table = None
    if any(p.config.normalized for p in plans):  # a damaged table fails now, not after the first studies
        from ermrl.experiments import baselines

        table = baselines.load_table(storage.check_file(args.baselines or baselines.default_table(), "--baselines",
                                                        "baselines.json"))
    for env_id in sorted({e for p in plans for e in p.config.env_ids + tuple(t.env_id for t in p.tests if t.env_id)}):
        envs.describe(env_id, args.backend)  # every env exists and its simulator is installed, before any work
    url = args.storage or runner.default_storage(folder)
    check_writable(url)
    make_storage(url)
    done, left, unselected, paces = {}, {}, {p.study for p in plans}, []
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    for p in plans:
        try:
            study = optuna.load_study(study_name=p.study, storage=make_storage(url))
            done[p.study] = runner.trials_done(p, study)
            left[p.study] = runner.tests_left(p, study)
            if not runner.selection_left(p, study):
                unselected.discard(p.study)
            paces += [line] if (line := pace_line(p, study)) else []
        except KeyError:
            pass
    print(f"experiment {experiment.name} at {scale.name} scale: {_count(len(plans), 'study', 'studies')} in {folder} "
          f"(storage {shown_url(url)})")
    if not args.no_estimate:
        lines, seconds = estimate_lines(plans, scale, done, left, unselected, args.baseline_store, budget, table)
        print("\n".join(lines + paces))
        if seconds >= 60 and (note := busy_note()):
            print(note)

    progress, close = bars(args.quiet)
    try:
        report = runner.run_experiment(experiment, scale, folder, url, args.backend, args.env_workers, tuple(args.only),
                                       print, progress, args.baselines, budget, args.baseline_store,
                                       args.env_threads, args.processes, stop_at)
    finally:
        close()
    print(f"report: {report.resolve()}")
    return 0


def estimate_lines(plans: list, scale: Scale, done: dict[str, int], left: dict[str, list],
                   unselected: set[str], baseline_store, budget, table) -> tuple[list[str], float]:
    """The time estimate printed before an experiment runs, and its seconds (the likelier ones, at a scale that
    stops at convergence): ``done`` and ``left`` are each study's completed trials and remaining test phases."""
    import dataclasses

    from ermrl.experiments import registry, runner

    finished = sum(len(p.tests) - len(left.get(p.study, p.tests)) for p in plans)
    seconds = runner.estimate_seconds(plans, done, left, baseline_store, budget.agents_per_run, unselected, table)
    lines = [f"estimated time: {seconds / 60:.0f} min (rough: nominal throughput, "
             f"{_count(sum(done.values()), 'trial')} and {_count(finished, 'test phase')} already done)"
             + (" if every study runs to its trial limit" if scale.until_converged else "")]
    if scale.until_converged and any(done.get(p.study, 0) < registry.CONVERGED_TRIALS for p in plans):
        typical = [dataclasses.replace(p, config=dataclasses.replace(
            p.config, trials=min(p.config.trials, registry.CONVERGED_TRIALS))) for p in plans]
        seconds = runner.estimate_seconds(typical, done, left, baseline_store, budget.agents_per_run, unselected,
                                          table)
        lines.append(f"  about {seconds / 60:.0f} min if each study converges after about "
                     f"{registry.CONVERGED_TRIALS} trials, as the paper's 900-trial CartPoleNoVel study did")
        if any(p.spec.reservoirs > 1 for p in plans):
            lines.append("  (a study of 2 or more reservoirs searches 6 or more parameters and may not converge "
                         "before its trial limit; `ermrl convergence` projects a running study)")
    return lines, seconds


def pace_line(p, study) -> str | None:
    """For a study still evolving with a generation completed, its remaining evolution at the pace of its last
    generation (as recorded in the study, on whatever machine ran it), and, at a scale that stops at convergence,
    where the trend of CMA-ES's spread (`ermrl convergence`) puts the stop, by the later half of its generations and,
    once that is longer, by the last :data:`~ermrl.evolution.convergence.RECENT_WINDOW`; None for any other study."""
    import math

    from optuna.trial import TrialState

    from ermrl.evolution import convergence
    from ermrl.evolution.generations import duration_text, generation_seconds

    trials = study.get_trials(deepcopy=False)
    size, limit = p.config.generation_size, p.config.trials
    done = sum(t.state == TrialState.COMPLETE for t in trials)
    took = generation_seconds(trials, size)
    if took is None or done >= limit:
        return None
    left = math.ceil((limit - done) / size)
    line = (f"  {p.study}: {duration_text(took)} a generation (its last one): {left} more to its trial limit, "
            f"about {duration_text(left * took)}")
    if p.until_converged is None or p.config.sampler != "cmaes":
        return line
    verdict = convergence.judge(study, p.config.space, size, p.until_converged, trials)
    projection = None if verdict.generation is not None else convergence.project(verdict.spread, p.until_converged)
    if projection is None:
        return line
    recent = convergence.recent_projection(verdict.spread, p.until_converged)
    if recent is not None:  # the later half can average over a stretch where the spread widened
        at = "not shrinking" if recent.generation is None else f"generation {math.ceil(recent.generation):,}"
        recent_text = f" (the trend of its last {convergence.RECENT_WINDOW} generations: {at})"
    else:
        recent_text = ""
    if projection.generation is None:
        return line + ("; its spread is not shrinking (`ermrl convergence`), so it will likely run to that limit"
                       + recent_text)
    stop = math.ceil(projection.generation)  # the last generation it trains
    if (stop + 1) * size >= limit:
        return line + (f"; the trend of its spread (`ermrl convergence`) puts the stop near generation {stop:,}, "
                       f"beyond that limit{recent_text}")
    more = max(stop + 1 - done // size, 0)
    return line + (f"; the trend of its spread (`ermrl convergence`) puts the stop near generation {stop:,}, "
                   f"{more} more, about {duration_text(more * took)}{recent_text}")
