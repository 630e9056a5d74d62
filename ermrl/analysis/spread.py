"""The Φ spread per generation of a CMA-ES study, as a table and a figure, with the convergence stop marked
(:mod:`ermrl.evolution.convergence` defines the spread and the rule)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ermrl import storage
from ermrl.evolution.convergence import Convergence
from ermrl.model_labels import PHI_NAMES


Distributions = dict[int, dict[str, tuple[float, float]]]
"""{generation: {parameter: (mean Φ value, spread in decades)}}, as ``convergence.centers_and_spreads``."""


def rows(dists: Distributions) -> tuple[list[str], list[list]]:
    """(header, rows) of the table: generation, then each parameter's spread (decades) and mean."""
    names = sorted({n for d in dists.values() for n in d})
    header = ["generation"] + [f"{n}_spread_decades" for n in names] + [f"{n}_mean" for n in names]
    table = [[g] + [f"{dists[g][n][1]:.6g}" for n in names] + [f"{dists[g][n][0]:.6g}" for n in names]
             for g in sorted(dists)]
    return header, table


def write_table(path: Path, dists: Distributions) -> Path:
    return storage.write_csv(path, *rows(dists))


def figure(dists: Distributions, rule: Convergence, stop: int | None, title: str, path: Path) -> Path:
    """Each parameter's spread (log axis) per generation, the rule's width as a dashed line and the stop
    generation as a vertical line."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    generations = sorted(dists)
    for name in sorted({n for d in dists.values() for n in d}):
        hp, _, k = name.partition("_")
        ax.plot(generations, [dists[g][name][1] for g in generations], label=f"{PHI_NAMES.get(hp, hp)} {k}".strip())
    ax.axhline(rule.width, color="0.4", ls="--", lw=1, label=f"width {rule.width:g} decades")
    if stop is not None:
        ax.axvline(stop, color="C3", lw=1, label=f"converged: generation {stop} ({rule.generations} in a row)")
    ax.set_yscale("log")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("generation")
    ax.set_ylabel("spread of the search distribution (decades, 1 std)")
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return storage.save_figure(fig, path)


def summary(dists: Distributions, stop: int | None) -> dict:
    """The distribution at the stop and at the last generation: {"stop": {...}, "last": {...}} of
    {parameter: {"mean": Φ value, "spread": decades}}, with their generations."""
    def at(g):
        return None if g is None else {"generation": g, **{n: {"mean": m, "spread": s} for n, (m, s) in dists[g].items()}}

    return {"stop": at(stop), "last": at(max(dists) if dists else None)}


def shift(dists: Distributions, stop: int) -> dict[str, float]:
    """{parameter: |log10(mean at the last generation / mean at ``stop``)|}, in decades."""
    last = max(dists)
    return {n: float(abs(np.log10(dists[last][n][0] / dists[stop][n][0]))) for n in dists[stop]}
