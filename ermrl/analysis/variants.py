"""Reservoir variants of one env (sizes, observed units, reservoir counts, other HPs, learning rates) compared on the
same seeds: what ``ermrl compare`` prints and draws.

A variant is the ``summary.json`` of a test phase (``runs/experiments/EXPERIMENT-SCALE/STUDY/test/``, or
``test-ENV/`` for a study tested on another env; collected under ``docs/data/``) or of an ``ermrl train`` run. Every
test phase trains its ER-MRL agents and its PPO baselines on the seeds 1000, 1001, ..., so a variant's seed k and
another's share the env noise and the policy's initialization, not the reservoirs. Several ``ermrl train`` runs of
the same settings on other seeds may be joined into one variant (their seeds pooled); test phases cannot be joined
(their summaries number their seeds from 1000).

:func:`table` is the Markdown table: each variant's ER-MRL row (n, mean ± std, IQM [95% CI], the area under the
curve over the first 300k steps), then the PPO rows of the first test phase; then, for each comparison (A, B),
P(A > B) with its 95% CI (rliable) and the paired difference A − B over the shared seeds (SciPy: BCa CI, Wilcoxon p).
:func:`curves` gives the learning curves to draw, from the ``curves.csv`` beside each ``summary.json``. Errors are
ValueError (a file of the wrong kind, an unknown label: a ConfigError where it names a parameter) or OSError (a
missing file), each one line.
"""

from __future__ import annotations

import json
from pathlib import Path

from ermrl.errors import ConfigError


def read_rows(path: Path, auc: bool = True) -> tuple[dict, list[dict]]:
    """(the ER-MRL row, the PPO rows) of a test phase's ``summary.json``, which must have one ER-MRL row; or of an
    ``ermrl train`` run's (one model, no PPO rows; its row holds ``scores``, {seed: final score}, and, if ``auc``,
    the AUC from the ``curves.csv`` beside it). A model labelled by an older version reads under its label today
    (:func:`ermrl.model_labels.current`)."""
    from ermrl.model_labels import current

    rows = json.loads(path.read_text())
    if isinstance(rows, dict):
        if "seeds" not in rows or "fitness" not in rows:
            raise ValueError(f"{path} is neither a test phase's nor an `ermrl train` run's summary.json")
        scores = {int(s): float(f) for s, f in zip(rows["seeds"], rows["fitness"]) if f is not None and f == f}
        return {"model": None, "kind": _run_kind(path), "scores": scores,
                "auc_early_mean": _early_auc(path) if auc else None}, []
    rows = [{**r, "model": current(r["model"])} for r in rows]  # as read_curves_csv names them: older labels too
    if auc and any(r.get("auc_early_mean") is None for r in rows):
        rows = _with_early_auc(path, rows)
    ermrl = [r for r in rows if r["kind"] == "ER-MRL"]
    if len(ermrl) != 1:
        raise ValueError(f"{path} has {len(ermrl)} ER-MRL rows; give a test phase of one learning rate")
    return ermrl[0], [r for r in rows if r["kind"] == "PPO"]


def _with_early_auc(summary: Path, rows: list[dict]) -> list[dict]:
    """A test phase's rows, those without an AUC over the first 300k steps (a test phase run without
    ``auc_steps``) given it from the ``curves.csv`` beside the summary, as the test phase computes it."""
    return [row if row.get("auc_early_mean") is not None
            else {**row, "auc_early_mean": _early_auc(summary, model=row["model"])} for row in rows]


def _run_kind(summary: Path) -> str:
    """"PPO" for an ``ermrl train --no-reservoir`` run (its config.json has no reservoir), else "ER-MRL"."""
    config = summary.parent / "config.json"
    if config.is_file() and json.loads(config.read_text())["train"]["agent"]["reservoirs"] == 0:
        return "PPO"
    return "ER-MRL"


def read_variant(paths: list[Path]) -> tuple[dict, list[dict]]:
    """``read_rows`` of one summary, or of several ``ermrl train`` runs joined: one row of their pooled scores
    (their seeds must differ) and AUC; no PPO rows."""
    if len(paths) == 1:
        return read_rows(paths[0])
    return {"model": None, "kind": _run_kind(paths[0]), "scores": _joined_scores(paths),
            "auc_early_mean": _early_auc(*paths)}, []


def _joined_scores(paths: list[Path]) -> dict[int, float]:
    """{seed: final score} of several ``ermrl train`` runs pooled; refuses a test phase's summary or a seed that
    two runs share."""
    scores, owner = {}, {}
    for path in paths:
        row, _ = read_rows(path, auc=False)
        if row["model"] is not None:
            raise ValueError(f"{path} is a test phase's summary.json; only `ermrl train` runs (which record their "
                             "seeds) can be joined with ','")
        shared = sorted(set(row["scores"]) & set(scores))
        if shared:
            raise ValueError(f"{owner[shared[0]]} and {path} both have seed {shared[0]}; join runs of other seeds")
        scores.update(row["scores"])
        owner.update(dict.fromkeys(row["scores"], path))
    return scores


def _train_curves(summaries: tuple[Path, ...]) -> tuple | None:
    """(timesteps (I,), values (S, I)) of ``ermrl train`` runs, from the ``curves.csv`` beside each summary, the
    runs' seeds stacked in their order; None if one has no curves.csv."""
    import numpy as np

    from ermrl.storage import read_curves_csv

    read = []
    for summary in summaries:
        path = summary.parent / "curves.csv"
        if not path.is_file():
            return None
        (curve,) = read_curves_csv(path).values()
        if read and not np.array_equal(curve[0], read[0][0]):
            from ermrl.training.config import TrainConfig

            raise ConfigError(f"{path} has other update steps than {summaries[0].parent / 'curves.csv'}; join runs "
                              "of the same `total_timesteps`", owner=TrainConfig)
        read.append(curve)
    return read[0][0], np.concatenate([values for _, values in read])


def _early_auc(*summaries: Path, model: str | None = None) -> float | None:
    """The mean over seeds of :func:`early_auc_by_seed` (a test phase's ``auc_early_mean``); None without curves."""
    by_seed = early_auc_by_seed(list(summaries), model)
    return sum(by_seed.values()) / len(by_seed) if by_seed else None


def early_auc_by_seed(paths: list[Path], model: str | None, steps: int = 300_000) -> dict[int, float]:
    """{seed: the mean of its learning curve over the first ``steps``} of ``model`` (None: the one model of an
    ``ermrl train`` run), read from the ``curves.csv`` beside each summary (as a test phase's ``auc_early_mean``
    averages them); {} when a curves.csv is missing or lacks the model."""
    import csv

    from ermrl.model_labels import current

    sums: dict[int, list[float]] = {}
    for summary in paths:
        path = summary.parent / "curves.csv"
        if not path.is_file():
            return {}
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                if (model is None or current(row["model"]) == model) and int(row["timestep"]) <= steps \
                        and row["mean_return_100"]:
                    sums.setdefault(int(row["seed"]), []).append(float(row["mean_return_100"]))
    return {seed: sum(v) / len(v) for seed, v in sums.items()}


def per_seed(row: dict) -> dict[int, float]:
    """{seed: final score} of a row (a test phase's seeds are 1000, 1001, ...; a diverged seed is left out)."""
    from ermrl.experiments.evaluation import FIRST_TEST_SEED

    if "scores" in row:
        return row["scores"]

    return {FIRST_TEST_SEED + i: float(v) for i, v in enumerate(row["per_seed"]) if v is not None}


def table(variants: dict[str, list[Path]], comparisons: list[tuple[str, str]]) -> str:
    """The Markdown table of ``variants`` ({label: [summary.json, ...]}) and the ``comparisons`` (pairs of
    labels)."""
    from ermrl.analysis.statistics import format_ci, paired_difference, probability_of_improvement, summarize

    scores, lines = {}, ["| model | n | mean ± std | IQM [95% CI] | AUC 0–300k |", "|---|---|---|---|---|"]

    def line(name: str, row: dict) -> str:
        s = summarize(list(per_seed(row).values()))
        auc = "" if row.get("auc_early_mean") is None else f"{row['auc_early_mean']:.1f}"
        return f"| {name} | {s.n} | {s.mean:.1f} ± {s.std:.1f} | {format_ci(s.iqm, s.iqm_low, s.iqm_high)} | {auc} |"

    ppo_rows, aucs = None, {}
    for name, paths in variants.items():
        ermrl, ppo = read_variant(paths)
        scores[name] = per_seed(ermrl)
        aucs[name] = early_auc_by_seed(paths, ermrl["model"])
        lines.append(line(f"{ermrl['kind']}, {name}", ermrl))
        if ppo_rows is None:
            ppo_rows, ppo_paths = ppo, paths
    lines += [line(r["model"], r) for r in ppo_rows or []]
    lines.append("")
    for r in ppo_rows or []:  # a PPO row of the first test phase is comparable by its model name
        scores.setdefault(r["model"], per_seed(r))
        aucs.setdefault(r["model"], early_auc_by_seed(ppo_paths, r["model"]))
    for a, b in comparisons:
        for name in (a, b):
            if name not in scores:
                raise ConfigError(f"`comparisons` names {name!r}, which is none of the variants or PPO rows "
                                  f"({', '.join(scores)})", owner=table)
    for a, b in comparisons:
        p = probability_of_improvement(list(scores[a].values()), list(scores[b].values()))
        shared = sorted(set(scores[a]) & set(scores[b]))
        diff = paired_difference([scores[a][s] for s in shared], [scores[b][s] for s in shared])
        lines.append(f"- P({a} > {b}) = {format_ci(*p, digits=2)}; paired {a} − {b} over {len(shared)} seeds: {diff}")
        early = sorted(set(aucs[a]) & set(aucs[b]))
        if early:
            diff = paired_difference([aucs[a][s] for s in early], [aucs[b][s] for s in early])
            lines.append(f"  - AUC 0–300k: paired {a} − {b} over {len(early)} seeds: {diff}")
    return "\n".join(lines) + "\n"


def curves(variants: dict[str, list[Path]]) -> dict[str, tuple]:
    """{"ER-MRL, LABEL" ("PPO, LABEL" for a run without reservoir): (timesteps (I,), values (S, I))} of each
    variant's model, then the PPO curves of the first variant's test phase, read from the ``curves.csv`` beside each
    ``summary.json``."""
    from ermrl.storage import read_curves_csv

    out, ppo = {}, None
    for label, paths in variants.items():
        if len(paths) > 1:  # joined `ermrl train` runs: their seeds stacked
            _joined_scores(paths)  # refuses runs that cannot be joined
            curve = _train_curves(tuple(paths))
            if curve is None:
                raise FileNotFoundError("No such file or directory: a curves.csv beside one of "
                                        + ", ".join(map(str, paths)))
            out[f"{_run_kind(paths[0])}, {label}"] = curve
            continue
        path, = paths
        ermrl, rows = read_rows(path)
        read = read_curves_csv(path.parent / "curves.csv")
        if ermrl["model"] is None and len(read) == 1:  # an `ermrl train` run: its one model
            ermrl = {**ermrl, "model": next(iter(read))}
        if ermrl["model"] not in read:
            raise ValueError(f"{path.parent / 'curves.csv'} has no curve of {ermrl['model']!r}; give the curves.csv "
                             "written with this summary.json")
        out[f"{ermrl['kind']}, {label}"] = read[ermrl["model"]]
        ppo = {r["model"]: read[r["model"]] for r in rows if r["model"] in read} if ppo is None else ppo
    return {**out, **(ppo or {})}


def parse_variant(text: str) -> tuple[str, list[Path]]:
    """``LABEL=SUMMARY.json`` or ``LABEL=RUN1.json,RUN2.json`` as (label, [paths]); ValueError when it is not."""
    label, sep, paths = text.partition("=")
    if not sep or not label or "" in paths.split(","):
        raise ValueError(f"{text!r} is not LABEL=SUMMARY.json (e.g. '25 units=.../test/summary.json')")
    return label, [Path(path) for path in paths.split(",")]


def env_id(path: Path) -> str:
    """The env id a summary.json names (a test phase's first row's, or an ``ermrl train`` run's); "" if none."""
    first = json.loads(path.read_text())
    return (first if isinstance(first, dict) else first[0]).get("env_id", "")
