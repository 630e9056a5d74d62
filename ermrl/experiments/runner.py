"""Runs a named experiment: for each of its studies, the baselines it needs, the evolution, the selection of Φ*
and the test phases; then one combined report. Every step resumes: a rerun continues the studies and skips
selections and test phases that are done with the same settings.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import time
from pathlib import Path
from typing import Callable

from ermrl import envs, storage
from ermrl.agent import AgentConfig
from ermrl.errors import ConfigError, OutOfTime
from ermrl.evolution import record as study_record
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.convergence import Convergence
from ermrl.evolution.search_space import SearchSpace
from ermrl.experiments.evaluation import MAX_TEST_SEEDS, TestConfig, baseline_files, recorded_test
from ermrl.experiments.registry import Experiment, Scale, StudySpec
from ermrl.ppo.config import SB3_DEFAULTS
from ermrl.reservoir import ReservoirSpec
from ermrl.training import TrainConfig
from ermrl.training.config import MAX_TIMESTEPS

JAX_RATE = 40_000.0
"""Nominal agent-steps/s of the JAX backend on 2 cores at a generation's population size (docs/benchmarks.md)."""
HOST_LOOP_RATE = 45_000.0
"""Agent-steps/s of the host loop with the physics taken out (the per-step JAX calls and the PPO update): 48k
measured on HalfCheetah-v5 with 21 agents on 2 cores (docs/benchmarks.md)."""
WEIGHT_S = 0.2e-9
"""Seconds per agent-step for each recurrent weight beyond a 100-unit reservoir's. Every step reads the whole
(units, units) W of every agent from memory, so 1000 units step ≈ 8× slower than 100 on a quiet machine
(docs/benchmarks.md, "Reservoir size": 1/4,375 − 1/34,269 s over 1000² − 100² weights). The nominal rates are
those of 100-unit reservoirs."""


EVOLUTION_SNAPSHOTS = "evolution.partial"
"""The folder, in the experiment's, of the snapshots of the generations in training (``WorkerConfig.snapshots``):
a stopped run, rerun, continues its generation where the last snapshot (every 5 minutes) left it."""


@dataclasses.dataclass(frozen=True)
class StudyPlan:
    """One study of an experiment at one scale, with everything needed to run it."""

    spec: StudySpec
    study: str
    """The Optuna study name."""
    run_dir: Path
    config: EvolveConfig
    tests: tuple[TestConfig, ...]
    select_top: int = 0
    select_seeds: int = 0
    """Selection after the evolution: the top ``select_top`` trials, each re-evaluated on ``select_seeds`` new seeds
    at the evolution's budget (the scale's values)."""
    until_converged: Convergence | None = None
    """The scale's convergence rule: the evolution also stops once CMA-ES has converged by it."""


@dataclasses.dataclass(frozen=True)
class TestBudget:
    """Overrides of every test phase of a run (``--test-seeds``, ``--test-timesteps``, ``--test-learning-rates``);
    None keeps the scale's or the study's value. They change the test phases only, never the studies' stored
    configs, so a rerun with other values keeps the evolutions and selections and redoes only the test phases."""

    seeds: int | None = None
    """New seeds per model in every test phase; None: the scale's (smoke 1, small 5, paper 10)."""
    timesteps: int | None = None
    """Env steps per agent in every test phase, the long ones (LunarLander) included; None: the scale's."""
    learning_rates: tuple[float, ...] | None = None
    """ER-MRL's learning rates in every test phase, one model each; None: the study's (e.g. 3e-4 1e-4 5e-5).
    The PPO baselines keep the study's rate (SB3's default, 3e-4)."""
    agents_per_run: int | None = None
    """Train each test model in groups of at most N agents (a seed at one learning rate), each kept when it
    finishes, so that a stop loses one group at most: for models that take hours (LunarLander at 3M).
    Results are the same up to rounding; None: all agents of a model at once (the fastest)."""

    def __post_init__(self):
        if self.seeds is not None and self.seeds < 1:
            raise ConfigError(f"`seeds` must be >= 1, got {self.seeds}", owner=type(self))
        if self.seeds is not None and self.seeds > MAX_TEST_SEEDS:
            raise ConfigError(f"`seeds` must be <= {MAX_TEST_SEEDS:,} (the paper tests on 10), got {self.seeds}",
                              owner=type(self))
        if self.timesteps is not None and self.timesteps < 1:
            raise ConfigError(f"`timesteps` must be >= 1, got {self.timesteps}", owner=type(self))
        if self.timesteps is not None and self.timesteps > MAX_TIMESTEPS:
            raise ConfigError(f"`timesteps` must be <= {MAX_TIMESTEPS:,}, got {self.timesteps}", owner=type(self))
        if self.learning_rates is not None and not self.learning_rates:
            raise ConfigError("`learning_rates` needs at least one learning rate (e.g. 1e-4)", owner=type(self))
        if self.agents_per_run is not None and self.agents_per_run < 1:
            raise ConfigError(f"`agents_per_run` must be >= 1, got {self.agents_per_run}", owner=type(self))
        for i, rate in enumerate(self.learning_rates or ()):
            if not 0 < rate < 1:
                raise ConfigError(f"`learning_rates`: learning rate {rate:g} is outside (0, 1); the paper uses 3e-4 "
                                  "or 1e-4", owner=type(self))
            if rate in self.learning_rates[:i]:
                raise ConfigError(f"`learning_rates` gives {rate:g} twice; give each learning rate once",
                                  owner=type(self))


def experiment_dir(experiment: Experiment, scale: Scale, root: Path = Path("runs") / "experiments") -> Path:
    return root / f"{experiment.name}-{scale.name}"


WEAK_ADVICE = "give the study longer trials (a larger `scale`) or leave it out (`only`)"
"""What to do when a study's PPO baseline does not beat a random agent at its trial budget."""


def default_storage(folder: Path) -> str:
    """A journal file: text, append-only, safe to kill at any point, and small enough to commit."""
    return f"journal:{folder / 'studies.log'}"


def plan(experiment: Experiment, scale: Scale, folder: Path, backend: str = "auto",
         env_workers: int | str = "auto", budget: TestBudget = TestBudget(), env_threads: int | str = "auto",
         processes: int = 1) -> list[StudyPlan]:
    """Every study of ``experiment`` at ``scale``, its test phases at ``budget``'s overrides of the scale's.
    ``backend``, ``env_workers``, ``env_threads`` and ``processes`` go to every study's TrainConfig."""
    plans = []
    for spec in experiment.studies:
        agent = AgentConfig(reservoirs=spec.reservoirs, spec=ReservoirSpec(units=spec.units),
                            observed_units=spec.observed_units)
        ppo = dataclasses.replace(SB3_DEFAULTS, learning_rate=spec.evolve_learning_rate)
        trial_steps = scale.timesteps if scale.wiring_only else max(scale.timesteps, spec.min_trial_timesteps)
        train = TrainConfig(env_id=spec.envs[0], total_timesteps=trial_steps, agent=agent, ppo=ppo,
                            backend=backend, env_workers=env_workers, env_threads=env_threads, processes=processes)
        config = EvolveConfig(train=train, space=SearchSpace(spec.reservoirs, fixed_iss=spec.fixed_iss),
                              trials=scale.trials, seeds=scale.seeds, popsize=scale.popsize,
                              envs=spec.envs if len(spec.envs) > 1 else ())
        steps = budget.timesteps or (scale.long_test_timesteps if spec.long_test else scale.test_timesteps)
        tests = tuple(TestConfig(seeds=budget.seeds or scale.test_seeds, timesteps=steps,
                                 learning_rates=budget.learning_rates or spec.learning_rates,
                                 baseline_learning_rate=spec.baseline_learning_rate,
                                 env_id=None if (e,) == spec.envs else e, auc_steps=min(300_000, steps))
                      for e in spec.tested_on)
        name = f"{experiment.name}-{scale.name}-{spec.name}"
        plans.append(StudyPlan(spec, name, folder / spec.name, config, tests, scale.select_top, scale.select_seeds,
                               scale.until_converged))
    return plans


@functools.lru_cache(maxsize=None)
def _rate(env_id: str, backend: str) -> float:
    """Rough agent-steps/s of ``env_id`` here: nominal on JAX, from a measured env step on the host backends,
    measured once per process, so that the estimates a command prints are at one rate."""
    resolved = envs.resolve_backend(env_id, backend)
    if resolved == "jax":
        return JAX_RATE
    from ermrl.envs import host_backend

    if resolved == "mujoco":
        step = host_backend.batched_step_seconds(envs.describe(env_id, backend))
        return 1.0 / (step + 1.0 / HOST_LOOP_RATE)
    step = host_backend.step_seconds(envs.describe(env_id, backend))
    return min(2.0 / (step + 150e-6), JAX_RATE / 3)  # 2 cores; ~0.15 ms of JAX and IPC per step


COMPILE_S = 60.0  # compiles of a study with work left: evolution, selection and the test models (15 s each)


def reservoir_seconds(agent) -> float:
    """Extra seconds per agent-step of ``agent``'s (an AgentConfig) reservoirs over 100-unit ones."""
    return WEIGHT_S * agent.reservoirs * max(agent.spec.units ** 2 - 100 ** 2, 0)


def trials_done(p: StudyPlan, study) -> int:
    """The study's completed trials, or ``p.config.trials`` once it has converged by the plan's rule (its
    evolution is then done)."""
    from optuna.trial import TrialState

    from ermrl.evolution import convergence

    done = len(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)))
    if done < p.config.trials and p.until_converged is not None and p.config.sampler == "cmaes":
        verdict = convergence.judge(study, p.config.space, p.config.generation_size, p.until_converged)
        if verdict.generation is not None:
            return p.config.trials
    return done


def selection_left(p: StudyPlan, study) -> bool:
    """Whether the study's selection is still to run: none stored, or one of other trials (the evolution went on
    since) or another number of seeds."""
    from ermrl.evolution.selection import recorded_selection

    return study is None or recorded_selection(study, p.select_top, p.select_seeds) is None


def tests_left(p: StudyPlan, study) -> tuple[TestConfig, ...]:
    """The test phases of ``p`` not yet written for the study's current Φ* (all of them before a selection)."""
    from ermrl.evolution.selection import load_selection
    from ermrl.evolution.study import ATTR
    from ermrl.experiments.evaluation import test_dir

    sel = load_selection(study) if study is not None else None
    if sel is None:
        return p.tests
    return tuple(t for t in p.tests
                 if not _test_done(test_dir(p.run_dir, study.user_attrs[ATTR], t.env_id), t, sel.winner))


def estimate_seconds(plans: list[StudyPlan], done: dict[str, int] | None = None,
                     left: dict[str, tuple[TestConfig, ...]] | None = None, store: Path | None = None,
                     agents_per_run: int | None = None, unselected: set[str] | None = None,
                     table=None) -> float:
    """The experiment's remaining time, from nominal rates, the trials already completed (``done``: study name ->
    count), the studies whose selection is still to run (``unselected``: names, see :func:`selection_left`;
    default those with trials left) and the test phases still to run (``left``: study name -> :func:`tests_left`;
    default all). With a baseline ``store`` (``--baseline-store``), a PPO baseline already there costs nothing, and
    one that several test phases share is counted once; without, every test phase trains its own. With the
    baselines ``table`` (a BaselineTable), a study over several envs not yet started (absent from ``done``) also
    pays for the vanilla PPO fitness its normalization needs where the table lacks it, once per env and budget
    (the random agent's 100 episodes are not counted: seconds)."""
    from ermrl.experiments.baselines import ppo_settings

    done, left = done or {}, left or {}
    if unselected is None:
        unselected = {p.study for p in plans if done.get(p.study, 0) < p.config.trials}
    rates: dict[str, float] = {}
    total = 0.0
    counted: set[Path] = set()
    normalizing: set[tuple] = set()
    for p in plans:
        c = p.config
        if table is not None and c.normalized and p.study not in done:
            lr, settings = c.train.ppo.learning_rate, ppo_settings(c.train.ppo)
            for env_id in c.env_ids:
                key = (env_id, c.train.total_timesteps, c.seeds, lr, repr(settings))
                if key not in normalizing and table.ppo(*key[:4], settings) is None:
                    normalizing.add(key)
                    rate = rates.setdefault(env_id, _rate(env_id, c.train.backend))
                    total += c.seeds * c.train.total_timesteps / rate
        extra = reservoir_seconds(c.train.agent)  # ER-MRL agents only; PPO baselines have no reservoir
        remaining = max(c.trials - done.get(p.study, 0), 0) * c.seeds
        if p.study in unselected:
            remaining += p.select_top * p.select_seeds
        for env_id in c.env_ids:
            rate = rates.setdefault(env_id, _rate(env_id, c.train.backend))
            total += remaining * c.train.total_timesteps * (1 / rate + extra)
        for t in left.get(p.study, p.tests):
            env_id = t.env_id or c.env_ids[0]
            rate = rates.setdefault(env_id, _rate(env_id, c.train.backend))
            files = baseline_files(c, t, store if store is not None else Path("."), agents_per_run)
            if store is not None:
                files = [f for f in files if f not in counted and not f.exists()]
                counted.update(files)
            total += t.seeds * t.timesteps * (len(t.learning_rates) * (1 / rate + extra) + len(files) / rate)
    busy = sum(1 for p in plans if p.study in unselected or left.get(p.study, p.tests))
    return total + COMPILE_S * busy


def _check_time(stop_at: float | None, what: str) -> None:
    """OutOfTime when ``stop_at`` has passed, before ``what`` starts."""
    if stop_at is not None and time.time() >= stop_at:
        raise OutOfTime(f"stopped before {what}: the time limit has passed; rerun the same command to continue")


def run_experiment(experiment: Experiment, scale: Scale, folder: Path, storage_url: str | None = None,
                   backend: str = "auto", env_workers: int | str = "auto", only: tuple[str, ...] = (),
                   log: Callable[[str], None] = print, progress: Callable | None = None,
                   baselines_table: Path | None = None, budget: TestBudget = TestBudget(),
                   baseline_store: Path | None = None, env_threads: int | str = "auto", processes: int = 1,
                   stop_at: float | None = None) -> Path:
    """Runs (or resumes) every study of ``experiment`` (or those named in ``only``); returns the report's path.
    Studies over several envs take their constants from ``baselines_table`` (default runs/baselines.json over
    the shipped table), computing the missing ones first. ``budget`` overrides the test phases' budgets; a test
    phase stopped midway keeps its finished models for the rerun (:mod:`ermrl.experiments.checkpoints`), and with
    ``baseline_store`` the PPO baselines are shared with other test phases (:mod:`ermrl.experiments.baseline_models`).
    With ``stop_at`` (a ``time.time()``), :class:`~ermrl.errors.OutOfTime` once an evolution's next generation
    would not end by then (``WorkerConfig.stop_at``), or when a selection or test phase would start after it; one
    already started runs to its end."""
    import optuna

    from ermrl.analysis.experiment_report import write_experiment_report
    from ermrl.evolution import convergence
    from ermrl.evolution.evolve import Member, evolve_together, make_trainers, shared_envs
    from ermrl.evolution.selection import load_selection, select
    from ermrl.evolution.study import ATTR, make_sampler, open_study
    from ermrl.evolution.worker_config import WorkerConfig
    from ermrl.experiments import baseline_runs, baselines, checkpoints
    from ermrl.experiments.evaluation import run_test_phase, test_dir

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    plans = [p for p in plan(experiment, scale, folder, backend, env_workers, budget, env_threads, processes)
             if not only or p.spec.name in only]
    url = storage_url or default_storage(folder)
    opened: dict[str, tuple] = {}

    def prepare(p: StudyPlan) -> tuple[EvolveConfig, object]:
        """The plan's config (with its baselines: computed first when missing) and its opened study."""
        if p.study not in opened:
            config = p.config
            if config.normalized:
                # smoke budgets are too short for PPO to beat a random agent: it checks the wiring, not the science
                config = baseline_runs.with_baselines(config, baselines_table, url, p.study, log, progress,
                                                      allow_weak=scale.wiring_only, advice=WEAK_ADVICE)
            study = open_study(url, p.study, make_sampler(config.sampler, config.generation_size, config.sampler_seed),
                               study_record.encode_study_record(config))
            stored = study_record.decode_study_record(study.user_attrs[ATTR])
            opened[p.study] = (dataclasses.replace(config, baselines=stored.baselines), study)
        return opened[p.study]

    for i, p in enumerate(plans):
        start = time.perf_counter()
        log(f"[{i + 1}/{len(plans)}] {p.study}: evolve on {', '.join(p.config.env_ids)} ({p.config.trials} trials × "
            f"{p.config.seeds} seeds × {p.config.train.total_timesteps:,} steps, {p.spec.reservoirs} reservoir(s))")
        config, study = prepare(p)
        if trials_done(p, study) < config.trials:  # with every later study still evolving on one of its envs alike
            group = [q for q in plans[i:] if q is p or (shared_envs(q.config, p.config)
                                                         and trials_done(q, prepare(q)[1]) < q.config.trials)]
            if len(group) > 1:
                log(f"    evolving {len(group)} studies together, one population per env: "
                    f"{', '.join(q.spec.name for q in group)}")
            # no bar for a finished evolution: entering one prints "compiling" where nothing trains
            bar = progress(f"evolve {'+'.join(q.spec.name for q in group)}") if progress else None
            evolve_together([Member(prepare(q)[1], prepare(q)[0], WorkerConfig(until_converged=q.until_converged,
                                                                                snapshots=folder / EVOLUTION_SNAPSHOTS,
                                                                                stop_at=stop_at))
                             for q in group], make_trainers(*(prepare(q)[0] for q in group)),
                            (lambda g: bar(g.train) if g.train else None) if bar else None,
                            lambda line: log(f"    {line}"))
            with contextlib.suppress(OSError):  # left empty once every study's snapshots are removed
                (folder / EVOLUTION_SNAPSHOTS).rmdir()
        stopped = convergence.recorded(study, p.until_converged) if p.until_converged else None
        if stopped:
            log(f"    converged at generation {stopped['generation']} ({stopped['trials']} trials)")
        sel = load_selection(study)
        if selection_left(p, study):
            _check_time(stop_at, f"the selection of study {p.study!r}")
            sel = select(study, config, p.select_top, p.select_seeds, progress)
        log(f"    Φ* = trial {sel.winner} (selected among the top {len(sel.trials)} on {len(sel.seeds)} fresh seeds)")
        for t in p.tests:
            out = test_dir(p.run_dir, study.user_attrs[ATTR], t.env_id)
            where = f"    test on {t.env_id or config.env_ids[0]}"
            if _test_done(out, t, sel.winner, lambda s, where=where: log(f"{where}: {s}")):
                checkpoints.discard(out)  # left by a stop between writing the test phase and removing it
                log(f"{where}: done before, kept ({out})")
                continue
            _check_time(stop_at, f"the test phase of study {p.study!r} on {t.env_id or config.env_ids[0]}")
            rates = t.learning_rates or (config.train.ppo.learning_rate,)
            log(f"{where}: {t.seeds} seeds × {t.timesteps:,} steps, ER-MRL at learning rate"
                f"{'s' if len(rates) > 1 else ''} {', '.join(f'{rate:g}' for rate in rates)}")
            rows = run_test_phase(study, out, t, progress, log=lambda s, where=where: log(f"{where}: {s}"),
                                  agents_per_run=budget.agents_per_run, env_workers=env_workers,
                                  baseline_store=baseline_store, processes=processes)
            for r in rows:
                log(f"    test on {r['env_id']}: {r['model']}: final {r['final_mean']:.1f} ± {r['final_std']:.1f}"
                    if r["final_mean"] is not None else f"    test on {r['env_id']}: {r['model']}: all seeds diverged")
        from ermrl.analysis.report import write_report

        write_report(study, p.run_dir)
        log(f"    done in {time.perf_counter() - start:.0f} s")
    table = baselines.load_table(baselines_table)
    tested = {t.env_id or p.config.env_ids[0] for p in plans for t in p.tests}
    randoms = {e: r.mean_return for e in tested if (r := table.random(e)) is not None}
    return write_experiment_report(experiment, scale, plans, url, folder, randoms)


def _test_done(out: Path, test: TestConfig, winner: int, log: Callable[[str], None] | None = None) -> bool:
    """Whether ``out`` holds this test phase, for this Φ* and settings, finished. The saved settings are decoded
    first, so that fields added to TestConfig since they were written take their defaults, and fields renamed
    since are read under their current names, instead of forcing the test phase to be redone. A test phase whose
    summary.json or test_config.json is damaged (cut short, not what ermrl wrote) is not done: it is redone, and
    ``log`` tells why."""
    path = out / "test_config.json"
    if not (path.is_file() and (out / "summary.json").is_file()):
        return False
    problem = storage.test_summary_problem(out)
    try:
        saved = storage.read_json(path)
        if problem is None and not isinstance(saved, dict):
            problem = f"{path} is damaged or was not written by `ermrl test` (it holds no table of settings)"
    except ValueError as e:  # JSONDecodeError (cut short), UnicodeDecodeError (not text)
        problem = problem or (f"{path} is damaged or was not written by `ermrl test` "
                              f"({type(e).__name__}: {(str(e).strip().splitlines() or [''])[0]})")
    if problem is not None:
        if log is not None:
            log(f"{problem}; redoing this test phase")
        return False
    names = {f.name for f in dataclasses.fields(TestConfig)}
    try:  # recorded by an older version: its fields under their current names
        before = storage.from_dict(TestConfig, {k: v for k, v in recorded_test(saved).items() if k in names},
                                   "test_config")
    except ConfigError:
        return False
    return saved.get("phi_trial") == winner and before == test
