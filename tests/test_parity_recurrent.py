"""Parity with sb3-contrib's RecurrentPPO (optional suite: `make parity`): our PPO-LSTM (``PPOConfig.model =
"lstm"``) and RecurrentPPO("MlpLstmPolicy") with the same hyperparameters learn alike on CartPoleNoVel-v1.

The settings are ours (SB3's PPO defaults, 64 LSTM units, 64-step sequences), given to RecurrentPPO explicitly
where its defaults differ; see :func:`recurrent_ppo`. The metric is SB3's, as in tests/test_parity_sb3.py: the
mean return of the last 100 episodes finished by a timestep, here 25k and 50k, over 5 seeds per side. 50k steps
(25 iterations) keeps RecurrentPPO, whose update runs its LSTMs step by step in Python, within minutes per seed on
a CPU core. The numbers are written to docs/data/parity_recurrent.json (recorded in docs/results.md).

The learning run is backed by exact checks on one RecurrentPPO iteration (seed 0): with RecurrentPPO's weights,
our LSTMs give its rollout's values and log-probs, from the states its buffer stored, in whole rollouts and in
its minibatch windows; and its update (10 epochs × 32 windows, Adam), replayed in the same window order, moves
every parameter as ours does."""

import concurrent.futures as cf
import json
import multiprocessing as mp
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.reference

ENV_ID = "CartPoleNoVel-v1"
SEEDS = 5
CHECKPOINTS = (25_000, 50_000)
LEARNS = 100.0
"""Both sides' mean at the last checkpoint must exceed this: the random agent scores about 22 on CartPole and
plain PPO on the masked observation stays near 45 (tests/test_train.py), so only a policy that recovers the
velocities gets here (ours measured 161.9 ± 23.1 at 50k over seeds 0–8)."""
Z = 2.5
"""Tolerance of the seed means' gap in standard errors of the difference, √(s_a²/n + s_b²/n): under equal
learning a gap beyond it has a two-sided chance of about 1% per checkpoint (normal approximation)."""
RELATIVE = 0.10
"""A gap within 10% of the larger mean also passes, so that a chance-tight seed spread does not turn an equal
result into a failure."""
OUT = Path(__file__).resolve().parents[1] / "docs" / "data" / "parity_recurrent.json"


def last_100_mean(ends: np.ndarray, returns: np.ndarray, t: int) -> float:
    """Mean return of the (at most) 100 last episodes that ended at or before step t."""
    done = returns[ends <= t]
    return float(np.mean(done[-100:])) if len(done) else float("nan")


def masked_env(env_id: str):
    """The Gymnasium env of a NoVel id with its velocity dims deleted, as ermrl's saved agents build it."""
    import gymnasium as gym

    from ermrl import envs
    from ermrl.saved_agent import DeleteDims

    info = envs.describe(env_id)
    env = gym.make(info.base_id)
    return DeleteDims(env, info.kept_dims) if info.kept_dims != tuple(range(env.observation_space.shape[0])) else env


def recurrent_ppo(env, seed: int, **overrides):
    """RecurrentPPO("MlpLstmPolicy") set to our PPO-LSTM's hyperparameters (ermrl.ppo.config.PPOConfig):
    - n_steps 2048, batch_size 64 (RecurrentPPO's defaults are 128, 128): our SB3 defaults, one env. A 64-row
      minibatch of its rotated buffer is our one 64-step window (lstm_seq_len 64) at the same offset;
    - n_epochs 10, learning_rate 3e-4, gamma 0.99, gae_lambda 0.95, clip_range 0.2, no value clipping,
      normalize_advantage, ent_coef 0, vf_coef 0.5, max_grad_norm 0.5, no target_kl, no gSDE: the defaults
      of both;
    - lstm_hidden_size 64 (its default is 256), n_lstm_layers 1, shared_lstm False, enable_critic_lstm True:
      separate actor and critic LSTMs, as ours;
    - net_arch pi [64, 64], vf [64, 64], tanh, ortho_init True (SB3's gains on the MLPs and heads; the LSTMs keep
      torch's init, as ours), log_std_init 0, Adam with eps 1e-5: SB3's policy defaults, written out.
    Torch runs on one thread (one process per seed)."""
    import torch
    from sb3_contrib import RecurrentPPO

    torch.set_num_threads(1)
    kwargs = dict(n_steps=2048, batch_size=64, n_epochs=10, learning_rate=3e-4, gamma=0.99, gae_lambda=0.95,
                  clip_range=0.2, clip_range_vf=None, normalize_advantage=True, ent_coef=0.0, vf_coef=0.5,
                  max_grad_norm=0.5, target_kl=None, use_sde=False)
    policy_kwargs = dict(lstm_hidden_size=64, n_lstm_layers=1, shared_lstm=False, enable_critic_lstm=True,
                         net_arch=dict(pi=[64, 64], vf=[64, 64]), activation_fn=torch.nn.Tanh, ortho_init=True,
                         log_std_init=0.0)
    return RecurrentPPO("MlpLstmPolicy", env, seed=seed, policy_kwargs=policy_kwargs, **{**kwargs, **overrides})


def sb3_episodes(env_id: str, seed: int, timesteps: int) -> tuple[np.ndarray, np.ndarray, float]:
    """One RecurrentPPO run; (end timestep, return) of each episode, and its wall seconds."""
    from stable_baselines3.common.monitor import Monitor

    env = Monitor(masked_env(env_id))
    start = time.perf_counter()
    recurrent_ppo(env, seed).learn(timesteps)
    wall = time.perf_counter() - start
    return np.cumsum(env.get_episode_lengths()), np.asarray(env.get_episode_rewards()), wall


def ours(env_id: str, timesteps: int) -> tuple[list[tuple[np.ndarray, np.ndarray]], float]:
    """Our PPO-LSTM, seeds 0..SEEDS-1 as one population; per seed (end timestep, return) of each episode, and
    the population's wall seconds (compile included)."""
    import dataclasses

    from ermrl.agent import AgentConfig, Phi
    from ermrl.ppo.config import SB3_DEFAULTS
    from ermrl.training import Population, TrainConfig, Trainer

    config = TrainConfig(env_id=env_id, total_timesteps=timesteps, agent=AgentConfig(reservoirs=0),
                         ppo=dataclasses.replace(SB3_DEFAULTS, model="lstm", lstm_hidden_size=64, lstm_seq_len=64))
    start = time.perf_counter()
    results = Trainer(config).run(Population.grid(Phi(1.0, 1.0, 1.0), SEEDS, 3e-4, 0))
    return [(e.timestep, e.ret) for e in results.episodes], time.perf_counter() - start


def test_ppo_lstm_learns_like_recurrent_ppo():
    with cf.ProcessPoolExecutor(2, mp_context=mp.get_context("spawn")) as pool:
        sb3_runs = list(pool.map(sb3_episodes, [ENV_ID] * SEEDS, range(SEEDS), [CHECKPOINTS[-1]] * SEEDS))
    our_runs, our_wall = ours(ENV_ID, CHECKPOINTS[-1])
    record = {"env": ENV_ID, "seeds": list(range(SEEDS)), "metric": "mean return of the last 100 episodes",
              "wall_s": {"ermrl_population": our_wall, "sb3_contrib_per_seed": [w for _, _, w in sb3_runs]}}
    failures = []
    for t in CHECKPOINTS:
        a = np.array([last_100_mean(e, r, t) for e, r in our_runs])
        b = np.array([last_100_mean(e, r, t) for e, r, _ in sb3_runs])
        gap = abs(a.mean() - b.mean())
        tolerance = max(Z * np.sqrt((a.var(ddof=1) + b.var(ddof=1)) / SEEDS), RELATIVE * max(a.mean(), b.mean()))
        record[str(t)] = {"ermrl": a.tolist(), "sb3_contrib": b.tolist(), "ermrl_mean": a.mean(),
                          "sb3_contrib_mean": b.mean(), "ermrl_std": a.std(), "sb3_contrib_std": b.std(),
                          "gap": gap, "tolerance": tolerance}
        print(f"{ENV_ID} @ {t}: ermrl {a.mean():.1f} ± {a.std():.1f}   sb3-contrib {b.mean():.1f} ± {b.std():.1f}"
              f"   gap {gap:.1f} (tolerance {tolerance:.1f})")
        if gap > tolerance:
            failures.append(f"at {t}: ermrl {a.mean():.1f}±{a.std():.1f} vs sb3-contrib "
                            f"{b.mean():.1f}±{b.std():.1f}, gap {gap:.1f} > {tolerance:.1f}")
    print(f"wall: ermrl {our_wall:.0f} s for {SEEDS} seeds; sb3-contrib "
          + ", ".join(f"{w:.0f}" for w in record["wall_s"]["sb3_contrib_per_seed"]) + " s per seed")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(record, indent=1))
    assert not failures, "; ".join(failures)
    final = record[str(CHECKPOINTS[-1])]
    assert min(final["ermrl_mean"], final["sb3_contrib_mean"]) > LEARNS, final


def _sb3_dense(state: dict, names: list[str]) -> dict:
    """SB3 Linear layers (weight (out, in)) as our flax Dense params (kernel (in, out))."""
    import jax.numpy as jnp

    layer = lambda n: {"kernel": jnp.asarray(state[f"{n}.weight"].T), "bias": jnp.asarray(state[f"{n}.bias"])}
    return {"params": {f"Dense_{i}": layer(n) for i, n in enumerate(names)}}


def _sb3_lstm(state: dict, name: str) -> dict:
    """A one-layer torch ``nn.LSTM`` (weights (4H, in) and (4H, H), gates i, f, g, o) as our LSTM params."""
    import jax.numpy as jnp

    get = lambda field: jnp.asarray(state[f"{name}.{field}_l0"])
    return {"kernel_x": get("weight_ih").T, "kernel_h": get("weight_hh").T, "bias_ih": get("bias_ih"),
            "bias_hh": get("bias_hh")}


def _ours_from(state: dict):
    """An sb3-contrib MlpLstmPolicy state dict (separate LSTMs, Discrete actions) as our PolicyParams."""
    from ermrl.ppo.networks import PolicyParams

    return PolicyParams(
        actor={"lstm": _sb3_lstm(state, "lstm_actor"),
               "mlp": _sb3_dense(state, ["mlp_extractor.policy_net.0", "mlp_extractor.policy_net.2", "action_net"])},
        critic={"lstm": _sb3_lstm(state, "lstm_critic"),
                "mlp": _sb3_dense(state, ["mlp_extractor.value_net.0", "mlp_extractor.value_net.2", "value_net"])},
        log_std=None)


@pytest.fixture(scope="module")
def one_iteration():
    """RecurrentPPO (seed 0, our settings): one 2048-step rollout on CartPoleNoVel-v1, then one ``train()``.
    Returns the policy's state before and after (NumPy), the rollout buffer (rows env-major after ``train()``),
    and each epoch's ``split_index``, the rotation that sets its minibatches."""
    model = recurrent_ppo(masked_env(ENV_ID), 0)
    before = {k: v.detach().clone().numpy() for k, v in model.policy.state_dict().items()}
    buffer_rows, splits, real = 2048, [], np.random.randint

    def record(*args, **kwargs):
        value = real(*args, **kwargs)
        if args == (buffer_rows,):  # the buffer's split_index, drawn once per epoch
            splits.append(int(value))
        return value

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(np.random, "randint", record)
        model.learn(buffer_rows)
    assert len(splits) == model.n_epochs
    after = {k: v.detach().numpy() for k, v in model.policy.state_dict().items()}
    return before, after, model.rollout_buffer, splits


def _sequence_batch(buf):
    """sb3-contrib's flattened buffer (one env: row = step) as our SequenceBatch."""
    import jax.numpy as jnp

    from ermrl.ppo.recurrent import LSTMState, RecurrentState
    from ermrl.ppo.recurrent_update import SequenceBatch

    rows = lambda x: jnp.asarray(np.asarray(x).reshape(len(buf.observations)))
    state = lambda name: jnp.asarray(getattr(buf, name)[:, 0, :])  # (rows, layers = 1, H)
    return SequenceBatch(
        jnp.asarray(buf.observations), jnp.asarray(buf.actions.reshape(-1).astype(np.int32)), rows(buf.log_probs),
        rows(buf.advantages), rows(buf.returns), rows(buf.episode_starts).astype(bool),
        RecurrentState(LSTMState(state("hidden_states_pi"), state("cell_states_pi")),
                       LSTMState(state("hidden_states_vf"), state("cell_states_vf"))))


def test_policy_matches_recurrent_ppo(one_iteration):
    """With RecurrentPPO's initial weights, our LSTMs (torch's gate order, both biases) give its rollout's
    log-probs and values: over the whole rollout as one sequence (state zeroed at its episode starts), and in
    every 64-step window of each epoch's rotation, started from the state its buffer stored (so the stored state
    is the one before the step, before the episode-start reset, as ours)."""
    import jax
    import jax.numpy as jnp

    from ermrl import envs
    from ermrl.ppo.config import PPOConfig
    from ermrl.ppo.losses import ppo_loss
    from ermrl.ppo.recurrent import RecurrentActorCritic
    from ermrl.ppo.recurrent_update import sequences

    before, _, buf, splits = one_iteration
    net = RecurrentActorCritic(envs.describe(ENV_ID).action, (64, 64), 64)
    ppo = PPOConfig(model="lstm")
    params, batch = _ours_from(before), _sequence_batch(buf)
    assert 10 < int(batch.episode_start.sum()) < 2048  # episodes start inside the rollout

    whole = sequences(batch, jnp.arange(2048)[None], ppo.n_steps)
    log_prob = net.log_prob(params, net.head(params, whole.context), batch.action)
    np.testing.assert_allclose(np.asarray(log_prob), np.asarray(batch.log_prob), atol=1e-5)
    np.testing.assert_allclose(np.asarray(net.value(params, whole.context)), buf.values.reshape(-1), atol=1e-5)

    @jax.jit
    def window(rows):
        minibatch = sequences(batch, rows[None], ppo.n_steps)
        return ppo_loss(params, net, minibatch, ppo)[1], net.value(params, minibatch.context)

    for split in splits[:2]:
        for rows in ((split + np.arange(2048)) % 2048).reshape(32, 64):
            metrics, value = window(jnp.asarray(rows))
            assert abs(float(metrics["approx_kl"])) < 1e-6 and float(metrics["clip_fraction"]) == 0.0
            np.testing.assert_allclose(np.asarray(value), buf.values.reshape(-1)[rows], atol=1e-5)


def test_update_matches_recurrent_ppo(one_iteration):
    """Same weights, same rollout buffer (RecurrentPPO's, seed 0): our update, visiting each epoch's 64-step windows
    in RecurrentPPO's order (its rotation by ``split_index``, minibatches in buffer order), moves every parameter as
    its ``train()`` does: 10 epochs × 32 minibatches with Adam, gradient clipping, the advantage normalized per
    minibatch, each window's LSTMs started from the stored state and reset at episode starts. Among others this
    pins down that torch's two LSTM biases are two parameters (with one summed bias, both biases' sum moves about
    half as far)."""
    import jax
    import jax.numpy as jnp

    from ermrl import envs
    from ermrl.ppo.config import PPOConfig
    from ermrl.ppo.recurrent import RecurrentActorCritic
    from ermrl.ppo.recurrent_update import update
    from ermrl.ppo.update import LearnerState, make_optimizer

    before, after, buf, splits = one_iteration
    net = RecurrentActorCritic(envs.describe(ENV_ID).action, (64, 64), 64)
    ppo = PPOConfig(model="lstm")
    params = _ours_from(before)
    learner = LearnerState(params, make_optimizer(ppo).init(params), jnp.float32(ppo.learning_rate))
    orders = np.stack([((s + np.arange(2048)) % 2048).reshape(32, 64) for s in splits])
    learner, _ = jax.jit(lambda l, o: update(l, _sequence_batch(buf), jax.random.PRNGKey(0), net, ppo, orders=o))(
        learner, orders)
    for ours_after, sb3_after, start in zip(*(jax.tree.leaves(p) for p in (learner.params, _ours_from(after), params))):
        sb3_step = np.asarray(sb3_after - start)
        np.testing.assert_allclose(np.asarray(ours_after - start), sb3_step, atol=1e-3 * np.abs(sb3_step).max())
