"""C3, one reservoir against two on LunarLanderNoVel: the two evolved Φ* trained on the same 10 test seeds.

Reads what ``ermrl reproduce lunarlander lunarlander_1res`` writes:

- the 2-reservoir Φ*'s agents: the ER-MRL row of the test phase's ``summary.json``
  (``docs/data/partial-observability-small/lunarlander-2res/test/``), or, while its PPO baselines still train,
  the ER-MRL model it has kept (``.../test.partial/ermrl.npz``, :func:`ermrl.experiments.checkpoints.read_job`);
- the 1-reservoir Φ*'s agents: the ``summary.json`` of each ``ermrl train`` run under the folder
  (``docs/data/c3-lunarlander/ermrl-1res``), the same seeds (1000-1009), budget (3M steps) and PPO learning
  rate (1e-4).

Prints a Markdown table: each model's n, mean ± std (population std) and IQM [95% CI]
(``ermrl.analysis.statistics.summarize``), then P(2 reservoirs > 1) with its 95% CI (rliable) and the paired
difference 2 − 1 over the shared seeds (SciPy: BCa CI, Wilcoxon p). A pair shares its seed (env noise, policy
initialization), not its reservoirs.

Example:
    .venv/bin/python paper/reservoir_count_summary.py \\
        docs/data/partial-observability-small/lunarlander-2res/test/summary.json docs/data/c3-lunarlander
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def two_reservoirs(test_summary: Path) -> dict[int, float]:
    """{seed: final score} of the ER-MRL model of a test phase (its seeds are 1000, 1001, ...): from its
    ``summary.json``, or from the model kept in its ``.partial/`` folder (an ``.npz``)."""
    from ermrl.experiments.evaluation import FIRST_TEST_SEED

    if test_summary.suffix == ".npz":
        from ermrl.experiments import checkpoints

        identity, results = checkpoints.read_job(test_summary)
        if identity.get("job") != "ermrl" or len(identity.get("labels", [])) != 1:
            raise ValueError(f"{test_summary} is not the ER-MRL model of a test phase of one learning rate")
        return {int(s): float(f) for s, f in zip(results.seeds, results.fitness()) if f == f}
    rows = [r for r in json.loads(test_summary.read_text()) if r["kind"] == "ER-MRL"]
    if len(rows) != 1:
        raise ValueError(f"{test_summary} has {len(rows)} ER-MRL rows; give a test phase of one learning rate")
    return {FIRST_TEST_SEED + i: v for i, v in enumerate(rows[0]["per_seed"]) if v is not None}


def one_reservoir(folder: Path) -> dict[int, float]:
    """{seed: final score} over every ``ermrl train`` part under ``folder`` (``*/summary.json``)."""
    scores = {}
    for path in sorted(folder.glob("*/summary.json")):
        d = json.loads(path.read_text())
        scores.update({int(s): float(f) for s, f in zip(d["seeds"], d["fitness"], strict=True)})
    if not scores:
        raise ValueError(f"no */summary.json under {folder}; run `ermrl reproduce lunarlander_1res`")
    return scores


def table(two: dict[int, float], one: dict[int, float]) -> str:
    from ermrl.analysis.statistics import format_ci, paired_difference, probability_of_improvement, summarize

    lines = ["| model | n | mean ± std | IQM [95% CI] |", "|---|---|---|---|"]
    for name, scores in (("2 reservoirs", two), ("1 reservoir", one)):
        s = summarize(list(scores.values()))
        lines.append(f"| {name} | {s.n} | {s.mean:.1f} ± {s.std:.1f} | {format_ci(s.iqm, s.iqm_low, s.iqm_high)} |")
    p = probability_of_improvement(list(two.values()), list(one.values()))
    shared = sorted(set(two) & set(one))
    diff = paired_difference([two[s] for s in shared], [one[s] for s in shared])
    lines += ["", f"P(2 reservoirs > 1) = {format_ci(*p, digits=2)}; paired 2 − 1 over {len(shared)} seeds: {diff}"]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("test_summary", type=Path, help="the 2-reservoir test phase's summary.json, or the ER-MRL "
                                                        "model its .partial/ folder keeps (ermrl.npz)")
    parser.add_argument("one_reservoir", type=Path, help="folder of the 1-reservoir `ermrl train` parts")
    args = parser.parse_args(argv)
    try:
        sys.stdout.write(table(two_reservoirs(args.test_summary), one_reservoir(args.one_reservoir)))
    except (OSError, ValueError) as e:
        parser.error(str(e))  # exit code 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
