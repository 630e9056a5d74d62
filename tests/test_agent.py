import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ermrl import envs, reservoir
from ermrl.agent import Agent, AgentConfig, Phi
from ermrl.errors import ConfigError
from ermrl.reservoir import ReservoirSpec


def make(env_id="CartPoleNoVel-v1", **kw):
    agent = Agent(AgentConfig(**kw), envs.describe(env_id))
    k = max(agent.config.reservoirs, 1)
    phi = Phi(jnp.full((k,), 0.9), jnp.full((k,), 0.3), jnp.full((k,), 1.5))
    return agent, Agent.build(agent.unit_weights(0), phi) if agent.config.reservoirs else None


def test_input_is_obs_previous_action_and_reward():
    agent, res = make()
    assert agent.input_dim == 2 + 2 + 1  # masked CartPole obs, one-hot of 2 actions, reward
    np.testing.assert_array_equal(agent.encode_action(jnp.array(1)), [0.0, 1.0])
    x0 = jnp.zeros((1, 100))
    obs = jnp.array([0.1, -0.2])
    state, ctx = agent.observe(res, x0, obs, agent.encode_action(jnp.array(1)), jnp.float32(1.0))
    u = jnp.array([0.1, -0.2, 0.0, 1.0, 1.0])
    w = jax.tree.map(lambda x: x[0], res.weights)
    np.testing.assert_allclose(state[0], reservoir.step(w, 0.3, x0[0], u), rtol=1e-6)
    np.testing.assert_array_equal(ctx, state[0])


def test_episode_start_resets_and_feeds_zeros():
    agent, res = make()
    obs = jnp.array([0.05, 0.01])
    state, ctx = agent.start_episode(res, obs)
    w = jax.tree.map(lambda x: x[0], res.weights)
    expected = 0.3 * jnp.tanh(w.Win @ jnp.array([0.05, 0.01, 0.0, 0.0, 0.0]) + w.bias)
    np.testing.assert_allclose(ctx, expected, rtol=1e-6)


def test_feed_action_none_reproduces_the_reference_constant():
    agent, _ = make(feed_action="none")
    for a in (0, 1):  # the reference fed one_hot(0) whatever the action
        np.testing.assert_array_equal(agent.encode_action(jnp.array(a)), [1.0, 0.0])
    box, _ = make("Pendulum-v1", feed_action="none")
    np.testing.assert_array_equal(box.encode_action(jnp.array([1.7])), [0.0])
    box_fed, _ = make("Pendulum-v1")
    np.testing.assert_allclose(box_fed.encode_action(jnp.array([1.7])), [1.7], rtol=1e-6)


def test_context_layouts():
    agent, res = make(reservoirs=2, spec=ReservoirSpec(units=50))
    assert agent.context_dim == 100
    state, ctx = agent.start_episode(res, jnp.zeros(2))
    np.testing.assert_array_equal(ctx, state.reshape(-1))
    skip, res_s = make(skip_connection=True)
    _, ctx = skip.start_episode(res_s, jnp.array([0.5, 0.25]))
    assert skip.context_dim == 105
    np.testing.assert_array_equal(ctx[100:], [0.5, 0.25, 0.0, 0.0, 0.0])
    part, res_p = make(reservoirs=2, observed_units=10)
    state, ctx = part.start_episode(res_p, jnp.ones(2))
    assert part.context_dim == 20
    np.testing.assert_array_equal(ctx, state[:, :10].reshape(-1))
    plain, _ = make(reservoirs=0)
    assert plain.context_dim == 2
    _, ctx = plain.start_episode(None, jnp.array([3.0, 4.0]))
    np.testing.assert_array_equal(ctx, [3.0, 4.0])


def test_multi_reservoir_seeds_follow_the_reference():
    agent, _ = make(reservoirs=2)
    w = agent.unit_weights(5)
    np.testing.assert_array_equal(w.W[1], reservoir.generate(agent.config.spec, 6, agent.input_dim).W)


def test_bad_agent_configs():
    with pytest.raises(ConfigError, match="observed_units must be in"):
        AgentConfig(observed_units=0)
    with pytest.raises(ConfigError, match="feed_action must be"):
        AgentConfig(feed_action="last")
