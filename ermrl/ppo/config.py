"""PPO hyperparameters. The defaults are stable-baselines3's PPO defaults, which the paper used (App. A.2.2)."""

from __future__ import annotations

import dataclasses
from typing import Literal

from ermrl.errors import ConfigError
from ermrl.codec import OMIT_WHEN_DEFAULT


MAX_EPOCHS = 1000
"""The most passes over a rollout that an update may make."""


@dataclasses.dataclass(frozen=True)
class PPOConfig:
    """Static PPO settings (they set array shapes or loop lengths), except ``learning_rate``,
    which is passed to the trainer per agent and so can differ inside one population."""

    n_envs: int = 1
    """Parallel envs per agent (SB3 default 1). The rollout buffer holds n_steps × n_envs transitions."""
    n_steps: int = 2048
    """Env steps per env between updates."""
    batch_size: int = 64
    """Minibatch size; must divide n_steps × n_envs."""
    n_epochs: int = 10
    """Passes over the rollout buffer per update."""
    learning_rate: float = 3e-4
    """Adam step size (the paper uses 1e-4 on partially observable tasks); constant, as in SB3."""
    gamma: float = 0.99
    """Discount factor, in (0, 1]."""
    gae_lambda: float = 0.95
    """GAE's λ, in [0, 1]: the bias–variance trade-off of the advantage estimate."""
    clip_range: float = 0.2
    """PPO's clip ε of the probability ratio (constant, as SB3's default)."""
    ent_coef: float = 0.0
    """Weight of the entropy bonus in the loss."""
    vf_coef: float = 0.5
    """Weight of the value loss in the loss."""
    max_grad_norm: float = 0.5
    """Global gradient-norm clip per minibatch."""
    adam_eps: float = 1e-5
    """Adam's epsilon (SB3 passes eps=1e-5 to torch.optim.Adam)."""
    normalize_advantage: bool = True
    """Per-minibatch normalization with the unbiased std, as torch's ``Tensor.std`` computes it."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden widths of the separate actor and critic MLPs (SB3 MlpPolicy's ``net_arch``, the same for both)."""
    activation: Literal["tanh", "relu"] = dataclasses.field(default="tanh", metadata={OMIT_WHEN_DEFAULT: True})
    """The MLPs' hidden activation (SB3's ``activation_fn``: tanh by default; rl-zoo's recurrent Pendulum settings
    use ReLU).

    Left out of a config's record while tanh."""
    ortho_init: bool = dataclasses.field(default=True, metadata={OMIT_WHEN_DEFAULT: True})
    """SB3's ``ortho_init``: orthogonal weights (gains √2, 0.01 for the policy head, 1 for the value head) and zero
    biases; off, every layer keeps torch's default ``nn.Linear`` init, U(±1/√fan_in) for weights and biases."""
    log_std_init: float = 0.0
    """Initial state-independent log std of the Gaussian policy (Box actions)."""
    normalize: bool = dataclasses.field(default=False, metadata={OMIT_WHEN_DEFAULT: True})
    """Normalize what the policy sees (the context) and the rewards with running statistics, as SB3's
    ``VecNormalize`` (rl-baselines3-zoo's ``normalize: True``; :mod:`ermrl.ppo.normalize`). Off in SB3's
    PPO and in the paper.

    Left out of a config's record while off, so that older studies and stores match."""
    use_sde: bool = dataclasses.field(default=False, metadata={OMIT_WHEN_DEFAULT: True})
    """gSDE, generalized State-Dependent Exploration (SB3's ``use_sde``; Box actions only): the policy's noise is
    the actor's last hidden features times an exploration matrix held for ``sde_sample_freq`` steps, its scale
    learnt per feature and action dim (:mod:`ermrl.ppo.networks`). Off in SB3's PPO and in the paper; rl-zoo's
    Pendulum settings use it."""
    sde_sample_freq: int = dataclasses.field(default=-1, metadata={OMIT_WHEN_DEFAULT: True})
    """With ``use_sde``: steps between new exploration matrices; -1 draws one per rollout (SB3's default)."""
    model: Literal["ff", "lstm"] = "ff"
    """Policy model: "ff", SB3's MlpPolicy on the context (what ER-MRL and plain PPO use); "lstm", the recurrent
    baseline, sb3-contrib RecurrentPPO's MlpLstmPolicy (separate actor and critic LSTMs on the raw observation,
    then the same MLPs), trained end to end (see :mod:`ermrl.ppo.recurrent`). JAX backend and no reservoir only."""
    lstm_hidden_size: int = 64
    """Units of each LSTM (model "lstm"). sb3-contrib's default is 256; 64 is what rl-baselines3-zoo's tuned
    RecurrentPPO settings for CartPoleNoVel-v1 and PendulumNoVel-v1 use.

    rl-baselines3-zoo's hyperparams/ppo_lstm.yml, commit c94924e: ``lstm_hidden_size=64``; their other tuned
    values, e.g. 8 envs × 32 steps for CartPole, are not taken: the rest stays at SB3's PPO defaults, as for our
    PPO."""
    lstm_seq_len: int = 64
    """Steps per training sequence (model "lstm"), the truncated-BPTT length: each epoch cuts the rollout into
    windows of this many consecutive steps from a random offset; a window starts from the LSTM state stored during
    the rollout (as does another env's first step inside it) and episode starts reset the state within it
    (:mod:`ermrl.ppo.recurrent_update`). batch_size must be a multiple of it; at batch_size = lstm_seq_len (64 with
    SB3's batch_size) a minibatch is one window, the same steps as an sb3-contrib minibatch."""

    def __post_init__(self):
        buffer = self.n_steps * self.n_envs
        if min(self.n_envs, self.n_steps, self.batch_size, self.n_epochs) < 1:
            raise ConfigError("n_envs, n_steps, batch_size and n_epochs must all be >= 1")
        if self.n_epochs > MAX_EPOCHS:
            raise ConfigError(f"n_epochs must be <= {MAX_EPOCHS} (SB3's default is 10), got {self.n_epochs}")
        if buffer % self.batch_size:
            raise ConfigError(
                f"batch_size {self.batch_size} must divide n_steps × n_envs = {buffer}; pick a divisor of {buffer}"
            )
        if not (self.learning_rate > 0 and self.learning_rate < 1):
            raise ConfigError(f"learning rate {self.learning_rate} is outside (0, 1); the paper uses 3e-4 or 1e-4")
        if not 0 < self.gamma <= 1:
            raise ConfigError(f"gamma {self.gamma} is outside (0, 1]; SB3's default is 0.99")
        if not 0 <= self.gae_lambda <= 1:
            raise ConfigError(f"gae_lambda {self.gae_lambda} is outside [0, 1]; SB3's default is 0.95")
        for name, default in (("clip_range", 0.2), ("max_grad_norm", 0.5)):
            if not 0 < getattr(self, name) < float("inf"):
                raise ConfigError(f"{name} must be positive and finite, got {getattr(self, name)}; SB3's default is "
                                  f"{default}")
        for name, default in (("ent_coef", 0.0), ("vf_coef", 0.5)):
            if not 0 <= getattr(self, name) < float("inf"):
                raise ConfigError(f"{name} must be >= 0 and finite, got {getattr(self, name)}; SB3's default is "
                                  f"{default}")
        if self.sde_sample_freq != -1 and self.sde_sample_freq < 1:
            raise ConfigError(f"sde_sample_freq must be -1 (one exploration matrix per rollout) or >= 1, got "
                              f"{self.sde_sample_freq}")
        if self.activation not in ("tanh", "relu"):
            raise ConfigError(f"activation must be 'tanh' or 'relu', got {self.activation!r}")
        if not self.hidden or min(self.hidden) < 1:
            raise ConfigError(f"net_arch must be one or more layer widths >= 1, got {list(self.hidden)}; SB3's "
                              "default is 64 64")
        if self.model not in ("ff", "lstm"):
            raise ConfigError(f"model must be 'ff' or 'lstm', got {self.model!r}")
        if self.model == "lstm":
            if min(self.lstm_hidden_size, self.lstm_seq_len) < 1:
                raise ConfigError("lstm_hidden_size and lstm_seq_len must be >= 1")
            if self.batch_size % self.lstm_seq_len:
                raise ConfigError(f"batch_size {self.batch_size} must be a multiple of lstm_seq_len "
                                  f"{self.lstm_seq_len} (a minibatch is whole sequences)")

    def check_actions(self, env_id: str, discrete: bool) -> None:
        """ConfigError when these settings cannot act in ``env_id`` (gSDE needs Box actions, as in SB3)."""
        if self.use_sde and discrete:
            raise ConfigError(f"`use_sde` needs continuous (Box) actions; {env_id}'s actions are discrete",
                              owner=type(self))

    @property
    def buffer_size(self) -> int:
        return self.n_steps * self.n_envs

    @property
    def n_minibatches(self) -> int:
        return self.buffer_size // self.batch_size

    def iterations(self, total_timesteps: int) -> int:
        """Rollout/update cycles that SB3's ``learn(total_timesteps)`` runs: it stops once steps >= total."""
        return max(1, -(-total_timesteps // self.buffer_size))


SB3_DEFAULTS = PPOConfig()
"""stable-baselines3 PPO defaults (1 env, 2048 steps, 64 per batch, 10 epochs)."""

FAST = PPOConfig(n_envs=8, n_steps=256, batch_size=512, n_epochs=4)
"""A PureJaxRL-like preset: more envs, fewer and larger minibatches. Not the paper's setting."""

PRESETS = {"sb3": SB3_DEFAULTS, "fast": FAST}
