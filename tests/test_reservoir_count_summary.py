"""paper/reservoir_count_summary.py (C3): the 2-reservoir test phase against the 1-reservoir `ermrl train` parts."""

import json
from pathlib import Path

import numpy as np

from ermrl.analysis.statistics import format_ci, paired_difference, probability_of_improvement, summarize
from ermrl.experiments import checkpoints
from ermrl.training.results import Episodes, Results

from cli_runs import script

SCRIPT = Path(__file__).resolve().parent.parent / "paper" / "reservoir_count_summary.py"
TWO = [150.0, 200.0, 210.0, -30.0, 180.0, 220.0, 190.0, 100.0, 240.0, 230.0]
ONE = [100.0, 120.0, 210.0, -50.0, 180.0, 20.0, 90.0, 100.0, 40.0, 230.0]


def _run(*args):
    return script(SCRIPT, *args)


def _write(tmp_path, ermrl_rows):
    tmp_path.mkdir(parents=True, exist_ok=True)
    test = tmp_path / "summary.json"
    test.write_text(json.dumps([*({"kind": "ER-MRL", "per_seed": r} for r in ermrl_rows),
                                {"kind": "PPO", "per_seed": [-90.0] * 10}]))
    folder = tmp_path / "one"
    for first in (1000, 1005):  # two `ermrl train` parts of 5 seeds
        (folder / f"ermrl-1res-{first}").mkdir(parents=True)
        (folder / f"ermrl-1res-{first}" / "summary.json").write_text(json.dumps(
            {"seeds": list(range(first, first + 5)), "fitness": ONE[first - 1000:first - 995]}))
    return test, folder


def test_table_pairs_the_seeds_of_both_models(tmp_path):
    test, folder = _write(tmp_path, [TWO])
    done = _run(test, folder)
    assert done.returncode == 0, done.stderr
    two, one = summarize(TWO), summarize(ONE)
    assert f"| 2 reservoirs | 10 | {two.mean:.1f} ± {two.std:.1f} | {format_ci(two.iqm, two.iqm_low, two.iqm_high)} |" \
        in done.stdout
    assert f"| 1 reservoir | 10 | {one.mean:.1f} ± {one.std:.1f} |" in done.stdout
    p = format_ci(*probability_of_improvement(TWO, ONE), digits=2)
    assert f"P(2 reservoirs > 1) = {p}; paired 2 − 1 over 10 seeds: {paired_difference(TWO, ONE)}" in done.stdout


def test_bad_input_is_one_line_and_exit_code_2(tmp_path):
    test, folder = _write(tmp_path, [TWO, ONE])  # a test phase at two learning rates
    done = _run(test, folder)
    assert done.returncode == 2
    assert f"{test} has 2 ER-MRL rows; give a test phase of one learning rate" in done.stderr
    done = _run(tmp_path / "missing.json", folder)
    assert done.returncode == 2 and "No such file or directory" in done.stderr
    test, _ = _write(tmp_path / "one-rate", [TWO])
    done = _run(test, tmp_path / "empty")
    assert done.returncode == 2
    assert "no */summary.json under" in done.stderr and "`ermrl reproduce lunarlander_1res`" in done.stderr


def _kept_model(folder, job, labels, finals):
    """A test phase's kept model as `ermrl test` writes it (checkpoints.save_job): each seed's last 10 episodes
    return its final score, after 5 episodes that do not count."""
    seeds = np.arange(1000, 1000 + len(finals))
    episodes = [Episodes(np.arange(1, 16) * 1000, np.r_[np.full(5, -500.0), np.full(10, f)], np.full(15, 1000))
                for f in finals]
    results = Results(env_id="LunarLanderNoVel-v3", total_timesteps=15000, timesteps_per_iteration=1000, seeds=seeds,
                      phi={}, learning_rate=np.full(len(finals), 1e-4), episodes=episodes,
                      finite=np.ones(len(finals), bool), metrics={}, compile_s=0.0, train_s=0.0)
    identity = {"job": job, "labels": labels, "seeds": seeds.tolist()}
    return checkpoints.save_job(folder, job, identity, results)


def test_the_two_reservoir_model_kept_by_an_unfinished_test_phase_gives_the_same_table(tmp_path):
    test, folder = _write(tmp_path, [TWO])
    kept = _kept_model(tmp_path / "test.partial", "ermrl", ["ER-MRL (trial 6)"], TWO)
    from_summary, from_kept = _run(test, folder), _run(kept, folder)
    assert from_kept.returncode == 0, from_kept.stderr
    assert from_kept.stdout == from_summary.stdout
    ppo = _kept_model(tmp_path / "test.partial", "ppo", ["PPO (same observation)"], ONE)
    done = _run(ppo, folder)
    assert done.returncode == 2
    assert f"{ppo} is not the ER-MRL model of a test phase of one learning rate" in done.stderr
