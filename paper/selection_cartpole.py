"""Does robust selection of Φ* help? On CartPoleNoVel-v1, several independent CMA-ES studies; in each, the raw best
trial (the paper's Φ*) and the winner of `ermrl select` (the top K re-evaluated on fresh seeds) are both trained
on the same new test seeds, and their final fitness compared.

    python paper/selection_cartpole.py --studies 3 --trials 30 --timesteps 100000 \
        --storage docs/data/selection_cartpole.log --out docs/data/selection_cartpole.json

The studies live in one Optuna journal file (``--storage``), so a rerun resumes them and reuses their selections;
only the test runs are trained again. Prints a Markdown table and writes the raw numbers as JSON.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from ermrl import devices

devices.setup()  # one JAX CPU device per core
from ermrl import storage
from ermrl.evolution import record as study_record
from ermrl.agent import AgentConfig
from ermrl.analysis import statistics
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.evolve import evolve
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.selection import load_selection, ranked_trials, select
from ermrl.evolution.study import make_sampler, open_study
from ermrl.experiments.evaluation import FIRST_TEST_SEED
from ermrl.training import Population, TrainConfig, Trainer

ENV = "CartPoleNoVel-v1"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--studies", type=int, default=3, help="independent studies (sampler seeds 0, 1, ...)")
    p.add_argument("--trials", type=int, default=30)
    p.add_argument("--seeds", type=int, default=3, help="seeds per trial in the evolution")
    p.add_argument("--timesteps", type=int, default=100_000, help="steps per run in the evolution and selection")
    p.add_argument("--top", type=int, default=5)
    p.add_argument("--select-seeds", type=int, default=5)
    p.add_argument("--test-seeds", type=int, default=10)
    p.add_argument("--test-timesteps", type=int, default=300_000)
    p.add_argument("--learning-rate", type=float, default=3e-4)
    p.add_argument("--storage", default="runs/selection_cartpole.log", help="journal file holding the studies")
    p.add_argument("--out", type=Path, default=Path("runs/selection_cartpole.json"))
    a = p.parse_args()

    train = TrainConfig(env_id=ENV, total_timesteps=a.timesteps, agent=AgentConfig(reservoirs=1))
    train = dataclasses.replace(train, ppo=dataclasses.replace(train.ppo, learning_rate=a.learning_rate))
    test_train = dataclasses.replace(train, total_timesteps=a.test_timesteps)
    test_seeds = list(range(FIRST_TEST_SEED, FIRST_TEST_SEED + a.test_seeds))
    url = f"journal:{a.storage}"
    rows = []
    start = time.perf_counter()
    for i in range(a.studies):
        config = EvolveConfig(train=train, space=SearchSpace(1, fixed_iss=1.0), trials=a.trials, seeds=a.seeds,
                              sampler_seed=i)
        study = open_study(url, f"selection-cartpole-{i}", make_sampler("cmaes", config.generation_size, i),
                           study_record.encode_study_record(config))
        evolve(study, config)
        top = tuple(t.number for t in ranked_trials(study)[:a.top])
        sel = load_selection(study)
        if sel is None or sel.trials != top or len(sel.seeds) != a.select_seeds:
            sel = select(study, config, a.top, a.select_seeds)
        best = ranked_trials(study)[0]
        winner = next(t for t in ranked_trials(study) if t.number == sel.winner)
        tested = [best] if winner.number == best.number else [best, winner]
        phis = [config.space.phi_from_params(t.params) for t in tested]
        res = Trainer(test_train).run(Population.grid(phis, test_seeds, a.learning_rate, 1))
        fit = res.fitness().reshape(len(tested), len(test_seeds))
        fit[~res.finite.reshape(len(tested), len(test_seeds))] = np.nan
        test = {t.number: [None if not np.isfinite(v) else float(v) for v in row] for t, row in zip(tested, fit)}
        rows.append({"study": study.study_name, "raw_best": best.number, "raw_best_value": best.value,
                     "raw_best_params": best.params, "selected": winner.number, "selected_value": winner.value,
                     "selected_params": winner.params, "selection": dataclasses.asdict(sel),
                     "test_raw_best": test[best.number], "test_selected": test[winner.number]})
        print(f"{study.study_name}: raw best trial {best.number} (evolution {best.value:.1f}), selected trial "
              f"{winner.number} (re-evaluated {sel.values[sel.trials.index(winner.number)]:.1f}); test "
              f"{np.nanmean(test[best.number]):.1f} vs {np.nanmean(test[winner.number]):.1f}", flush=True)
    wall = time.perf_counter() - start

    raw = np.array([v for r in rows for v in r["test_raw_best"]], dtype=object)
    chosen = np.array([v for r in rows for v in r["test_selected"]], dtype=object)
    summary = {"raw_best": statistics.summarize(raw).as_dict(), "selected": statistics.summarize(chosen).as_dict(),
               "p_selected_beats_raw_best": statistics.probability_of_improvement(chosen, raw)}
    out = {"command": "python paper/selection_cartpole.py " + " ".join(
        f"--{k.replace('_', '-')} {v}" for k, v in vars(a).items()), "wall_seconds": wall, "studies": rows,
        "summary": summary}
    storage.write_json(a.out, out)
    print("\n| Φ* | studies × test seeds | final, mean ± std | IQM [95% CI] |")
    print("|---|---|---|---|")
    for label, key in (("raw best of the evolution", "raw_best"), ("selected by `ermrl select`", "selected")):
        s = summary[key]
        print(f"| {label} | {a.studies} × {a.test_seeds} | {s['mean']:.1f} ± {s['std']:.1f} | "
              f"{statistics.format_ci(s['iqm'], s['iqm_low'], s['iqm_high'])} |")
    p, lo, hi = summary["p_selected_beats_raw_best"]
    print(f"\nP(selected > raw best) = {p:.2f} [{lo:.2f}, {hi:.2f}]; wall time {wall / 60:.1f} min")
    print(json.dumps({r["study"]: (r["raw_best"], r["selected"]) for r in rows}))


if __name__ == "__main__":
    main()
