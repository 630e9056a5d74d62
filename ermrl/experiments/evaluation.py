"""The test phase (paper §3, "Evaluation"): Φ* trained on new seeds against the baselines.

Models, all with the evolution's agent and PPO settings:
- ER-MRL with Φ*, at one or several learning rates (trained as one population: the step size is traced);
- vanilla PPO on the same (masked) observation, a feedforward policy;
- PPO with full observations (the unmasked env), when the env is a NoVel variant;
- with ``recurrent_baseline``, PPO-LSTM on the same observation (the recurrent baseline, sb3-contrib
  RecurrentPPO's policy: :mod:`ermrl.ppo.recurrent`), at the PPO baselines' learning rate; JAX envs only.

Φ* is the study's selected trial when ``ermrl select`` ran (see :mod:`ermrl.evolution.selection`), else its
best trial, or any trial asked for. The test env may differ from the evolution's (paper §4.3, generalization):
the reservoirs get a new input matrix for that env's input size and Φ carries over.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable

import numpy as np
import optuna

from ermrl import agent_files, envs, model_labels, provenance, storage
from ermrl.agent import AgentConfig, Phi
from ermrl.analysis import statistics
from ermrl.envs import masking
from ermrl.errors import ConfigError
from ermrl.evolution import record as study_record
from ermrl.evolution.selection import chosen_trial
from ermrl.evolution.study import ATTR
from ermrl.experiments import baseline_models, checkpoints
from ermrl.training import Population, Results, Trainer, recurrent, snapshots

FIRST_TEST_SEED = 1000
"""Test seeds start here, away from the evolution's seeds 0, 1, 2, ... and selection's (new reservoirs,
policies, envs)."""


MAX_TEST_SEEDS = 10_000
"""The most seeds a test phase may train each model on."""


@dataclasses.dataclass(frozen=True)
class TestConfig:
    """One test phase."""

    seeds: int = 10
    """New seeds per model (the paper: 10)."""
    timesteps: int = 1_000_000
    """Env steps per agent (the paper: 1M, 3M for LunarLander)."""
    learning_rates: tuple[float, ...] = ()
    """PPO learning rates of the ER-MRL agents, one model each (the reference tested 3e-4, 1e-4 and 5e-5);
    empty: the evolution's."""
    baseline_learning_rate: float | None = None
    """Learning rate of the PPO baselines (the reference: 3e-4); None: the evolution's."""
    env_id: str | None = None
    """Env to test on; None: the evolution's (first) env. Another env tests generalization."""
    trial: int | None = None
    """Trial number whose Φ to test; None: the selected Φ* if ``ermrl select`` ran, else the best trial."""
    auc_steps: int | None = None
    """Also report the area under the curve over the first this many steps (e.g. 300k, where the paper's
    locomotion curves separate); None: the whole curve only."""
    recurrent_baseline: bool = False
    """Also train PPO-LSTM (the recurrent baseline: an LSTM policy trained end to end on the same observation)
    at the PPO baselines' learning rate; JAX envs only."""

    def __post_init__(self):
        if not 1 <= self.seeds <= MAX_TEST_SEEDS:
            raise ConfigError(f"`seeds` must be in 1..{MAX_TEST_SEEDS:,} (the paper tests on 10), got {self.seeds}",
                              owner=type(self))
        if self.timesteps < 1:
            raise ConfigError(f"`timesteps` must be >= 1, got {self.timesteps}", owner=type(self))
        baseline = () if self.baseline_learning_rate is None else (self.baseline_learning_rate,)
        for rate in self.learning_rates + baseline:
            if not 0 < rate < 1:
                raise ConfigError(f"learning rate {rate} is outside (0, 1); the paper uses 3e-4 or 1e-4")
        if self.trial is not None and self.trial < 0:
            raise ConfigError(f"`trial` must be a trial number >= 0, got {self.trial}", owner=type(self))
        if self.auc_steps is not None and self.auc_steps < 1:
            raise ConfigError(f"`auc_steps` must be >= 1, got {self.auc_steps}", owner=type(self))
        if self.env_id is not None and not self.env_id.strip():
            raise ConfigError("`env_id` is empty; give an env id, or leave `env_id` out to test on the evolution's env",
                              owner=type(self))


RENAMED_FIELDS = {"ermrl_lrs": "learning_rates", "ppo_lr": "baseline_learning_rate"}
"""TestConfig's fields under the names that older versions recorded them with (test_config.json, the settings of
an unfinished test phase): {old name: current name}."""


def recorded_test(saved: dict) -> dict:
    """A TestConfig as recorded (test_config.json, an unfinished test phase's settings), by older versions too:
    its fields under their current names (:data:`RENAMED_FIELDS`), the other keys as they are."""
    return {RENAMED_FIELDS.get(k, k): v for k, v in saved.items()}


def test_dir(run_dir: Path, record: dict, env_id: str | None) -> Path:
    """``run_dir/test`` on the evolution's env, ``run_dir/test-ENV`` on another one."""
    evolved_on = record.get("envs") or [record["env_id"]]
    return run_dir / "test" if env_id is None or (len(evolved_on) == 1 and env_id == evolved_on[0]) \
        else run_dir / f"test-{env_id}"


def summarize(label: str, kind: str, results: Results, auc_steps: int | None = None) -> dict:
    """Final score (each seed's fitness: the mean of its last 10 episodes) with mean ± std, IQM and its 95%
    stratified-bootstrap CI, the diverged seeds counted (never dropped silently), and the area under the
    curve (the curve's mean), over the whole run and, with ``auc_steps``, over its first steps."""
    fit = results.fitness()
    steps, curves = results.curves()
    with np.errstate(all="ignore"):
        auc = np.nanmean(curves, axis=1)
        early = np.nanmean(curves[:, steps <= auc_steps], axis=1) if auc_steps else None
    s = statistics.summarize(fit)
    row = {"model": label, "kind": kind, "env_id": results.env_id, "n_seeds": results.size,
           "learning_rate": float(results.learning_rate[0]), "timesteps": results.total_timesteps,
           "final_mean": s.mean, "final_std": s.std, "final_iqm": s.iqm, "final_iqm_low": s.iqm_low,
           "final_iqm_high": s.iqm_high, "diverged": s.n_diverged,
           "auc_mean": _nanstat(np.nanmean, auc), "auc_std": _nanstat(np.nanstd, auc),
           "per_seed": [None if not np.isfinite(v) else float(v) for v in fit]}
    if early is not None:
        row.update(auc_steps=auc_steps, auc_early_mean=_nanstat(np.nanmean, early),
                   auc_early_std=_nanstat(np.nanstd, early))
    return row


def _nanstat(fn, x) -> float | None:
    x = np.asarray(x, float)
    return float(fn(x)) if np.isfinite(x).any() else None


def run_test_phase(study: optuna.Study, out: Path, test: TestConfig,
                   progress: Callable[[str], Callable] | None = None, save_agents: bool = True,
                   log: Callable[[str], None] | None = None,
                   on_results: Callable[[str, object], None] | None = None,
                   agents_per_run: int | None = None, snapshot_every_s: float = 300.0,
                   env_workers: int | str | None = None, baseline_store: Path | None = None,
                   processes: int | None = None) -> list[dict]:
    """Trains the models and writes curves.csv, summary.json/.csv, test_config.json and test_phase.png/.svg
    into ``out`` (checked before any training, written all at once at the end: :func:`ermrl.storage.staged_folder`),
    and with ``save_agents`` every agent's final policy in ``out/agents/MODEL/seedS.npz`` (MODEL:
    ermrl, ermrl-learning-rate-RATE with several learning rates, ppo, ppo-full-observation, ppo-lstm). Returns one
    summary row per model (see :func:`summarize`), each ER-MRL row with its probability of improvement over every
    PPO baseline (PPO-LSTM included). An ER-MRL model's label names its learning rate and Φ
    (:mod:`ermrl.model_labels`).

    Each trained model is kept in ``out.partial/`` until ``out`` is written (:mod:`ermrl.experiments.checkpoints`):
    a rerun after a stop loads the models finished for the same settings and Φ* instead of training them again,
    telling ``log`` "kept MODEL from an earlier run"; the outputs are the same as those of an uninterrupted run.

    ``agents_per_run`` trains each model in groups of at most that many agents (a seed at one learning rate is
    one agent), one after another, each kept in ``out.partial/`` when it finishes: for a model longer than one
    machine's allocation (LunarLander at 3M steps), a stop then loses one group at most. Each agent trains as it
    would in the whole population (its own seed, reservoirs, policy and envs), to the bit (the update runs one
    agent at a time, :mod:`ermrl.training.programs`). None: every agent of a model at once,
    the fastest.

    While a model (or group) trains, its state is kept in ``out.partial/JOB.snapshot`` every ``snapshot_every_s``
    seconds (:mod:`ermrl.training.snapshots`): a rerun after a stop continues it from there, to the same results,
    telling ``log`` "resumed from ...".

    ``env_workers`` (host envs: 0, N or 'auto') and ``processes`` (``TrainConfig.processes``) override the
    evolution's settings; results do not depend on them.

    ``baseline_store`` (a folder): the PPO baselines are looked up there before training, and kept there once
    trained, so that another test phase with the same baseline (same env, seeds, budget and PPO settings, any Φ*)
    loads it instead of training it again (:mod:`ermrl.experiments.baseline_models`), telling ``log`` "reused
    MODEL from the baseline store (PATH)". None: every baseline is trained here.

    ``on_results(label, results)`` is called with each model's :class:`~ermrl.training.results.Results` (its
    ``test.seeds`` agents), e.g. to write TensorBoard logs of its learning curves and PPO diagnostics."""
    config = study_record.decode_study_record(study.user_attrs[ATTR])
    trial, phi, how = chosen_trial(study, config, test.trial)
    base, seeds, baseline_rate = _settings(config, test)
    envs.describe(base.env_id, config.train.backend)  # an unknown id fails before any training
    storage.check_folder(storage.check_rerun_folder(out, "test"))
    if env_workers is not None:
        base = dataclasses.replace(base, env_workers=env_workers)
    if processes is not None:
        base = dataclasses.replace(base, processes=processes)
    k = config.space.reservoirs
    rates = test.learning_rates or (config.train.ppo.learning_rate,)
    baselines = baseline_jobs(base, seeds, baseline_rate, test.recurrent_baseline)
    for _, _, train_config, _, _ in baselines:
        if train_config.ppo.model == "lstm":  # checked before any training: JAX envs only
            recurrent.check(train_config)

    labels = [model_labels.ermrl_label(rate, model_labels.phi_text(phi, k, trial.number)) for rate in rates]
    older = {labels[0]: model_labels.older_ermrl_labels(phi, k, trial.number, rates)}  # what older versions kept
    jobs = [("ER-MRL", base, Population.grid(phi, seeds, list(rates), k), labels)]
    folders = {label: "ermrl" if len(rates) == 1 else model_labels.ermrl_folder(rate)
               for label, rate in zip(labels, rates)}
    for kind, folder, train_config, population, baseline_labels in baselines:
        jobs.append((kind, train_config, population, baseline_labels))
        folders[baseline_labels[0]] = folder

    if agents_per_run is not None and agents_per_run < 1:
        raise ConfigError(f"`agents_per_run` must be >= 1, got {agents_per_run}", owner=run_test_phase)
    if baseline_store is not None:
        storage.check_folder(baseline_store, "`baseline_store`")
    partial, discarded = checkpoints.open_partial(out, {"test": storage.to_dict(test), "phi_trial": trial.number},
                                                  _recorded_settings)
    if discarded and log:
        log(f"discarded the models of an unfinished test phase with other settings ({partial})")
    curves, seed_map, rows, agents = {}, {}, [], []
    for kind, train_config, population, labels_of_job in jobs:
        name = folders[labels_of_job[0]] if len(labels_of_job) == 1 else "ermrl"
        shown = labels_of_job[0] if len(labels_of_job) == 1 else kind
        results = _trained(partial, name, labels_of_job, train_config, population, agents_per_run, shown,
                           progress, log, snapshot_every_s, baseline_store if kind != "ER-MRL" else None,
                           older.get(labels_of_job[0]))
        for m, label in enumerate(labels_of_job):
            part = results.select(np.arange(m * len(seeds), (m + 1) * len(seeds)))
            curves[label] = part.curves()
            seed_map[label] = part.seeds
            rows.append(summarize(label, kind, part, test.auc_steps))
            if on_results is not None:
                on_results(label, part)
            if save_agents:
                agents.append((folders[label], train_config, part, label))
    _add_improvement(rows)
    evolved_on = list(config.env_ids)
    for r in rows:
        r.update(evolved_on=evolved_on, phi_trial=trial.number, phi_choice=how)

    from ermrl.analysis.plots import learning_curves

    title = f"{base.env_id}: test phase, {test.seeds} new seeds"
    if evolved_on != [base.env_id]:
        title += f"\nΦ* evolved on {', '.join(evolved_on)}"
    with storage.staged_folder(out, stale=agent_files.AGENT_FILES) as stage:  # all or nothing: summary.json last
        for folder, train_config, part, label in agents:
            agent_files.write_agents(stage / agent_files.AGENTS_DIR / folder, train_config, part, label)
        storage.write_curves_csv(stage / "curves.csv", curves, seed_map)
        storage.write_json(stage / "test_config.json", {**dataclasses.asdict(test), "phi_trial": trial.number,
                                                        "phi_choice": how, "evolved_on": evolved_on,
                                                        "software": provenance.software()})
        learning_curves(curves, title, stage / "test_phase", ("png", "svg"))
        storage.write_test_summary(stage, rows)
    checkpoints.discard(out)
    return rows


def _recorded_settings(settings):
    """An unfinished test phase's settings as recorded, by older versions too: its TestConfig's fields under their
    current names (:func:`recorded_test`)."""
    if isinstance(settings, dict) and isinstance(settings.get("test"), dict):
        return {**settings, "test": recorded_test(settings["test"])}
    return settings


def _settings(config, test: TestConfig) -> tuple:
    """(the ER-MRL model's TrainConfig on the tested env at the test's budget, the test seeds, the PPO baselines'
    learning rate)."""
    env_id = test.env_id or config.env_ids[0]
    base = dataclasses.replace(config.train_for(env_id), total_timesteps=test.timesteps)
    seeds = list(range(FIRST_TEST_SEED, FIRST_TEST_SEED + test.seeds))
    rate = test.baseline_learning_rate
    return base, seeds, config.train.ppo.learning_rate if rate is None else rate


def baseline_jobs(base, seeds: list[int], learning_rate: float, recurrent_baseline: bool = False) -> list[tuple]:
    """The PPO baselines of a test phase whose ER-MRL model trains with ``base`` (a TrainConfig on the tested env),
    as (kind, folder, TrainConfig, Population, [label]) each: PPO on the same observation, on the full one (masked
    envs), and PPO-LSTM if asked; ``seeds`` agents each at ``learning_rate``. Their agent is plain PPO,
    ``AgentConfig(reservoirs=0)``, whatever ``base``'s reservoirs (units, observed units, fed action: unused
    without a reservoir), and their PPO config holds ``learning_rate``, the rate they train at, not the
    evolution's (the trainer steps at the population's rate), so that test phases of reservoirs of any size,
    evolved at any rate, share their baselines in a store."""
    base_id, deleted = masking.parse(base.env_id)
    plain = dataclasses.replace(base, agent=AgentConfig(reservoirs=0),
                                ppo=dataclasses.replace(base.ppo, learning_rate=learning_rate))
    grid = Population.grid(Phi(1.0, 1.0, 1.0), seeds, learning_rate, 0)
    jobs = [("PPO", "ppo", plain, grid, ["PPO (same observation)"])]
    if deleted:
        jobs.append(("PPO", "ppo-full-observation", dataclasses.replace(plain, env_id=base_id), grid,
                     ["PPO (full observation)"]))
    if recurrent_baseline:
        lstm = dataclasses.replace(plain, ppo=dataclasses.replace(plain.ppo, model="lstm"))
        jobs.append(("PPO-LSTM", "ppo-lstm", lstm, grid, ["PPO-LSTM (same observation)"]))
    return jobs


def baseline_files(config, test: TestConfig, store: Path, agents_per_run: int | None = None) -> list[Path]:
    """Where ``store`` keeps (or will keep) the PPO baselines of ``test`` for a study evolved with ``config`` (an
    EvolveConfig), one path per baseline: what the time estimate of `ermrl experiment run` checks."""
    base, seeds, rate = _settings(config, test)
    paths = []
    for _, folder, train_config, population, labels in baseline_jobs(base, seeds, rate, test.recurrent_baseline):
        n = population.size
        size = n if agents_per_run is None else min(agents_per_run, n)
        identity = _shared_identity(_job_identity(folder, labels, train_config, population), size, n)
        paths.append(baseline_models.path_for(store, identity))
    return paths


def _trained(partial: Path, name: str, labels: list[str], train_config, population: Population,
             agents_per_run: int | None, shown: str, progress, log, snapshot_every_s: float,
             store: Path | None = None, older: list[str] | None = None) -> Results:
    """The results of one model (a job): kept from ``partial`` when an earlier run finished it, whole or in
    groups of agents (under ``labels``, or ``older``: the labels an older version gave it), or from ``store`` (a
    baseline store, None for ER-MRL), else trained (in groups of ``agents_per_run``) and kept in ``partial`` group
    by group, then whole in ``store``."""
    n = population.size
    size = n if agents_per_run is None else min(agents_per_run, n)
    identity = _job_identity(name, labels, train_config, population)
    whole = _kept(partial, name, name, labels, older, train_config, population)  # kept whole: trained as one group
    if whole is not None:
        if log:
            log(f"kept {', '.join(labels)} from an earlier run ({partial / name}.npz)")
        size = n
    elif store is not None:
        whole, path = baseline_models.load(store, _shared_identity(identity, size, n))
        if whole is not None:
            if log:
                changed = provenance.differences(checkpoints.software_of(path) or {})
                log(f"reused {', '.join(labels)} from the baseline store ({path})"
                    + (f"; it was trained with other versions ({', '.join(changed)}), so it is not bit for bit what "
                       "this machine would train" if changed else ""))
            return whole
    if whole is None:
        whole = _train(partial, name, labels, train_config, population, size, shown, progress, log,
                       snapshot_every_s, older)
    if store is not None:
        baseline_models.save(store, _shared_identity(identity, size, n), whole)
    return whole


def _kept(partial: Path, file: str, name: str, labels: list[str], older: list[str] | None, train_config,
          population: Population) -> Results | None:
    """The results that ``partial`` keeps as ``file`` for the job ``name`` with ``labels``, or with ``older`` (the
    labels an older version gave the same job); None when it keeps none."""
    for shown in (labels, older) if older else (labels,):
        found = checkpoints.load_job(partial, file, _job_identity(name, shown, train_config, population))
        if found is not None:
            return found
    return None


def _shared_identity(identity: dict, size: int, n: int) -> dict:
    """A job's identity in a baseline store: with its group size, since groups of agents round differently."""
    return {**identity, "agents_per_run": None if size == n else size}


def _train(partial: Path, name: str, labels: list[str], train_config, population: Population, size: int,
           shown: str, progress, log, snapshot_every_s: float, older: list[str] | None = None) -> Results:
    """Trains one model in groups of ``size`` agents, keeping each group in ``partial`` as it finishes (and
    loading the groups an earlier run kept, under ``labels`` or ``older``)."""
    n = population.size
    trainer, parts = None, []
    for lo in range(0, n, size):
        hi = min(lo + size, n)
        part = population if size == n else Population(population.seeds[lo:hi],
                                                       Phi(*(f[lo:hi] for f in population.phi)),
                                                       population.learning_rate[lo:hi])
        part_name = name if size == n else f"{name}.agents-{lo}-{hi - 1}"
        group = "" if size == n else f", agents {lo + 1}–{hi} of {n}" if hi - lo > 1 else f", agent {hi} of {n}"
        identity = _job_identity(name, labels, train_config, part)
        # the whole model was looked for above
        results = None if size == n else _kept(partial, part_name, name, labels, older, train_config, part)
        if results is not None:
            if log:
                log(f"kept {shown}{group} from an earlier run ({partial / part_name}.npz)")
        else:
            trainer = trainer or Trainer(train_config)  # one compile serves every group of this size
            snapshot = checkpoints.snapshot_path(partial, part_name)
            results = trainer.run(part, progress(shown + group) if progress else None, snapshot=snapshot,
                                  snapshot_every_s=snapshot_every_s, log=log)
            checkpoints.save_job(partial, part_name, identity, results)
            snapshot.unlink(missing_ok=True)
        parts.append(results)
    return parts[0] if len(parts) == 1 else Results.concat(parts)


def _job_identity(name: str, labels: list[str], train_config, population: Population) -> dict:
    """What a test job's results depend on (beyond the test phase's settings), JSON-ready: its name and labels,
    and what a training run's state depends on (:func:`ermrl.training.snapshots.identity`: the TrainConfig without
    the env workers, seeds, learning rates, Φ) but the number of devices, which kept models predate."""
    run = snapshots.identity(train_config, population, n_devices=1)
    del run["devices"]
    return {"job": name, "labels": list(labels), **run}


def _add_improvement(rows: list[dict]) -> None:
    """Adds to each ER-MRL row the probability that it beats each PPO baseline, with its 95% CI."""
    baselines = [r for r in rows if r["kind"] in ("PPO", "PPO-LSTM")]
    for r in rows:
        if r["kind"] != "ER-MRL":
            continue
        r["improvement"] = {}
        for b in baselines:
            x, y = (np.array([np.nan if v is None else v for v in row["per_seed"]]) for row in (r, b))
            if np.isfinite(x).any() and np.isfinite(y).any():
                r["improvement"][b["model"]] = list(statistics.probability_of_improvement(x, y))
