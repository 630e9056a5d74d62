"""Linear probes of the reservoir context (paper, appendix "Results analysis").

A reservoir fed what the ER-MRL agent is fed, u_t = (masked o_t, a_{t−1}, r_{t−1}), is read out by a ridge
regression to (a) reconstruct the velocity dims that the NoVel env deleted, at the same step t, and (b) predict
the kept observation k = 1..horizon steps ahead. A reservoir with memory recovers the velocities (they are
differences of the positions it saw); a memoryless one (:data:`MEMORYLESS`) cannot.

The data are rollouts of the *full* base env under a uniformly random, seeded policy. The reservoir is the
project's own: :meth:`ermrl.agent.Agent.unit_weights` draws it, :meth:`~ermrl.agent.Agent.build` applies Φ, and
:meth:`~ermrl.agent.Agent.start_episode` / :meth:`~ermrl.agent.Agent.observe` / ``encode_action`` run it, so the
states are the contexts c_t the policy (or :class:`ermrl.wrappers.ReservoirObservation`) would see, reset at
every episode start. Readouts are fitted on the training episodes and scored (R², scikit-learn) on held-out
episodes: the split is by episode, never by step.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ermrl.agent import Agent, AgentConfig, DEFAULT_PHI, Phi
from ermrl.analysis.html import markdown_table
from ermrl.envs import masking
from ermrl.envs.host_backend import describe
from ermrl.envs.host_groups import make_gymnasium
from ermrl.envs.spaces import EnvInfo
from ermrl.errors import ConfigError
from ermrl.reservoir import ReservoirSpec

MEMORY = DEFAULT_PHI
"""A reservoir with memory: the default Φ of :class:`ermrl.wrappers.ReservoirObservation`."""
MEMORYLESS = Phi(1e-4, 1.0, 1.0)
"""No memory: with sr 1e-4 and leak rate 1, x_t ≈ tanh(Win u_t + b) depends on u_t alone."""
DEFAULT_ALPHA = 1e-2
"""Ridge penalty of the readout (scikit-learn's, on the sum of squared errors over a few thousand steps).
Measured on CartPoleNoVel-v1 (300 random episodes): with memory, velocity R² is 0.998 for α in 1e-8..1e-3 and
0.996 at 1e-2. Smaller α lets the readout amplify the faint echo of the past that :data:`MEMORYLESS` keeps
(sr 1e-4 is not 0): its R² is 0.95 at α = 1e-8, 0.72 at 1e-6, 0.68 at 1e-4, and 0.62 at 1e-2, where it equals
sr = 0 exactly. That 0.62 floor is no memory: under a random policy the velocities correlate with the current
positions (a linear fit on (x, θ, a_(t−1)) gets 0.61), since the pole falls as it turns."""


@dataclasses.dataclass(frozen=True)
class Rollouts:
    """Episodes of a base env under a random policy, concatenated: T steps in all.

    Step t of an episode holds o_t, the action a_t taken after it and the reward r_t it earned; each episode's
    last step holds its final observation (after the last action), with action 0 and reward 0 never fed.
    """

    base_id: str
    obs: np.ndarray
    """(T, full_obs_dim) float32 full (unmasked) observations."""
    actions: np.ndarray
    """(T,) int32 for Discrete actions, (T, action_dim) float32 for Box."""
    rewards: np.ndarray
    """(T,) float32."""
    episode: np.ndarray
    """(T,) int64 index of each step's episode."""
    t: np.ndarray
    """(T,) int64 index of each step within its episode (0 at episode start)."""
    remaining: np.ndarray
    """(T,) int64 steps left in the episode after this one (0 on its final observation)."""

    @property
    def n_episodes(self) -> int:
        return int(self.episode[-1]) + 1


def collect(base_id: str, episodes: int, seed: int = 0, max_steps: int | None = None) -> Rollouts:
    """Runs ``episodes`` episodes of the Gymnasium env ``base_id`` with uniformly random actions.

    The env is reset with ``seed`` once (then continues its own RNG); the action space is seeded with ``seed``.
    ``max_steps`` truncates each episode early (None: the env's own time limit).
    """
    if episodes < 2:
        raise ConfigError(f"episodes must be >= 2 to hold some out, got {episodes}")
    import gymnasium as gym

    env = make_gymnasium(base_id)
    env.action_space.seed(seed)
    discrete = isinstance(env.action_space, gym.spaces.Discrete)
    obs, acts, rews, ep, ts, rem = [], [], [], [], [], []
    try:
        for e in range(episodes):
            o, _ = env.reset(seed=seed if e == 0 else None)
            ep_obs, ep_act, ep_rew = [o], [], []
            done = False
            while not done and (max_steps is None or len(ep_act) < max_steps):
                a = env.action_space.sample()
                o, r, terminated, truncated, _ = env.step(a)
                ep_obs.append(o)
                ep_act.append(a)
                ep_rew.append(r)
                done = terminated or truncated
            n = len(ep_obs)
            ep_act.append(np.zeros_like(ep_act[0]) if ep_act else 0)
            ep_rew.append(0.0)
            obs += ep_obs
            acts += ep_act
            rews += ep_rew
            ep.append(np.full(n, e))
            ts.append(np.arange(n))
            rem.append(np.arange(n)[::-1])
    finally:
        env.close()
    actions = np.asarray(acts, np.int32) if discrete else np.asarray(acts, np.float32).reshape(len(acts), -1)
    return Rollouts(base_id, np.asarray(obs, np.float32), actions, np.asarray(rews, np.float32),
                    np.concatenate(ep), np.concatenate(ts), np.concatenate(rem))


@functools.lru_cache(maxsize=16)
def _runner(config: AgentConfig, info: EnvInfo):
    """A jitted (reservoirs, inputs) -> contexts (T, context_dim) for one agent layout (Φ is traced)."""
    agent = Agent(config, info)

    def run(res, obs, prev_action, prev_reward, start):
        def body(state, x):
            o, a, r, s = x
            start_state, start_ctx = agent.start_episode(res, o)
            next_state, next_ctx = agent.observe(res, state, o, agent.encode_action(a), r)
            state = jnp.where(s, start_state, next_state)
            return state, jnp.where(s, start_ctx, next_ctx)

        state0 = jnp.zeros((config.reservoirs, config.spec.units), jnp.float32)
        _, contexts = jax.lax.scan(body, state0, (obs, prev_action, prev_reward, start))
        return contexts

    return jax.jit(run)


def as_k(phi: Phi) -> Phi:
    """Φ with (K,) float32 fields (scalar fields give K = 1)."""
    fields = [np.atleast_1d(np.asarray(v, np.float32)) for v in phi]
    if len({f.shape for f in fields}) != 1 or fields[0].ndim != 1:
        raise ConfigError(f"Φ fields must be scalars or equal-length lists (one value per reservoir), got {phi}")
    return Phi(*fields)


def phi_text(phi: Phi) -> str:
    """'sr=0.95 leak rate=0.5 iss=1' (K = 1) or 'sr=0.95/0.95 leak rate=0.5/0.05 iss=1/1'."""
    names = ("sr", "leak rate", "iss")  # Phi's fields; in RL, "lr" reads as a learning rate
    return " ".join(f"{n}={'/'.join(f'{float(v):.3g}' for v in f)}" for n, f in zip(names, as_k(phi)))


def reservoir_states(env_id: str, rollouts: Rollouts, phi: Phi, *, units: int = 100, seed: int = 0,
                     feed_action: str = "previous", spec: ReservoirSpec | None = None) -> np.ndarray:
    """Contexts c_t (T, K·units) of K reservoirs with Φ = ``phi`` (scalar fields: K = 1; (K,) fields: K
    reservoirs) and ``seed``, fed each episode of ``rollouts`` as the agent on ``env_id`` is: reset and fed
    (o_0, zeros, 0), then (masked o_t, a_{t−1}, r_{t−1}). ``spec`` sets the reservoir's static settings
    (connectivities, bias; its units replace ``units``); None: ReservoirPy's defaults with ``units``."""
    base_id, deleted = masking.parse(env_id)
    if base_id != rollouts.base_id:
        raise ConfigError(f"rollouts come from {rollouts.base_id!r}, not {base_id!r}; collect them from {base_id!r}")
    info = describe(env_id, base_id, deleted)
    phi = as_k(phi)
    spec = ReservoirSpec(units=units) if spec is None else spec
    config = AgentConfig(reservoirs=len(phi.sr), spec=spec, feed_action=feed_action)
    res = Agent.build(Agent(config, info).unit_weights(seed), phi)
    start = rollouts.t == 0
    prev_action = np.roll(rollouts.actions, 1, axis=0)
    prev_action[start] = 0
    prev_reward = np.where(start, 0.0, np.roll(rollouts.rewards, 1)).astype(np.float32)
    obs = info.mask(rollouts.obs)
    return np.asarray(_runner(config, info)(res, obs, prev_action, prev_reward, start))


@dataclasses.dataclass(frozen=True)
class ProbeResult:
    """R² of ridge readouts on held-out episodes (1 is perfect, 0 is the held-out mean, < 0 worse)."""

    label: str
    phi: Phi
    env_id: str
    velocity_dims: tuple[int, ...]
    """Indices (in the full observation) of the deleted velocities."""
    r2_velocity: float
    """R² of the deleted velocities at t, averaged over them."""
    r2_velocity_per_dim: tuple[float, ...]
    """One R² per entry of ``velocity_dims``."""
    r2_future: tuple[float, ...]
    """R² of the kept observation at t + k, averaged over the kept dims, for k = 1..horizon."""
    train_steps: int
    test_steps: int


def _r2(features: np.ndarray, targets: np.ndarray, train: np.ndarray, test: np.ndarray, alpha: float) -> np.ndarray:
    """Per-target R² on ``test`` of a ridge fitted on ``train``. features (T, N), targets (T, D) -> (D,)."""
    from sklearn.linear_model import Ridge
    from sklearn.metrics import r2_score

    model = Ridge(alpha=alpha).fit(features[train], targets[train])
    return np.atleast_1d(r2_score(targets[test], model.predict(features[test]), multioutput="raw_values"))


def probe(env_id: str, phi: Phi = MEMORY, *, units: int = 100, seed: int = 0, episodes: int = 300,
          alpha: float = DEFAULT_ALPHA, feed_action: str = "previous", horizon: int = 5, washout: int = 0,
          test_fraction: float = 0.25, label: str | None = None, rollouts: Rollouts | None = None,
          spec: ReservoirSpec | None = None) -> ProbeResult:
    """Probes the context of a reservoir with Φ = ``phi`` on the NoVel env ``env_id`` (e.g. 'CartPoleNoVel-v1').

    ``episodes`` random episodes (seeded with ``seed``, or the given ``rollouts`` of the base env) are split by
    episode: the last ``test_fraction`` of them are held out. The reservoir is drawn from ``seed``. Steps with
    t < ``washout`` in their episode are left out of fitting and scoring (the velocity at t = 0 is the env's
    random initial state, which no observation has revealed yet). On CartPoleNoVel the default 0 costs little:
    300 episodes give velocity R² 0.998 with washout 0 and 0.999 with 3. Future targets keep only the steps
    whose t + k lies within the same episode. ``spec``: the reservoir's static settings, as in
    :func:`reservoir_states`.
    """
    base_id, deleted = masking.parse(env_id)
    if not deleted:
        fix = f"use {masking.novel_id(env_id)!r}" if env_id in masking.VELOCITY_DIMS else \
            "NoVel ids are: " + ", ".join(map(masking.novel_id, masking.VELOCITY_DIMS))
        raise ConfigError(f"probe needs a NoVel env id whose velocities are deleted, got {env_id!r}; {fix}")
    if horizon < 1:
        raise ConfigError(f"horizon must be >= 1 (predict o_(t+1) .. o_(t+horizon)), got {horizon}")
    if washout < 0:
        raise ConfigError(f"washout must be >= 0 steps, got {washout}")
    if not 0.0 < test_fraction < 1.0:
        raise ConfigError(f"test_fraction must be in (0, 1), got {test_fraction}")
    if not alpha > 0:
        raise ConfigError(f"alpha (ridge penalty) must be > 0, got {alpha}; try {DEFAULT_ALPHA}")
    rollouts = collect(base_id, episodes, seed) if rollouts is None else rollouts
    n_test = int(round(test_fraction * rollouts.n_episodes))
    if not 1 <= n_test < rollouts.n_episodes:
        raise ConfigError(f"{rollouts.n_episodes} episodes leave no train or test episode at test_fraction "
                          f"{test_fraction}; collect more episodes")
    states = reservoir_states(env_id, rollouts, phi, units=units, seed=seed, feed_action=feed_action,
                              spec=spec)
    features = states.astype(np.float64)
    is_test = rollouts.episode >= rollouts.n_episodes - n_test
    used = rollouts.t >= washout
    train, test = used & ~is_test, used & is_test
    if min(train.sum(), test.sum()) < 2:
        raise ConfigError(f"washout {washout} leaves no step to fit or score; lower it")
    velocity = _r2(features, rollouts.obs[:, list(deleted)].astype(np.float64), train, test, alpha)

    kept = list(masking.kept_dims(rollouts.obs.shape[1], deleted))
    future = []
    for k in range(1, horizon + 1):
        ok = rollouts.remaining >= k
        rows = np.flatnonzero(ok)
        if min((train & ok).sum(), (test & ok).sum()) < 2:  # R² needs two held-out steps
            raise ConfigError(f"no episode lasts {k} steps past the washout; lower horizon (now {horizon})")
        targets = np.zeros((len(features), len(kept)))
        targets[rows] = rollouts.obs[rows + k][:, kept]
        future.append(float(np.mean(_r2(features, targets, train & ok, test & ok, alpha))))

    phi = Phi(*(tuple(map(float, f)) if len(f) > 1 else float(f[0]) for f in as_k(phi)))
    return ProbeResult(label or phi_text(phi), phi, env_id, tuple(deleted),
                       float(np.mean(velocity)), tuple(map(float, velocity)), tuple(future),
                       int(train.sum()), int(test.sum()))


def probe_table(results: list[ProbeResult]) -> str:
    """A Markdown table: one row per result, R² of each deleted velocity, their mean, and of o_(t+k)."""
    if not results:
        raise ConfigError("probe_table needs at least one ProbeResult; run probe() first")
    dims = results[0].velocity_dims
    horizon = max(len(r.r2_future) for r in results)
    head = ["reservoir", "sr", "leak rate", "iss", *(f"R² v[{d}]" for d in dims), "R² velocities",
            *(f"R² o(t+{k})" for k in range(1, horizon + 1))]
    rows = []
    for r in results:
        future = [f"{v:.3f}" for v in r.r2_future] + [""] * (horizon - len(r.r2_future))
        per_dim = [f"{v:.3f}" for v in r.r2_velocity_per_dim] if r.velocity_dims == dims else [""] * len(dims)
        cells = [r.label, *("/".join(f"{float(v):.3g}" for v in f) for f in as_k(r.phi)), *per_dim, f"{r.r2_velocity:.3f}",
                 *future]
        rows.append(cells)
    return markdown_table(head, rows)


def plot_probe(results: list[ProbeResult], path: Path | str) -> Path:
    """Bar chart of each result's velocity R², and R² of o_(t+k) against k, side by side. Writes a PNG."""
    from matplotlib.figure import Figure

    from ermrl.storage import save_figure

    if not results:
        raise ConfigError("plot_probe needs at least one ProbeResult; run probe() first")
    fig = Figure(figsize=(10, 4))
    left, right = fig.subplots(1, 2)
    x = np.arange(len(results))
    left.bar(x, [r.r2_velocity for r in results], color=[f"C{i}" for i in x])
    left.set_xticks(x, [r.label for r in results], rotation=15)
    left.set_ylabel("R² (held-out episodes)")
    left.set_title(f"deleted velocities at t ({results[0].env_id})")
    for i, r in enumerate(results):
        k = np.arange(1, len(r.r2_future) + 1)
        right.plot(k, r.r2_future, "o-", color=f"C{i}", label=r.label)
    right.set_xlabel("k (steps ahead)")
    right.set_title("kept observation at t + k")
    right.legend()
    for ax in (left, right):
        ax.set_ylim(min(0.0, *(min(r.r2_velocity, *r.r2_future) for r in results)) - 0.05, 1.05)
        ax.grid(alpha=0.3)
    return save_figure(fig, Path(path).with_suffix(".png"))
