"""The recurrent baseline's policy: sb3-contrib RecurrentPPO's ``MlpLstmPolicy``, written in JAX.

With RecurrentPPO's defaults (``enable_critic_lstm=True, shared_lstm=False``, one LSTM layer) the actor and the
critic each have their own LSTM on the raw observation, followed by the same heads as our feedforward PPO:

    o_t → LSTM_pi → tanh MLP (64, 64) → logits (Discrete) or Gaussian means (Box)
    o_t → LSTM_vf → tanh MLP (64, 64) → V

The MLPs are :class:`~ermrl.ppo.networks.MLP` with SB3's orthogonal gains, as sb3-contrib builds its
``mlp_extractor`` on the LSTM output. The LSTMs keep torch's ``nn.LSTM`` initialization, since sb3-contrib's
orthogonal init reaches only linear layers: every weight and both biases U(−1/√H, 1/√H). Gates are in torch's
order (input, forget, cell, output). Both of torch's biases are kept as parameters (``bias_ih``, ``bias_hh``):
the gates see their sum, but each gets the sum's gradient, so under Adam the sum moves twice as far per step as
one bias would, and the global-norm clipping counts that gradient twice; one summed bias learned differently.

A state is zeroed before a step that starts an episode, ``(1 − episode_start) · state``, as sb3-contrib's
``_process_sequence`` does; so during the rollout the state is carried across steps and reset at episode starts,
and in the update each sequence starts from the state stored during the rollout (see
:mod:`ermrl.ppo.recurrent_update`). Unlike a reservoir, every LSTM weight is trained by the PPO loss.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp

from ermrl.envs.spaces import ActionSpace
from ermrl.ppo.networks import ActorCritic, PolicyParams


class LSTMState(NamedTuple):
    """One LSTM's state; each (..., H)."""

    h: jax.Array
    c: jax.Array


class RecurrentState(NamedTuple):
    """The actor's and the critic's LSTM states."""

    pi: LSTMState
    vf: LSTMState


class Sequences(NamedTuple):
    """Training sequences, the ``context`` of a recurrent minibatch (see :func:`ermrl.ppo.losses.ppo_loss`).
    Every field has leading axes (N sequences, T steps)."""

    obs: jax.Array
    """(N, T, obs_dim) what the policy saw."""
    episode_start: jax.Array
    """(N, T) bool: the step starts an episode, so the state is zeroed before it."""
    begin: jax.Array
    """(N, T) bool: the state before this step is the one stored in ``state`` (a sequence's first step, or the
    first step of another env's data inside a window); elsewhere it is carried from the previous step."""
    state: RecurrentState
    """(N, T, H) leaves: the states the rollout stored before each step (before the episode-start reset)."""


def lstm_init(key: jax.Array, in_dim: int, hidden: int) -> dict:
    """torch ``nn.LSTM``'s default init: U(−k, k), k = 1/√hidden, for the input and recurrent weights and for
    both of torch's biases, (4H,) each. Kernels are (in, 4H) and (H, 4H), gates in torch's order i, f, g, o."""
    k = 1.0 / jnp.sqrt(jnp.float32(hidden))
    kx, kh, kb1, kb2 = jax.random.split(key, 4)
    u = lambda key, shape: jax.random.uniform(key, shape, jnp.float32, -k, k)
    return {"kernel_x": u(kx, (in_dim, 4 * hidden)), "kernel_h": u(kh, (hidden, 4 * hidden)),
            "bias_ih": u(kb1, (4 * hidden,)), "bias_hh": u(kb2, (4 * hidden,))}


def lstm_cell(params: dict, state: LSTMState, gates_x: jax.Array) -> LSTMState:
    """One LSTM step from the input's gate contribution ``gates_x`` = :func:`input_gates`, (..., 4H)."""
    gates = gates_x + state.h @ params["kernel_h"]
    i, f, g, o = jnp.split(gates, 4, axis=-1)
    c = jax.nn.sigmoid(f) * state.c + jax.nn.sigmoid(i) * jnp.tanh(g)
    return LSTMState(jax.nn.sigmoid(o) * jnp.tanh(c), c)


def input_gates(params: dict, x: jax.Array) -> jax.Array:
    """x @ kernel_x + bias_ih + bias_hh for any leading axes (done for a whole sequence at once, outside the time
    loop)."""
    return x @ params["kernel_x"] + (params["bias_ih"] + params["bias_hh"])


def reset(state, episode_start: jax.Array):
    """Zeroes the state (any pytree of (..., H) leaves) where ``episode_start`` (...,) is True."""
    keep = 1.0 - episode_start.astype(jnp.float32)[..., None]
    return jax.tree.map(lambda x: keep * x, state)


def unroll(params: dict, seq: Sequences, stored: LSTMState) -> jax.Array:
    """Runs one LSTM over sequences: before step t the state is the stored one where ``seq.begin``, else the
    previous step's; then it is zeroed where ``seq.episode_start``. Returns the outputs h, (N, T, H)."""
    time_major = lambda x: jnp.moveaxis(x, 1, 0)
    gates_x = time_major(input_gates(params, seq.obs))

    def body(state: LSTMState, xs):
        gx, start, begin, stored_t = xs
        state = jax.tree.map(lambda s, k: jnp.where(begin[:, None], k, s), state, stored_t)
        state = lstm_cell(params, reset(state, start), gx)
        return state, state.h

    stored_t = jax.tree.map(time_major, stored)
    init = jax.tree.map(lambda x: jnp.zeros_like(x[0]), stored_t)
    _, h = jax.lax.scan(body, init, (gates_x, time_major(seq.episode_start), time_major(seq.begin), stored_t))
    return time_major(h)


class RecurrentActorCritic(ActorCritic):
    """Separate actor and critic LSTMs, then :class:`ActorCritic`'s MLP heads and action distribution.

    Params are a :class:`PolicyParams` whose ``actor`` and ``critic`` are ``{"lstm": {kernel_x, kernel_h,
    bias_ih, bias_hh}, "mlp": Flax MLP params}``. :meth:`step` acts during the rollout; :meth:`head` and
    :meth:`value` take :class:`Sequences` and return one row per step, (N·T, ...), in sequence-major order."""

    def __init__(self, action: ActionSpace, hidden: Sequence[int], lstm_hidden: int, log_std_init: float = 0.0,
                 use_sde: bool = False, activation: str = "tanh", ortho_init: bool = True):
        super().__init__(action, hidden, log_std_init, use_sde, activation, ortho_init)
        self.lstm_hidden = lstm_hidden

    @classmethod
    def of(cls, action: ActionSpace, ppo) -> "RecurrentActorCritic":
        """The network of a PPOConfig ``ppo``'s settings (model "lstm")."""
        return cls(action, ppo.hidden, ppo.lstm_hidden_size, ppo.log_std_init, ppo.use_sde, ppo.activation,
                   ppo.ortho_init)

    def init(self, key: jax.Array, obs_dim: int) -> PolicyParams:
        k_mlp, k_pi, k_vf = jax.random.split(key, 3)
        mlp = super().init(k_mlp, self.lstm_hidden)
        return PolicyParams(actor={"lstm": lstm_init(k_pi, obs_dim, self.lstm_hidden), "mlp": mlp.actor},
                            critic={"lstm": lstm_init(k_vf, obs_dim, self.lstm_hidden), "mlp": mlp.critic},
                            log_std=mlp.log_std)

    def initial_state(self, batch_shape: tuple[int, ...]) -> RecurrentState:
        """Zero states, (*batch_shape, H) leaves (sb3-contrib starts training from zeros)."""
        zero = jnp.zeros((*batch_shape, self.lstm_hidden), jnp.float32)
        return RecurrentState(LSTMState(zero, zero), LSTMState(zero, zero))

    def _policy(self, params: PolicyParams, h: jax.Array) -> tuple[jax.Array, jax.Array | None]:
        """(head, the actor MLP's last hidden features with gSDE, else None) of actor LSTM outputs h (..., H)."""
        if not self.use_sde:
            return self.actor.apply(params.actor["mlp"], h), None
        return self.actor.apply(params.actor["mlp"], h, features=True)

    def _value(self, params: PolicyParams, h: jax.Array) -> jax.Array:
        return self.critic.apply(params.critic["mlp"], h)[..., 0]

    def step(self, params: PolicyParams, state: RecurrentState, obs: jax.Array, episode_start: jax.Array):
        """One rollout step for a batch of envs: obs (..., obs_dim), episode_start (...,) bool, state (..., H).
        Returns (the new state, head (..., policy_dim), value (...,), the gSDE features (..., latent_dim) or
        None)."""
        state = reset(state, episode_start)
        pi = lstm_cell(params.actor["lstm"], state.pi, input_gates(params.actor["lstm"], obs))
        vf = lstm_cell(params.critic["lstm"], state.vf, input_gates(params.critic["lstm"], obs))
        head, latent = self._policy(params, pi.h)
        return RecurrentState(pi, vf), head, self._value(params, vf.h), latent

    def step_value(self, params: PolicyParams, vf: LSTMState, obs: jax.Array) -> jax.Array:
        """V of ``obs`` fed to the critic LSTM in state ``vf`` without a reset (the value of an episode's final
        observation, for the time-limit bootstrap, as RecurrentPPO computes it)."""
        return self._value(params, lstm_cell(params.critic["lstm"], vf, input_gates(params.critic["lstm"], obs)).h)

    def policy(self, params: PolicyParams, seq: Sequences) -> tuple[jax.Array, jax.Array | None]:
        """(:meth:`head`, the gSDE features (N·T, latent_dim) or None) along the sequences."""
        head, latent = self._policy(params, unroll(params.actor["lstm"], seq, seq.state.pi))
        return (head.reshape(-1, self.action.policy_dim),
                None if latent is None else latent.reshape(-1, self.latent_dim))

    def head(self, params: PolicyParams, seq: Sequences) -> jax.Array:
        """(N·T, policy_dim) logits or means along the sequences."""
        return self.policy(params, seq)[0]

    def value(self, params: PolicyParams, seq: Sequences) -> jax.Array:
        """(N·T,) values along the sequences."""
        return self._value(params, unroll(params.critic["lstm"], seq, seq.state.vf)).reshape(-1)
