"""The recurrent baseline against ER-MRL on the masked classic-control tasks.

Models, each trained as its own population of --seeds agents (seeds 0..N-1), SB3-default PPO otherwise:
- ``lstm``: PPO-LSTM (``PPOConfig.model = "lstm"``, sb3-contrib RecurrentPPO's policy, LSTM 64), lr 3e-4;
- ``ermrl-1e-4``: ER-MRL, one reservoir with sr 0.95, lr 0.5, iss 1.0 (the paper's partially observable
  setting), PPO learning rate 1e-4;
- ``ermrl-3e-4``: the same reservoir at PPO learning rate 3e-4.

Every (env, model) run is saved as JSON under --data (final fitness per seed, curves, the wall time after every
iteration, compile_s, train_s, the machine's load); a rerun skips what is saved, so the script resumes. The
figures (return against steps and against wall time, mean ± std over seeds) go to --figures:

    python paper/recurrent_vs_ermrl.py --timesteps 300000                 # train what is missing, then plot
    python paper/recurrent_vs_ermrl.py --timesteps 300000 --plot-only
    python paper/recurrent_vs_ermrl.py --models lstm --envs PendulumNoVel-v1 --timesteps 1000000
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np

from ermrl import devices

devices.setup()  # one JAX CPU device per core
from ermrl import storage
from ermrl.agent import AgentConfig, Phi
from ermrl.analysis.plots import learning_curves
from ermrl.ppo.config import SB3_DEFAULTS
from ermrl.training import Population, TrainConfig, Trainer

ENVS = ("CartPoleNoVel-v1", "PendulumNoVel-v1")
PHI = Phi(0.95, 0.5, 1.0)
MODELS = {
    # name: (label, reservoirs, PPO model, learning rate)
    "lstm": ("PPO-LSTM (64 units), lr 3e-4", 0, "lstm", 3e-4),
    "ermrl-1e-4": ("ER-MRL (sr 0.95, lr 0.5, iss 1), lr 1e-4", 1, "ff", 1e-4),
    "ermrl-3e-4": ("ER-MRL (sr 0.95, lr 0.5, iss 1), lr 3e-4", 1, "ff", 3e-4),
}


def config_for(model: str, env_id: str, timesteps: int) -> TrainConfig:
    _, k, kind, _ = MODELS[model]
    return TrainConfig(env_id=env_id, total_timesteps=timesteps, agent=AgentConfig(reservoirs=k),
                       ppo=dataclasses.replace(SB3_DEFAULTS, model=kind))


def data_path(folder: Path, env_id: str, model: str, timesteps: int, seeds: int) -> Path:
    return folder / f"{env_id}_{model}_{seeds}x{timesteps}.json"


def _commit() -> str | None:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip() + "+changes"
    except (OSError, subprocess.CalledProcessError):
        return None


def run(model: str, env_id: str, timesteps: int, seeds: int) -> dict:
    """Trains one model on one env; returns the JSON record."""
    label, k, _, lr = MODELS[model]
    config = config_for(model, env_id, timesteps)
    wall: list[float] = []
    load_start = os.getloadavg()
    started = datetime.datetime.now().isoformat(timespec="seconds")
    t0 = time.perf_counter()

    def progress(p):
        wall.append(p.elapsed_s)
        if p.iteration % 25 == 0 or p.iteration == p.n_iterations:
            print(f"  {env_id} {model}: iteration {p.iteration}/{p.n_iterations}, {p.elapsed_s:.0f} s", flush=True)

    results = Trainer(config).run(Population.grid(PHI, seeds, lr, k), progress)
    steps, values = results.curves()
    fit = results.fitness()
    return {
        "model": model, "label": label, "env_id": env_id, "seeds": results.seeds.tolist(), "learning_rate": lr,
        "phi": PHI._asdict() if k else None, "train": storage.to_dict(config),
        "fitness": [None if not np.isfinite(v) else float(v) for v in fit],
        "fitness_mean": float(np.nanmean(fit)), "fitness_std": float(np.nanstd(fit)),
        "diverged": int((~results.finite).sum()),
        "curve_steps": steps.tolist(), "curves": [[None if not np.isfinite(v) else float(v) for v in row]
                                                  for row in values],
        "wall_s": wall, "compile_s": results.compile_s, "train_s": results.train_s,
        "total_s": time.perf_counter() - t0, "agent_steps_per_s": results.agent_steps_per_s(),
        "machine": {"cpus": os.cpu_count(), "load_start": load_start, "load_end": os.getloadavg()},
        "started": started, "commit": _commit(),
    }


def curves_of(record: dict, against: str) -> tuple[np.ndarray, np.ndarray]:
    values = np.array([[np.nan if v is None else v for v in row] for row in record["curves"]], float)
    x = np.asarray(record["curve_steps"], float) if against == "steps" else np.asarray(record["wall_s"], float)
    return x, values


def plot(records: list[dict], figures: Path, timesteps: int, seeds: int) -> list[Path]:
    written = []
    for env_id in sorted({r["env_id"] for r in records}):
        mine = [r for r in records if r["env_id"] == env_id]
        for against, xlabel in (("steps", "timesteps"), ("wall", "wall time (s, compile excluded)")):
            curves = {r["label"]: curves_of(r, against) for r in mine}
            path = figures / f"recurrent_vs_ermrl_{env_id}_{timesteps // 1000}k_{against}"
            written += learning_curves(curves, f"{env_id}: {seeds} seeds × {timesteps:,} steps", path,
                                       xlabel=xlabel)
    return written


def table(records: list[dict]) -> str:
    lines = ["| env | model | fitness mean ± std | per seed | compile_s | train_s | agent-steps/s |",
             "|---|---|---|---|---|---|---|"]
    for r in records:
        per_seed = ", ".join("nan" if v is None else f"{v:.1f}" for v in r["fitness"])
        lines.append(f"| {r['env_id']} | {r['label']} | {r['fitness_mean']:.1f} ± {r['fitness_std']:.1f} | {per_seed} "
                     f"| {r['compile_s']:.1f} | {r['train_s']:.1f} | {r['agent_steps_per_s']:,.0f} |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", nargs="+", default=list(ENVS))
    p.add_argument("--models", nargs="+", default=list(MODELS), choices=list(MODELS))
    p.add_argument("--seeds", type=int, default=10)
    p.add_argument("--timesteps", type=int, default=1_000_000)
    p.add_argument("--data", type=Path, default=Path("docs/data/recurrent_vs_ermrl"))
    p.add_argument("--figures", type=Path, default=Path("docs/figures"))
    p.add_argument("--plot-only", action="store_true", help="only plot and tabulate what is saved")
    a = p.parse_args()
    records = []
    for env_id in a.envs:
        for model in a.models:
            path = data_path(a.data, env_id, model, a.timesteps, a.seeds)
            if path.is_file():
                records.append(json.loads(path.read_text()))
                continue
            if a.plot_only:
                continue
            print(f"training {model} on {env_id}: {a.seeds} seeds × {a.timesteps:,} steps", flush=True)
            record = run(model, env_id, a.timesteps, a.seeds)
            storage.write_json(path, record)
            records.append(record)
            print(f"  fitness {record['fitness_mean']:.1f} ± {record['fitness_std']:.1f}, compile "
                  f"{record['compile_s']:.1f} s, train {record['train_s']:.1f} s", flush=True)
    if records:
        print(table(records))
        for f in plot(records, a.figures, a.timesteps, a.seeds):
            print(f"wrote {f}")


if __name__ == "__main__":
    main()
