"""``PPOConfig.use_sde``: SB3's gSDE (generalized State-Dependent Exploration) in ermrl.ppo.networks.

The distribution is checked against SB3's own ``StateDependentNoiseDistribution`` (reference suite); the rest with
real rollouts: actions are the mean plus the actor's features times an exploration matrix held for
``sde_sample_freq`` steps, per env, and a saved gSDE agent acts the same way."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ermrl
from ermrl import agent_files
from ermrl.agent import AgentConfig, Phi
from ermrl.envs.spaces import ActionSpace
from ermrl.errors import ConfigError
from ermrl.experiments import baselines
from ermrl.ppo.config import PPOConfig
from ermrl.ppo.networks import ActorCritic
from ermrl.training import Population, TrainConfig, Trainer, make_agent_fns
from ermrl.training.rollout import collect, draw_noise

SDE = PPOConfig(n_steps=512, batch_size=128, n_epochs=1, use_sde=True, log_std_init=-1.0)


def _net(dim=2):
    return ActorCritic(ActionSpace(False, dim, (-2.0,) * dim, (2.0,) * dim), (64, 64), -0.5, use_sde=True)


@pytest.mark.reference
def test_log_prob_entropy_and_noise_match_sb3():
    import torch as th
    from stable_baselines3.common.distributions import StateDependentNoiseDistribution

    rng = np.random.default_rng(0)
    batch, latent_dim, dim = 7, 64, 3
    mean = rng.normal(size=(batch, dim)).astype(np.float32)
    latent = np.tanh(rng.normal(size=(batch, latent_dim))).astype(np.float32)
    log_std = rng.normal(-0.5, 0.3, size=(latent_dim, dim)).astype(np.float32)
    actions = rng.normal(size=(batch, dim)).astype(np.float32)
    eps = rng.normal(size=(batch, latent_dim, dim)).astype(np.float32)

    theirs = StateDependentNoiseDistribution(dim)  # full_std, no expln, no squashing, features not learnt
    theirs.proba_distribution(th.tensor(mean), th.tensor(log_std), th.tensor(latent))
    theirs.exploration_matrices = th.exp(th.tensor(log_std)) * th.tensor(eps)  # what sample_weights draws

    net = ActorCritic(ActionSpace(False, dim, (-1.0,) * dim, (1.0,) * dim), (64, latent_dim), use_sde=True)
    params = net.init(jax.random.PRNGKey(0), 4)._replace(log_std=jnp.asarray(log_std))
    np.testing.assert_allclose(net.log_prob(params, jnp.asarray(mean), jnp.asarray(actions), jnp.asarray(latent)),
                               theirs.log_prob(th.tensor(actions)).numpy(), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(net.entropy(params, jnp.asarray(mean), jnp.asarray(latent)),
                               theirs.entropy().numpy(), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(net.sample(params, jnp.asarray(mean), jnp.asarray(eps), jnp.asarray(latent)),
                               mean + theirs.get_noise(th.tensor(latent)).numpy(), rtol=1e-5, atol=1e-5)


def test_each_env_keeps_its_exploration_matrix_for_sde_sample_freq_steps():
    net = _net()
    keys = jax.random.split(jax.random.PRNGKey(1), 10)
    every4 = np.asarray(draw_noise(net, keys, 3, 4))
    assert every4.shape == (10, 3, 64, 2)
    for t in range(10):
        np.testing.assert_array_equal(every4[t], every4[t // 4 * 4])
    assert not np.allclose(every4[0], every4[4]) and not np.allclose(every4[0, 0], every4[0, 1])
    once = np.asarray(draw_noise(net, keys, 3, -1))
    assert all(np.array_equal(once[t], once[0]) for t in range(10))


@pytest.mark.parametrize("freq", [-1, 128])  # blocks longer than the 64 features: a fit can fail
def test_a_rollouts_actions_are_the_mean_plus_features_times_a_held_matrix(freq):
    config = TrainConfig(env_id="Pendulum-v1", total_timesteps=512, agent=AgentConfig(reservoirs=0),
                         ppo=dataclasses.replace(SDE, sde_sample_freq=freq))
    fns = make_agent_fns(config)
    state = jax.jit(fns.init)(jnp.uint32(0), None, None, jnp.float32(3e-4), None)
    _, steps = jax.jit(lambda s: collect(fns.env, fns.agent, fns.net, s.learner.params, s.reservoirs, s.envs, s.key,
                                         512, 0.99, freq))(state)
    head, latent = fns.net.policy(state.learner.params, steps.context[:, 0])
    residual = np.asarray(steps.action[:, 0] - head)  # (512, 1): z_t · M_t
    block = 512 if freq == -1 else freq
    for start in (0, block, 512 - block):
        z, r = np.asarray(latent[start:start + block]), residual[start:start + block]
        m, *_ = np.linalg.lstsq(z, r, rcond=None)
        np.testing.assert_allclose(z @ m, r, atol=1e-4)  # one matrix explains the block exactly
    if freq > 0:  # but not two blocks
        z, r = np.asarray(latent[:2 * block]), residual[:2 * block]
        m, *_ = np.linalg.lstsq(z, r, rcond=None)
        assert np.abs(z @ m - r).max() > 1e-2
    log_std = fns.net._log_std(state.learner.params, latent)
    expected = -0.5 * (residual / np.exp(log_std)) ** 2 - log_std - 0.5 * np.log(2 * np.pi)
    np.testing.assert_allclose(steps.log_prob[:, 0], expected.sum(-1), rtol=1e-4, atol=1e-4)


def test_a_saved_gsde_agent_explores_with_one_matrix_per_episode(tmp_path):
    config = TrainConfig(env_id="PendulumNoVel-v1", total_timesteps=1024, ppo=SDE)
    results = Trainer(config).run(Population.grid(Phi(0.95, 0.5, 1.0), [0], 3e-4, 1))
    assert results.policies.log_std.shape == (1, 64, 1)
    agent = ermrl.load_agent(agent_files.write_agents(tmp_path, config, results)[0])
    assert agent.sde
    env = agent.make_env()
    obs, _ = env.reset(seed=0)
    agent.reset(sampling_seed=3)
    matrix = agent._exploration.copy()
    assert matrix.shape == (64, 1) and 0.6 < (matrix / np.exp(agent.log_std)).std() < 1.4  # N(0, exp(log_std)²)
    reward = None
    for _ in range(50):
        action = agent.act(obs, reward, deterministic=False)
        np.testing.assert_allclose(action, np.clip(agent.head + agent._latent @ matrix, -2, 2), rtol=1e-5, atol=1e-5)
        obs, reward, *_ = env.step(action)
    assert agent.std.shape == (1,) and agent.std[0] > 0
    agent.reset(sampling_seed=3)
    np.testing.assert_array_equal(agent._exploration, matrix)
    agent.reset(sampling_seed=4)
    assert not np.allclose(agent._exploration, matrix)


def test_use_sde_is_refused_where_sb3_refuses_it_and_kept_out_of_old_records():
    with pytest.raises(ConfigError, match="^sde_sample_freq must be -1"):
        PPOConfig(use_sde=True, sde_sample_freq=0)
    for model in ("ff", "lstm"):
        with pytest.raises(ConfigError, match="^`use_sde` needs continuous"):
            make_agent_fns(TrainConfig(env_id="CartPoleNoVel-v1", agent=AgentConfig(reservoirs=0),
                                       ppo=PPOConfig(use_sde=True, model=model)))
    assert "use_sde" not in ermrl.storage.to_dict(PPOConfig())
    assert baselines.ppo_settings(PPOConfig(use_sde=True, sde_sample_freq=4)) == {"use_sde": True,
                                                                                  "sde_sample_freq": 4}
