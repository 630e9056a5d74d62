
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ermrl.envs.spaces import ActionSpace
from ermrl.errors import ConfigError
from ermrl.ppo.config import PPOConfig, SB3_DEFAULTS
from ermrl.ppo.losses import Batch, gae, ppo_loss
from ermrl.ppo.networks import ActorCritic


def sb3_gae(rewards, values, dones, last_value, gamma, lam):
    """stable-baselines3's RolloutBuffer.compute_returns_and_advantage, written as a plain loop.
    SB3 stores episode_starts; episode_starts[t + 1] == dones[t]."""
    n = len(rewards)
    adv = np.zeros(n)
    last = 0.0
    for t in reversed(range(n)):
        next_nonterminal = 1.0 - dones[t]
        next_value = last_value if t == n - 1 else values[t + 1]
        delta = rewards[t] + gamma * next_value * next_nonterminal - values[t]
        last = delta + gamma * lam * next_nonterminal * last
        adv[t] = last
    return adv, adv + values


def test_gae_matches_sb3_loop():
    rng = np.random.default_rng(0)
    r, v = rng.normal(size=50), rng.normal(size=50)
    d = rng.random(50) < 0.1
    adv, ret = gae(jnp.asarray(r)[:, None], jnp.asarray(v)[:, None], jnp.asarray(d)[:, None], jnp.array([0.7]), 0.99, 0.95)
    ref_adv, ref_ret = sb3_gae(r, v, d.astype(float), 0.7, 0.99, 0.95)
    np.testing.assert_allclose(adv[:, 0], ref_adv, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(ret[:, 0], ref_ret, rtol=1e-5, atol=1e-5)


def test_sb3_defaults():
    c = SB3_DEFAULTS
    assert (c.n_envs, c.n_steps, c.batch_size, c.n_epochs, c.learning_rate) == (1, 2048, 64, 10, 3e-4)
    assert (c.gamma, c.gae_lambda, c.clip_range, c.ent_coef, c.vf_coef, c.max_grad_norm) == (0.99, 0.95, 0.2, 0.0, 0.5, 0.5)
    assert c.adam_eps == 1e-5 and c.hidden == (64, 64) and c.n_minibatches == 32
    assert c.iterations(300_000) == 147  # SB3 stops at the first rollout boundary past total_timesteps


def test_bad_ppo_configs():
    with pytest.raises(ConfigError, match="batch_size 100 must divide n_steps × n_envs = 2048"):
        PPOConfig(batch_size=100)
    with pytest.raises(ConfigError, match="learning rate 5.0 is outside"):
        PPOConfig(learning_rate=5.0)


def test_orthogonal_init_gains():
    net = ActorCritic(ActionSpace(False, 3, (-1.0,) * 3, (1.0,) * 3), (64, 64))
    p = net.init(jax.random.PRNGKey(0), 100)
    hidden = np.asarray(p.actor["params"]["Dense_0"]["kernel"])  # (100, 64): orthonormal columns × √2
    np.testing.assert_allclose(hidden.T @ hidden, 2.0 * np.eye(64), atol=1e-4)
    head = np.asarray(p.actor["params"]["Dense_2"]["kernel"])
    np.testing.assert_allclose(head.T @ head, 1e-4 * np.eye(3), atol=1e-8)
    vhead = np.asarray(p.critic["params"]["Dense_2"]["kernel"])
    assert float((vhead.T @ vhead)[0, 0]) == pytest.approx(1.0, rel=1e-5)
    assert not np.any(np.asarray(p.actor["params"]["Dense_0"]["bias"]))
    np.testing.assert_array_equal(p.log_std, np.zeros(3))


def test_log_prob_and_entropy():
    from scipy import stats

    box = ActorCritic(ActionSpace(False, 2, (-1.0, -1.0), (1.0, 1.0)), (8,))
    p = box.init(jax.random.PRNGKey(1), 4)._replace(log_std=jnp.array([0.3, -0.5]))
    mean, a = jnp.array([[0.1, -0.2]]), jnp.array([[0.5, 0.4]])
    expected = stats.norm(mean[0], np.exp([0.3, -0.5])).logpdf(a[0]).sum()
    assert float(box.log_prob(p, mean, a)[0]) == pytest.approx(expected, rel=1e-5)
    assert float(box.entropy(p, mean)[0]) == pytest.approx(stats.norm(0, np.exp([0.3, -0.5])).entropy().sum(), rel=1e-5)

    cat = ActorCritic(ActionSpace(True, 3), (8,))
    q = cat.init(jax.random.PRNGKey(1), 4)
    logits = jnp.array([[1.0, 2.0, 0.5]])
    probs = np.exp(logits[0]) / np.exp(logits[0]).sum()
    assert float(cat.log_prob(q, logits, jnp.array([1]))[0]) == pytest.approx(np.log(probs[1]), rel=1e-5)
    assert float(cat.entropy(q, logits)[0]) == pytest.approx(-(probs * np.log(probs)).sum(), rel=1e-5)


def test_sampling_from_noise_drawn_ahead():
    """``sample(noise(key))`` is ``jax.random.categorical(key)`` for Discrete, and N(mean, exp(log_std)²) for Box."""
    cat = ActorCritic(ActionSpace(True, 3), (8,))
    q = cat.init(jax.random.PRNGKey(1), 4)
    logits = jnp.tile(jnp.array([[1.0, 2.0, 0.5]]), (20_000, 1))
    key = jax.random.PRNGKey(5)
    drawn = cat.sample(q, logits, cat.noise(key, (20_000,)))
    np.testing.assert_array_equal(drawn, jax.random.categorical(key, logits, axis=-1))
    probs = np.exp([1.0, 2.0, 0.5]) / np.exp([1.0, 2.0, 0.5]).sum()
    np.testing.assert_allclose(np.bincount(np.asarray(drawn), minlength=3) / 20_000, probs, atol=0.01)

    box = ActorCritic(ActionSpace(False, 2, (-1.0, -1.0), (1.0, 1.0)), (8,))
    p = box.init(jax.random.PRNGKey(1), 4)._replace(log_std=jnp.array([0.3, -0.5]))
    actions = np.asarray(box.sample(p, jnp.zeros((20_000, 2)) + jnp.array([0.1, -0.2]), box.noise(key, (20_000,))))
    np.testing.assert_allclose(actions.mean(0), [0.1, -0.2], atol=0.03)
    np.testing.assert_allclose(actions.std(0), np.exp([0.3, -0.5]), rtol=0.03)


def test_loss_uses_unbiased_advantage_std_and_clipping():
    """At the old policy the ratio is 1, so the policy loss is −mean of the normalized advantages (= 0) and the
    gradient of the normalized advantages uses torch's unbiased std."""
    net = ActorCritic(ActionSpace(True, 2), (8,))
    p = net.init(jax.random.PRNGKey(0), 3)
    ctx = jax.random.normal(jax.random.PRNGKey(1), (6, 3))
    act = jnp.array([0, 1, 1, 0, 1, 0])
    logp = net.log_prob(p, net.head(p, ctx), act)
    adv = jnp.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    batch = Batch(ctx, act, logp, adv, jnp.zeros(6))
    cfg = SB3_DEFAULTS
    loss, m = ppo_loss(p, net, batch, cfg)
    assert float(m["policy_loss"]) == pytest.approx(0.0, abs=1e-6)
    assert float(m["clip_fraction"]) == 0.0
    # Shift the old log-probs so that every ratio is e^0.5 > 1.2: the clipped term takes over.
    shifted = batch._replace(log_prob=logp - 0.5)
    _, m2 = ppo_loss(p, net, shifted, cfg)
    norm = (adv - adv.mean()) / (np.std(np.asarray(adv), ddof=1) + 1e-8)
    expected = -np.mean(np.minimum(norm * np.exp(0.5), norm * 1.2))
    assert float(m2["policy_loss"]) == pytest.approx(expected, rel=1e-5)
    assert float(m2["clip_fraction"]) == 1.0


@pytest.mark.parametrize("n", [1, 2, 5, 64, 2048, 70_000])
def test_permutation_is_a_permutation(n):
    from ermrl.ppo.update import permutation

    order = np.asarray(permutation(jax.random.PRNGKey(n), n))
    assert order.dtype == np.int32 and sorted(order.tolist()) == list(range(n))
    if n >= 64:
        assert not np.array_equal(order, np.arange(n))


def test_permutation_is_uniform():
    """All 24 orderings of 4 rows equally likely, and at SB3's buffer size every row equally likely to land in
    each of the 32 minibatches (chi-square tests on fixed keys, so the test is deterministic)."""
    from scipy.stats import chisquare

    from ermrl.ppo.update import permutation

    keys = jax.random.split(jax.random.PRNGKey(0), 48_000)
    small = np.asarray(jax.jit(jax.vmap(lambda k: permutation(k, 4)))(keys))
    codes = small @ np.array([64, 16, 4, 1])
    counts = np.unique(codes, return_counts=True)[1]
    assert len(counts) == 24 and chisquare(counts).pvalue > 1e-3

    big = np.asarray(jax.jit(jax.vmap(lambda k: permutation(k, 2048)))(keys[:4000]))
    for row in (0, 1, 2047):
        minibatch = np.argmax(big == row, axis=1) // 64
        assert chisquare(np.bincount(minibatch, minlength=32)).pvalue > 1e-3
