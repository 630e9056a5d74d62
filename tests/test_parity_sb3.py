"""Parity with stable-baselines3 (optional suite: `make parity`): with no reservoir, our PPO and SB3's PPO with
the same defaults learn alike on full-observation CartPole-v1 and Pendulum-v1.

The metric is SB3's: the mean return of the last 100 episodes finished by a timestep, here 50k and 100k,
over 5 seeds. The numbers are written to docs/data/parity_sb3.json (recorded in docs/results.md)."""

import concurrent.futures as cf
import json
import multiprocessing as mp
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.reference

SEEDS = 5
CHECKPOINTS = (50_000, 100_000)
OUT = Path(__file__).resolve().parents[1] / "docs" / "data" / "parity_sb3.json"


def last_100_mean(ends: np.ndarray, returns: np.ndarray, t: int) -> float:
    """Mean return of the (at most) 100 last episodes that ended at or before step t."""
    done = returns[ends <= t]
    return float(np.mean(done[-100:])) if len(done) else float("nan")


def sb3_episodes(env_id: str, seed: int, timesteps: int) -> tuple[np.ndarray, np.ndarray]:
    """One SB3 PPO("MlpPolicy") run with default hyperparameters; (end timestep, return) of each episode."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.monitor import Monitor

    torch.set_num_threads(1)
    env = Monitor(gym.make(env_id))
    PPO("MlpPolicy", env, seed=seed).learn(timesteps)
    lengths = np.asarray(env.get_episode_lengths())
    return np.cumsum(lengths), np.asarray(env.get_episode_rewards())


def ours(env_id: str, timesteps: int) -> list[tuple[np.ndarray, np.ndarray]]:
    from ermrl.agent import AgentConfig, Phi
    from ermrl.training import Population, TrainConfig, Trainer

    config = TrainConfig(env_id=env_id, total_timesteps=timesteps, agent=AgentConfig(reservoirs=0))
    results = Trainer(config).run(Population.grid(Phi(1.0, 1.0, 1.0), SEEDS, 3e-4, 0))
    return [(e.timestep, e.ret) for e in results.episodes]


@pytest.mark.parametrize("env_id", ["CartPole-v1", "Pendulum-v1"])
def test_ppo_learns_like_sb3(env_id):
    with cf.ProcessPoolExecutor(2, mp_context=mp.get_context("spawn")) as pool:
        sb3_runs = list(pool.map(sb3_episodes, [env_id] * SEEDS, range(SEEDS), [CHECKPOINTS[-1]] * SEEDS))
    our_runs = ours(env_id, CHECKPOINTS[-1])
    record = json.loads(OUT.read_text()) if OUT.exists() else {}
    record[env_id] = {}
    for t in CHECKPOINTS:
        a = np.array([last_100_mean(e, r, t) for e, r in our_runs])
        b = np.array([last_100_mean(e, r, t) for e, r in sb3_runs])
        record[env_id][str(t)] = {"ermrl": a.tolist(), "sb3": b.tolist(), "ermrl_mean": a.mean(), "sb3_mean": b.mean(),
                                  "ermrl_std": a.std(), "sb3_std": b.std()}
        print(f"{env_id} @ {t}: ermrl {a.mean():.1f} ± {a.std():.1f}   sb3 {b.mean():.1f} ± {b.std():.1f}")
        gap = abs(a.mean() - b.mean())
        within_15 = gap <= 0.15 * max(abs(a.mean()), abs(b.mean()))
        inside_spread = gap <= max(a.std(), b.std())
        assert within_15 or inside_spread, f"{env_id} at {t}: ermrl {a.mean():.1f}±{a.std():.1f} vs sb3 {b.mean():.1f}±{b.std():.1f}"
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(record, indent=1))


def _sb3_dense(state: dict, names: list[str]) -> dict:
    """SB3 Linear layers (weight (out, in)) as our flax Dense params (kernel (in, out))."""
    import jax.numpy as jnp

    return {"params": {f"Dense_{i}": {"kernel": jnp.asarray(state[f"{n}.weight"].T), "bias": jnp.asarray(state[f"{n}.bias"])}
                       for i, n in enumerate(names)}}


def _ours_from(state: dict):
    """An SB3 MlpPolicy state dict as our PolicyParams."""
    import jax.numpy as jnp

    from ermrl.ppo.networks import PolicyParams

    return PolicyParams(
        actor=_sb3_dense(state, ["mlp_extractor.policy_net.0", "mlp_extractor.policy_net.2", "action_net"]),
        critic=_sb3_dense(state, ["mlp_extractor.value_net.0", "mlp_extractor.value_net.2", "value_net"]),
        log_std=jnp.asarray(state["log_std"]) if "log_std" in state else None,
    )


def _sb3_one_iteration(env_id: str, monkeypatch, orders=None, sgd=False, **ppo_kwargs) -> tuple[dict, dict, object]:
    """SB3 PPO("MlpPolicy", seed=0): one 2048-step rollout, then one ``train()`` on it. With ``orders``
    (n_epochs, 2048), the epochs shuffle the buffer in those orders; with ``sgd`` the optimizer is plain SGD,
    so a step is −lr × the clipped gradient. Returns the policy's state before and
    after (NumPy) and the rollout buffer (flattened to (2048, ...) rows by ``train()``)."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    model = PPO("MlpPolicy", gym.make(env_id), seed=0, **ppo_kwargs)
    if sgd:
        model.policy.optimizer = torch.optim.SGD(model.policy.parameters(), lr=model.learning_rate)
    before = {k: v.detach().clone().numpy() for k, v in model.policy.state_dict().items()}
    with monkeypatch.context() as patch:
        if orders is not None:
            given, real = iter(orders), np.random.permutation
            patch.setattr(np.random, "permutation", lambda n: np.array(next(given)) if n == len(orders[0]) else real(n))
        model.learn(2048)
    return before, {k: v.detach().numpy() for k, v in model.policy.state_dict().items()}, model.rollout_buffer


@pytest.mark.parametrize("env_id", ["CartPole-v1", "Pendulum-v1"])
def test_update_matches_sb3(env_id, monkeypatch):
    """Same weights, same rollout buffer (SB3's, seed 0):
    - our log-probs and values equal SB3's;
    - the loss gradient after global-norm clipping equals SB3's (SB3 run once with plain SGD on the full batch,
      so its step is −lr × its clipped gradient); this checks the clipped surrogate, the advantage
      normalization, vf_coef and the clipping, which Adam would hide (its first step is ≈ ±lr whatever the
      gradient's scale);
    - a whole SB3-default update (10 epochs × 32 minibatches of 64, Adam), with both sides shuffling in the
      same orders, moves every parameter as SB3's ``train()`` does."""
    import jax
    import jax.numpy as jnp
    import optax

    from ermrl import envs
    from ermrl.ppo import update as ppo_update
    from ermrl.ppo.config import PPOConfig
    from ermrl.ppo.losses import Batch, ppo_loss
    from ermrl.ppo.networks import ActorCritic

    def assert_same_steps(ours_after, sb3_after, start):
        for a, b, s in zip(*(jax.tree.leaves(p) for p in (ours_after, sb3_after, start))):
            sb3_step = np.asarray(b - s)
            np.testing.assert_allclose(np.asarray(a - s), sb3_step, atol=1e-3 * np.abs(sb3_step).max() + 1e-9)

    info = envs.describe(env_id)
    net = ActorCritic(info.action, (64, 64))
    config = PPOConfig()
    lr = jnp.float32(config.learning_rate)
    orders = np.stack([np.random.default_rng(e).permutation(config.buffer_size) for e in range(config.n_epochs)])
    before, after, buf = _sb3_one_iteration(env_id, monkeypatch, orders)
    params = _ours_from(before)
    obs = jnp.asarray(buf.observations.reshape(2048, -1))
    action = jnp.asarray(buf.actions.reshape(2048).astype(np.int32) if info.action.discrete else buf.actions.reshape(2048, -1))
    head = net.head(params, obs)
    np.testing.assert_allclose(net.log_prob(params, head, action), buf.log_probs.reshape(-1), atol=1e-5)
    np.testing.assert_allclose(net.value(params, obs), buf.values.reshape(-1), rtol=1e-5, atol=1e-5)
    batch = Batch(obs, action, *(jnp.asarray(x.reshape(-1)) for x in (buf.log_probs, buf.advantages, buf.returns)))

    learner = ppo_update.LearnerState(params, ppo_update.make_optimizer(config).init(params), lr)
    learner, _ = ppo_update.update(learner, batch, jax.random.PRNGKey(0), net, config, orders=orders)
    assert_same_steps(learner.params, _ours_from(after), params)

    _, after_sgd, sgd_buf = _sb3_one_iteration(env_id, monkeypatch, None, n_epochs=1, batch_size=2048, sgd=True)
    np.testing.assert_array_equal(sgd_buf.actions, buf.actions)  # same seed: same weights and rollout
    full = PPOConfig(n_epochs=1, batch_size=2048)
    grads = jax.grad(lambda p: ppo_loss(p, net, batch, full)[0])(params)
    clipped, _ = optax.clip_by_global_norm(full.max_grad_norm).update(grads, optax.EmptyState())
    assert_same_steps(jax.tree.map(lambda p, g: p - lr * g, params, clipped), _ours_from(after_sgd), params)


@pytest.mark.parametrize("env_id", ["CartPole-v1", "Pendulum-v1"])
def test_rollout_targets_match_sb3(env_id, monkeypatch):
    """SB3's rollout (seed 0) replayed in a plain Gymnasium env: our time-limit bootstrap and GAE
    (``bootstrapped_gae``, what ``learn`` uses) give SB3's advantages and returns. Pendulum's 2048 steps hold
    10 time-limit truncations."""
    import gymnasium as gym
    import jax.numpy as jnp

    from ermrl import envs
    from ermrl.ppo.config import PPOConfig
    from ermrl.ppo.losses import bootstrapped_gae
    from ermrl.ppo.networks import ActorCritic

    before, _, buf = _sb3_one_iteration(env_id, monkeypatch)
    info = envs.describe(env_id)
    obs, actions = buf.observations.reshape(2048, -1), buf.actions.reshape(2048, -1)
    low, high = info.action.low, info.action.high
    env = gym.make(env_id)
    o, _ = env.reset(seed=0)  # SB3's seed=0 seeds the env's first reset
    reward, terminated, truncated = np.zeros(2048, np.float32), np.zeros(2048, bool), np.zeros(2048, bool)
    final = np.zeros_like(obs)
    for t in range(2048):
        np.testing.assert_allclose(o, obs[t], atol=1e-5)
        a = int(actions[t, 0]) if info.action.discrete else np.clip(actions[t], *(np.float32(b) for b in (low, high)))
        final[t], reward[t], terminated[t], truncated[t], _ = env.step(a)
        o = env.reset()[0] if terminated[t] or truncated[t] else final[t]
    if env_id == "Pendulum-v1":
        assert truncated.sum() == 10

    net, ppo = ActorCritic(info.action, (64, 64)), PPOConfig()
    params = _ours_from(before)
    column = lambda x: jnp.asarray(x).reshape(2048, 1)
    advantage, ret = bootstrapped_gae(
        column(reward), column(buf.values), column(terminated | truncated), column(truncated & ~terminated),
        net.value(params, jnp.asarray(final))[:, None], net.value(params, jnp.asarray(o)[None]), ppo.gamma,
        ppo.gae_lambda)
    scale = np.abs(buf.advantages).max()
    np.testing.assert_allclose(advantage[:, 0], buf.advantages.reshape(-1), atol=1e-5 * scale)
    np.testing.assert_allclose(ret[:, 0], buf.returns.reshape(-1), atol=1e-5 * np.abs(buf.returns).max())
