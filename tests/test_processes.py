"""A population trained in several processes (`TrainConfig.processes`, `--processes`): the same Results as in one
process, agent for agent, with its progress counted over the whole population; its helper processes end when
the run is stopped (SIGTERM) or killed (SIGKILL)."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import time

import jax
import numpy as np

from ermrl.agent import Phi
from ermrl.errors import TERMINATED
from ermrl.ppo.config import PPOConfig
from ermrl.training import Population, TrainConfig, Trainer
from ermrl.training.processes import part_bounds

from cli_runs import COMMAND


def test_part_bounds_split_the_agents_evenly_and_never_into_empty_parts():
    assert part_bounds(27, 2) == [0, 13, 27]
    assert part_bounds(6, 3) == [0, 2, 4, 6]
    assert part_bounds(2, 5) == [0, 1, 2]
    assert part_bounds(1, 2) == [0, 1]


def test_a_population_trained_in_two_processes_is_the_one_trained_in_one():
    """Hopper-v5 terminates early, so every agent finishes episodes: fitness, episodes, curves and policies are
    compared exactly; the progress seen during the split run counts the whole population's steps."""
    config = TrainConfig(env_id="Hopper-v5", total_timesteps=512, backend="mujoco",
                         ppo=PPOConfig(n_steps=256, n_epochs=2))
    population = Population.grid([Phi(0.9, 0.3, 1.0), Phi(0.5, 0.8, 0.3)], [0, 1, 2], 3e-4, 1)
    one = Trainer(config).run(population)
    seen = []
    two = Trainer(dataclasses.replace(config, processes=2)).run(population, seen.append)
    assert np.isfinite(one.fitness()).all()
    assert np.array_equal(one.fitness(), two.fitness())
    assert np.array_equal(one.seeds, two.seeds)
    for a, b in zip(one.episodes, two.episodes):
        assert np.array_equal(a.ret, b.ret) and np.array_equal(a.length, b.length)
        assert np.array_equal(a.timestep, b.timestep)
    for tree in ("actor", "critic"):
        leaves = zip(jax.tree.leaves(getattr(one.policies, tree)), jax.tree.leaves(getattr(two.policies, tree)))
        assert all(np.array_equal(a, b) for a, b in leaves)
    assert np.array_equal(one.policies.log_std, two.policies.log_std)
    assert seen[-1].agent_steps == seen[-1].total_agent_steps == population.size * 512


def _children(pid: int) -> list[int]:
    """The pids of ``pid``'s child processes (from /proc)."""
    out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout
    return [int(p) for p in out.split()]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    status = open(f"/proc/{pid}/status").read() if os.path.exists(f"/proc/{pid}/status") else ""
    return "zombie" not in status


def _start_and_find_helper(tmp_path) -> tuple[subprocess.Popen, int]:
    """An ``ermrl train --processes 2`` process long enough to be stopped, and the pid of its helper, once the
    helper trains (it has started JAX's threads)."""
    proc = subprocess.Popen([*COMMAND, "train", "--env", "Hopper-v5", "--seeds", "4", "--timesteps", "1000000",
                             "--units", "10", "--processes", "2", "--quiet", "--out", "run"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 240
    while time.time() < deadline:
        helpers = [p for p in _children(proc.pid)
                   if "ermrl.training.part_process" in open(f"/proc/{p}/cmdline").read().replace("\0", " ")]
        if helpers and len(os.listdir(f"/proc/{helpers[0]}/task")) > 4:
            return proc, helpers[0]
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.5)
    proc.kill()
    raise AssertionError("the helper process did not start training within 240 s")


def _gone_within(pid: int, seconds: float) -> bool:
    deadline = time.time() + seconds
    while time.time() < deadline:
        if not _alive(pid):
            return True
        time.sleep(0.2)
    return False


def test_sigterm_ends_the_run_and_its_helper_process(tmp_path):
    proc, helper = _start_and_find_helper(tmp_path)
    time.sleep(2)  # inside the first iterations
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == TERMINATED, err
    assert err.splitlines()[-1] == "terminated (SIGTERM)"
    assert _gone_within(helper, 10)
    assert not (tmp_path / "run").exists()


def test_a_helper_process_ends_when_its_parent_is_killed(tmp_path):
    proc, helper = _start_and_find_helper(tmp_path)
    proc.kill()
    proc.communicate(timeout=30)
    assert _gone_within(helper, 10)


def test_a_helper_process_killed_mid_run_stops_the_run_at_once_with_one_line(tmp_path):
    """The first part would train for most of an hour more: the run notices the dead helper after its next
    iteration (seconds; the timeout leaves room for the first part's compile on a loaded machine)."""
    proc, helper = _start_and_find_helper(tmp_path)
    os.kill(helper, signal.SIGKILL)
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == 1, err
    assert err.splitlines()[-1] == "ermrl train: error: a training process died (exit code -9); see its error above"
    assert not (tmp_path / "run").exists()
