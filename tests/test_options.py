"""Command-line options come from one definition (the config dataclasses) and config files feed them."""

import argparse
import json
import re

import numpy as np
import pytest

from ermrl import load_agent
from ermrl.agent import AgentConfig
from ermrl.cli import build_parser, parse
from ermrl.cli import configs
from ermrl.cli.options import AGENT_DESTS, PPO_FIELDS, field_docs
from ermrl.errors import ConfigError
from ermrl.ppo.config import PPOConfig
from ermrl.reservoir import ReservoirSpec
from ermrl.training import TrainConfig

from cli_runs import ermrl


def subparser(name: str) -> argparse.ArgumentParser:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name]


def options_of(parser) -> dict[str, argparse.Action]:
    return {a.dest: a for a in parser._actions if a.option_strings}


def test_every_training_command_takes_every_agent_option_from_one_definition():
    commands = {name: options_of(subparser(name)) for name in ("train", "evolve", "baselines")}
    expected_defaults = {"reservoirs": AgentConfig.reservoirs, "units": ReservoirSpec.units, "bias": ReservoirSpec.bias,
                         "rc_connectivity": 0.1, "input_connectivity": 0.1, "bias_scaling": 1.0,  # ReservoirPy's
                         "feed_action": AgentConfig.feed_action, "skip_connection": False,
                         "observed_units": AgentConfig.observed_units, "preset": "sb3", "learning_rate": None,
                         "timesteps": TrainConfig.total_timesteps, "backend": TrainConfig.backend,
                         "env_workers": TrainConfig.env_workers, "env_threads": "auto", "processes": 1, "normalize": None,
                         "use_sde": None,
                         "sde_sample_freq": None, "activation": None, "ortho_init": None, "net_arch": None,
                         **dict.fromkeys(PPO_FIELDS)}  # None: the preset's value
    assert set(expected_defaults) == set(AGENT_DESTS)
    for dest in AGENT_DESTS:
        actions = [c[dest] for c in commands.values()]
        assert len({a.option_strings[0] for a in actions}) == 1, dest
        assert len({repr(a.default) for a in actions}) == 1, dest
        assert len({a.help for a in actions}) == 1, dest
        assert actions[0].default == expected_defaults[dest], dest
    # the help is the field's docstring
    assert field_docs(ReservoirSpec)["units"] in commands["evolve"]["units"].help
    assert field_docs(AgentConfig)["observed_units"] in commands["train"]["observed_units"].help
    assert field_docs(PPOConfig)["learning_rate"] in commands["evolve"]["learning_rate"].help
    # the evolution's options that used to be missing
    for flag in ("skip_connection", "bias", "observed_units", "preset"):
        assert flag in commands["evolve"]


def test_help_still_shows_defaults():
    text = subparser("evolve").format_help()
    for flag in ("--units", "--skip-connection", "--observed-units", "--bias", "--preset", "--normalization",
                 "--config", "--fixed-iss", "--min-sr"):
        assert flag in text, flag
    assert re.search(r"--units UNITS\s+Number of neurons N \(the paper uses\s+100\)\.\s+\(default:\s+100\)", text)


def test_config_file_sets_options_and_flags_override_it(tmp_path):
    toml = tmp_path / "run.toml"
    toml.write_text('units = 20\nlearning-rate = 1e-4\nsr = [0.9]\nskip_connection = true\nenv = "PendulumNoVel-v1"\n')
    args = parse(["train", "--config", str(toml), "--units", "30"])
    assert (args.units, args.learning_rate, args.sr, args.skip_connection, args.env) == (30, 1e-4, [0.9], True,
                                                                                   "PendulumNoVel-v1")
    yaml = tmp_path / "run.yaml"
    yaml.write_text("trials: 12\nenv: [CartPoleNoVel-v1, PendulumNoVel-v1]\nnormalization: reference\n")
    args = parse(["evolve", "--config", str(yaml)])
    assert (args.trials, args.env, args.normalization) == (12, ["CartPoleNoVel-v1", "PendulumNoVel-v1"], "reference")


def test_the_run_folder_stores_the_effective_config(tmp_path):
    """The flag (30) beats the file (20) and the default (100). --no-reservoir trains plain PPO, whose program the
    units do not enter: the one that every CartPoleNoVel test phase compiles for its PPO baseline."""
    toml = tmp_path / "run.toml"
    toml.write_text("units = 20\nseeds = 1\ntimesteps = 2048\n")
    out = tmp_path / "run"
    r = ermrl("train", "--config", str(toml), "--units", "30", "--no-reservoir", "--out", str(out), "--quiet")
    assert r.returncode == 0, r.stderr
    config = json.loads((out / "config.json").read_text())
    assert config["train"]["agent"]["spec"]["units"] == 30 and config["train"]["total_timesteps"] == 2048
    assert config["options"]["units"] == 30 and config["options"]["seeds"] == 1


def test_ppo_hyperparameters_override_the_preset_and_reach_the_training(tmp_path):
    """--gamma, --n-envs, ... (rl-baselines3-zoo's tuned settings are given this way) replace the preset's values one
    by one, in every training command; the run trains with them: SB3's stopping rule counts n_envs × n_steps."""
    zoo = ["--n-envs", "2", "--n-steps", "32", "--batch-size", "16", "--gamma", "0.9", "--gae-lambda", "0.8",
           "--n-epochs", "3", "--clip-range", "0.1", "--ent-coef", "0.01", "--vf-coef", "0.25", "--max-grad-norm", "1",
           "--normalize", "--use-sde", "--sde-sample-freq", "4"]
    expected = {"n_envs": 2, "n_steps": 32, "batch_size": 16, "gamma": 0.9, "gae_lambda": 0.8, "n_epochs": 3,
                "clip_range": 0.1, "ent_coef": 0.01, "vf_coef": 0.25, "max_grad_norm": 1.0, "normalize": True,
                "use_sde": True, "sde_sample_freq": 4}
    for command in ("train", "evolve", "baselines --env CartPole-v1"):
        ppo = configs.ppo_config(parse([*command.split(), *zoo, "--preset", "fast", "--learning-rate", "1e-3"]))
        assert {k: getattr(ppo, k) for k in expected} == expected and ppo.learning_rate == 1e-3, command
    fast = configs.ppo_config(parse(["evolve", "--preset", "fast", "--gamma", "0.9"]))  # the rest stays the preset's
    assert (fast.n_envs, fast.n_steps, fast.n_epochs, fast.gamma, fast.normalize) == (8, 256, 4, 0.9, False)
    out = tmp_path / "run"
    r = ermrl("train", "--env", "PendulumNoVel-v1", "--no-reservoir", "--seeds", "1", "--timesteps", "200", *zoo,
              "--out", str(out), "--quiet")  # gSDE needs Box actions
    assert r.returncode == 0, r.stderr
    assert "no fitness: no episode finished (train for longer than one episode)" in r.stdout  # 128 < 200 steps
    config = json.loads((out / "config.json").read_text())["train"]["ppo"]
    assert {k: config[k] for k in expected} == expected
    assert json.loads((out / "summary.json").read_text())["total_timesteps"] == 256  # 4 rollouts of 2 × 32 steps
    saved = load_agent(out)
    assert saved.context_norm["mean"].shape == (2,) and saved.sde  # plain PPO on PendulumNoVel: cos θ and sin θ


def test_reservoirpy_hyperparameters_reach_the_reservoirs_drawn(tmp_path):
    """--rc-connectivity, --input-connectivity and --bias-scaling (C17's sweep) are stored in the run's config, and
    the reservoir of a saved agent, drawn again from it, has that many non-zero weights and that bias."""
    out = tmp_path / "run"
    r = ermrl("train", "--seeds", "1", "--timesteps", "2048", "--rc-connectivity", "0.5", "--input-connectivity", "1",
              "--bias-scaling", "0.25", "--out", str(out), "--quiet")
    assert r.returncode == 0, r.stderr
    spec = json.loads((out / "config.json").read_text())["train"]["agent"]["spec"]
    assert (spec["rc_connectivity"], spec["input_connectivity"], spec["bias_scaling"]) == (0.5, 1.0, 0.25)
    agent = load_agent(out)
    (W,), (Win,), (bias,) = agent._W, agent._Win, agent._bias  # one reservoir
    assert np.count_nonzero(W) == 5000 and np.count_nonzero(Win) == Win.size == 100 * 5  # CartPoleNoVel: 2 + 2 + 1
    np.testing.assert_array_equal(np.abs(bias), np.full(100, 0.25, np.float32))


@pytest.mark.parametrize("text, suffix, message", [
    ("unitz = 20\n", ".toml", "unknown option 'unitz' for `ermrl train`; did you mean 'units'?"),
    ("color = 1\n", ".toml", "unknown option 'color' for `ermrl train`; options here: activation, backend, batch-size, "),
    ('units = "many"\n', ".toml", "units has the wrong type: 'many'"),
    ("units = 2.5\n", ".toml", "units must be an integer, got 2.5"),
    ('bias = "gaussian"\n', ".toml", "bias must be one of bernoulli, none, got 'gaussian'"),
    ("units = [1, 2]\n", ".toml", "units takes one value, got a list [1, 2]"),
    ("skip-connection = 1\n", ".toml", "skip-connection must be true or false, got 1"),
    ("units = \n", ".toml", "is not valid TOML"),
    ("- a\n- b\n", ".yaml", "must hold a table of option = value pairs"),
    ("units: 2\n", ".ini", "must end in .toml, .yaml or .yml"),
])
def test_bad_config_files_are_one_line_errors(tmp_path, text, suffix, message):
    path = tmp_path / f"c{suffix}"
    path.write_text(text)
    r = ermrl("train", "--config", str(path), "--timesteps", "2048", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert r.stderr.startswith(f"ermrl train: error: config file {path}"), r.stderr
    assert message in r.stderr and r.stderr.count("\n") == 1
    assert not (tmp_path / "runs").exists()


def test_missing_config_file(tmp_path):
    r = ermrl("evolve", "--config", str(tmp_path / "nope.toml"), cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr == (f"ermrl evolve: error: config file {tmp_path / 'nope.toml'} does not exist; "
                        "give the path of a .toml or .yaml file\n")


def test_ppo_settings_are_checked_together():
    """A PPO-LSTM window longer than the preset's batch is fine when the batch given with it holds whole windows
    (rl-zoo's RecurrentPPO settings: 128-step minibatches); a batch that does not is one error naming both."""
    ppo = configs.ppo_config(parse(["train", "--model", "lstm", "--batch-size", "128", "--lstm-seq-len", "128"]))
    assert (ppo.model, ppo.batch_size, ppo.lstm_seq_len) == ("lstm", 128, 128)
    with pytest.raises(ConfigError, match="^batch_size 64 must be a multiple of lstm_seq_len 128"):
        configs.ppo_config(parse(["train", "--model", "lstm", "--lstm-seq-len", "128"]))


def test_an_old_config_file_with_lr_still_sets_the_leak_rate_and_the_new_names_work(tmp_path):
    """`lr = 0.3` in a config file written before the flag was renamed keeps its meaning (the value's name is
    still `lr`); `leak-rate = 0.3` and `--spectral-radius` say the same; `--lr` on the command line is refused."""
    from ermrl.cli import parse

    old = tmp_path / "old.toml"
    old.write_text("lr = 0.3\n")
    old_search = tmp_path / "old_search.toml"
    old_search.write_text("min-lr = 0.05\n")
    new = tmp_path / "new.toml"
    new.write_text("leak-rate = 0.3\n")
    assert parse(["train", "--config", str(old)]).lr == [0.3]
    assert parse(["train", "--config", str(new)]).lr == [0.3]
    assert parse(["train", "--spectral-radius", "0.7"]).sr == [0.7]
    assert parse(["evolve", "--config", str(old_search)]).min_lr == 0.05
    assert parse(["evolve", "--min-leak-rate", "0.05"]).min_lr == 0.05


@pytest.mark.parametrize("command, suffix, text, expected", [
    ("train", ".toml", "ppo-lr = 1e-4\n", {"learning_rate": 1e-4}),
    ("evolve", ".yaml", "ppo_lr: 1e-4\n", {"learning_rate": 1e-4}),
    ("baselines --env CartPole-v1", ".toml", "ppo-lr = 1e-4\n", {"learning_rate": 1e-4}),
    ("test --study s", ".toml", "ermrl-lr = [3e-4, 1e-4]\nppo-lr = 1e-4\n",
     {"learning_rates": [3e-4, 1e-4], "baseline_learning_rate": 1e-4}),
    ("test --study s", ".yaml", "ermrl-lr: 5.0e-5\nppo-lr: 3.0e-4\n",
     {"learning_rates": [5e-5], "baseline_learning_rate": 3e-4}),
    ("experiment run partial-observability", ".toml", "test-lrs = [1e-4, 3e-4]\n",
     {"test_learning_rates": [1e-4, 3e-4]}),
])
def test_a_config_file_with_the_learning_rates_old_keys_sets_their_options_of_today(tmp_path, command, suffix, text,
                                                                                  expected):
    """A config file written for the flags of older versions (ppo-lr, ermrl-lr, test-lrs) loads: each key sets the
    option it is now (--learning-rate, --baseline-learning-rate, --test-learning-rates); a flag still overrides it."""
    path = tmp_path / f"old{suffix}"
    path.write_text(text)
    args = parse([*command.split(), "--config", str(path)])
    assert {k: getattr(args, k) for k in expected} == expected
    assert not any(hasattr(args, old) for old in ("ppo_lr", "ermrl_lr", "test_lrs"))
    if command == "train":
        assert configs.ppo_config(args).learning_rate == 1e-4
        assert parse(["train", "--config", str(path), "--learning-rate", "3e-4"]).learning_rate == 3e-4
    if command.startswith("test"):
        from ermrl.experiments.evaluation import TestConfig

        assert configs.test_config(args) == TestConfig(learning_rates=tuple(expected["learning_rates"]),
                                                       baseline_learning_rate=expected["baseline_learning_rate"])
