import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ermrl import envs
from ermrl.envs import masking
from ermrl.errors import ConfigError


@pytest.mark.parametrize("env_id, kept", [("CartPoleNoVel-v1", [0, 2]), ("PendulumNoVel-v1", [0, 1])])
def test_novel_deletes_exactly_the_velocity_dims(env_id, kept):
    base, _ = masking.parse(env_id)
    full, masked = envs.make(base), envs.make(env_id)
    key = jax.random.PRNGKey(4)
    obs_full, state = full.reset(key)
    obs_masked, _ = masked.reset(key)
    np.testing.assert_array_equal(obs_masked, obs_full[np.array(kept)])
    action = jnp.array(1) if full.info.action.discrete else jnp.array([0.3])
    step_full = full.step(key, state, action)
    step_masked = masked.step(key, state, action)
    np.testing.assert_array_equal(step_masked.obs, step_full.obs[np.array(kept)])
    assert masked.info.obs_dim == len(kept)


def test_registry_ids_and_errors():
    assert masking.novel_id("CartPole-v1") == "CartPoleNoVel-v1"
    assert masking.parse("LunarLanderNoVel-v3") == ("LunarLander-v3", (2, 3, 5))
    with pytest.raises(ConfigError, match=r"^no velocity mask is known for 'Acrobot-v1' \(from 'AcrobotNoVel-v1'\)"):
        envs.describe("AcrobotNoVel-v1")
    with pytest.raises(ConfigError, match=r"^unknown env id 'Nope-v0': Gymnasium has no 'Nope-v0'"):
        envs.describe("Nope-v0")
    with pytest.raises(ConfigError, match="unknown backend 'gpu'"):
        envs.describe("CartPole-v1", backend="gpu")


def _gymnasium_state(env_id, jax_state):
    if env_id == "CartPole-v1":
        return np.array([jax_state.x, jax_state.x_dot, jax_state.theta, jax_state.theta_dot], np.float64)
    return np.array([jax_state.theta, jax_state.theta_dot], np.float64)


@pytest.mark.parametrize("env_id", ["CartPole-v1", "Pendulum-v1"])
def test_jax_dynamics_match_gymnasium(env_id):
    """Same start state and actions: observations, rewards and episode ends agree with Gymnasium's."""
    env = envs.make(env_id)
    ref = gym.make(env_id)
    rng = np.random.default_rng(0)
    key = jax.random.PRNGKey(0)
    obs, state = env.reset(key)
    ref.reset(seed=0)
    ref.unwrapped.state = _gymnasium_state(env_id, state)
    step = jax.jit(env.step)
    for t in range(300):
        if env.info.action.discrete:
            a = int(rng.integers(2))
            jax_a = jnp.array(a)
        else:
            a = rng.uniform(-2, 2, size=(1,)).astype(np.float32)
            jax_a = jnp.asarray(a)
        ref_obs, ref_r, term, trunc, _ = ref.step(a)
        tr = step(jax.random.PRNGKey(t), state, jax_a)
        np.testing.assert_allclose(tr.final_obs, ref_obs, rtol=1e-4, atol=1e-4)
        assert float(tr.reward) == pytest.approx(ref_r, rel=1e-4, abs=1e-4)
        assert bool(tr.terminated) == term and bool(tr.truncated) == (trunc and not term)
        if term or trunc:
            break
        state = tr.state
    assert t > 5


@pytest.mark.parametrize("env_id", ["CartPole-v1", "Pendulum-v1"])
def test_step_with_randomness_drawn_ahead_equals_gymnax_step(env_id):
    """The rollout draws each step's reset ahead (``draw`` then ``step_from``); over several episodes, with
    terminations (CartPole) and time limits (Pendulum), it matches gymnax's own auto-resetting ``step``."""
    env = envs.make(env_id)
    raw, params = env._env, env._params
    ours, theirs = jax.jit(env.step), jax.jit(lambda k, s, a: raw.step(k, s, a, params))
    _, state = env.reset(jax.random.PRNGKey(0))
    rng = np.random.default_rng(1)
    ends = 0
    for t in range(700):
        key = jax.random.PRNGKey(100 + t)
        action = jnp.array(int(rng.integers(2))) if env.info.action.discrete else jnp.array([rng.uniform(-2, 2)])
        tr = ours(key, state, action)
        obs, ref_state, reward, terminated, truncated, info = theirs(key, state, action)
        np.testing.assert_array_equal(tr.obs, obs)
        np.testing.assert_array_equal(tr.final_obs, info["final_observation"])
        jax.tree.map(np.testing.assert_array_equal, tr.state, ref_state)
        assert (float(tr.reward), bool(tr.terminated)) == (float(reward), bool(terminated))
        assert bool(tr.truncated) == (bool(truncated) and not bool(terminated))
        ends += bool(terminated) or bool(truncated)
        state = tr.state
    assert ends >= 3
