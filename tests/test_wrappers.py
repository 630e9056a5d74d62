"""ermrl.wrappers.ReservoirObservation: the trainer's context, as a Gymnasium wrapper."""

import gymnasium as gym
import jax.numpy as jnp
import numpy as np
import pytest

from ermrl import reservoir
from ermrl.agent import AgentConfig
from ermrl.errors import ConfigError
from ermrl.reservoir import ReservoirSpec
from ermrl.wrappers import ReservoirObservation


def test_context_follows_the_reservoir_update_with_previous_action_and_reward():
    env = ReservoirObservation(gym.make("CartPole-v1"), sr=0.9, lr=0.3, iss=1.5, seed=4)
    assert env.observation_space.shape == (100,)
    unit = reservoir.generate(ReservoirSpec(), 4, 4 + 2 + 1)
    w = reservoir.scale(unit, 0.9, 1.5)
    ctx, _ = env.reset(seed=0)
    raw = env.unwrapped.state.astype(np.float32)
    x = reservoir.step(w, 0.3, jnp.zeros(100), jnp.concatenate([raw, jnp.zeros(3)]))
    np.testing.assert_allclose(ctx, x, rtol=1e-5, atol=1e-6)
    for action in (1, 0, 1):
        ctx, r, *_ = env.step(action)
        raw = env.unwrapped.state.astype(np.float32)
        u = jnp.concatenate([raw, jnp.eye(2)[action], jnp.array([r], jnp.float32)])
        x = reservoir.step(w, 0.3, x, u)
        np.testing.assert_allclose(ctx, x, rtol=1e-5, atol=1e-6)
    assert env.observation_space.contains(ctx.astype(np.float32))


def test_several_reservoirs_box_actions_and_errors():
    env = ReservoirObservation(gym.make("Pendulum-v1"), sr=[0.5, 2.0], lr=[0.2, 0.9], seed=1,
                               agent=AgentConfig(reservoirs=2, spec=ReservoirSpec(units=30), skip_connection=True))
    ctx, _ = env.reset(seed=0)
    assert ctx.shape == (2 * 30 + 3 + 1 + 1,) and env.observation_space.shape == ctx.shape
    ctx, *_ = env.step(np.array([1.5], np.float32))
    assert ctx[-2] == pytest.approx(1.5)  # the skip connection shows u_t = (o_t, a_{t-1}, r_{t-1})
    with pytest.raises(ConfigError, match="at least one reservoir"):
        ReservoirObservation(gym.make("CartPole-v1"), agent=AgentConfig(reservoirs=0))


@pytest.mark.reference
def test_sb3_ppo_trains_on_the_wrapper():
    sb3 = pytest.importorskip("stable_baselines3")
    env = ReservoirObservation(gym.make("CartPole-v1"), seed=0)
    model = sb3.PPO("MlpPolicy", env, n_steps=512, seed=0, device="cpu").learn(2048)
    assert model.num_timesteps == 2048
