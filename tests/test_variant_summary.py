"""benchmarks/variant_summary.py (C14, C15): reservoir variants' test phases, compared seed by seed."""

import json
import subprocess
import sys
from pathlib import Path

from ermrl.analysis.statistics import format_ci, paired_difference, probability_of_improvement, summarize

SCRIPT = Path(__file__).resolve().parent.parent / "benchmarks" / "variant_summary.py"
SMALL = [500.0, 480.0, 210.0, 30.0, 500.0, 420.0, 190.0, 100.0, 440.0, 230.0]
LARGE = [100.0, None, 210.0, 50.0, 180.0, 20.0, 90.0, 100.0, 40.0, 230.0]  # seed 1001 diverged
PPO = [40.0, 35.0, 52.0, 28.0, 44.0, 39.0, 31.0, 47.0, 36.0, 41.0]


def _run(*args):
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True)


def _summary(folder: Path, *ermrl_rows) -> Path:
    folder.mkdir(parents=True)
    path = folder / "summary.json"
    path.write_text(json.dumps(
        [*({"model": "ER-MRL lr 0.0001", "kind": "ER-MRL", "per_seed": r, "auc_early_mean": 12.5} for r in ermrl_rows),
         {"model": "PPO (same observation)", "kind": "PPO", "per_seed": PPO, "auc_early_mean": 3.0}]))
    return path


def test_table_gives_every_variant_and_pairs_their_seeds(tmp_path):
    small, large = _summary(tmp_path / "small", SMALL), _summary(tmp_path / "large", LARGE)
    done = _run(f"100 units={small}", f"1000 units={large}", "--compare", "100 units", "1000 units")
    assert done.returncode == 0, done.stderr
    s = summarize(SMALL)
    assert f"| ER-MRL, 100 units | 10 | {s.mean:.1f} ± {s.std:.1f} | {format_ci(s.iqm, s.iqm_low, s.iqm_high)} | 12.5 |" \
        in done.stdout
    kept = [v for v in LARGE if v is not None]
    assert f"| ER-MRL, 1000 units | 9 | {summarize(kept).mean:.1f} ± {summarize(kept).std:.1f} |" in done.stdout
    assert f"| PPO (same observation) | 10 | {summarize(PPO).mean:.1f} ± {summarize(PPO).std:.1f} |" in done.stdout
    p = format_ci(*probability_of_improvement(SMALL, kept), digits=2)
    paired = paired_difference([v for v, w in zip(SMALL, LARGE) if w is not None], kept)
    assert f"- P(100 units > 1000 units) = {p}; paired 100 units − 1000 units over 9 seeds: {paired}" in done.stdout


def test_bad_input_is_one_line_and_exit_code_2(tmp_path):
    small = _summary(tmp_path / "small", SMALL)
    two_rates = _summary(tmp_path / "two", SMALL, LARGE)
    cases = [
        ((f"a={two_rates}",), f"{two_rates} has 2 ER-MRL rows; give a test phase of one learning rate"),
        ((f"a={small}", "--compare", "a", "b"), "--compare names 'b', which is none of the variants (a)"),
        ((f"a={small}", f"a={small}"), "two variants are named 'a'; name each once"),
        ((str(small),), f"{str(small)!r} is not LABEL=SUMMARY.json"),
        ((f"a={tmp_path / 'missing.json'}",), "No such file or directory"),
    ]
    for args, message in cases:
        done = _run(*args)
        assert done.returncode == 2, (args, done.stderr)
        last = done.stderr.strip().splitlines()[-1]  # after argparse's usage lines: the one-line error
        assert last.startswith("variant_summary.py: error: ") and message in last, (args, done.stderr)
        assert done.stdout == ""
