"""Peer agreement, paired: the two training stacks (SB3 + ReservoirPy's pipeline, ermrl) on the *same* reservoirs.

Reads the JSON files that ``ermrl reproduce peer`` writes under
``docs/data/partial-observability-paper/peer/`` and pairs them seed by seed:

- ReservoirPy's draws: ``reference-bernoulli*.json`` (SB3 on ReservoirPy's reservoir for each seed) against
  ``ermrl-ppo-draws-*.json``'s ``reservoirpy`` entry (ermrl's PPO on those very reservoirs,
  ``paper/peer_reservoir_draws.py``);
- ermrl's draws: ``reference-bernoulli-ermrl-weights-*.json`` (SB3 on ermrl's reservoir for each seed,
  ``reference_pipeline.py --weights ermrl``) against ``ermrl-bernoulli-fresh/summary.json`` (``ermrl train``).

A pair shares the reservoir; policy initialization, minibatch order and env noise differ (each stack has its own
random streams). Prints one Markdown row per draw set and one pooled: n, each stack's mean ± std (population
std) and IQM [95% CI] (``ermrl.analysis.statistics.summarize``), the mean paired difference SB3 − ermrl with a
95% bootstrap CI (SciPy, BCa, 10,000 resamples) and the Wilcoxon signed-rank p-value (SciPy).

Example:
    .venv/bin/python paper/peer_summary.py docs/data/partial-observability-paper/peer
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def _by_seed(seeds, fitness) -> dict[int, float]:
    return {int(s): float(f) for s, f in zip(seeds, fitness, strict=True)}


def load_pairs(folder: Path) -> dict[str, tuple[dict[int, float], dict[int, float]]]:
    """{draw set: (SB3 fitness by seed, ermrl fitness by seed)}, each restricted to the seeds both stacks ran."""
    sb3_rpy, sb3_erm, erm_rpy, erm_erm = {}, {}, {}, {}
    for path in sorted(folder.glob("reference-bernoulli*.json")):
        d = json.loads(path.read_text())
        (sb3_erm if d.get("weights") == "ermrl" else sb3_rpy).update(_by_seed(d["seeds"], d["fitness"]))
    for path in sorted(folder.glob("ermrl-ppo-draws-*.json")):
        d = json.loads(path.read_text())
        if "reservoirpy" in d:
            erm_rpy.update(_by_seed(d["seeds"], d["reservoirpy"]["fitness"]))
    fresh = folder / "ermrl-bernoulli-fresh" / "summary.json"
    if fresh.exists():
        d = json.loads(fresh.read_text())
        erm_erm.update(_by_seed(d["seeds"], d["fitness"]))
    pairs = {}
    for name, sb3, erm in (("ReservoirPy's draws", sb3_rpy, erm_rpy), ("ermrl's draws", sb3_erm, erm_erm)):
        common = sorted(set(sb3) & set(erm))
        if common:
            pairs[name] = ({s: sb3[s] for s in common}, {s: erm[s] for s in common})
    return pairs


def row(name: str, sb3: np.ndarray, erm: np.ndarray, seeds: str) -> str:
    """One Markdown row: name | seeds | n | SB3 | ermrl | SB3 − ermrl [95% CI] | Wilcoxon p."""
    from ermrl.analysis.statistics import format_ci, paired_difference, summarize

    d = paired_difference(sb3, erm)  # Wilcoxon drops ties (both at the 500 ceiling)

    def cell(x):
        s = summarize(x)
        return f"{s.mean:.1f} ± {s.std:.1f}; IQM {format_ci(s.iqm, s.iqm_low, s.iqm_high)}"

    return (f"| {name} | {seeds} | {d.n} | {cell(sb3)} | {cell(erm)} | "
            f"{d.mean:+.1f} [{d.low:+.1f}, {d.high:+.1f}] | {d.p:.2f} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folder", type=Path, help="the peer folder (docs/data/partial-observability-paper/peer)")
    a = p.parse_args(argv)
    if not a.folder.is_dir():
        p.error(f"{a.folder} is not a folder: give the peer results' folder, e.g. "
                "docs/data/partial-observability-paper/peer")
    pairs = load_pairs(a.folder)
    if not pairs:
        p.error(f"no paired results in {a.folder}: run `ermrl reproduce peer` first")
    print("| reservoirs | seeds | n | SB3 + ReservoirPy pipeline | ermrl | SB3 − ermrl, paired [95% CI] | Wilcoxon p |")
    print("|---|---|---|---|---|---|---|")
    pooled_sb3, pooled_erm = [], []
    for name, (sb3, erm) in pairs.items():
        seeds = sorted(sb3)
        span = f"{seeds[0]}–{seeds[-1]}" if seeds == list(range(seeds[0], seeds[-1] + 1)) else ", ".join(map(str, seeds))
        x, y = np.array([sb3[s] for s in seeds]), np.array([erm[s] for s in seeds])
        print(row(name, x, y, span))
        pooled_sb3.append(x)
        pooled_erm.append(y)
    if len(pairs) > 1:
        print(row("both, pooled", np.concatenate(pooled_sb3), np.concatenate(pooled_erm), "all above"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
