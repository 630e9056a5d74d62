"""A trained agent, loaded back from its file, acting in a plain Gymnasium loop: :func:`load_agent`.

``ermrl train`` and ``ermrl test`` save every agent's final policy (``RUN/agents/seedS.npz``, see
:func:`ermrl.agent_files.write_agents`). The reservoirs are not in the file: they are regenerated from Φ and the seed
(:meth:`ermrl.agent.Agent.unit_weights`), as :class:`ermrl.wrappers.ReservoirObservation` does. The agent here
runs the trainer's perception and policy in NumPy (float32), so that one step costs microseconds, not a JAX call:

    agent = ermrl.load_agent("runs/train-CartPoleNoVel-v1-.../agents/seed0.npz")
    env = agent.make_env()                      # the Gymnasium env, velocity dims deleted for NoVel ids
    obs, _ = env.reset(seed=0)
    agent.reset()
    reward, done = None, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(agent.act(obs, reward))
        done = terminated or truncated

The input convention is the trainer's: at an episode's first ``act`` the reservoirs start from zero and are fed
(o_0, zeros, 0); then (o_t, a_{t−1}, r_{t−1}), where a_{t−1} is the action ``act`` returned last (clipped to
the bounds for Box actions).
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from ermrl import agent_files, storage
from ermrl.agent import Agent, AgentConfig, Phi
from ermrl.envs.spaces import EnvInfo
from ermrl.errors import ConfigError
from ermrl.ppo.normalize import CLIP_OBS as NORM_CLIP, EPSILON as NORM_EPSILON


class DeleteDims(gym.ObservationWrapper):
    """Keeps only the observation dims ``kept`` (the NoVel ids' velocity masking: deleted, not zeroed)."""

    def __init__(self, env: gym.Env, kept: tuple[int, ...]):
        super().__init__(env)
        self.kept = np.asarray(kept)
        space = env.observation_space
        self.observation_space = gym.spaces.Box(space.low[self.kept], space.high[self.kept], dtype=space.dtype)

    def observation(self, observation):
        return observation[self.kept]


ACTIVATIONS = {"tanh": np.tanh, "relu": lambda x: np.maximum(x, 0.0)}
"""NumPy twins of :data:`ermrl.ppo.networks.ACTIVATIONS`."""


def _mlp(layers: list[tuple[np.ndarray, np.ndarray]], x: np.ndarray, features: bool = False,
         activation: str = "tanh"):
    """The MLP of :class:`ermrl.ppo.networks.MLP`: (in,) -> (out,), the last layer linear; with
    ``features``, (out, the last hidden layer)."""
    act = ACTIVATIONS[activation]
    for kernel, bias in layers[:-1]:
        x = act(x @ kernel + bias)
    kernel, bias = layers[-1]
    return (x @ kernel + bias, x) if features else x @ kernel + bias


def _layers(params: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(kernel (in, out), bias (out,)), ...] of a Flax MLP's params, in layer order."""
    dense = params["params"]
    names = sorted(dense, key=lambda name: int(name.rsplit("_", 1)[1]))
    return [(dense[n]["kernel"], dense[n]["bias"]) for n in names]


def _lstm_step(params: dict, state: tuple[np.ndarray, np.ndarray] | None, x: np.ndarray):
    """One step of :mod:`ermrl.ppo.recurrent`'s LSTM (torch's gate order i, f, g, o) from ``state`` (h, c), None
    for zeros. Returns the new (h, c)."""
    hidden = params["kernel_h"].shape[0]
    h, c = (np.zeros(hidden, np.float32),) * 2 if state is None else state
    bias = params["bias_ih"] + params["bias_hh"] if "bias_ih" in params else params["bias"]  # "bias": older files
    i, f, g, o = np.split(x @ params["kernel_x"] + bias + h @ params["kernel_h"], 4)
    sigmoid = lambda z: 1.0 / (1.0 + np.exp(-z))
    c = (sigmoid(f) * c + sigmoid(i) * np.tanh(g)).astype(np.float32)
    return (sigmoid(o) * np.tanh(c)).astype(np.float32), c


class SavedAgent:
    """One saved agent: its reservoirs (regenerated), policy and critic, and the state of the running episode.

    Attributes after an ``act``: ``context`` (context_dim,) float32, the c_t the policy saw (K·units reservoir
    states, plus u_t with a skip connection; the observation itself for plain PPO; the actor LSTM's output h_t
    for PPO-LSTM); ``head`` (action_dim,), the policy's logits (Discrete) or Gaussian means (Box)."""

    def __init__(self, path: Path, meta: dict, actor: dict, critic: dict, log_std: np.ndarray | None,
                 sampling_seed: int = 0, context_norm: dict | None = None):
        self.path = Path(path)
        self.meta = meta
        ppo = meta.get("train", {}).get("ppo") or {}
        model = ppo.get("model", "ff")
        if model not in ("ff", "lstm"):
            raise ConfigError(f"{path} holds a {model!r} policy; load_agent runs the policies of ER-MRL, PPO and "
                              "PPO-LSTM only")
        self.activation: str = ppo.get("activation", "tanh")  # left out of the record while tanh
        if self.activation not in ACTIVATIONS:
            raise ConfigError(f"{path} holds a policy with a {self.activation!r} activation; load_agent runs tanh "
                              "and relu MLPs only")
        try:
            self.env: EnvInfo = storage.from_dict(EnvInfo, meta["env"], "env")
            self.config: AgentConfig = storage.from_dict(AgentConfig, meta["train"]["agent"], "train.agent")
        except (KeyError, TypeError, IndexError, ValueError) as e:
            raise ConfigError(f"{path} is not a complete ermrl agent file ({type(e).__name__}: {e}); "
                              "retrain, or load another agent") from None
        agent_files.check_weights(path, ppo, self.env, self.config, meta.get("phi"), actor, critic, log_std,
                                  context_norm)
        try:
            self.recurrent = model == "lstm"
            if self.recurrent:  # PPO-LSTM: an LSTM before each MLP (ermrl.ppo.recurrent)
                self._lstm_pi, self._lstm_vf = actor["lstm"], critic["lstm"]
                actor, critic = actor["mlp"], critic["mlp"]
            self._actor, self._critic = _layers(actor), _layers(critic)
            phi = meta["phi"]
            self.phi = Phi(*(np.asarray(phi[f], np.float32) for f in Phi._fields))
        except (KeyError, TypeError, IndexError, ValueError) as e:
            raise ConfigError(f"{path} is not a complete ermrl agent file ({type(e).__name__}: {e}); "
                              "retrain, or load another agent") from None
        self.env_id: str = meta["env_id"]
        self.seed: int = int(meta["seed"])
        self.learning_rate: float = float(meta["learning_rate"])
        self.log_std = None if log_std is None else np.asarray(log_std, np.float32)
        self.sde = self.log_std is not None and self.log_std.ndim == 2  # gSDE (PPOConfig.use_sde)
        self.context_norm = context_norm  # {"mean", "var"}: frozen statistics of a normalized agent, else None
        if bool(ppo.get("normalize")) != (context_norm is not None):
            raise ConfigError(f"{path} is not a complete ermrl agent file (normalization statistics "
                              f"{'missing' if context_norm is None else 'without normalize'}); retrain, or load "
                              "another agent")
        self.agent = Agent(self.config, self.env)
        self.context_dim = self.agent.context_dim if not self.recurrent else self._lstm_pi["kernel_h"].shape[0]
        action = self.env.action
        self._low, self._high = (None, None) if action.discrete else (np.asarray(action.low, np.float32),
                                                                     np.asarray(action.high, np.float32))
        self._first_action = np.zeros(action.feature_dim, np.float32)  # the action slot at episode start
        if self.config.feed_action == "none" and action.discrete:
            self._first_action[0] = 1.0
        unit = self.agent.unit_weights(self.seed)  # None for plain PPO
        if unit is not None:
            self._W = unit.W * self.phi.sr[:, None, None]
            self._Win = unit.Win * self.phi.iss[:, None, None]
            self._bias = unit.bias
            self._leak = self.phi.lr[:, None]
        self.rng = np.random.default_rng(sampling_seed)
        self.reset()

    # -- the episode ------------------------------------------------------------------------------------
    def reset(self, sampling_seed: int | None = None) -> None:
        """Starts a new episode: the next ``act`` resets the reservoirs and feeds (o_0, zeros, 0).
        ``sampling_seed`` re-seeds the Generator that stochastic actions are drawn from."""
        if sampling_seed is not None:
            self.rng = np.random.default_rng(sampling_seed)
        self._state: np.ndarray | None = None
        self._previous = None
        self.context: np.ndarray | None = None
        self.head: np.ndarray | None = None
        self._latent: np.ndarray | None = None
        if self.sde:  # one exploration matrix (latent_dim, action_dim) per episode, N(0, exp(log_std)²)
            self._exploration = np.exp(self.log_std) * self.rng.standard_normal(self.log_std.shape)

    def act(self, obs, reward: float | None = None, deterministic: bool = True):
        """The env action for observation ``obs`` (obs_dim,), the masked one for NoVel ids (``make_env``).

        ``reward``: the reward of the previous step; needed from the episode's second call on (ignored at its
        first). Deterministic: the argmax of the logits (Discrete: an int) or the mean clipped to the bounds
        (Box: (action_dim,) float32); else a draw from the policy with ``self.rng``."""
        obs = np.asarray(obs, np.float32).reshape(-1)
        if obs.shape != (self.env.obs_dim,):
            raise ConfigError(f"{self.env_id} agent expects observations of {self.env.obs_dim} dims (dims "
                              f"{list(self.env.kept_dims)} of {self.env.base_id}), got shape {obs.shape}; "
                              "step the env from agent.make_env()")
        if self._previous is None:
            action_enc, r = self._first_action, 0.0
            self._state = None
        elif reward is None:
            raise ConfigError("act() needs the reward of the previous step after an episode's first step "
                              "(act(obs, reward)); call reset() when a new episode starts")
        else:
            action_enc, r = self._encode(self._previous), float(reward)
        if self.recurrent:  # a normalized PPO-LSTM normalizes what its LSTMs see
            self.context = self._observe(self._normalized(obs), action_enc, r)
        else:
            self.context = self._normalized(self._observe(obs, action_enc, r))
        self._critic_in = self.context if not self.recurrent else self._state[1][0]
        if self.sde:
            self.head, self._latent = _mlp(self._actor, self.context, True, self.activation)
        else:
            self.head = _mlp(self._actor, self.context, activation=self.activation)
        self._previous = action = self._choose(self.head, deterministic)
        return action

    def _normalized(self, x: np.ndarray) -> np.ndarray:
        """x standardized as in training, with the statistics frozen (VecNormalize.training=False); x itself
        for an agent trained without ``normalize``."""
        if self.context_norm is None:
            return x
        mean, var = self.context_norm["mean"], self.context_norm["var"]
        return np.clip((x - mean) / np.sqrt(var + NORM_EPSILON), -NORM_CLIP, NORM_CLIP).astype(np.float32)

    def _encode(self, env_action) -> np.ndarray:
        """(feature_dim,): one-hot for Discrete, the clipped Box action; constant with feed_action="none"."""
        if self.config.feed_action == "none":
            return self._first_action
        if self.env.action.discrete:
            return np.eye(self.env.action.dim, dtype=np.float32)[int(env_action)]
        return np.asarray(env_action, np.float32).reshape(self.env.action.dim)

    def _observe(self, obs: np.ndarray, action_enc: np.ndarray, reward: float) -> np.ndarray:
        """Feeds u = (obs, action, reward) to the K reservoirs; returns the context (context_dim,). A PPO-LSTM
        agent feeds obs to its actor and critic LSTMs (zero states at an episode's start) and returns the actor's."""
        if self.recurrent:
            pi, vf = (None, None) if self._state is None else self._state
            self._state = (_lstm_step(self._lstm_pi, pi, obs), _lstm_step(self._lstm_vf, vf, obs))
            return self._state[0][0]
        if self.config.reservoirs == 0:
            return obs
        u = np.concatenate([obs, action_enc, np.float32([reward])])
        drive = np.einsum("kni,i->kn", self._Win, u) + self._bias
        if self._state is None:
            self._state = self._leak * np.tanh(drive)
        else:
            drive += np.einsum("knm,km->kn", self._W, self._state)
            self._state = (1.0 - self._leak) * self._state + self._leak * np.tanh(drive)
        self._state = self._state.astype(np.float32)
        context = self._state[:, : self.config.units_seen].reshape(-1)
        return np.concatenate([context, u]) if self.config.skip_connection else context

    def _choose(self, head: np.ndarray, deterministic: bool):
        if self.env.action.discrete:
            noise = 0.0 if deterministic else self.rng.gumbel(size=head.shape)
            return int(np.argmax(head + noise))
        if deterministic:
            action = head
        elif self.sde:
            action = head + self._latent @ self._exploration
        else:
            action = head + np.exp(self.log_std) * self.rng.standard_normal(head.shape)
        return np.clip(action, self._low, self._high).astype(np.float32)

    # -- what the policy thinks ----------------------------------------------------------------------------
    @property
    def probabilities(self) -> np.ndarray:
        """(n,) π(a | c_t) of the last ``act`` (Discrete actions)."""
        if not self.env.action.discrete or self.head is None:
            raise ConfigError("probabilities exist for Discrete actions after an act(); Box agents have mean and std")
        z = np.exp(self.head - self.head.max())
        return z / z.sum()

    @property
    def std(self) -> np.ndarray:
        """(action_dim,) the Gaussian policy's standard deviation (Box actions); with gSDE, at the last ``act``'s
        features: sqrt(z² · exp(log_std)² + 1e-6)."""
        if self.log_std is None:
            raise ConfigError("a Discrete agent has no standard deviation; see probabilities")
        if not self.sde:
            return np.exp(self.log_std)
        if self._latent is None:
            raise ConfigError("a gSDE agent's standard deviation depends on its input: call act() first")
        return np.sqrt(np.square(self._latent) @ np.square(np.exp(self.log_std)) + 1e-6)

    @property
    def value(self) -> float:
        """The critic's V(c_t) of the last ``act``."""
        if self.context is None:
            raise ConfigError("value needs an act() first")
        return float(_mlp(self._critic, self._critic_in, activation=self.activation)[0])

    # -- its env ----------------------------------------------------------------------------------------------
    def make_env(self, render_mode: str | None = None, **kwargs) -> gym.Env:
        """``gymnasium.make`` of the agent's env (``kwargs`` passed on), with the velocity dims of a NoVel id
        deleted: its observations are what ``act`` takes."""
        base = self.env.base_id
        if base not in gym.registry:
            raise ConfigError(f"Gymnasium has no env {base!r} (the agent was trained on {self.env_id!r})")
        from ermrl.envs.host_backend import extra_for
        from ermrl.envs.host_groups import _quiet_mujoco

        if extra_for(base) == "mujoco":
            _quiet_mujoco()
        try:
            env = gym.make(base, render_mode=render_mode, **kwargs)
        except gym.error.DependencyNotInstalled:
            extra = extra_for(base)
            fix = f"pip install 'ermrl[{extra}]'" if extra else "pip install 'ermrl[video]' (pygame renders it)"
            raise ConfigError(f"env {base!r} needs a package that is not installed; run: {fix}") from None
        full = env.observation_space.shape[0]
        if self.env.kept_dims != tuple(range(full)):
            env = DeleteDims(env, self.env.kept_dims)
        return env

    def __repr__(self) -> str:
        phi = ", ".join(f"{f} " + "/".join(f"{v:.4g}" for v in getattr(self.phi, f)) for f in Phi._fields)
        return (f"SavedAgent({self.env_id}, seed {self.seed}, {self.config.reservoirs} reservoir(s), {phi}, "
                f"fitness {self.meta.get('fitness')}, from {self.path})")


def load_agent(path: Path | str, sampling_seed: int = 0) -> SavedAgent:
    """The agent saved at ``path``: a ``.npz`` file, or a folder (a run folder, a test phase, an agents/
    folder), which gives its first saved agent. Raises a one-line ConfigError when there is none or the file is
    missing or damaged. ``sampling_seed`` seeds the Generator of stochastic actions."""
    path = Path(path)
    if path.is_dir():
        found = agent_files.find_agents(path)
        if not found:
            raise ConfigError(f"{path} has no saved agents (agents/*.npz); `ermrl train` and `ermrl test` save "
                              "them with `save_agents` (the default)")
        path = found[0]
    meta, actor, critic, log_std, context_norm = agent_files.read_agent(path)
    return SavedAgent(path, meta, actor, critic, log_std, sampling_seed, context_norm)
