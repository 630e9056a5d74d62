"""Baselines of the normalized score: episodic constants from real envs, the table, and nScore arithmetic."""

import dataclasses
import json

import numpy as np
import pytest

from ermrl.errors import ConfigError
from ermrl.experiments import baselines as bl


def test_random_cartpole_constants_are_episodic():
    r = bl.random_scores("CartPole-v1", episodes=100)
    assert 15 < r.mean_return < 30  # about 22 steps of reward 1, not about 1
    assert r.mean_step_reward == 1.0 and r.std_return > 0 and r.episodes == 100
    assert bl.random_scores("CartPoleNoVel-v1", episodes=100) == r  # masking changes no reward


def test_nscore_arithmetic_and_both_normalizations():
    b = bl.Baseline("E", random_return=-200.0, random_step_reward=-0.2, ppo=800.0)
    assert bl.nscore(800.0, b) == 1.0 and bl.nscore(-200.0, b) == 0.0
    assert bl.nscore(300.0, b) == pytest.approx(0.5)
    assert bl.nscore(300.0, b, "reference") == pytest.approx((300.0 + 0.2) / (800.0 + 0.2))
    np.testing.assert_allclose(bl.nscore(np.array([-200.0, 800.0]), b), [0.0, 1.0])
    with pytest.raises(ConfigError, match="PPO scores the same as the random agent"):
        bl.nscore(1.0, bl.Baseline("E", 5.0, 5.0, 5.0))
    with pytest.raises(ConfigError, match="unknown normalization 'per-step'"):
        bl.nscore(1.0, b, "per-step")


def test_table_round_trip_user_over_shipped(tmp_path):
    shipped = bl.load_table(tmp_path / "none.json")
    assert shipped.random("HalfCheetah-v5") is not None  # ships with the package
    table = bl.load_table(tmp_path / "t.json")
    table.add_random("HalfCheetah-v5", bl.RandomScore(10, -1.5, 0.5, -0.0015), "ermrl baselines --env HalfCheetah-v5")
    table.add_ppo("HalfCheetah-v5", bl.PPOScore(2, 4096, 3e-4, 12.0, 1.0, (11.0, 13.0)), "cmd")
    bl.save_table(table, tmp_path / "t.json")
    saved = json.loads((tmp_path / "t.json").read_text())
    assert list(saved["random"]) == ["HalfCheetah-v5"] and len(saved["ppo"]) == 1  # only the user's entries
    assert saved["random"]["HalfCheetah-v5"]["command"] == "ermrl baselines --env HalfCheetah-v5"
    again = bl.load_table(tmp_path / "t.json")
    assert again.random("HalfCheetah-v5").mean_return == -1.5  # the user's entry wins
    assert again.ppo("HalfCheetah-v5", 4096, 2, 3e-4).per_seed == (11.0, 13.0)
    assert again.ppo("HalfCheetah-v5", 4096, 3, 3e-4) is None
    assert bl.resolve("HalfCheetah-v5", 4096, 2, 3e-4, again) == bl.Baseline("HalfCheetah-v5", -1.5, -0.0015, 12.0)



def test_ppo_entries_are_kept_apart_by_their_ppo_settings(tmp_path):
    """An evolution with other PPO settings (--gamma, --n-steps, ...) normalizes by a PPO trained with them; an entry
    written before settings were recorded is SB3's defaults."""
    table = bl.load_table(tmp_path / "t.json")
    table.add_ppo("E-v1", bl.PPOScore(2, 4096, 3e-4, 12.0, 1.0, (11.0, 13.0)), "cmd")
    table.add_ppo("E-v1", bl.PPOScore(2, 4096, 3e-4, 30.0, 1.0, (29.0, 31.0), {"gamma": 0.9}), "cmd --gamma 0.9")
    bl.save_table(table, tmp_path / "t.json")
    saved = json.loads((tmp_path / "t.json").read_text())
    del saved["ppo"][0]["settings"]  # as a table written before settings were recorded
    (tmp_path / "t.json").write_text(json.dumps(saved))
    again = bl.load_table(tmp_path / "t.json")
    assert again.ppo("E-v1", 4096, 2, 3e-4).mean == 12.0
    assert again.ppo("E-v1", 4096, 2, 3e-4, {"gamma": 0.9}).mean == 30.0
    assert again.ppo("E-v1", 4096, 2, 3e-4, {"gamma": 0.8}) is None
    from ermrl.ppo.config import FAST, SB3_DEFAULTS

    assert bl.ppo_settings(SB3_DEFAULTS) == {} and bl.ppo_settings(dataclasses.replace(SB3_DEFAULTS, learning_rate=1e-4)) == {}
    assert bl.ppo_settings(FAST) == {"n_envs": 8, "n_steps": 256, "batch_size": 512, "n_epochs": 4}


def test_an_entrys_recorded_command_gives_back_its_settings():
    """The command kept with a PPO entry reruns it: parsed again, its flags give the same settings."""
    import shlex

    from ermrl.cli import configs, parse
    from ermrl.experiments.baseline_runs import _flags
    from ermrl.ppo.config import PPOConfig

    for ppo in (PPOConfig(gamma=0.9, n_steps=512, normalize=True, use_sde=True, sde_sample_freq=4),
                PPOConfig(hidden=(64,), activation="relu", ortho_init=False)):  # rl-zoo's recurrent Pendulum policy
        settings = bl.ppo_settings(ppo)
        argv = shlex.split(" ".join(["baselines", "--env", "Pendulum-v1", *_flags(settings)]))
        assert bl.ppo_settings(configs.ppo_config(parse(argv))) == settings


def test_a_damaged_table_is_a_one_line_error(tmp_path):
    path = tmp_path / "t.json"
    path.write_text('{"random": [}')
    with pytest.raises(ConfigError) as e:
        bl.load_table(path)
    assert str(e.value).startswith(f"baselines table {path} is damaged (")
    assert str(e.value).endswith("; fix it or delete it and rerun `ermrl baselines`")


def test_ppo_fitness_trains_the_evolutions_seeds():
    p = bl.ppo_fitness("CartPole-v1", 2048, 2)
    assert len(p.per_seed) == 2 and all(v is not None and v > 5 for v in p.per_seed)
    assert p.mean == pytest.approx(np.mean(p.per_seed)) and p.settings == {}
    other = bl.ppo_fitness("CartPole-v1", 2048, 2, settings={"n_envs": 2, "n_steps": 512, "gamma": 0.9})
    assert other.settings == {"n_envs": 2, "n_steps": 512, "gamma": 0.9}
    assert other.per_seed != p.per_seed  # the settings reach the training (same seeds; training is deterministic)


def test_baselines_command_stores_both_constants_with_provenance(tmp_path):
    import ermrl
    from cli_runs import ermrl as cli

    table = tmp_path / "t.json"
    r = cli("baselines", "--env", "CartPole-v1", "--timesteps", "2048", "--seeds", "1", "--random-episodes", "50",
            "--table", table, "--recompute", "--quiet")
    assert r.returncode == 0, r.stderr
    saved = json.loads(table.read_text())
    random = saved["random"]["CartPole-v1"]
    assert 15 < random["mean_return"] < 30 and random["episodes"] == 50
    ppo = saved["ppo"][0]
    assert (ppo["env_id"], ppo["timesteps"], ppo["seeds"], ppo["learning_rate"]) == ("CartPole-v1", 2048, 1, 3e-4)
    for entry in (random, ppo):
        assert entry["ermrl_version"] == ermrl.__version__ and entry["date"] and entry["command"].startswith("ermrl baselines")
    assert "CartPole-v1: random" in r.stdout
    # without --recompute, the shipped random constant is used and only what is missing is computed
    other = tmp_path / "other.json"
    r = cli("baselines", "--env", "CartPole-v1", "--timesteps", "2048", "--seeds", "1", "--table", other, "--quiet")
    assert r.returncode == 0, r.stderr
    assert json.loads(other.read_text())["random"] == {} and "random agent" not in r.stdout
    # other PPO settings are another entry, whose command names them
    r = cli("baselines", "--env", "CartPole-v1", "--timesteps", "2048", "--seeds", "1", "--table", other, "--n-steps",
            "512", "--gamma", "0.9", "--quiet")
    assert r.returncode == 0, r.stderr
    first, second = json.loads(other.read_text())["ppo"]
    assert (first["settings"], second["settings"]) == ({}, {"n_steps": 512, "gamma": 0.9})
    assert first["mean"] != second["mean"]  # 3 updates instead of none before the last episodes
    assert second["command"].endswith("--learning-rate 0.0003 --n-steps 512 --gamma 0.9")
