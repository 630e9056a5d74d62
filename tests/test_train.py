"""Population training: determinism, vectorization and learning at CI-sized budgets."""

import dataclasses

import jax
import numpy as np
import pytest

from ermrl.agent import AgentConfig, Phi
from ermrl.ppo.config import SB3_DEFAULTS
from ermrl.training import Population, TrainConfig, Trainer, train


def config(env_id="CartPoleNoVel-v1", timesteps=4096, reservoirs=1, **ppo):
    return TrainConfig(env_id=env_id, total_timesteps=timesteps, agent=AgentConfig(reservoirs=reservoirs),
                       ppo=dataclasses.replace(SB3_DEFAULTS, **ppo))


def test_same_seeds_give_identical_fitness():
    cfg = config(timesteps=3 * 2048)
    pop = Population.grid([Phi(0.95, 0.5, 1.0), Phi(2.0, 0.1, 0.5)], 2, 3e-4, 1)
    trainer = Trainer(cfg)
    a = trainer.run(pop)
    compiled = dict(trainer.programs.compiled)
    b = trainer.run(pop)
    assert trainer.programs.compiled == compiled  # the second run reuses the compiled program
    assert np.all(np.isfinite(a.fitness()))
    np.testing.assert_array_equal(a.fitness(), b.fitness())
    for ea, eb in zip(a.episodes, b.episodes):
        np.testing.assert_array_equal(ea.ret, eb.ret)
    assert not np.array_equal(a.fitness()[:2], a.fitness()[2:])  # different Φ, different agents


def test_a_trainer_of_the_same_config_reuses_its_programs_and_trains_alike():
    """A second Trainer of the same static config (any budget) neither traces nor compiles again, and trains the
    same agents to the same bits; another config, or the host backend (whose functions hold its envs), gets its own."""
    cfg = config(timesteps=2048)
    pop = Population.grid(Phi(0.95, 0.5, 1.0), 2, 3e-4, 1)
    first = Trainer(cfg)
    a = first.run(pop)
    again = Trainer(dataclasses.replace(cfg, total_timesteps=3 * 2048, backend="jax"))
    assert again.programs is first.programs and (first.n_iterations, again.n_iterations) == (1, 3)
    compiled = dict(first.programs.compiled)
    b = Trainer(cfg).run(pop)
    assert first.programs.compiled == compiled
    np.testing.assert_array_equal(a.fitness(), b.fitness())
    for ea, eb in zip(a.episodes, b.episodes):
        np.testing.assert_array_equal(ea.ret, eb.ret)
    assert Trainer(config(timesteps=2048, reservoirs=2)).programs is not first.programs
    host = dataclasses.replace(cfg, backend="host")
    assert Trainer(host).programs is not Trainer(host).programs


def test_agent_in_a_population_of_12_matches_agent_alone():
    """12 agents: the population size of a CMA-ES generation in test_evolve.py (6 trials × 2 seeds), whose program
    this reuses; agents 0, 5 and 11 are the first and last of one device's shard and the last of the other's (on 2
    devices). Alone, an agent is padded to the devices' count."""
    cfg = config(timesteps=2048)
    rng = np.random.default_rng(0)
    phis = [Phi(*np.exp(rng.uniform(np.log([0.1, 0.05, 0.2]), np.log([3.0, 1.0, 5.0])))) for _ in range(4)]
    big = Population.grid(phis, 3, 3e-4, 1)
    trainer = Trainer(cfg)
    state, _ = trainer.step(trainer.init(big))
    for i in (0, 5, 11):
        alone = Population(big.seeds[i:i + 1], Phi(*(f[i:i + 1] for f in big.phi)), big.learning_rate[i:i + 1])
        solo, _ = trainer.step(trainer.init(alone))
        for x, y in zip(jax.tree.leaves(state.learner.params), jax.tree.leaves(solo.learner.params)):
            np.testing.assert_allclose(np.asarray(x)[i], np.asarray(y)[0], rtol=1e-4, atol=1e-5)


def test_curves_and_fitness_bookkeeping():
    res = train(config("CartPole-v1", timesteps=2048, reservoirs=0), Population.grid(Phi(1.0, 1.0, 1.0), 1, 3e-4, 0))
    ep = res.episodes[0]
    assert ep.length.sum() <= 2048 and np.all(np.diff(ep.timestep) > 0)
    np.testing.assert_array_equal(ep.ret, ep.length)  # CartPole pays 1 per step
    np.testing.assert_array_equal(np.cumsum(ep.length), ep.timestep)  # episodes follow each other
    assert res.fitness()[0] == pytest.approx(ep.ret[-10:].mean())
    steps, values = res.curves()
    assert steps.tolist() == [2048] and values[0, 0] == pytest.approx(ep.ret[-100:].mean())


def test_full_cartpole_ppo_reaches_450_within_100k():
    res = train(config("CartPole-v1", timesteps=100_000, reservoirs=0), Population.grid(Phi(1.0, 1.0, 1.0), 3, 3e-4, 0))
    _, curves = res.curves()
    assert np.nanmax(np.nanmean(curves, axis=0)) >= 450, curves[:, -5:]
    assert res.fitness().mean() >= 450


def test_masked_cartpole_needs_the_reservoir(tmp_path):
    """Without velocities plain PPO stays below 100; a reservoir (sr 0.95, lr 0.5) recovers them (≥ 250), on the same
    100k steps. SB3's PPO on 8 envs × 256 steps (its 2048-step rollout): the reservoir learns within 100k there.
    The saved agents, evaluated after training with their deterministic policy in Gymnasium's own CartPole (10
    episodes each), keep the difference."""
    from ermrl.agent_files import write_agents
    from ermrl.analysis.policy_eval import agent_returns

    cfg = config(timesteps=100_000, reservoirs=0, n_envs=8, n_steps=256)
    plain = train(cfg, Population.grid(Phi(1.0, 1.0, 1.0), 3, 3e-4, 0))
    assert plain.fitness().mean() < 100, plain.fitness()
    reservoir_cfg = dataclasses.replace(cfg, agent=AgentConfig(reservoirs=1))
    ermrl = train(reservoir_cfg, Population.grid(Phi(0.95, 0.5, 1.0), 3, 3e-4, 1))
    assert ermrl.fitness().mean() >= 250, ermrl.fitness()
    _, curves = ermrl.curves()
    mean = np.nanmean(curves, axis=0)
    assert mean[-1] > 2 * mean[5]  # the curve rises
    evaluated = {name: np.array([agent_returns(f, 10)[1].mean() for f in write_agents(tmp_path / name, c, res)])
                 for name, c, res in [("plain", cfg, plain), ("ermrl", reservoir_cfg, ermrl)]}
    assert evaluated["plain"].mean() < 100 and evaluated["ermrl"].mean() >= 250, evaluated


def test_box_actions_and_time_limit_truncation_on_pendulum():
    res = train(config("PendulumNoVel-v1", timesteps=2048), Population.grid(Phi(0.9, 0.3, 1.0), 2, 3e-4, 1))
    for ep in res.episodes:
        assert ep.length.tolist() == [200] * 10  # every Pendulum episode is cut by its time limit
        assert np.all(ep.ret < 0) and np.all(ep.ret > -16.3 * 200)  # reward is in [-16.27, 0] per step
    assert np.all(res.finite) and np.isfinite(res.metrics["value_loss"]).all()


def test_several_envs_per_agent():
    """8 envs × 256 steps per agent: the plain PPO of test_masked_cartpole_needs_the_reservoir, whose program this
    reuses (3 seeds)."""
    cfg = config(timesteps=4096, reservoirs=0, n_envs=8, n_steps=256)
    res = train(cfg, Population.grid(Phi(1.0, 1.0, 1.0), 3, 3e-4, 0))
    assert res.total_timesteps == 4096
    for ep in res.episodes:
        assert ep.length.sum() <= 4096
        np.testing.assert_array_equal(ep.ret, ep.length)  # CartPoleNoVel pays 1 per step, like CartPole
