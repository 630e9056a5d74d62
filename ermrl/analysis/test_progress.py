"""The scores so far of an unfinished test phase: the models (or groups of agents) it has kept in ``OUT.partial/``.

A test phase on a host env runs for hours (LunarLander: 10 agents × 3M steps a model), and writes its summary
only at the end. Until then each finished model, or group of agents with ``--agents-per-run``, waits in
``OUT.partial/NAME.npz`` (:mod:`ermrl.experiments.checkpoints`). This prints one Markdown row per model, its kept
groups joined: the agents kept out of the model's, their seeds, and the same final-score statistics as the test
summary (mean ± std over seeds, population std; IQM with its 95% CI) and per-seed scores. The model in training,
if any, gets a row from its snapshot (``OUT.partial/NAME.snapshot``, :mod:`ermrl.training.snapshots`): how far it
is, and each agent's mean return over its last 10 episodes so far. ``ermrl test-progress OUT`` prints it.
"""

from __future__ import annotations

import re
from pathlib import Path

GROUP = re.compile(r"^(?P<job>.+)\.agents-(?P<lo>\d+)-(?P<hi>\d+)$")


def kept_models(partial: Path) -> dict[str, tuple[dict, list]]:
    """{job name: (identity of one of its files, [Results of each kept file, in agent order])}."""
    from ermrl.experiments.checkpoints import read_job

    if not partial.is_dir():
        raise ValueError(f"{partial} is not a folder; give an unfinished test phase's OUT.partial folder")
    models: dict[str, list] = {}
    for path in sorted(partial.glob("*.npz")):
        match = GROUP.match(path.stem)
        job, lo = (match["job"], int(match["lo"])) if match else (path.stem, 0)
        identity, results = read_job(path)
        models.setdefault(job, []).append((lo, identity, results))
    return {job: (parts[0][1], [r for _, _, r in sorted(parts, key=lambda p: p[0])]) for job, parts in models.items()}


def in_training(partial: Path) -> list[str]:
    """One Markdown row per model in training (``*.snapshot``): iterations done, fitness so far per agent."""
    import numpy as np

    from ermrl.training import snapshots

    rows = []
    for path in sorted(partial.glob("*.snapshot")):
        identity, snap = snapshots.read_any(path)
        train = identity["train"]
        per_iteration = train["ppo"]["n_steps"] * train["ppo"]["n_envs"]
        total = -(-train["total_timesteps"] // per_iteration)
        n = len(identity["seeds"])
        rets = np.stack([r for r, _ in snap.finished])  # (iterations, n, n_steps, n_envs), NaN where none ended
        so_far = []
        for a in range(n):
            ended = rets[:, a].reshape(-1).astype(np.float64)
            ended = ended[~np.isnan(ended)]
            so_far.append(float(np.mean(ended[-10:])) if len(ended) else float("nan"))
        fit = np.array(so_far)
        mean = f"{np.nanmean(fit):.1f} ± {np.nanstd(fit):.1f}" if np.isfinite(fit).any() else "—"
        rows.append(f"| `{path.stem}` (in training) | {n} | {', '.join(str(s) for s in identity['seeds'])} | "
                    f"{snap.iteration * per_iteration:,} of {total * per_iteration:,} | {mean} (last 10 episodes "
                    f"so far) | — | {', '.join(f'{v:.1f}' for v in fit)} |")
    return rows


def partial_folder(path: Path) -> Path:
    """The ``OUT.partial`` folder of a test phase given as ``OUT`` or ``OUT.partial``; ValueError when there is none
    (and says so when the test phase is finished)."""
    partial = path if path.name.endswith(".partial") else path.with_name(path.name + ".partial")
    if partial.is_dir():
        return partial
    out = partial.with_name(partial.name[: -len(".partial")])
    if (out / "summary.json").is_file():
        raise ValueError(f"the test phase in {out} is finished; its scores are in {out / 'summary.json'}")
    raise ValueError(f"{partial} is not a folder; give an unfinished test phase's OUT or OUT.partial folder")


def table(partial: Path) -> str:
    """The Markdown table of ``partial`` (an ``OUT.partial`` folder): a row per kept model, then a row per model
    in training; ValueError when it holds neither."""
    from ermrl import storage
    from ermrl.analysis.statistics import format_ci
    from ermrl.experiments.checkpoints import SETTINGS
    from ermrl.experiments.evaluation import summarize
    from ermrl.training.results import Results

    from ermrl.model_labels import current

    models = kept_models(partial)
    training = in_training(partial)
    if not models and not training:
        raise ValueError(f"{partial} holds no kept model or snapshot yet (*.npz, *.snapshot)")
    if models:  # one agent per seed and learning rate
        seeds_per_model = storage.read_json(partial / SETTINGS)["test"]["seeds"]
    lines = ["| model | agents kept | seeds | steps | final mean ± std | IQM [95% CI] | per seed |",
             "|---|---|---|---|---|---|---|"]
    for job, (identity, parts) in models.items():
        results = parts[0] if len(parts) == 1 else Results.concat(parts)
        row = summarize(", ".join(map(current, identity["labels"])), "", results)  # older labels in today's words
        mean = "—" if row["final_mean"] is None else f"{row['final_mean']:.1f} ± {row['final_std']:.1f}"
        per_seed = ", ".join("—" if v is None else f"{v:.1f}" for v in row["per_seed"])
        seeds = ", ".join(str(int(s)) for s in results.seeds)
        lines.append(f"| {row['model']} (`{job}`) | {results.size} of {seeds_per_model * len(identity['labels'])} | "
                     f"{seeds} | {results.total_timesteps:,} | {mean} | "
                     f"{format_ci(row['final_iqm'], row['final_iqm_low'], row['final_iqm_high'])} | {per_seed} |")
    return "\n".join(lines + training) + "\n"

