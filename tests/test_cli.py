"""The CLI as a user runs it (in this process, see cli_runs.py; a real process where one matters) at a tiny budget:
help texts and one-line errors with exit code 2."""

import json
import re

import jax
import mujoco
import pytest

from cli_runs import ermrl, ermrl_process


def test_train_writes_a_run_folder(tmp_path):
    out = tmp_path / "run"
    r = ermrl("train", "--env", "CartPoleNoVel-v1", "--seeds", "2", "--timesteps", "2048", "--out", str(out), "--quiet")
    assert r.returncode == 0, r.stderr
    assert "seed 0: fitness" in r.stdout and "seed 1: fitness" in r.stdout
    for name in ("config.json", "episodes.csv", "curves.csv", "summary.json", "learning_curve.png"):
        assert (out / name).stat().st_size > 0, name
    config = json.loads((out / "config.json").read_text())
    assert config["train"]["env_id"] == "CartPoleNoVel-v1" and config["population"]["seeds"] == [0, 1]
    assert config["train"]["ppo"]["n_steps"] == 2048
    assert config["population"]["phi"]["sr"] == [[pytest.approx(0.95)], [pytest.approx(0.95)]]
    assert config["software"]["jax"] == jax.__version__ and config["software"]["mujoco"] == mujoco.__version__
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["fitness"]) == 2 and summary["episodes"][0] > 10
    assert (out / "learning_curve.png").read_bytes()[:4] == b"\x89PNG"
    # the same run as a real process (how every other test here runs the CLI is checked by this one): the same
    # output, the same fitness to the bit, the same files
    alone = tmp_path / "alone"
    p = ermrl_process("train", "--env", "CartPoleNoVel-v1", "--seeds", "2", "--timesteps", "2048", "--out", alone,
                      "--quiet")
    speed = re.compile(r" \| [\d,]+ agent-steps/s, compile [\d.]+s, train [\d.]+s$", re.M)  # this run's speed
    assert speed.search(r.stdout) and speed.search(p.stdout)
    assert (p.returncode, speed.sub("", p.stdout.replace(str(alone), str(out))), p.stderr) == (
        0, speed.sub("", r.stdout), r.stderr)
    assert json.loads((alone / "summary.json").read_text())["fitness"] == summary["fitness"]
    assert (alone / "episodes.csv").read_bytes() == (out / "episodes.csv").read_bytes()
    assert sorted(f.name for f in alone.rglob("*")) == sorted(f.name for f in out.rglob("*"))

    plain = tmp_path / "plain"
    r = ermrl("train", "--env", "CartPoleNoVel-v1", "--no-reservoir", "--seeds", "1", "--first-seed", "1000",
              "--timesteps", "2048", "--out", str(plain), "--quiet")
    assert r.returncode == 0, r.stderr
    assert "seed 1000: fitness" in r.stdout and "seed 0:" not in r.stdout
    assert json.loads((plain / "config.json").read_text())["population"]["seeds"] == [1000]
    figure = tmp_path / "both.png"
    r = ermrl("plot", str(out), str(plain), "--out", str(figure))
    assert r.returncode == 0, r.stderr
    assert figure.read_bytes()[:4] == b"\x89PNG" and figure.with_suffix(".svg").stat().st_size > 0
    r = ermrl("plot", str(tmp_path / "missing"), "--out", str(figure))
    assert r.returncode == 2 and r.stderr == (f"ermrl plot: error: {tmp_path / 'missing'} has no curves.csv; "
                                              "give folders written by `ermrl train` or `ermrl test`\n")


def test_help_explains_every_flag():
    top = ermrl_process("--help")  # the interpreter's way in, ``python -m ermrl.cli``
    assert top.returncode == 0 and "train" in top.stdout
    sub = ermrl("train", "--help")
    assert sub.returncode == 0
    for flag in ("--env", "--units", "--sr", "--leak-rate", "--iss", "--seeds", "--first-seed", "--timesteps", "--no-reservoir", "--learning-rate",
                 "--out", "--reservoirs", "--feed-action", "--skip-connection", "--observed-units", "--bias", "--preset",
                 "--backend", "--env-workers"):
        assert flag in sub.stdout, flag


@pytest.mark.parametrize("args, message", [
    (["--env", "Nope-v0"], "ermrl train: error: unknown env id 'Nope-v0': Gymnasium has no 'Nope-v0'"),
    (["--env", "LunarLander-v3", "--backend", "jax"], "ermrl train: error: env 'LunarLander-v3' has no JAX version"),
    (["--env", "AcrobotNoVel-v1"], "ermrl train: error: no velocity mask is known for 'Acrobot-v1'"),
    (["--leak-rate", "1.5"], "ermrl train: error: --leak-rate must be in (0, 1], got [1.5]"),
    (["--sr", "-1"], "ermrl train: error: --sr must be positive and finite, got [-1.0]"),
    (["--reservoirs", "2", "--sr", "1", "2", "3"], "ermrl train: error: --sr got 3 values for 2 reservoirs; give one value or 2"),
    (["--learning-rate", "3"], "ermrl train: error: learning rate 3.0 is outside (0, 1)"),
    (["--first-seed", "-1"], "ermrl train: error: --first-seed must be >= 0, got -1"),
])
def test_bad_input_is_one_line_and_exit_code_2(args, message, tmp_path):
    r = ermrl("train", *args, "--timesteps", "2048", cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.startswith(message), r.stderr
    assert r.stderr.count("\n") == 1
    assert not (tmp_path / "runs").exists()  # nothing written


@pytest.mark.parametrize("value", ["abc", "0", "-2", "1.5"])
def test_a_bad_cpu_device_count_is_refused_before_any_work(tmp_path, value):
    import os

    r = ermrl_process("train", "--env", "CartPole-v1", "--timesteps", "2048", "--out", tmp_path / "run",
                      env={"ERMRL_CPU_DEVICES": value})  # read at import: a process of its own
    cores = os.cpu_count() or 1
    assert r.returncode == 2 and r.stderr == (
        f"ermrl train: error: ERMRL_CPU_DEVICES must be a whole number >= 1 (the CPU devices a population is sharded "
        f"over), got {value!r}; unset it to use one per core ({cores})\n"), r.stderr
    assert not (tmp_path / "run").exists()


def test_a_cpu_device_count_far_above_the_cores_is_refused(tmp_path):
    """1000 devices on a few cores would pad every population to a multiple of 1000 agents."""
    import os

    r = ermrl_process("train", "--env", "CartPole-v1", "--timesteps", "2048", "--out", tmp_path / "run",
                      env={"ERMRL_CPU_DEVICES": "1000"})
    cores = os.cpu_count() or 1
    assert r.returncode == 2 and r.stderr == (
        f"ermrl train: error: ERMRL_CPU_DEVICES must be at most {max(8, 4 * cores)} (4 per core, at least 8: more "
        f"devices than cores run no faster, and a population is padded to a multiple of them), got '1000'; unset it "
        f"to use one per core ({cores})\n"), r.stderr
    assert not (tmp_path / "run").exists()


def test_output_paths_are_checked_before_any_training(tmp_path):
    """An --out that is a file, lies under a file, or in a folder that cannot be written is refused in one line
    before training (it used to train to the end and then die with a traceback, losing the results)."""
    import os

    afile = tmp_path / "afile"
    afile.write_text("keep me")
    locked = tmp_path / "locked"
    locked.mkdir()
    cases = [
        (["train", "--env", "CartPole-v1", "--out", str(afile)],
         f"ermrl train: error: --out {afile} is a file, not a folder; give a folder path (it is created if missing)"),
        (["train", "--env", "CartPole-v1", "--out", str(afile / "run")],
         f"ermrl train: error: --out {afile / 'run'}: its parent {afile} is a file, not a folder; give a folder path "
         "(it is created if missing)"),
        (["evolve", "--env", "CartPole-v1", "--study", "s", "--out", str(afile)],
         f"ermrl evolve: error: --out {afile} is a file, not a folder; give a folder path (it is created if missing)"),
        (["experiment", "run", "observed-units", "--scale", "smoke", "--out", str(afile)],
         f"ermrl experiment: error: --out {afile} is a file, not a folder; give a folder path (it is created if "
         "missing)"),
    ]
    if os.geteuid() != 0:  # root may write anywhere
        locked.chmod(0o555)
        cases.append((["train", "--env", "CartPole-v1", "--out", str(locked / "run")],
                      f"ermrl train: error: --out {locked / 'run'}: cannot write in {locked} (permission denied); "
                      "give a folder you can write"))
    for args, message in cases:
        r = ermrl(*args, "--timesteps", "2048") if args[0] != "experiment" else ermrl(*args)
        assert r.returncode == 2 and r.stderr == message + "\n", r.stderr
    assert afile.read_text() == "keep me" and set(tmp_path.iterdir()) == {afile, locked}  # nothing created


def test_python_m_ermrl_is_the_ermrl_command():
    import subprocess
    import sys

    import ermrl as package

    run = subprocess.run([sys.executable, "-m", "ermrl", "--version"], capture_output=True, text=True, timeout=120)
    assert (run.returncode, run.stdout) == (0, f"ermrl {package.__version__}\n")
    run = subprocess.run([sys.executable, "-m", "ermrl", "train", "--timestep", "1000"], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 2 and "unrecognized arguments: --timestep 1000 (did you mean --timesteps?)" in run.stderr
