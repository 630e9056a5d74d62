"""The test phase (paper §3, "Evaluation"): Φ* (the best trial) trained on new seeds against the baselines.

Models, all on the evolution's env and PPO settings:
- ER-MRL with Φ*;
- vanilla PPO on the same (masked) observation, a feedforward policy;
- PPO with full observations (the unmasked env), when the env is a NoVel variant.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Callable

import numpy as np
import optuna

from ermrl.agent import AgentConfig, Phi
from ermrl.analysis.plots import learning_curves
from ermrl.envs import masking
from ermrl.errors import ConfigError
from ermrl.reservoir import ReservoirSpec
from ermrl.results import Results
from ermrl.runs import write_curves_csv
from ermrl.search_space import SearchSpace
from ermrl.study import ATTR
from ermrl.train import Population, TrainConfig, Trainer
from ermrl.ppo.config import PPOConfig

FIRST_TEST_SEED = 1000
"""Test seeds start here, away from the evolution's seeds 0, 1, 2, ... (new reservoirs, policies, envs)."""


def space_from_record(record: dict) -> SearchSpace:
    ss = record["search_space"]
    fixed = ss["iss"]["fixed"] if isinstance(ss["iss"], dict) else None
    iss = (0.1, 10.0) if fixed is not None else tuple(ss["iss"])
    return SearchSpace(record["reservoirs"], tuple(ss["sr"]), tuple(ss["lr"]), iss, fixed)


def train_config_from_record(record: dict, timesteps: int) -> TrainConfig:
    t = record["train"]
    agent = dict(t["agent"])
    agent["spec"] = ReservoirSpec(**agent["spec"])
    ppo = dict(t["ppo"])
    ppo["hidden"] = tuple(ppo["hidden"])
    return TrainConfig(env_id=t["env_id"], total_timesteps=timesteps, agent=AgentConfig(**agent),
                       ppo=PPOConfig(**ppo), backend=t.get("backend", "auto"),
                       env_workers=t.get("env_workers", "auto"))


def best_phi(study: optuna.Study) -> tuple[optuna.trial.FrozenTrial, Phi]:
    record = study.user_attrs[ATTR]
    try:
        best = study.best_trial
    except ValueError:
        raise ConfigError(f"study {study.study_name!r} has no completed trial yet; run `ermrl evolve` first") from None
    return best, space_from_record(record).phi_from_params(best.params)


def summarize(label: str, results: Results) -> dict:
    """Final fitness (last 10 episodes) and area under the curve (mean of the curve), mean ± std over seeds."""
    fit = results.fitness()
    _, curves = results.curves()
    with np.errstate(all="ignore"):
        auc = np.nanmean(curves, axis=1)
    return {"model": label, "env_id": results.env_id, "n_seeds": results.size,
            "learning_rate": float(results.learning_rate[0]), "timesteps": results.total_timesteps,
            "final_mean": float(np.nanmean(fit)), "final_std": float(np.nanstd(fit)),
            "auc_mean": float(np.nanmean(auc)), "auc_std": float(np.nanstd(auc)),
            "per_seed": [None if np.isnan(v) else float(v) for v in fit]}


def run_test_phase(study: optuna.Study, out: Path, seeds: int, timesteps: int,
                   progress: Callable[[str], Callable] | None = None, learning_rate: float | None = None) -> list[dict]:
    """Trains the three models and writes curves.csv, summary.json/.csv and test_phase.png/.svg into ``out``.

    ``learning_rate`` overrides the evolution's PPO step size for every model."""
    record = study.user_attrs[ATTR]
    best, phi = best_phi(study)
    base = train_config_from_record(record, timesteps)
    test_seeds = list(range(FIRST_TEST_SEED, FIRST_TEST_SEED + seeds))
    lr = record["learning_rate"] if learning_rate is None else learning_rate
    if not 0 < lr < 1:
        raise ConfigError(f"learning rate {lr} is outside (0, 1); the paper uses 3e-4 or 1e-4")
    k = record["reservoirs"]
    base_id, deleted = masking.parse(base.env_id)
    phi_text = ", ".join(f"{n} {float(v[0]):.3g}" for n, v in zip(("sr", "lr", "iss"), phi)) if k == 1 else f"trial {best.number}"
    models = [(f"ER-MRL ({phi_text})", base, k)]
    plain = dataclasses.replace(base, agent=dataclasses.replace(base.agent, reservoirs=0))
    models.append(("PPO (same observation)", plain, 0))
    if deleted:
        models.append(("PPO (full observation)", dataclasses.replace(plain, env_id=base_id), 0))

    out.mkdir(parents=True, exist_ok=True)
    curves, seed_map, rows = {}, {}, []
    for label, config, reservoirs in models:
        population = Population.grid(phi, test_seeds, lr, reservoirs) if reservoirs else \
            Population.grid(Phi(1.0, 1.0, 1.0), test_seeds, lr, 0)
        fn = progress(label) if progress else None
        results = Trainer(config).run(population, fn)
        curves[label] = results.curves()
        seed_map[label] = results.seeds
        rows.append(summarize(label, results))
    write_curves_csv(out / "curves.csv", curves, seed_map)
    (out / "summary.json").write_text(json.dumps(rows, indent=2))
    with open(out / "summary.csv", "w") as f:
        f.write("model,env_id,n_seeds,final_mean,final_std,auc_mean,auc_std\n")
        for r in rows:
            f.write(f"{r['model']},{r['env_id']},{r['n_seeds']},{r['final_mean']:.6g},{r['final_std']:.6g},"
                    f"{r['auc_mean']:.6g},{r['auc_std']:.6g}\n")
    learning_curves(curves, f"{base.env_id}: test phase, {seeds} new seeds", out / "test_phase", ("png", "svg"))
    return rows
