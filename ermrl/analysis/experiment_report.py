"""One HTML report for a named experiment: every study's Φ* and test phases, the aggregate over envs (IQM of
normalized scores and performance profiles), and the cross-study HP map."""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from ermrl import storage
from ermrl.model_labels import current, number
from ermrl.analysis import statistics
from ermrl.analysis.html import img, page, table
from ermrl.analysis.hp_map import LEAK_RATE_HEADER, draw_hp_map, hp_map_points, leak_rate_rows
from ermrl.analysis.report import skipped_note, test_dirs, test_phase_sections
from ermrl.analysis.trials import ranked
from ermrl.errors import ConfigError

def normalized_test_scores(rows_by_env: dict[str, list[dict]], random_returns: dict[str, float]) -> dict[str, np.ndarray]:
    """{model kind: (n_seeds, n_envs)} final scores normalized per env as (score − random) / (PPO − random),
    with PPO the test phase's own 'PPO (same observation)' mean: PPO scores 1 on average, random 0."""
    kinds: dict[str, list[np.ndarray]] = {}
    for env, rows in rows_by_env.items():
        ppo = next((r for r in rows if r["model"] == "PPO (same observation)"), None)
        if ppo is None or ppo["final_mean"] is None or env not in random_returns:
            continue
        rnd = random_returns[env]
        if ppo["final_mean"] == rnd:
            continue
        for r in rows:
            if r["model"] == "PPO (full observation)" or "per_seed" not in r:  # per_seed: summary_schema.TEST_SUMMARY_EXTRA
                continue
            x = np.array([np.nan if v is None else v for v in r["per_seed"]], float)
            kinds.setdefault(aggregate_name(r, rows), []).append((x - rnd) / (ppo["final_mean"] - rnd))
    n = min((len(v) for v in kinds.values()), default=0)
    return {k: np.stack(v, axis=1) for k, v in kinds.items() if len(v) == n and n > 0}


def aggregate_name(row: dict, rows: list[dict]) -> str:
    """The model that ``row`` of a test phase (with ``rows``) counts for in the aggregate over envs: "PPO",
    "PPO-LSTM", "ER-MRL", or with several ER-MRL learning rates in the test phase "ER-MRL (learning rate 0.0003)"."""
    kind = _kind(row)
    if kind != "ER-MRL":
        return kind
    if sum(_kind(r) == "ER-MRL" for r in rows) > 1 and row.get("learning_rate") is not None:
        return f"ER-MRL (learning rate {number(row['learning_rate'])})"
    return "ER-MRL"


def _kind(row: dict) -> str:
    """A row's kind of model ("ER-MRL", "PPO", "PPO-LSTM"), read from its label where it has none."""
    return row.get("kind") or current(row["model"]).split(" (")[0]


def write_experiment_report(experiment, scale, plans, storage_url: str, folder: Path,
                            random_returns: dict[str, float] | None = None) -> Path:
    """Writes ``folder/report.html`` and returns its path. ``random_returns`` (env id -> the random agent's mean
    episode return) normalizes the test phases' final scores for the aggregate over envs."""
    from ermrl.evolution.study import load_study

    folder = Path(folder)
    title = f"ER-MRL experiment {experiment.name} ({scale.name} scale)"
    parts = [f"<h1>{html.escape(title)}</h1>", f"<p>{html.escape(experiment.title)}. Paper: "
             f"{html.escape(experiment.paper)}; claims {', '.join(experiment.claims)}. Scale: "
             f"{html.escape(scale.description)}. Storage: <code>{html.escape(storage_url)}</code></p>"]
    studies, rows_by_env, summary = [], {}, []
    skipped: dict[Path, str] = {}  # damaged test phases, left out
    for p in plans:
        try:
            study = load_study(storage_url, p.study)
        except Exception:  # not run yet (e.g. --only ran other studies)
            continue
        studies.append(study)
        best = ranked(study)[:1]
        sel = study.user_attrs.get("selection", {})
        summary.append([p.spec.name, ", ".join(p.config.env_ids), p.spec.reservoirs, p.spec.units,
                        len(ranked(study)), best[0].value if best else None, sel.get("winner")])
        for d in test_dirs(p.run_dir):
            try:
                rows = storage.read_test_summary(d)
            except ConfigError:
                continue  # told of with its section's below
            rows_by_env.setdefault(rows[0]["env_id"], rows) if rows else None
    parts += ["<h2>Studies</h2>", table(["study", "evolved on", "K", "units", "completed trials", "best fitness",
                                         "Φ* (selected trial)"], summary)]
    scores = normalized_test_scores(rows_by_env, random_returns or {})
    if scores and next(iter(scores.values())).shape[1] > 1:
        agg = statistics.aggregate_iqm(scores)
        parts += ["<h2>Aggregate over envs</h2>",
                  f"<p>Final test scores normalized per env by the random agent (0) and the test phase's PPO on the "
                  f"same observation (1), over {next(iter(scores.values())).shape[1]} envs: IQM with 95% stratified "
                  "bootstrap CIs (rliable).</p>",
                  table(["model", "IQM of nScore [95% CI]"], [[m, statistics.format_ci(*v, digits=2)] for m, v in agg.items()]),
                  img(statistics.performance_profile(scores, folder / "performance_profile.png"), "performance profile")]
    if experiment.hp_map and studies:
        series = hp_map_points(studies)  # read once: the map and its leak-rate table
        parts += ["<h2>HP map across studies</h2>",
                  img(draw_hp_map(series, folder / "hp_map_across_studies.png"), "HP map"),
                  table(LEAK_RATE_HEADER, leak_rate_rows(series))]
    for p in plans:
        sections = test_phase_sections(p.run_dir, skipped)
        if sections:
            parts += [f"<h2>{html.escape(p.spec.name)}</h2>",
                      f'<p><a href="{html.escape(p.spec.name)}/report.html">study report</a></p>', *sections]
    if skipped:
        parts += ["<h2>Skipped test phases</h2>", *skipped_note(skipped)]
    out = folder / "report.html"
    storage.write_text(out, page(title, parts))
    return out
