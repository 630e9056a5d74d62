"""The context against the observation (the paper's appendix figure "context-observation").

One episode of a saved agent: its observation traces in a panel above the traces of its first reservoir units,
the context c_t the policy sees, with the env step t on the x axis.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from ermrl.errors import ConfigError
from ermrl.storage import save_figure

UNITS = 20
"""Reservoir units plotted by default."""


def record_episode(agent, env, seed: int = 0, max_steps: int | None = None,
                   deterministic: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs one episode of ``agent`` (a :class:`~ermrl.saved_agent.SavedAgent`) in ``env`` (its
    ``make_env()``), reset with ``seed``, for at most ``max_steps`` steps.

    Returns (obs (T, D), context (T, N), rewards (T,)): row t holds the observation the agent acted on at
    step t, the context c_t built from it, and the reward that step's action earned; D = obs dims (masked for
    NoVel ids), N = the agent's context_dim."""
    if max_steps is not None and max_steps < 1:
        raise ConfigError(f"max steps must be >= 1, got {max_steps}")
    obs, _ = env.reset(seed=seed)
    agent.reset()
    observations, contexts, rewards = [], [], []
    reward, done = None, False
    while not done and (max_steps is None or len(rewards) < max_steps):
        action = agent.act(obs, reward, deterministic=deterministic)
        observations.append(np.asarray(obs, np.float32))
        contexts.append(agent.context.copy())
        obs, reward, terminated, truncated, _ = env.step(action)
        rewards.append(float(reward))
        done = terminated or truncated
    return np.stack(observations), np.stack(contexts), np.asarray(rewards)


def plot_context(obs: np.ndarray, context: np.ndarray, path: Path | str, units: int = UNITS, title: str = "",
                 obs_labels: list[str] | None = None) -> Path:
    """Draws obs (T, D) in a top panel and the first ``units`` columns of context (T, N) below it, against the
    step t; writes the PNG ``path`` (atomically) and returns it."""
    obs, context = np.asarray(obs), np.asarray(context)
    if obs.ndim != 2 or context.ndim != 2 or len(obs) != len(context) or len(obs) == 0:
        raise ConfigError(f"plot_context needs obs (T, D) and context (T, N) with the same T >= 1, got "
                          f"{obs.shape} and {context.shape}")
    if units < 1:
        raise ConfigError(f"units must be >= 1, got {units}")
    shown = min(units, context.shape[1])
    steps = np.arange(len(obs))
    fig = Figure(figsize=(8, 5.5))
    top, bottom = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [1, 1.6]})
    labels = obs_labels or [f"o[{i}]" for i in range(obs.shape[1])]
    for i in range(obs.shape[1]):
        top.plot(steps, obs[:, i], lw=1.2, label=labels[i])
    top.set_ylabel("observation")
    top.legend(loc="upper right", fontsize=8, ncol=min(obs.shape[1], 6))
    top.grid(alpha=0.3)
    colors = matplotlib.colormaps["viridis"](np.linspace(0, 1, shown))
    for j in range(shown):
        bottom.plot(steps, context[:, j], lw=0.8, color=colors[j])
    bottom.set_ylabel(f"reservoir state\n(first {shown} units)")
    bottom.set_xlabel("step t")
    bottom.grid(alpha=0.3)
    if title:
        top.set_title(title)
    return save_figure(fig, Path(path).with_suffix(".png"))


def context_figure(source: Path | str, out: Path | str, seed: int = 0, units: int = UNITS,
                   max_steps: int | None = None) -> Path:
    """The context-observation figure of a saved agent: ``source`` is an agent file, or a run folder (its first
    saved agent). Runs one deterministic episode reset with ``seed``; writes the PNG ``out`` and returns it."""
    from ermrl.saved_agent import load_agent

    agent = load_agent(source)
    if agent.config.reservoirs == 0:
        raise ConfigError(f"{agent.path} is a plain PPO agent: it has no reservoir to plot; give an ER-MRL agent")
    env = agent.make_env()
    try:
        obs, context, rewards = record_episode(agent, env, seed, max_steps)
    finally:
        env.close()
    phi = ", ".join(f"{f} " + "/".join(f"{v:.3g}" for v in getattr(agent.phi, f)) for f in agent.phi._fields)
    title = f"{agent.env_id}, seed {agent.seed} ({phi}): episode return {rewards.sum():.1f} in {len(rewards)} steps"
    kept = agent.env.kept_dims
    return plot_context(obs, context, out, units, title, [f"o[{d}]" for d in kept])
