"""Getting the normalization constants an evolution over several envs needs: from its study when it resumes,
else from the baselines table, computing (and storing) the ones the table lacks."""

from __future__ import annotations

import dataclasses
import shlex
from pathlib import Path
from typing import Callable

from ermrl.errors import ConfigError
from ermrl.experiments import baselines as bl


def _command(argv: list[str]) -> str:
    return "ermrl " + " ".join(shlex.quote(a) for a in argv)


def _flags(settings: dict) -> list[str]:
    """The `ermrl baselines` flags of PPO settings (:func:`baselines.ppo_settings`), e.g. ['--gamma', '0.9'];
    a switch is its flag alone (``--normalize``, ``--no-normalize``), widths one value each (``--net-arch 64``)."""
    out = []
    for k, v in settings.items():
        flag = "net-arch" if k == "hidden" else k.replace("_", "-")  # PPOConfig.hidden's flag is SB3's name
        if isinstance(v, bool):
            out.append(f"--{flag}" if v else f"--no-{flag}")
        elif isinstance(v, (list, tuple)):
            out += [f"--{flag}", *map(str, v)]
        else:
            out += [f"--{flag}", f"{v:g}" if isinstance(v, float) else str(v)]
    return out


def ensure(env_ids, timesteps: int, seeds: int, learning_rate: float, table_path: Path | None,
           log: Callable[[str], None], progress: Callable | None = None, backend: str = "auto",
           env_workers="auto", random_episodes: int = 100, recompute: bool = False,
           settings: dict | None = None, env_threads="auto", processes: int = 1) -> dict[str, "bl.Baseline"]:
    """Each env's Baseline at this budget and PPO setting (``settings``: :func:`baselines.ppo_settings` of the
    evolution's PPO, beside ``learning_rate``); missing random or PPO entries are computed and saved first, PPO's
    trained as ``backend``, ``env_workers``, ``env_threads`` and ``processes`` say (TrainConfig's fields)."""
    settings = settings or {}
    table_path = table_path or bl.default_table()
    table = bl.load_table(table_path)
    if recompute or any(table.random(e) is None or table.ppo(e, timesteps, seeds, learning_rate, settings) is None
                        for e in env_ids):
        from ermrl.storage import check_file

        check_file(table_path, "baselines table", "baselines.json")  # before computing what it will store
    changed = False
    for env_id in env_ids:
        if recompute or table.random(env_id) is None:
            log(f"baselines: random agent on {env_id} ({random_episodes} episodes)")
            r = bl.random_scores(env_id, random_episodes)
            table.add_random(env_id, r, _command(["baselines", "--env", env_id, "--random-episodes",
                                                  str(random_episodes)]))
            changed = True
        if recompute or table.ppo(env_id, timesteps, seeds, learning_rate, settings) is None:
            shown = "".join(f", {k} {v}" for k, v in settings.items())
            log(f"baselines: vanilla PPO on {env_id} ({seeds} seeds × {timesteps:,} steps, learning rate "
                f"{learning_rate:g}{shown})")
            fn = progress(f"PPO baseline {env_id}") if progress else None
            p = bl.ppo_fitness(env_id, timesteps, seeds, learning_rate, backend, env_workers, fn, settings,
                               env_threads, processes)
            table.add_ppo(env_id, p, _command(["baselines", "--env", env_id, "--timesteps", str(timesteps),
                                               "--seeds", str(seeds), "--learning-rate", f"{learning_rate:g}",
                                               *_flags(settings)]))
            changed = True
        if changed:
            bl.save_table(table, table_path)
    out = {}
    for env_id in env_ids:
        out[env_id] = bl.resolve(env_id, timesteps, seeds, learning_rate, table, settings)
    return out


EVOLVE_ADVICE = "use a larger `total_timesteps`, drop the env, or pass `allow_weak` to go on anyway"


def check_informative(baselines, normalization: str, advice: str = EVOLVE_ADVICE) -> None:
    """Refuses constants where vanilla PPO does not beat the random agent: there nScore's denominator is zero
    or negative, so maximizing it would reward scores *below* random (Ant-v5 at 50k steps is such a case:
    see ``registry.ANT_MIN_TRIAL_TIMESTEPS``). ``advice`` ends the message."""
    weak = [b for b in baselines
            if b.ppo <= (b.random_return if normalization == "episodic" else b.random_step_reward)]
    if weak:
        b = weak[0]
        rnd = b.random_return if normalization == "episodic" else b.random_step_reward
        raise ConfigError(f"on {b.env_id}, vanilla PPO ({b.ppo:.4g}) does not beat the random agent ({rnd:.4g}) at this "
                          f"budget, so nScore would reward scores below random; {advice}")


def with_baselines(config, table_path: Path | None, storage_url: str, study_name: str,
                   log: Callable[[str], None], progress: Callable | None = None, allow_weak: bool = False,
                   advice: str = EVOLVE_ADVICE):
    """``config`` (an EvolveConfig over several envs) with its constants: the stored ones when the study exists
    already (a resumed study keeps the constants it started with), else from the table, computed if missing.
    Unless ``allow_weak``, refuses constants where PPO does not beat the random agent (``advice``: what to do)."""
    from ermrl import storage
    from ermrl.evolution import record as study_record
    from ermrl.evolution.study import ATTR, load_study

    try:  # looking creates nothing
        record = load_study(storage_url, study_name).user_attrs[ATTR]
        if record.get("baselines"):
            return dataclasses.replace(config, baselines=study_record.decode_study_record(record).baselines)
    except ConfigError:  # no such study yet
        pass
    found = ensure(config.env_ids, config.train.total_timesteps, config.seeds, config.train.ppo.learning_rate,
                   table_path, log, progress, config.train.backend, config.train.env_workers,
                   settings=bl.ppo_settings(config.train.ppo), env_threads=config.train.env_threads,
                   processes=config.train.processes)
    constants = tuple(found[e] for e in config.env_ids)
    if not allow_weak:
        check_informative(constants, config.normalization, advice)
    return dataclasses.replace(config, baselines=constants)
