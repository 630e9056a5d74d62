"""``ermrl analyze hp-map|probe|context|fft|evaluate``: the HP map across studies, the probe of what a reservoir's
context holds, a saved agent's context and its rhythm, and saved agents' returns evaluated after training."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ermrl.cli import options
from ermrl.errors import ConfigError


def add_parser(sub, formatter) -> None:
    p = sub.add_parser("analyze", help="analyses: the HP map of several evolutions, the velocity probe",
                       description="`ermrl analyze hp-map STUDY [STUDY ...] --out FIG.png` draws the best Φ of "
                                   "several studies on spectral radius × leak rate (the paper's HP map); "
                                   "`ermrl analyze probe --env NOVEL_ID` measures how well a linear readout of "
                                   "the reservoir recovers the deleted velocities and predicts o_(t+k).",
                       formatter_class=formatter)
    asub = p.add_subparsers(dest="analyze_command", required=True, metavar="hp-map|probe|context|fft|evaluate")
    hp = asub.add_parser("hp-map", help="the top trials of several studies on sr × leak rate (log axes)",
                         description="Draw the --top best completed trials of each study on spectral radius × leak "
                                     "rate (log axes), one colour per env, circles for 1-reservoir studies and, in a "
                                     "second panel for 2-reservoir studies, circles for reservoir 1 and triangles for "
                                     "reservoir 2 (paper appendix, HP map). The points drawn go to a CSV beside the "
                                     "figure, and a leak-rate table (each study's median sr and leak rate, and a "
                                     "Mann–Whitney test of its leak rates against the other studies' of the same K) "
                                     "to a .md beside it, also printed.", formatter_class=formatter)
    hp.add_argument("studies", nargs="+", metavar="STUDY", help="study names, as given to or printed by `ermrl evolve`")
    options.sets(hp.add_argument("--storage", type=options.storage, default=None,
                                 help="Optuna storage URL or journal file holding every study (default: each "
                                      "study's sqlite in runs/STUDY)"), "storage_url")
    hp.add_argument("--top", type=int, default=30, help="best completed trials drawn per study")
    hp.add_argument("--out", type=options.path, required=True, metavar="FIG.png",
                    help="figure path (.png, .svg or .pdf); FIG.csv beside it holds the points drawn, FIG.md "
                         "the leak-rate table")
    options.add_config_option(hp)

    pr = asub.add_parser("probe", help="R² of a ridge readout of the reservoir: deleted velocities, o_(t+k)",
                         description="Feed a reservoir with (masked o_t, a_(t-1), r_(t-1)) from random-policy "
                                     "episodes of the full env, fit a ridge readout (scikit-learn) on 75%% of the "
                                     "episodes and report R² on the rest: for the deleted velocities and for the "
                                     "kept observation k = 1..5 steps ahead (paper appendix, Results analysis). Rows: "
                                     "the default Φ (sr 0.95, leak rate 0.5, iss 1), a memoryless reservoir (sr 1e-4, "
                                     "leak rate 1), "
                                     "each --phi, and each --study's Φ*.", formatter_class=formatter)
    pr.add_argument("--env", required=True, help="a NoVel env id, e.g. CartPoleNoVel-v1")
    pr.add_argument("--phi", nargs=3, type=float, action="append", default=[], metavar=("SR", "LEAK", "ISS"),
                    help="a 1-reservoir Φ to probe (repeatable)")
    pr.add_argument("--study", action="append", default=[], metavar="NAME",
                    help="probe this study's Φ* (the selected trial, else the best; repeatable)")
    options.sets(pr.add_argument("--storage", type=options.storage, default=None,
                                 help="Optuna storage URL or journal file of the studies (default: each study's "
                                      "sqlite in runs/STUDY)"), "storage_url")
    pr.add_argument("--units", type=int, default=100, help="units per reservoir")
    pr.add_argument("--episodes", type=int, default=300, help="random-policy episodes (a quarter held out)")
    pr.add_argument("--seed", type=int, default=0, help="seeds the episodes and the reservoir draw")
    pr.add_argument("--out", type=options.path, required=True, metavar="FIG.png",
                    help="figure path; FIG.md beside it holds the R² table")
    options.add_config_option(pr)

    cx = asub.add_parser("context", help="a saved agent's observation traces above its first reservoir units",
                         description="Run one deterministic episode of a saved ER-MRL agent and plot the observation "
                                     "traces above the first --units reservoir units (paper appendix, Fig. "
                                     "context-observation).", formatter_class=formatter)
    cx.add_argument("source", type=options.path, metavar="RUN", help="a run folder (its first saved agent) or an agent file")
    cx.add_argument("--out", type=options.path, default=None, metavar="FIG.png", help="figure (default RUN/context.png)")
    cx.add_argument("--units", type=int, default=20, help="reservoir units plotted")
    _episode_options(cx)

    ff = asub.add_parser("fft", help="spectra and rhythm score of saved agents' summed observation and context",
                         description="For every saved agent of each RUN (e.g. a test phase's ER-MRL and PPO "
                                     "folders), one deterministic episode: the rhythm score (fraction of spectral "
                                     "power near the dominant frequency) of the summed observation and of the summed "
                                     "policy input (the context; for PPO the observation). Prints a table, writes it "
                                     "beside the spectra figure (paper appendix, the CPG argument).",
                         formatter_class=formatter)
    ff.add_argument("sources", nargs="+", type=options.path, metavar="RUN", help="run folders or agents/ folders or agent files")
    ff.add_argument("--out", type=options.path, required=True, metavar="FIG.png",
                    help="spectra figure; FIG.md (table) and FIG.json (per agent) beside it")
    _episode_options(ff)

    ev = asub.add_parser("evaluate", help="saved agents' returns over fresh episodes, deterministic by default",
                         description="Run every saved agent of each RUN for --episodes episodes of its env (episode "
                                     "i reset with env seed --seed + i) with its deterministic action (the Gaussian "
                                     "mean, the argmax of the logits), as benchmarks such as rl-zoo's report a "
                                     "trained agent; --stochastic draws from the policy instead. Per RUN: the "
                                     "evaluation and the training score (final: the last 10 training episodes, the "
                                     "paper's fitness) over its agents, mean ± std and IQM [95%% CI], and their "
                                     "paired difference.", formatter_class=formatter)
    ev.add_argument("sources", nargs="+", type=options.path, metavar="RUN", help="run folders, agents/ folders or agent files")
    ev.add_argument("--episodes", type=int, default=10, help="evaluation episodes per agent")
    ev.add_argument("--stochastic", action="store_true", help="draw actions from the policy instead of its mode")
    ev.add_argument("--out", type=options.path, default=None, metavar="TABLE.md",
                    help="write the table here, and every agent's returns to TABLE.json beside it")
    _episode_options(ev)


def _episode_options(p) -> None:
    p.add_argument("--seed", type=int, default=0, help="env reset seed of the recorded episode")
    p.add_argument("--max-steps", type=int, default=None, help="stop the episode after this many steps")
    options.add_config_option(p)


def run_command(args) -> int:
    _check_numbers(args)
    return {"hp-map": cmd_hp_map, "probe": cmd_probe, "context": cmd_context, "fft": cmd_fft,
            "evaluate": cmd_evaluate}[args.analyze_command](args)


MAX_SEED = 2**31 - 1
MAX_COUNT = 100_000
"""The most episodes an analysis runs."""
MAX_UNITS = 10_000
"""The largest reservoir a probe draws (its (units, units) weights: 400 MB)."""
MAX_SCALE = 1e6
"""The largest spectral radius or input scaling a probe takes (float32 weights stay finite)."""


def _check_numbers(args) -> None:
    """One-line errors for the analyses' counts, seeds and Φ values, before any file is read."""
    if getattr(args, "seed", 0) < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    if getattr(args, "seed", 0) > MAX_SEED:
        raise ConfigError(f"--seed must be <= {MAX_SEED}, got {args.seed}")
    for flag in ("max_steps", "units", "episodes"):
        value = getattr(args, flag, None)
        if value is not None and value < 1:
            raise ConfigError(f"--{flag.replace('_', '-')} must be >= 1, got {value}")
        most = {"units": MAX_UNITS, "episodes": MAX_COUNT}.get(flag)
        if most is not None and value is not None and value > most:
            raise ConfigError(f"--{flag} must be <= {most:,}, got {value}")
    for sr, lr, iss in getattr(args, "phi", ()):
        if not all(math.isfinite(v) and 0 < v <= MAX_SCALE for v in (sr, lr, iss)) or lr > 1:
            raise ConfigError(f"--phi {sr:g} {lr:g} {iss:g}: SR and ISS must be in (0, {MAX_SCALE:g}] and LR (the "
                              "leak rate) in (0, 1]")


def _load(name: str, storage: str | None):
    """Study ``name`` from ``storage`` (default: its sqlite in runs/NAME), without creating any file."""
    from ermrl.cli.common import storage_url
    from ermrl.evolution.study import load_study, storage_file

    url = storage_url(argparse.Namespace(study=name, storage=storage, out=None))
    file = storage_file(url)
    if file is not None and not file.exists():  # looking must not create a database
        raise ConfigError(f"no study {name!r}: {file} does not exist; run `ermrl evolve --study {name}` first "
                          "or pass --storage")
    return load_study(url, name)


def cmd_hp_map(args) -> int:
    import optuna

    from ermrl import storage
    from ermrl.analysis.hp_map import cross_study_hp_map, points_csv, summary_path

    if args.top < 1:
        raise ConfigError(f"--top must be >= 1, got {args.top}")
    if args.out.is_dir():
        raise ConfigError(f"--out {args.out} is a folder; give a figure path such as {args.out / 'hp_map.png'}")
    storage.check_file(args.out)  # before any work
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    studies = []
    for name in dict.fromkeys(args.studies):  # each study once, in the given order
        studies.append(_load(name, args.storage))
    path = cross_study_hp_map(studies, args.out, args.top)
    print(summary_path(path).read_text(encoding="utf-8"))
    print(f"wrote {path}, {points_csv(path)} and {summary_path(path)} (top {args.top} trials of {len(studies)} "
          f"stud{'ies' if len(studies) > 1 else 'y'})")
    return 0


def cmd_probe(args) -> int:
    import optuna

    from ermrl import storage
    from ermrl.evolution import record as study_record
    from ermrl.agent import Phi
    from ermrl.analysis import probe
    from ermrl.envs import masking
    from ermrl.evolution.selection import chosen_trial
    from ermrl.evolution.study import ATTR

    if args.units < 1 or args.episodes < 4:
        raise ConfigError(f"--units must be >= 1 and --episodes >= 4, got {args.units} and {args.episodes}")
    if args.out.is_dir():
        raise ConfigError(f"--out {args.out} is a folder; give a figure path such as {args.out / 'probe.png'}")
    storage.check_file(args.out)  # before any work
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    from ermrl import envs

    envs.describe(args.env, "host")  # an unknown id or a missing simulator, before any episode
    if not masking.parse(args.env)[1]:
        fix = f"use {masking.novel_id(args.env)!r}" if args.env in masking.VELOCITY_DIMS else \
            "NoVel ids are: " + ", ".join(map(masking.novel_id, masking.VELOCITY_DIMS))
        raise ConfigError(f"probe needs a NoVel env id whose velocities are deleted, got {args.env!r}; {fix}")
    rows: list[tuple[str, Phi]] = [("default Φ", probe.MEMORY), ("memoryless", probe.MEMORYLESS)]
    rows += [(f"Φ {i + 1}", Phi(*v)) for i, v in enumerate(args.phi)]
    for name in dict.fromkeys(args.study):
        study = _load(name, args.storage)
        config = study_record.decode_study_record(study.user_attrs[ATTR])
        if config.space.reservoirs and config.train.agent.spec.units != args.units:
            raise ConfigError(f"study {name!r} evolved {config.train.agent.spec.units}-unit reservoirs; "
                              f"pass --units {config.train.agent.spec.units}")
        trial, phi, _ = chosen_trial(study, config)
        rows.append((f"{name} Φ* (trial {trial.number})", phi))
    base_id, _ = masking.parse(args.env)
    rollouts = probe.collect(base_id, args.episodes, args.seed)
    results = [probe.probe(args.env, phi, units=args.units, seed=args.seed, label=label, rollouts=rollouts)
               for label, phi in rows]
    table = probe.probe_table(results)
    path = probe.plot_probe(results, args.out)
    storage.write_text(path.with_suffix(".md"), table)
    print(table, end="")
    print(f"wrote {path} and {path.with_suffix('.md')}")
    return 0


def _agents(source: Path) -> list[Path]:
    from ermrl import agent_files

    if source.is_file():
        return [source]
    if not source.is_dir():
        raise ConfigError(f"{source} does not exist; give a run folder or a saved agent file (.npz)")
    found = agent_files.find_agents(source)
    if not found:
        raise ConfigError(f"{source} holds no saved agent; train with --save-agents (the default) first")
    return found


def _check_renderer(agents: list[Path]) -> None:
    """A MUJOCO_GL that MuJoCo refuses, named before the agents' MuJoCo envs are made (an import error then)."""
    from ermrl import agent_files
    from ermrl.envs import masking
    from ermrl.envs.host_backend import check_mujoco_gl

    for path in agents:
        check_mujoco_gl(masking.parse(agent_files.read_agent(path)[0]["env_id"])[0])


def cmd_context(args) -> int:
    from ermrl import storage
    from ermrl.analysis.context import context_figure

    agents = _agents(args.source)
    _check_renderer(agents[:1])
    out = storage.check_file(args.out or (args.source if args.source.is_dir() else args.source.parent) / "context.png")
    path = context_figure(agents[0], out, args.seed, args.units, args.max_steps)
    print(f"wrote {path} ({agents[0]})")
    return 0


def cmd_fft(args) -> int:
    from ermrl import storage
    from ermrl.analysis.rhythm import compare_runs

    if args.out.is_dir():
        raise ConfigError(f"--out {args.out} is a folder; give a figure path such as {args.out / 'fft.png'}")
    storage.check_file(args.out)  # before any work
    sources = {str(s): _agents(s) for s in dict.fromkeys(args.sources)}
    _check_renderer([a for found in sources.values() for a in found])
    table, rows = compare_runs(sources, args.out, args.seed, args.max_steps)
    storage.write_text(args.out.with_suffix(".md"), table)
    storage.write_json(args.out.with_suffix(".json"), rows)
    print(table, end="")
    print(f"wrote {args.out.with_suffix('.png')}, {args.out.with_suffix('.md')} and {args.out.with_suffix('.json')}")
    return 0


def cmd_evaluate(args) -> int:
    from ermrl import storage
    from ermrl.analysis.policy_eval import evaluate_runs

    out = args.out if args.out is None else storage.check_file(args.out, example="evaluation.md")  # before any work
    sources = {str(s): _agents(s) for s in dict.fromkeys(args.sources)}
    _check_renderer([a for found in sources.values() for a in found])
    table, rows = evaluate_runs(sources, args.episodes, args.seed, not args.stochastic, args.max_steps,
                                log=lambda line: print(line, file=sys.stderr, flush=True))
    print(table, end="")
    if out is not None:
        storage.write_text(out, table)
        storage.write_json(out.with_suffix(".json"), rows)
        print(f"wrote {out} and {out.with_suffix('.json')}")
    return 0
