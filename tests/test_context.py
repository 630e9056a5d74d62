"""The context-observation figure: one episode of a saved agent, its observation above its reservoir units."""

import gymnasium as gym
import numpy as np
import pytest
from test_saved_agent import write_untrained_agent

import ermrl
from ermrl.agent import AgentConfig
from ermrl.analysis.context import context_figure, plot_context, record_episode
from ermrl.errors import ConfigError
from ermrl.saved_agent import DeleteDims
from ermrl.wrappers import ReservoirObservation

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("run")
    write_untrained_agent(folder, "CartPoleNoVel-v1", seed=3)
    return folder


def test_record_episode_shapes_and_the_wrapper_sees_the_same_context(run):
    agent = ermrl.load_agent(run)
    obs, context, rewards = record_episode(agent, agent.make_env(), seed=1)
    T = len(rewards)
    assert obs.shape == (T, 2) and context.shape == (T, 100) and T >= 8 and np.all(rewards == 1.0)
    assert np.all(np.abs(context) <= 1)
    # ReservoirObservation (JAX) on the same masked env and actions builds the same contexts
    wrapped = ReservoirObservation(DeleteDims(gym.make("CartPole-v1"), (0, 2)), sr=0.95, lr=0.5, iss=1.0, seed=3)
    ctx, _ = wrapped.reset(seed=1)
    agent.reset()
    reference = [ctx]
    env = agent.make_env()
    o, _ = env.reset(seed=1)
    reward = None
    for t in range(T - 1):
        action = agent.act(o, reward)
        o, reward, *_ = env.step(action)
        ctx, *_ = wrapped.step(action)
        reference.append(ctx)
    np.testing.assert_allclose(context, np.stack(reference), atol=1e-5)
    short = record_episode(agent, env, seed=1, max_steps=5)
    assert [x.shape[0] for x in short] == [5, 5, 5]


def test_plot_context_and_context_figure_write_pngs(run, tmp_path):
    agent = ermrl.load_agent(run)
    obs, context, _ = record_episode(agent, agent.make_env(), seed=0)
    path = plot_context(obs, context, tmp_path / "ctx.png", units=20)
    assert path.read_bytes()[:8] == PNG
    out = context_figure(run, tmp_path / "figure.png", seed=2)
    assert out == tmp_path / "figure.png" and out.read_bytes()[:8] == PNG
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary file left


def test_bad_inputs_are_config_errors(run, tmp_path):
    with pytest.raises(ConfigError, match=r"obs \(T, D\) and context \(T, N\)"):
        plot_context(np.zeros((5, 2)), np.zeros((4, 100)), tmp_path / "x.png")
    with pytest.raises(ConfigError, match="has no saved agents"):
        context_figure(tmp_path, tmp_path / "x.png")
    plain = tmp_path / "plain"
    write_untrained_agent(plain, "CartPoleNoVel-v1", agent=AgentConfig(reservoirs=0))
    with pytest.raises(ConfigError, match="plain PPO agent: it has no reservoir"):
        context_figure(plain, tmp_path / "x.png")
