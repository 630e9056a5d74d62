"""Run folders: what a training run writes to disk (config, episodes, curves, summary, figure)."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np

from ermrl.analysis.plots import learning_curves
from ermrl.results import Results


def config_dict(config) -> dict:
    """A JSON-ready dict of a (nested) frozen dataclass config."""
    return json.loads(json.dumps(dataclasses.asdict(config), default=str))


def write_curves_csv(path: Path, curves: dict[str, tuple[np.ndarray, np.ndarray]], seeds: dict[str, np.ndarray]) -> None:
    """Long format: model, seed, timestep, value (mean return of the last 100 episodes)."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["model", "seed", "timestep", "mean_return_100"])
        for label, (steps, values) in curves.items():
            for s, row in zip(seeds[label], values):
                for t, v in zip(steps, row):
                    w.writerow([label, int(s), int(t), "" if np.isnan(v) else f"{v:.6g}"])


def read_curves_csv(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Inverse of :func:`write_curves_csv`: {model: (timesteps (I,), values (S, I))}, NaN where a seed has none."""
    cells: dict[str, dict[int, dict[int, float]]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            val = float(row["mean_return_100"]) if row["mean_return_100"] else np.nan
            cells.setdefault(row["model"], {}).setdefault(int(row["seed"]), {})[int(row["timestep"])] = val
    curves = {}
    for model, by_seed in cells.items():
        steps = np.array(sorted({t for s in by_seed.values() for t in s}))
        curves[model] = (steps, np.array([[s.get(t, np.nan) for t in steps] for s in by_seed.values()]))
    return curves


def write_train_run(out: Path, config, results: Results, label: str) -> dict[str, Path]:
    """Writes config.json, episodes.csv, curves.csv, summary.json and learning_curve.png into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    files = {
        "config": out / "config.json",
        "episodes": out / "episodes.csv",
        "curves": out / "curves.csv",
        "summary": out / "summary.json",
        "figure": out / "learning_curve.png",
    }
    population = {"seeds": results.seeds.tolist(), "phi": {k: v.tolist() for k, v in results.phi.items()},
                  "learning_rate": results.learning_rate.tolist()}
    files["config"].write_text(json.dumps({"train": config_dict(config), "population": population}, indent=2))
    results.write_csv(files["episodes"], label)
    curves = {label: results.curves()}
    write_curves_csv(files["curves"], curves, {label: results.seeds})
    results.write_summary(files["summary"])
    learning_curves(curves, f"{results.env_id}: {label}", files["figure"])
    return files
