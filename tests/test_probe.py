"""ermrl.analysis.probe: linear readouts of the reservoir context on random CartPoleNoVel rollouts (real env, real
reservoirs)."""

import gymnasium as gym
import numpy as np
import pytest

from ermrl.agent import Phi
from ermrl.analysis.probe import (MEMORY, MEMORYLESS, ProbeResult, collect, plot_probe, probe, probe_table,
                                  reservoir_states)
from ermrl.errors import ConfigError
from ermrl.wrappers import ReservoirObservation

from cli_runs import ermrl


@pytest.fixture(scope="module")
def rollouts():
    return collect("CartPole-v1", 300, seed=0)


@pytest.fixture(scope="module")
def results(rollouts):
    return [probe("CartPoleNoVel-v1", phi, rollouts=rollouts, label=label)
            for phi, label in ((MEMORY, "memory"), (MEMORYLESS, "memoryless"))]


def test_rollouts_mark_episodes_and_keep_the_full_observation(rollouts):
    n = len(rollouts.t)
    assert rollouts.obs.shape == (n, 4) and rollouts.actions.shape == (n,) and rollouts.rewards.shape == (n,)
    assert rollouts.n_episodes == 300 and np.all(np.diff(rollouts.episode) >= 0)
    starts = np.flatnonzero(rollouts.t == 0)
    assert len(starts) == 300 and np.all(rollouts.remaining[starts[1:] - 1] == 0)
    assert set(np.unique(rollouts.actions)) == {0, 1}


def test_states_are_the_wrappers_contexts(rollouts):
    """The probe's reservoir sees exactly what ReservoirObservation (the trainer's perception) gives a policy."""
    states = reservoir_states("CartPoleNoVel-v1", rollouts, MEMORY, seed=3)
    masked = gym.wrappers.TransformObservation(gym.make("CartPole-v1"), lambda o: o[[0, 2]],
                                               gym.spaces.Box(-np.inf, np.inf, (2,), np.float32))
    env = ReservoirObservation(masked, *MEMORY, seed=3)
    ctx, _ = env.reset(seed=0)  # collect() reset its first episode with seed 0 too
    steps = np.flatnonzero(rollouts.episode == 0)
    np.testing.assert_allclose(ctx, states[steps[0]], rtol=1e-5, atol=1e-6)
    for i in steps[:-1]:
        ctx, *_ = env.step(int(rollouts.actions[i]))
        np.testing.assert_allclose(ctx, states[i + 1], rtol=1e-5, atol=1e-5)


def test_memory_recovers_the_deleted_velocities_and_no_memory_does_not(results):
    memory, memoryless = results
    # Measured (seed 0, 300 episodes, alpha 1e-2): 0.996 vs 0.620; seeds 0..5: 0.985..0.998 vs 0.588..0.674.
    # The memoryless 0.62 is the velocities' correlation with the current positions under a random policy.
    assert memory.r2_velocity >= 0.9 and min(memory.r2_velocity_per_dim) >= 0.9
    assert memoryless.r2_velocity < 0.8
    assert memory.r2_velocity - memoryless.r2_velocity >= 0.25
    assert (1 - memoryless.r2_velocity) >= 10 * (1 - memory.r2_velocity)  # measured ~95x the unexplained variance
    assert memory.velocity_dims == (1, 3) and len(memory.r2_velocity_per_dim) == 2


def test_future_prediction_is_reported_for_k_1_to_5_and_fades(results):
    for r in results:
        assert len(r.r2_future) == 5
        assert r.r2_future[0] > 0.95 and r.r2_future[0] >= r.r2_future[-1]
        assert all(a >= b for a, b in zip(r.r2_future, r.r2_future[1:]))
        assert r.train_steps > 3 * r.test_steps > 0
    assert results[0].r2_future[-1] > results[1].r2_future[-1]  # measured 0.925 vs 0.767


def test_table_and_plot(results, tmp_path):
    table = probe_table(results)
    assert table.splitlines()[0].startswith("| reservoir | sr | leak rate | iss | R² v[1] | R² v[3] | R² velocities")
    assert "| memoryless | 0.0001 | 1 | 1 |" in table and "R² o(t+5)" in table
    out = plot_probe(results, tmp_path / "probe")
    assert out == tmp_path / "probe.png" and out.read_bytes()[:4] == b"\x89PNG"


def test_bad_inputs_raise_config_errors(rollouts):
    with pytest.raises(ConfigError) as error:
        probe("CartPole-v1", MEMORY, episodes=4)
    assert str(error.value) == ("probe needs a NoVel env id whose velocities are deleted, got 'CartPole-v1'; "
                                "use 'CartPoleNoVel-v1'")
    with pytest.raises(ConfigError, match="horizon must be >= 1"):
        probe("CartPoleNoVel-v1", MEMORY, horizon=0, rollouts=rollouts)
    with pytest.raises(ConfigError, match="lower horizon"):
        probe("CartPoleNoVel-v1", MEMORY, horizon=600, rollouts=rollouts)
    with pytest.raises(ConfigError, match="collect them from 'Pendulum-v1'"):
        probe("PendulumNoVel-v1", MEMORY, rollouts=rollouts)
    with pytest.raises(ConfigError, match="episodes must be >= 2"):
        probe("CartPoleNoVel-v1", MEMORY, episodes=1)
    with pytest.raises(ConfigError, match="NoVel ids are"):
        probe("Acrobot-v1", Phi(0.9, 0.5, 1.0), episodes=4)
    assert isinstance(probe("PendulumNoVel-v1", MEMORY, episodes=4, horizon=2), ProbeResult)


def test_cli_probes_the_defaults_a_given_phi_and_a_studys_phi_star(tmp_path):
    """`ermrl analyze probe`: the default Φ, the memoryless one, a --phi and a 2-reservoir study's Φ* (its best
    trial), each a row of the R² table written beside the figure; the memory rows beat the memoryless one."""
    from test_hp_map import make_study

    journal = str(tmp_path / "studies.log")
    study = make_study(journal, "cp-2res", ("CartPoleNoVel-v1",), 2, n_complete=4)
    best = max((t for t in study.trials if t.value is not None), key=lambda t: t.value)
    out = tmp_path / "probe.png"
    r = ermrl("analyze", "probe", "--env", "CartPoleNoVel-v1", "--episodes", "120", "--phi", "0.9", "0.3", "1",
              "--study", "cp-2res", "--storage", journal, "--out", out)
    assert r.returncode == 0, r.stderr
    assert out.is_file() and out.read_bytes().startswith(b"\x89PNG")
    rows = {line.split(" | ")[0].lstrip("| "): line for line in out.with_suffix(".md").read_text().splitlines()[2:]}
    assert list(rows) == ["default Φ", "memoryless", "Φ 1", f"cp-2res Φ* (trial {best.number})"]
    r2 = {k: float(v.split(" | ")[6]) for k, v in rows.items()}
    assert r2["default Φ"] > 0.9 and r2["Φ 1"] > 0.9 and r2["memoryless"] < r2["default Φ"] - 0.2
    assert "/" in rows[f"cp-2res Φ* (trial {best.number})"].split(" | ")[1]  # both reservoirs' sr


def test_cli_probe_errors_are_one_line(tmp_path):
    for args, message in [
        (["--env", "CartPole-v1"], "probe needs a NoVel env id whose velocities are deleted, got 'CartPole-v1'; "
                                   "use 'CartPoleNoVel-v1'"),
        (["--env", "CartPoleNoVel-v1", "--episodes", "2"], "--units must be >= 1 and --episodes >= 4, got 100 and 2"),
        (["--env", "CartPoleNoVel-v1", "--study", "nope", "--storage", str(tmp_path / "s.log")],
         f"no study 'nope': {tmp_path / 's.log'} does not exist; run `ermrl evolve --study nope` first or pass --storage"),
    ]:
        r = ermrl("analyze", "probe", *args, "--out", tmp_path / "p.png")
        assert r.returncode == 2 and r.stderr == f"ermrl analyze: error: {message}\n", r.stderr
    assert not (tmp_path / "s.log").exists() and not (tmp_path / "p.png").exists()
