"""Learning-curve figures in the paper's style: mean ± std over seeds, one line per model."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ermrl.storage import atomic_path


def learning_curves(curves: dict[str, tuple[np.ndarray, np.ndarray]], title: str, path: Path | str,
                    formats: tuple[str, ...] = ("png",), xlabel: str = "timesteps") -> list[Path]:
    """Plots {label: (timesteps (I,), values (S, I))} as mean ± std bands over the S seeds.

    Writes ``path`` with each suffix in ``formats`` and returns the files written. The x values may be anything
    on the update grid (e.g. wall seconds), named by ``xlabel``.
    """
    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    for label, (steps, values) in curves.items():
        with warnings.catch_warnings():  # all-NaN columns before a seed's first episode
            warnings.simplefilter("ignore", RuntimeWarning)
            mean, std = np.nanmean(values, axis=0), np.nanstd(values, axis=0)
        n = values.shape[0]
        ax.plot(steps, mean, label=f"{label} (n={n})")
        ax.fill_between(steps, mean - std, mean + std, alpha=0.2)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("mean episode return (last 100 episodes)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    path = Path(path)
    written = []
    for fmt in formats:
        out = path.with_suffix("." + fmt)
        with atomic_path(out) as tmp:
            fig.savefig(tmp, dpi=120, format=fmt)
        written.append(out)
    return written

