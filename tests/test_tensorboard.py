"""TensorBoard logs (`--tensorboard DIR` on `ermrl train` and `ermrl test`), read back with TensorBoard's own
reader (EventAccumulator, from the `tensorboard` package of the test extra)."""

import csv
import dataclasses

import numpy as np
import optuna
import pytest
from optuna.trial import create_trial
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from ermrl.analysis import tensorboard
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import make_sampler, open_study
from ermrl.evolution.record import encode_study_record
from ermrl.training import TrainConfig
from ermrl.training.results import WALL_S, Episodes, Results

from cli_runs import ermrl

optuna.logging.set_verbosity(optuna.logging.WARNING)


def scalars(run_dir) -> dict[str, tuple[list[int], list[float]]]:
    """{tag: (steps, values)} of one TensorBoard run folder."""
    acc = EventAccumulator(str(run_dir))
    acc.Reload()
    return {tag: ([e.step for e in acc.Scalars(tag)], [e.value for e in acc.Scalars(tag)])
            for tag in acc.Tags()["scalars"]}


def curves_csv(path) -> dict[tuple[str, int], dict[int, float]]:
    """{(model, seed): {timestep: mean return of the last 100 episodes}}, empty cells left out."""
    out = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if row["mean_return_100"]:
                out.setdefault((row["model"], int(row["seed"])), {})[int(row["timestep"])] = float(row["mean_return_100"])
    return out


def test_train_logs_each_agents_curves(tmp_path):
    logs, run = tmp_path / "tb", tmp_path / "run"
    r = ermrl("train", "--env", "CartPole-v1", "--timesteps", "4096", "--seeds", "2", "--tensorboard", str(logs),
              "--out", str(run), "--quiet")
    assert r.returncode == 0, r.stderr
    assert f"TensorBoard: tensorboard --logdir {logs}" in r.stdout
    assert sorted(p.name for p in logs.iterdir()) == ["ER-MRL_1_reservoir_seed0", "ER-MRL_1_reservoir_seed1"]
    expected = curves_csv(run / "curves.csv")
    assert set(expected) == {("ER-MRL (1 reservoir)", 0), ("ER-MRL (1 reservoir)", 1)}
    with open(run / "episodes.csv", newline="") as f:
        episodes = list(csv.DictReader(f))
    for seed in (0, 1):
        logged = scalars(logs / f"ER-MRL_1_reservoir_seed{seed}")
        assert {"rollout/ep_rew_mean", "rollout/ep_len_mean", "time/fps", "train/value_loss",
                "train/entropy_loss", "train/approx_kl", "train/clip_fraction",
                "train/policy_gradient_loss"} <= set(logged)
        steps, values = logged["rollout/ep_rew_mean"]
        curve = expected[("ER-MRL (1 reservoir)", seed)]
        assert steps == [2048, 4096] == sorted(curve)
        assert values == pytest.approx([curve[s] for s in steps], rel=1e-5)
        # CartPole's reward is 1 per step: an episode's length is its return
        assert logged["rollout/ep_len_mean"][1] == pytest.approx(values, rel=1e-5)
        last = [float(e["length"]) for e in episodes if int(e["seed"]) == seed][-100:]
        assert logged["rollout/ep_len_mean"][1][-1] == pytest.approx(np.mean(last), rel=1e-6)
        fps_steps, fps = logged["time/fps"]
        assert fps_steps == [2048, 4096] and all(v > 0 for v in fps)
        assert all(v < 0 for v in logged["train/entropy_loss"][1])  # minus the entropy, as SB3 logs it


def make_results(lengths: list[list[int]], ends: list[list[int]]) -> Results:
    """Results of agents whose episodes (one list per agent) have the given lengths and end steps (2 updates of 100)."""
    eps = [Episodes(np.array(t, np.int64), np.array(n, np.float64) * 2.0, np.array(n, np.int64))
           for t, n in zip(ends, lengths)]
    a = len(eps)
    return Results(env_id="X-v0", total_timesteps=200, timesteps_per_iteration=100, seeds=np.arange(7, 7 + a),
                   phi={k: np.ones((a, 1)) for k in ("sr", "lr", "iss")}, learning_rate=np.full(a, 3e-4),
                   episodes=eps, finite=np.ones(a, bool),
                   metrics={"entropy": np.full((a, 2), 0.5), WALL_S: np.tile([0.5, 0.8], (a, 1))}, compile_s=1.0,
                   train_s=2.0)


def test_write_results_in_process(tmp_path):
    """No point before an agent's first episode; lengths averaged like returns; fps from the update times; a second
    write into the same folder makes new run folders instead of mixing events."""
    results = make_results([[5, 7, 9], [4]], [[150, 160, 190], [20]])
    folders = tensorboard.write_results(tmp_path, results, "ER-MRL (1 reservoir)")
    assert [f.name for f in folders] == ["ER-MRL_1_reservoir_seed7", "ER-MRL_1_reservoir_seed8"]
    first, second = scalars(folders[0]), scalars(folders[1])
    assert first["rollout/ep_rew_mean"] == ([200], [pytest.approx(14.0)])  # no episode by step 100
    assert first["rollout/ep_len_mean"] == ([200], [pytest.approx(7.0)])
    assert second["rollout/ep_len_mean"] == ([100, 200], [pytest.approx(4.0), pytest.approx(4.0)])
    assert first["time/fps"] == ([100, 200], [pytest.approx(200.0), pytest.approx(250.0)])
    assert first["train/entropy_loss"] == ([100, 200], [pytest.approx(-0.5)] * 2)
    saved_before = dataclasses.replace(results, metrics={"entropy": results.metrics["entropy"]})  # no update times
    again = tensorboard.write_results(tmp_path, saved_before, "ER-MRL (1 reservoir)")
    assert [f.name for f in again] == ["ER-MRL_1_reservoir_seed7_2", "ER-MRL_1_reservoir_seed8_2"]
    assert "time/fps" not in scalars(again[0]) and "train/entropy_loss" in scalars(again[0])


@pytest.mark.parametrize("groups", [[], ["--agents-per-run", "1"]], ids=["whole", "one-agent-groups"])
def test_test_phase_logs_every_model(groups, tmp_path):
    """`ermrl test --tensorboard` on a hand-made study: one run per model and seed, ep_rew_mean = curves.csv, and the
    PPO diagnostics under train/* as `ermrl train --tensorboard` writes them; time/fps for every agent also when
    each model trains one agent at a time (the agents of a model then have their own update times)."""
    url = str(tmp_path / "s.log")
    space = SearchSpace(fixed_iss=1.0)
    config = EvolveConfig(train=TrainConfig(env_id="CartPole-v1", total_timesteps=2048), space=space, trials=2, seeds=2,
                          sampler="random")
    study = open_study(url, "s", make_sampler("random", 6, 0), encode_study_record(config))
    study.add_trial(create_trial(params={"sr": 0.9, "lr": 0.5}, distributions=space.distributions(), value=100.0))
    logs = tmp_path / "tb"
    r = ermrl("test", "--study", "s", "--storage", url, "--out", str(tmp_path / "out"), "--seeds", "2",
              "--timesteps", "2048", "--tensorboard", str(logs), *groups, "--quiet")
    assert r.returncode == 0, r.stderr
    expected = curves_csv(tmp_path / "out" / "test" / "curves.csv")
    models = sorted({m for m, _ in expected})
    assert len(models) == 2 and models[1] == "PPO (same observation)"
    for model, seed in expected:
        logged = scalars(logs / tensorboard.run_name(model, seed))
        steps, values = logged["rollout/ep_rew_mean"]
        assert steps == sorted(expected[model, seed])
        assert values == pytest.approx([expected[model, seed][s] for s in steps], rel=1e-5)
        assert logged["time/fps"][0] == [2048] and logged["time/fps"][1][0] > 0
        # the same tags as `train --tensorboard`: episode lengths and the PPO update's diagnostics, one per update
        assert {"rollout/ep_len_mean", "train/policy_gradient_loss", "train/value_loss", "train/entropy_loss",
                "train/approx_kl", "train/clip_fraction"} <= set(logged)
        assert logged["train/value_loss"][0] == [2048] and logged["train/value_loss"][1][0] > 0
        assert logged["train/entropy_loss"][1][0] < 0  # minus the entropy of a 2-action policy
        lengths = logged["rollout/ep_len_mean"][1]
        assert all(8 <= v <= 500 for v in lengths)  # CartPole episodes: at least 8 steps, at most 500
    assert len(list(logs.iterdir())) == 4 and {s for _, s in expected} == {1000, 1001}


@pytest.mark.parametrize("command", [["train", "--env", "CartPole-v1"], ["test", "--study", "s"]])
def test_tensorboard_at_a_file_is_one_line_and_exit_code_2(command, tmp_path):
    (tmp_path / "file").write_text("x")
    r = ermrl(*command, "--tensorboard", "file", cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr == (f"ermrl {command[0]}: error: --tensorboard file is a file, not a folder; give a folder "
                        "path (it is created if missing)\n")
    r = ermrl(*command, "--tensorboard", "file/tb", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr.startswith(f"ermrl {command[0]}: error: --tensorboard file/tb: its parent "
                                                     "file is a file, not a folder"), r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]  # nothing trained or written


@pytest.mark.parametrize("command", ["train", "test"])
def test_help_shows_the_flag(command):
    r = ermrl(command, "--help")
    assert r.returncode == 0 and "--tensorboard DIR" in r.stdout and "rollout/ep_rew_mean" in r.stdout


def test_groups_joined_keep_each_groups_update_times(tmp_path):
    """A model joined from groups of agents (Results.concat) keeps each group's own update times, so each agent's
    time/fps is its group's; joined with a group saved before update times were kept, it has no time/fps (rather
    than one made up for the old group) and keeps the diagnostics that every group has."""
    a, b = make_results([[5], [4]], [[150], [20]]), make_results([[6]], [[30]])
    b.metrics[WALL_S] = np.array([[1.0, 2.0]])
    b.seeds = np.array([9])
    folders = tensorboard.write_results(tmp_path / "new", Results.concat([a, b]), "ER-MRL")
    assert [scalars(f)["time/fps"][1] for f in folders] == [[pytest.approx(200.0), pytest.approx(250.0)]] * 2 + \
        [[pytest.approx(100.0), pytest.approx(100.0)]]
    old = dataclasses.replace(b, metrics={"entropy": b.metrics["entropy"]})
    joined = Results.concat([a, old])
    assert set(joined.metrics) == {"entropy"} and joined.metrics["entropy"].shape == (3, 2)
    assert "time/fps" not in scalars(tensorboard.write_results(tmp_path / "old", joined, "ER-MRL")[2])
