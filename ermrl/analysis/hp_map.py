"""The HP map across studies (paper appendix "Reservoir hyperparameters analysis"): the best Φ of several
evolutions on spectral radius × leak rate (both log axes), one colour per env, one panel per number of
reservoirs K (the paper's 1-reservoir and 2-reservoir panels side by side). Each reservoir of a trial is one
point: circles for reservoir 1, triangles for reservoir 2 (then squares, ...).

The figure comes with a CSV of exactly the points it draws (one row per reservoir of a trial), so the data
behind it can be checked or replotted.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import optuna
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from ermrl import storage
from ermrl.analysis.html import markdown_table
from ermrl.analysis.trials import phi, ranked
from ermrl.errors import ConfigError
from ermrl.evolution import record as study_record
from ermrl.evolution.study import ATTR

MARKERS = ("o", "^", "s", "D", "v", "P")
"""Reservoir r (0-based) of a trial is drawn with ``MARKERS[r]``."""
CSV_HEADER = ["study", "envs", "reservoirs", "rank", "trial", "fitness", "reservoir", "sr", "leak_rate"]


@dataclasses.dataclass(frozen=True)
class StudyPoints:
    """What one study contributes to the map: its ``top`` best completed trials (N ≤ top), best first."""

    study: str
    envs: tuple[str, ...]
    """The env id(s) the study evolved on."""
    trials: np.ndarray
    """(N,) int: trial numbers, best fitness first."""
    fitness: np.ndarray
    """(N,) float."""
    sr: np.ndarray
    """(N, K) float: spectral radius of each trial's reservoirs."""
    lr: np.ndarray
    """(N, K) float: leak rate of each trial's reservoirs."""
    bounds: dict
    """{"sr", "lr": (low, high)}: the study's search space, for the axis limits."""

    @property
    def reservoirs(self) -> int:
        """K."""
        return self.sr.shape[1]

    @property
    def env(self) -> str:
        """The colour key: the env id(s) joined by '+'."""
        return "+".join(self.envs)

    @property
    def label(self) -> str:
        return f"{self.env} ({self.study})"


def study_points(study: optuna.Study, top: int = 30) -> StudyPoints:
    """The ``top`` best completed trials of an ``ermrl evolve`` study and their (sr, lr) per reservoir.

    Trials are ranked by trials.ranked (completed, finite fitness, best first) and Φ read by trials.phi. Raises
    ConfigError (one line, naming the study) when it has no completed trial."""
    if top < 1:
        raise ConfigError(f"top must be >= 1, got {top}")
    if ATTR not in study.user_attrs:
        raise ConfigError(f"study {study.study_name!r} was not made by `ermrl evolve` (no '{ATTR}' attribute)")
    config = study_record.decode_study_record(study.user_attrs[ATTR])
    k = config.space.reservoirs
    rows = []
    for t in ranked(study):
        p = phi(t, k)
        if len(p.get("sr", ())) == k and len(p.get("lr", ())) == k:
            rows.append((t.number, t.value, p["sr"], p["lr"]))
        if len(rows) == top:
            break
    if not rows:
        raise ConfigError(f"study {study.study_name!r} has no completed trial; run `ermrl evolve --study "
                          f"{study.study_name}` until one completes")
    numbers, values, sr, lr = zip(*rows)
    return StudyPoints(study=study.study_name, envs=tuple(config.env_ids), trials=np.array(numbers, np.int64),
                       fitness=np.array(values, np.float64), sr=np.array(sr, np.float64).reshape(-1, k),
                       lr=np.array(lr, np.float64).reshape(-1, k),
                       bounds={"sr": tuple(config.space.sr), "lr": tuple(config.space.lr)})


def hp_map_points(studies: list[optuna.Study], top: int = 30) -> list[StudyPoints]:
    """:func:`study_points` of every study, in the given order: what :func:`cross_study_hp_map` draws."""
    return [study_points(s, top) for s in studies]


LEAK_RATE_HEADER = ["study", "envs", "K", "top trials", "median sr", "median leak rate",
                    "leak rate against the other studies of K reservoirs"]


def leak_rate_rows(series: list[StudyPoints]) -> list[list[str]]:
    """One row (``LEAK_RATE_HEADER``) per study: where its top trials lie, their median sr and lr (every
    reservoir pooled, then per reservoir when K > 1), and whether their leak rates are lower or higher than those
    of the other studies with the same K pooled (two-sided Mann–Whitney U test over every reservoir's lr; the
    paper's claim that Ant's top Φ form a cluster of lower leak rates)."""
    from scipy import stats

    def medians(s: StudyPoints, values: np.ndarray) -> str:
        pooled = f"{np.median(values):.3g}"
        if s.reservoirs == 1:
            return pooled
        return pooled + " (" + " / ".join(f"{np.median(values[:, r]):.3g}" for r in range(s.reservoirs)) + ")"

    rows = []
    for s in series:
        others = [o.lr.ravel() for o in series if o is not s and o.reservoirs == s.reservoirs]
        if others:
            rest = np.concatenate(others)
            p = stats.mannwhitneyu(s.lr.ravel(), rest, alternative="two-sided").pvalue
            mine, theirs = np.median(s.lr), np.median(rest)
            side = "lower" if mine < theirs else "higher" if mine > theirs else "the same median"
            contrast = (f"{side} (median {mine:.3g} vs {theirs:.3g}), Mann–Whitney p = "
                        f"{p:.2g}, {s.lr.size} vs {rest.size} reservoirs")
        else:
            contrast = "— (no other study of this K)"
        rows.append([s.study, s.env, str(s.reservoirs), str(len(s.trials)), medians(s, s.sr), medians(s, s.lr),
                     contrast])
    return rows


def leak_rate_table(series: list[StudyPoints]) -> str:
    """:func:`leak_rate_rows` as a Markdown table."""
    return markdown_table(LEAK_RATE_HEADER, leak_rate_rows(series))


def summary_path(path: Path | str) -> Path:
    """Where :func:`cross_study_hp_map` writes the :func:`leak_rate_table` of figure ``path``: the same name
    ending in .md."""
    return Path(path).with_suffix(".md")


def points_csv(path: Path | str) -> Path:
    """Where :func:`cross_study_hp_map` writes the points of figure ``path``: the same name ending in .csv."""
    return Path(path).with_suffix(".csv")


def cross_study_hp_map(studies: list[optuna.Study], path: Path | str, top: int = 30) -> Path:
    """Draws the ``top`` trials of each study on sr × lr (log-log), one colour per env, one panel per K; writes
    the figure to ``path`` (its suffix picks the format, .png by default), the points drawn to
    :func:`points_csv` (columns ``CSV_HEADER``, one row per reservoir of a trial) and their
    :func:`leak_rate_table` to :func:`summary_path`. Returns ``path``."""
    if not studies:
        raise ConfigError("the HP map needs at least one study")
    return draw_hp_map(hp_map_points(studies, top), path, top)


def draw_hp_map(series: list[StudyPoints], path: Path | str, top: int = 30) -> Path:
    """:func:`cross_study_hp_map` of points already read (``hp_map_points(studies, top)``). Returns ``path``."""
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    ks = sorted({s.reservoirs for s in series})
    fig = Figure(figsize=(6.2 * len(ks), 5))
    axes = fig.subplots(1, len(ks), sharex=True, sharey=True, squeeze=False)
    if fmt not in fig.canvas.get_supported_filetypes():
        raise ConfigError(f"cannot write a figure as .{fmt}; give a path ending in .png, .svg or .pdf")
    colours: dict[str, str] = {}
    for ax, k in zip(axes[0], ks):
        handles = []
        for s in (s for s in series if s.reservoirs == k):
            colour = colours.setdefault(s.env, f"C{len(colours) % 10}")
            for r in range(k):
                ax.scatter(s.sr[:, r], s.lr[:, r], color=colour, marker=MARKERS[r % len(MARKERS)], s=32, alpha=0.8,
                           edgecolors="k", linewidths=0.3)
            label = s.label if len(s.trials) >= top else f"{s.label}: all {len(s.trials)} trials"  # fewer than top
            handles.append(Line2D([], [], ls="", marker="o", color=colour, markeredgecolor="k", markeredgewidth=0.3,
                                  label=label))
        if k > 1:
            handles += [Line2D([], [], ls="", marker=MARKERS[r % len(MARKERS)], color="grey", label=f"reservoir {r + 1}")
                        for r in range(k)]
        ax.legend(handles=handles, fontsize=7)
        ax.set_title(f"{k} reservoir{'s' if k > 1 else ''}: the best {top} trials of each study")
        ax.set_xlabel("spectral radius (sr)")
        ax.grid(alpha=0.3, which="both")
    ax = axes[0, 0]
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_ylabel("leak rate")
    for name, setter in (("sr", ax.set_xlim), ("lr", ax.set_ylim)):
        setter(min(s.bounds[name][0] for s in series) / 1.2, max(s.bounds[name][1] for s in series) * 1.2)
    fig.tight_layout()
    with storage.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=fmt)
    storage.write_csv(points_csv(path), CSV_HEADER, (
        [s.study, "+".join(s.envs), s.reservoirs, rank + 1, int(n), repr(float(v)), r + 1, repr(float(s.sr[rank, r])),
         repr(float(s.lr[rank, r]))]
        for s in series for rank, (n, v) in enumerate(zip(s.trials, s.fitness)) for r in range(s.reservoirs)))
    storage.write_text(summary_path(path), f"Top {top} trials of each study (`ermrl analyze hp-map`)\n\n"
                       + leak_rate_table(series))
    return path
