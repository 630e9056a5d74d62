"""``PPOConfig.normalize``: SB3's VecNormalize over what the policy sees and the rewards (ermrl.ppo.normalize).

The parity test drives SB3's own VecNormalize and ours with the same stream (reference suite); the others check,
with real training runs, that the policy's inputs are standardized, that episode returns stay raw, that the
statistics travel with saved agents and snapshots, and that an unnormalized config keeps its old record."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ermrl
from ermrl import agent_files
from ermrl.agent import Phi
from ermrl import storage
from ermrl.experiments import baselines
from ermrl.ppo import normalize
from ermrl.ppo.config import PPOConfig
from ermrl.training import Population, TrainConfig, Trainer, make_agent_fns
from ermrl.training.rollout import collect

SMALL = PPOConfig(n_envs=2, n_steps=512, batch_size=256, n_epochs=1, normalize=True)


def _stream(seed=0, steps=300, n_envs=3, dim=5):
    """Contexts with features of very different scales, rewards like Pendulum's and episode ends."""
    rng = np.random.default_rng(seed)
    scale = np.array([1e-3, 0.1, 1.0, 10.0, 100.0], np.float32)[:dim]
    contexts = (rng.normal(size=(steps + 1, n_envs, dim)) * scale + scale).astype(np.float32)
    finals = (rng.normal(size=(steps, n_envs, dim)) * scale + scale).astype(np.float32)
    rewards = rng.uniform(-16.3, 0.0, size=(steps, n_envs)).astype(np.float32)
    dones = rng.random((steps, n_envs)) < 0.02
    return contexts, finals, rewards, dones


def test_running_statistics_are_the_streams_mean_and_variance():
    contexts, *_ = _stream()
    rms = normalize.rms_init((5,))
    for batch in contexts:
        rms = normalize.rms_update(rms, jnp.asarray(batch))
    flat = contexts.reshape(-1, 5).astype(np.float64)
    np.testing.assert_allclose(rms.mean, flat.mean(0), rtol=1e-4, atol=1e-6)
    # the prior (variance 1 with weight 1e-4) adds ~1e-4 / N, visible on the tiny feature only
    np.testing.assert_allclose(rms.var, flat.var(0), rtol=1e-3, atol=2e-7)
    assert float(rms.count) == pytest.approx(len(flat) + normalize.COUNT_INIT)


def test_returns_restart_at_an_episode_end_and_rewards_are_scaled_not_centred():
    ctx = jnp.ones((2, 3))
    norm, _ = normalize.start(ctx)
    reward = jnp.array([-2.0, -4.0])
    norm, _, _, r1 = normalize.step(norm, ctx, ctx, reward, jnp.array([True, False]), 0.9)
    np.testing.assert_allclose(norm.returns, [0.0, -4.0])
    assert np.all(np.asarray(r1) < 0) and float(r1[1] / r1[0]) == pytest.approx(2.0)  # one scale for all envs
    norm, _, _, _ = normalize.step(norm, ctx, ctx, reward, jnp.array([False, False]), 0.9)
    np.testing.assert_allclose(norm.returns, [-2.0, -4.0 * 0.9 - 4.0], rtol=1e-6)


@pytest.mark.reference
def test_parity_with_sb3_vecnormalize():
    """The same contexts, terminal contexts, rewards and episode ends through SB3's VecNormalize (float64)."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import VecEnv, VecNormalize

    contexts, finals, rewards, dones = _stream(seed=3)
    n_envs, dim = contexts.shape[1:]

    class Replay(VecEnv):
        def __init__(self):
            space = gym.spaces.Box(-np.inf, np.inf, (dim,), np.float32)
            super().__init__(n_envs, space, gym.spaces.Discrete(2))
            self.t = 0

        def reset(self):
            return contexts[0].copy()

        def step_async(self, actions):
            pass

        def step_wait(self):
            t, self.t = self.t, self.t + 1
            infos = [{"terminal_observation": finals[t, i].copy()} if dones[t, i] else {} for i in range(n_envs)]
            return contexts[t + 1].copy(), rewards[t].copy(), dones[t].copy(), infos

        def close(self): pass
        def get_attr(self, *a, **k): return [None] * n_envs
        def set_attr(self, *a, **k): pass
        def env_method(self, *a, **k): return [None] * n_envs
        def env_is_wrapped(self, *a, **k): return [False] * n_envs

    sb3 = VecNormalize(Replay(), gamma=0.95)
    theirs = sb3.reset()
    norm, ours = normalize.start(jnp.asarray(contexts[0]))
    np.testing.assert_allclose(ours, theirs, rtol=1e-4, atol=1e-4)
    for t in range(len(rewards)):
        obs, reward, _, infos = sb3.step(np.zeros(n_envs, np.int64))
        norm, ctx, final, r = normalize.step(norm, jnp.asarray(contexts[t + 1]), jnp.asarray(finals[t]),
                                             jnp.asarray(rewards[t]), jnp.asarray(dones[t]), 0.95)
        np.testing.assert_allclose(ctx, obs, rtol=1e-4, atol=1e-4, err_msg=f"step {t}")
        np.testing.assert_allclose(r, reward, rtol=1e-4, atol=1e-5, err_msg=f"step {t}")
        for i in np.flatnonzero(dones[t]):
            np.testing.assert_allclose(final[i], infos[i]["terminal_observation"], rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(norm.context.mean, sb3.obs_rms.mean, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(norm.context.var, sb3.obs_rms.var, rtol=1e-3)
    np.testing.assert_allclose(norm.ret.var, sb3.ret_rms.var, rtol=1e-3)


def test_the_policy_sees_standardized_contexts_and_episode_returns_stay_raw():
    config = TrainConfig(env_id="PendulumNoVel-v1", total_timesteps=4096, ppo=SMALL)
    fns = make_agent_fns(config)
    population = Population.grid(Phi(0.95, 0.5, 1.0), [0], 3e-4, 1)
    unit = fns.agent.unit_weights(0)
    state = jax.jit(fns.init)(jnp.uint32(0), unit, Phi(*(jnp.asarray(v[0]) for v in population.phi)),
                              jnp.float32(3e-4), None)
    carry, steps = jax.jit(lambda s: collect(fns.env, fns.agent, fns.net, s.learner.params, s.reservoirs, s.envs,
                                             s.key, 2048, SMALL.gamma))(state)
    seen = np.asarray(steps.context).reshape(-1, steps.context.shape[-1])[512:]  # past the first statistics
    moving = np.asarray(carry.norm.context.var) > 1e-4  # units that move (many are near 0 or saturated)
    assert moving.sum() > 50
    assert np.abs(seen[:, moving].mean(0)).mean() < 0.25
    assert 0.6 < seen[:, moving].std(0).mean() < 1.4
    finished = np.asarray(steps.finished_return)
    returns = finished[np.isfinite(finished)]
    assert len(returns) >= 15 and returns.max() < 0 and returns.mean() < -500  # raw Pendulum returns (200 steps)
    learned = np.asarray(steps.reward)
    assert np.abs(learned).max() <= normalize.CLIP_REWARD and np.abs(learned).mean() < 2.0  # scaled down


def test_a_normalized_run_saves_its_statistics_and_a_loaded_agent_uses_them(tmp_path):
    config = TrainConfig(env_id="PendulumNoVel-v1", total_timesteps=2048, ppo=SMALL)
    results = Trainer(config).run(Population.grid(Phi(0.95, 0.5, 1.0), [0, 1], 3e-4, 1))
    norm = results.policies.context_norm
    assert norm["mean"].shape == norm["var"].shape == (2, 100) and not np.allclose(norm["mean"][0], norm["mean"][1])
    paths = agent_files.write_agents(tmp_path, config, results)
    agent = ermrl.load_agent(paths[1])
    np.testing.assert_array_equal(agent.context_norm["var"], norm["var"][1])
    env = agent.make_env()
    obs, _ = env.reset(seed=0)
    agent.reset()
    agent.act(obs)
    raw = agent._state.reshape(-1)  # the reservoir's state: what an unnormalized agent would feed its policy
    expected = np.clip((raw - norm["mean"][1]) / np.sqrt(norm["var"][1] + normalize.EPSILON), -10, 10)
    np.testing.assert_allclose(agent.context, expected, rtol=1e-5, atol=1e-5)


def test_the_host_backend_normalizes_too():
    config = TrainConfig(env_id="Pendulum-v1", total_timesteps=1024, backend="host", env_workers=0,
                         ppo=dataclasses.replace(SMALL, n_steps=256, batch_size=128))
    results = Trainer(config).run(Population.grid(Phi(0.95, 0.5, 1.0), [0], 3e-4, 1))
    assert results.policies.context_norm["mean"].shape == (1, 100)
    assert all(np.all(e.ret < 0) for e in results.episodes)  # raw returns


def test_an_unnormalized_config_keeps_its_record_and_settings():
    """Configs recorded before the field existed (studies, snapshots, stored baselines) still match."""
    plain = storage.to_dict(TrainConfig())
    assert "normalize" not in plain["ppo"] and storage.to_dict(TrainConfig(ppo=SMALL))["ppo"]["normalize"] is True
    assert storage.from_dict(TrainConfig, plain) == TrainConfig()
    assert baselines.ppo_settings(PPOConfig()) == {}
    assert baselines.ppo_settings(PPOConfig(normalize=True)) == {"normalize": True}
