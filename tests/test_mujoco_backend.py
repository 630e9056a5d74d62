"""The batched MuJoCo backend inside whole runs: `ermrl train` with `--backend mujoco` (also with the seeds split
over two processes, `--processes 2`) and with `--backend host` (Gymnasium's envs) on the same seeds gives the same
episodes to the byte, on a task that runs to its 1000-step truncation (HalfCheetah-v5) and on one that terminates
(Hopper-v5); `--backend auto` picks it for the MuJoCo locomotion tasks only. The env layer itself is checked step by step in test_mujoco_group.py."""

from __future__ import annotations

import pytest

from ermrl import envs
from ermrl.errors import ConfigError

from cli_runs import ermrl

TINY = ["--seeds", "2", "--timesteps", "2048", "--units", "10", "--quiet"]


@pytest.mark.parametrize("env_id", ["HalfCheetah-v5", "Hopper-v5"])
def test_train_on_the_mujoco_backend_gives_the_host_backends_episodes(tmp_path, env_id):
    runs = {}
    for name, backend, extra in (("host", "host", ["--env-workers", "0"]), ("mujoco", "mujoco", ["--env-threads", "2"]),
                                 ("mujoco-2", "mujoco", ["--env-threads", "1", "--processes", "2"])):
        r = ermrl("train", "--env", env_id, *TINY, "--backend", backend, *extra, "--out", name, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        runs[name] = (tmp_path / name / "episodes.csv").read_text()
    lines = runs["host"].splitlines()
    assert len(lines) > 3  # episodes finished: 2 per seed at the truncation, many more where it terminates
    assert runs["mujoco"] == runs["host"]
    assert runs["mujoco-2"] == runs["host"]  # each seed trained in its own process


def test_auto_picks_the_mujoco_backend_for_the_locomotion_tasks_only():
    for env_id in ("Ant-v5", "HalfCheetah-v5", "Hopper-v5", "Walker2d-v5", "Swimmer-v5", "Humanoid-v5",
                   "HumanoidStandup-v5"):
        assert envs.resolve_backend(env_id) == "mujoco"
        assert envs.resolve_backend(env_id, "host") == "host"
    assert envs.resolve_backend("CartPoleNoVel-v1") == "jax"
    assert envs.resolve_backend("LunarLander-v3") == "host"
    assert envs.resolve_backend("InvertedPendulum-v5") == "host"  # a MuJoCo env without a batched version
    with pytest.raises(ConfigError, match="has no batched MuJoCo version; use `backend` host or auto"):
        envs.resolve_backend("LunarLander-v3", "mujoco")
