"""How much memory a population's training needs, estimated before any work, so that a run too big for the
machine (``--units 200000``: a 160 GB weight matrix per agent) is refused in one line instead of compiling and
then dying of a MemoryError.

The estimate counts the arrays whose size grows with the settings, in float32, per agent: the K reservoirs'
weights (W (N, N), Win (N, in), bias (N,)), held twice (the unit draw and its Φ-scaled copy); the policy and
value networks with Adam's two moments and a gradient (4 copies); and one rollout's buffer (n_steps × n_envs
rows of the context and the networks' activations), three times over for the update's minibatches and
gradients. It is a lower bound of the peak (XLA's temporaries come on top), so a refused run could never fit.
"""

from __future__ import annotations

import os

from ermrl.errors import ConfigError

FLOAT_BYTES = 4


def estimate_bytes(config, agents: int, obs_dim: int, action_dim: int) -> int:
    """Bytes that ``agents`` agents trained with ``config`` (a TrainConfig) hold at least, on an env with
    ``obs_dim`` observation dims and ``action_dim`` action features (see the module's docstring)."""
    agent, ppo = config.agent, config.ppo
    k, n = agent.reservoirs, agent.spec.units
    inputs = obs_dim + action_dim + 1  # (o_t, a_{t-1}, r_{t-1})
    reservoirs = 2 * k * (n * n + n * inputs + n)
    context = k * n + obs_dim if k else obs_dim
    if ppo.model == "lstm":
        h = ppo.lstm_hidden_size
        widths = [context, 4 * h, *ppo.hidden]  # the LSTM's four gates, then the MLP
    else:
        widths = [context, *ppo.hidden]
    layers = sum(a * b + b for a, b in zip(widths, widths[1:])) + widths[-1] * (action_dim + 1)
    networks = 4 * 2 * layers  # actor and critic; weights, two Adam moments and a gradient
    rollout = 3 * ppo.n_steps * ppo.n_envs * (context + 2 * sum(widths[1:]) + 16)
    return FLOAT_BYTES * agents * (reservoirs + networks + rollout)


def machine_bytes() -> int | None:
    """The machine's physical memory in bytes; None where the system does not say."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def check(config, agents: int, obs_dim: int, action_dim: int, what: str = "this run") -> None:
    """ConfigError (one line) when ``agents`` agents trained with ``config`` need more memory than the machine
    has (:func:`estimate_bytes` against :func:`machine_bytes`), naming the sizes that drive it."""
    need, have = estimate_bytes(config, agents, obs_dim, action_dim), machine_bytes()
    if have is None or need <= have:
        return
    k, n = config.agent.reservoirs, config.agent.spec.units
    raise ConfigError(f"{what} needs at least {need / 2**30:,.0f} GiB of memory ({agents} agent{'s' if agents > 1 else ''}"
                      + (f" × {k} reservoir{'s' if k > 1 else ''} of {n} units" if k else "")
                      + f", {config.ppo.n_envs} envs × {config.ppo.n_steps} steps per rollout), more than this "
                      f"machine's {have / 2**30:,.0f} GiB; lower `units`, `seeds`, `popsize`, `n_envs` or `n_steps`")
