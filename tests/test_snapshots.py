"""Resuming a stopped training run from its snapshot: the same Results, to the last bit, as a run that never
stopped, on the JAX backend and on real Gymnasium envs (Box2D and MuJoCo, in-process and in worker processes);
a snapshot of another run, or one whose envs do not replay, is not used."""

import dataclasses
import json
import os
import signal
import subprocess
import time

import numpy as np
import pytest

from ermrl import provenance
from ermrl.agent import AgentConfig, Phi
from ermrl.envs.host_groups import EnvGroup, ReplayMismatch
from ermrl.ppo.config import SB3_DEFAULTS
from ermrl.reservoir import ReservoirSpec
from ermrl.training import Population, TrainConfig, Trainer, snapshots
from ermrl.training.results import WALL_S

from cli_runs import COMMAND, ermrl


TINY = dataclasses.replace(SB3_DEFAULTS, n_steps=128, batch_size=64, n_epochs=1, hidden=(16, 16))
"""test_host.py's small PPO: a host agent of 2 seeds here is one that its every-listed-env test compiles."""


class Stop(Exception):
    """Raised from the progress callback: the run stops as if the machine went away."""


def stop_after(iterations: int):
    def progress(p):
        if p.iteration == iterations:
            raise Stop

    return progress


def assert_same_results(a, b):
    np.testing.assert_array_equal(a.fitness(), b.fitness())
    assert len(a.episodes) == len(b.episodes)
    for x, y in zip(a.episodes, b.episodes):
        np.testing.assert_array_equal(x.timestep, y.timestep)
        np.testing.assert_array_equal(x.ret, y.ret)
        np.testing.assert_array_equal(x.length, y.length)
    assert set(a.metrics) == set(b.metrics)
    for k in a.metrics:
        if k != WALL_S:
            np.testing.assert_array_equal(a.metrics[k], b.metrics[k], err_msg=k)
    np.testing.assert_array_equal(a.finite, b.finite)
    for part in ("actor", "critic"):
        flat_a = [np.asarray(x) for x in _leaves(getattr(a.policies, part))]
        flat_b = [np.asarray(x) for x in _leaves(getattr(b.policies, part))]
        for x, y in zip(flat_a, flat_b, strict=True):
            np.testing.assert_array_equal(x, y)


def _leaves(tree):
    import jax

    return jax.tree.leaves(tree)


CASES = [  # 3 seeds: a population padded (on 2 devices) and resumed with its padding. The JAX case at SB3's PPO (the
    # programs of the default CartPoleNoVel agent, which many tests compile); the 2-worker case at 2 seeds (TINY)
    pytest.param("CartPoleNoVel-v1", "jax", 0, 1, SB3_DEFAULTS, [3, 4, 5], id="cartpole-jax"),
    pytest.param("LunarLanderNoVel-v3", "host", 0, 2, TINY, [3, 4, 5], id="lunarlander-in-process"),
    pytest.param("Swimmer-v5", "host", 2, 1, TINY, [3, 4], id="swimmer-2-workers"),
    pytest.param("Hopper-v5", "mujoco", 0, 1, TINY, [3, 4], id="hopper-mujoco"),  # batched, terminations replayed
]


@pytest.mark.parametrize("env_id,backend,workers,reservoirs,ppo,seeds", CASES)
def test_a_stopped_run_resumes_to_the_same_results(tmp_path, env_id, backend, workers, reservoirs, ppo, seeds):
    config = TrainConfig(env_id=env_id, total_timesteps=10 * ppo.buffer_size, agent=AgentConfig(reservoirs=reservoirs),
                         ppo=ppo, backend=backend, env_workers=workers)
    population = Population.grid(Phi(0.9, 0.3, 1.0), seeds, 3e-4, reservoirs)
    trainer = Trainer(config)  # one compile for the three runs (a fresh process: the test below)
    unbroken = trainer.run(population)

    path = tmp_path / "run.snapshot"
    with pytest.raises(Stop):
        trainer.run(population, stop_after(6), snapshot=path, snapshot_every_s=0)
    assert snapshots.read(path, snapshots.identity(config, population, len(trainer.devices))).iteration == 5
    lines = []
    resumed = trainer.run(population, snapshot=path, log=lines.append)
    assert lines == [f"resumed from {path} at iteration 5 of 10"]
    assert_same_results(resumed, unbroken)
    assert resumed.train_s > 0


def test_a_run_that_ended_before_its_results_were_kept_trains_no_more(tmp_path):
    """The snapshot written after the last iteration (snapshots every hour: this one alone) gives a rerun the
    finished run's Results without an iteration: e.g. an evolution stopped between training a batch and telling it."""
    ppo = TINY
    config = TrainConfig(env_id="LunarLanderNoVel-v3", total_timesteps=4 * ppo.buffer_size,
                         agent=AgentConfig(reservoirs=2), ppo=ppo, backend="host")
    population = Population.grid(Phi(0.9, 0.3, 1.0), [3, 4], 3e-4, 2)
    trainer = Trainer(config)
    path = tmp_path / "run.snapshot"
    finished = trainer.run(population, snapshot=path, snapshot_every_s=3600)
    assert snapshots.read(path, snapshots.identity(config, population, len(trainer.devices))).iteration == 4
    lines, iterations = [], []
    again = trainer.run(population, iterations.append, snapshot=path, log=lines.append)
    assert (lines, iterations) == ([f"resumed from {path} at iteration 4 of 4"], [])
    assert_same_results(again, finished)


def test_a_snapshot_holds_no_reservoir_weights_and_an_older_one_with_them_still_resumes(tmp_path):
    """The reservoirs' weights are fixed and drawn again from the seeds and Φ on resume, so a snapshot leaves them
    out (at 1000 units they were 4 MB an agent, 57 MB for a 10-agent test model); a snapshot written with them,
    as before, resumes to the same results too. The agent of test_saved_agent.py's PendulumNoVel case (its
    programs): no other leaf ends in the reservoirs' (40, 40) or (40, 4) (inputs: 2 observed, 1 action, the
    reward; the policy sees 2 × 30 observed units + the 4 inputs, 64)."""
    import jax

    units = 40
    agent = AgentConfig(reservoirs=2, spec=ReservoirSpec(units=units), skip_connection=True, observed_units=30)
    config = TrainConfig(env_id="PendulumNoVel-v1", total_timesteps=6 * SB3_DEFAULTS.buffer_size, agent=agent)
    population = Population.grid(Phi(0.9, 0.3, 1.0), [3, 4], 3e-4, 2)
    trainer = Trainer(config)
    unbroken = trainer.run(population)
    path = tmp_path / "run.snapshot"
    with pytest.raises(Stop):
        trainer.run(population, stop_after(4), snapshot=path, snapshot_every_s=0)
    ident = snapshots.identity(config, population, len(trainer.devices))
    snap = snapshots.read(path, ident)
    assert not [x.shape for x in snap.leaves if x.shape[-2:] in ((units, units), (units, trainer.agent.input_dim))]
    assert_same_results(trainer.run(population, snapshot=path), unbroken)
    path.unlink()  # as a caller does once it has kept the Results: the run's last snapshot would resume at its end

    with pytest.raises(Stop):
        trainer.run(population, stop_after(4), snapshot=path, snapshot_every_s=0)
    snap = snapshots.read(path, ident)
    state = trainer.init(population)
    n_learner = len(jax.tree.leaves(state.learner))
    weights = jax.device_get(jax.tree.leaves(state.reservoirs))
    assert [w.shape[-2:] for w in weights][:2] == [(units, units), (units, trainer.agent.input_dim)]
    snapshots.write(path, ident, snap._replace(leaves=snap.leaves[:n_learner] + weights + snap.leaves[n_learner:]))
    lines = []
    assert_same_results(trainer.run(population, snapshot=path, log=lines.append), unbroken)
    assert lines == [f"resumed from {path} at iteration 3 of 6"]
    path.unlink()

    # a snapshot records the versions and CPU it was computed under; a resume under others says so
    with pytest.raises(Stop):
        trainer.run(population, stop_after(4), snapshot=path, snapshot_every_s=0)
    snap = snapshots.read(path, ident)
    assert snap.software == provenance.software()
    snapshots.write(path, ident, snap._replace(software={**snap.software, "cpu": "riscv64"}))
    lines = []
    trainer.run(population, snapshot=path, log=lines.append)
    assert lines == [f"resumed from {path} at iteration 3 of 6; it was written under other versions (cpu riscv64 "
                     f"→ {provenance.cpu()}), so the rest of the run is not bit for bit what they would compute"]


def test_a_snapshot_of_another_population_is_not_used(tmp_path):
    config = TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=4 * SB3_DEFAULTS.buffer_size)
    path, trainer = tmp_path / "run.snapshot", Trainer(config)
    with pytest.raises(Stop):
        trainer.run(Population.grid(Phi(0.9, 0.3, 1.0), [0, 1], 3e-4, 1), stop_after(3), snapshot=path,
                    snapshot_every_s=0)
    other = Population.grid(Phi(0.9, 0.3, 1.0), [7, 8], 3e-4, 1)
    lines = []
    from_snapshot = trainer.run(other, snapshot=path, log=lines.append)
    assert lines == []
    assert_same_results(from_snapshot, trainer.run(other))


def test_envs_that_do_not_replay_start_the_run_over(tmp_path):
    config = TrainConfig(env_id="LunarLander-v3", total_timesteps=4 * TINY.buffer_size, ppo=TINY,
                         backend="host", env_workers=0)
    population = Population.grid(Phi(0.9, 0.3, 1.0), [0, 1], 3e-4, 1)
    path, trainer = tmp_path / "run.snapshot", Trainer(config)
    with pytest.raises(Stop):
        trainer.run(population, stop_after(3), snapshot=path, snapshot_every_s=0)
    ident = snapshots.identity(config, population, len(trainer.devices))
    snap = snapshots.read(path, ident)
    first = snap.envs[0]
    snap.envs[0] = first._replace(obs=first.obs + 1.0)  # as if the simulator had changed
    snapshots.write(path, ident, snap)
    lines = []
    results = trainer.run(population, snapshot=path, log=lines.append)
    assert lines == [f"{path} does not replay exactly on this machine; training from the start"]
    assert_same_results(results, trainer.run(population))


@pytest.mark.parametrize("base_id,discrete", [("LunarLander-v3", True), ("Swimmer-v5", False)])
def test_env_groups_replay_to_the_same_future(base_id, discrete):
    """A group rebuilt from another's snapshot, across automatic resets, steps on identically."""
    kept = (0, 1, 2, 3, 4, 5, 6, 7) if discrete else tuple(range(8))
    a, b = EnvGroup(base_id, kept, discrete, 0, 3), EnvGroup(base_id, kept, discrete, 0, 3)
    rng = np.random.default_rng(0)
    draw = (lambda: rng.integers(0, 4, 3)) if discrete else (lambda: rng.uniform(-1, 1, (3, 2)).astype(np.float32))
    a.reset(np.array([10, 11, 12]))
    ends = 0
    for _ in range(1500):  # LunarLander's random episodes last ≈ 100 steps; Swimmer's are truncated at 1000
        ends += int(a.step(draw())[:, -2:].sum())
    assert ends > 0
    before = a.step(draw())[:, :len(kept)]  # the observations to act on next
    np.testing.assert_array_equal(b.restore(a.snapshot()), before)
    for _ in range(300):
        actions = draw()
        np.testing.assert_array_equal(a.step(actions), b.step(actions))
    broken = a.snapshot()
    broken[1] = broken[1]._replace(obs=broken[1].obs + 1e-9)
    with pytest.raises(ReplayMismatch, match="slot 1: the replayed observation differs from the recorded one"):
        b.restore(broken)
    a.close(), b.close()


@pytest.mark.parametrize("env", [["--env", "CartPoleNoVel-v1", "--timesteps", "40960"],
                                 ["--env", "Hopper-v5", "--backend", "mujoco", "--timesteps", "10240"]],
                         ids=["cartpole-jax", "hopper-mujoco"])
def test_ermrl_train_killed_resumes_from_its_snapshot(tmp_path, env):
    """A real stop: `ermrl train --out` killed (SIGKILL) once its snapshot exists; the rerun resumes and writes
    the same fitness as an unbroken run (both of those run in this process). On the MuJoCo backend the envs come
    back by replaying each one's episode."""
    args = [*COMMAND, "train", *env, "--seeds", "2", "--quiet", "--no-save-agents", "--snapshot-every", "0"]
    out, snap = tmp_path / "run", tmp_path / "run.snapshot"
    proc = subprocess.Popen(args + ["--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    deadline = time.time() + 300
    while not snap.exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    assert snap.exists(), proc.communicate()[0].decode()
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / "summary.json").exists()
    second = ermrl(*args[len(COMMAND):], "--out", out)
    assert second.returncode == 0, second.stderr
    assert f"resumed from {snap} at iteration" in second.stdout
    assert not snap.exists()
    unbroken = ermrl(*args[len(COMMAND):], "--out", tmp_path / "unbroken")
    assert unbroken.returncode == 0, unbroken.stderr
    fitness = lambda folder: json.loads((folder / "summary.json").read_text())["fitness"]
    assert fitness(out) == fitness(tmp_path / "unbroken")


def test_the_scores_so_far_of_a_model_in_training(tmp_path):
    """`ermrl test-progress` reads a model's snapshot: the steps done and each agent's mean return
    over its last 10 episodes by then, as the unbroken run's episodes give them."""
    steps = SB3_DEFAULTS.buffer_size
    config = TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=10 * steps)
    population = Population.grid(Phi(0.9, 0.3, 1.0), [0, 1], 3e-4, 1)
    trainer, partial = Trainer(config), tmp_path / "test.partial"
    unbroken = trainer.run(population)
    with pytest.raises(Stop):
        trainer.run(population, stop_after(5), snapshot=partial / "ermrl.snapshot", snapshot_every_s=0)
    done = 4 * steps
    so_far = [np.mean(e.ret[e.timestep <= done][-10:]) for e in unbroken.episodes]
    r = ermrl("test-progress", partial)
    assert r.returncode == 0, r.stderr
    row = r.stdout.splitlines()[2]
    assert row == (f"| `ermrl` (in training) | 2 | 0, 1 | {done:,} of {10 * steps:,} | "
                   f"{np.mean(so_far):.1f} ± {np.std(so_far):.1f} (last 10 episodes so far) | — | "
                   f"{so_far[0]:.1f}, {so_far[1]:.1f} |")
