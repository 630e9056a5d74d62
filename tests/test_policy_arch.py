"""The policy's architecture settings: ``PPOConfig.hidden`` (``--net-arch``), ``activation`` and ``ortho_init``,
as SB3's ``net_arch``, ``activation_fn`` and ``ortho_init`` (rl-baselines3-zoo's recurrent Pendulum settings use
``net_arch=[64]``, ReLU and no orthogonal init).

Checked against SB3's own ``ActorCriticPolicy`` in the reference suite (its outputs on the same weights, and its
initial weights' distribution); here, against torch's documented init and with real training."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ermrl.agent import AgentConfig, Phi
from ermrl.envs.spaces import ActionSpace
from ermrl.ppo.config import SB3_DEFAULTS
from ermrl.ppo.networks import ActorCritic
from ermrl.training import Population, TrainConfig, Trainer

RLZOO = dataclasses.replace(SB3_DEFAULTS, hidden=(64,), activation="relu", ortho_init=False)
"""rl-baselines3-zoo's policy for PendulumNoVel-v1 (hyperparams/ppo_lstm.yml), its LSTM aside."""
BOX = ActionSpace(False, 1, (-2.0,), (2.0,))


def _layers(params: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    dense = params["params"]
    return [(np.asarray(dense[f"Dense_{i}"]["kernel"]), np.asarray(dense[f"Dense_{i}"]["bias"]))
            for i in range(len(dense))]


def test_without_ortho_init_every_layer_has_torchs_default_init():
    """torch's nn.Linear default: weights and biases U(±1/√fan_in), the heads included (no 0.01 gain)."""
    net = ActorCritic.of(BOX, RLZOO)
    inits = jax.jit(jax.vmap(lambda k: net.init(k, 500)))(jax.random.split(jax.random.PRNGKey(0), 1000))
    for part, widths in (("actor", [(500, 64), (64, 1)]), ("critic", [(500, 64), (64, 1)])):
        for layer, (fan_in, out) in enumerate(widths):
            kernels, biases = _layers(getattr(inits, part))[layer]
            assert kernels.shape[1:] == (fan_in, out) and biases.shape[1:] == (out,)
            bound = 1 / np.sqrt(fan_in)
            for values in (kernels, biases):  # 1000 draws at least
                assert 0.99 * bound < np.abs(values).max() <= bound
                assert values.std() == pytest.approx(bound / np.sqrt(3), rel=0.05)  # a uniform's std
            if out > 1:
                singular = np.linalg.svd(kernels[0], compute_uv=False)
                assert singular.max() / singular.min() > 1.5  # not orthogonal
    np.testing.assert_array_equal(inits.log_std, np.zeros((1000, 1)))


def test_relu_layers_compute_relu():
    net = ActorCritic.of(BOX, RLZOO)
    params = net.init(jax.random.PRNGKey(0), 5)
    x = np.random.default_rng(0).normal(size=(7, 5)).astype(np.float32)
    (w0, b0), (w1, b1) = _layers(params.actor)
    hidden = np.maximum(x @ w0 + b0, 0)
    assert 0.2 < (hidden == 0).mean() < 0.8  # ReLU, not tanh: about half the units are cut at 0
    np.testing.assert_allclose(net.head(params, jnp.asarray(x)), hidden @ w1 + b1, rtol=1e-5, atol=1e-5)
    (v0, c0), (v1, c1) = _layers(params.critic)
    np.testing.assert_allclose(net.value(params, jnp.asarray(x)), (np.maximum(x @ v0 + c0, 0) @ v1 + c1)[:, 0],
                               rtol=1e-5, atol=1e-5)


def test_the_default_policy_is_unchanged_and_its_record_too():
    """tanh, orthogonal init: SB3's MlpPolicy; the new fields stay out of old records."""
    from ermrl import storage

    net = ActorCritic.of(BOX, SB3_DEFAULTS)
    assert (net.actor.activation, net.actor.ortho_init, net.actor.hidden) == ("tanh", True, (64, 64))
    record = storage.to_dict(SB3_DEFAULTS)
    assert "activation" not in record and "ortho_init" not in record
    assert storage.to_dict(RLZOO)["activation"] == "relu" and storage.to_dict(RLZOO)["ortho_init"] is False


def test_rlzoos_policy_learns_cartpole():
    """One hidden ReLU layer without orthogonal init learns full-observation CartPole as the default policy does."""
    config = TrainConfig(env_id="CartPole-v1", total_timesteps=40_960, agent=AgentConfig(reservoirs=0),
                         ppo=dataclasses.replace(RLZOO, n_envs=8, n_steps=256))
    results = Trainer(config).run(Population.grid(Phi(1.0, 1.0, 1.0), 3, 3e-4, 0))
    _, curves = results.curves()
    mean = np.nanmean(curves, axis=0)
    assert mean[-1] > 5 * mean[0] and results.fitness().mean() > 150, (mean[[0, -1]], results.fitness())


@pytest.mark.reference
def test_outputs_and_init_match_sb3s_policy():
    """SB3's ActorCriticPolicy with rl-zoo's policy_kwargs: the same weights give the same means, values and log
    probabilities; fresh weights are drawn from the same distribution."""
    import gymnasium as gym
    import torch as th
    from stable_baselines3.common.policies import ActorCriticPolicy

    obs_space = gym.spaces.Box(-np.inf, np.inf, (40,), np.float32)
    act_space = gym.spaces.Box(-2.0, 2.0, (1,), np.float32)

    def sb3(seed):
        th.manual_seed(seed)
        return ActorCriticPolicy(obs_space, act_space, lambda _: 3e-4, net_arch=dict(pi=[64], vf=[64]),
                                 activation_fn=th.nn.ReLU, ortho_init=False)

    def dense(*linears):
        return {"params": {f"Dense_{i}": {"kernel": jnp.asarray(m.weight.detach().numpy().T),
                                          "bias": jnp.asarray(m.bias.detach().numpy())}
                           for i, m in enumerate(linears)}}

    theirs = sb3(0)
    with th.no_grad():
        theirs.log_std.fill_(-0.7)
    net = ActorCritic.of(BOX, RLZOO)
    params = net.init(jax.random.PRNGKey(0), 40)._replace(
        actor=dense(theirs.mlp_extractor.policy_net[0], theirs.action_net),
        critic=dense(theirs.mlp_extractor.value_net[0], theirs.value_net), log_std=jnp.full((1,), -0.7))
    rng = np.random.default_rng(1)
    obs, actions = rng.normal(size=(32, 40)).astype(np.float32), rng.normal(size=(32, 1)).astype(np.float32)
    with th.no_grad():
        values, log_prob, entropy = theirs.evaluate_actions(th.tensor(obs), th.tensor(actions))
        mean = theirs.get_distribution(th.tensor(obs)).distribution.mean
    head = net.head(params, jnp.asarray(obs))
    np.testing.assert_allclose(head, mean.numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(net.value(params, jnp.asarray(obs)), values.numpy()[:, 0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(net.log_prob(params, head, jnp.asarray(actions)), log_prob.numpy(), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(net.entropy(params, head), entropy.numpy(), rtol=1e-5, atol=1e-5)

    policies = [sb3(seed) for seed in range(200)]
    layers = {"actor hidden": lambda p: p.mlp_extractor.policy_net[0], "actor head": lambda p: p.action_net,
              "critic hidden": lambda p: p.mlp_extractor.value_net[0], "critic head": lambda p: p.value_net}
    ours = [net.init(jax.random.PRNGKey(k), 40) for k in range(200)]
    mine = {"actor hidden": lambda p: _layers(p.actor)[0], "actor head": lambda p: _layers(p.actor)[1],
            "critic hidden": lambda p: _layers(p.critic)[0], "critic head": lambda p: _layers(p.critic)[1]}
    for name, layer in layers.items():
        for i, attr in enumerate(("weight", "bias")):
            a = np.concatenate([getattr(layer(p), attr).detach().numpy().ravel() for p in policies])
            b = np.concatenate([mine[name](p)[i].ravel() for p in ours])
            bound = 1 / np.sqrt(40 if "hidden" in name else 64)  # torch's U(±1/√fan_in)
            assert np.abs(a).max() <= bound and np.abs(b).max() <= bound, (name, attr)
            assert a.std() == pytest.approx(bound / np.sqrt(3), rel=0.15), (name, attr)
            assert b.std() == pytest.approx(a.std(), rel=0.15), (name, attr)
