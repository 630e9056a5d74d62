"""Saved agents: training keeps each agent's final policy, the files reload, and a loaded agent acts as the
training-time JAX code (Agent.observe + ActorCritic) does on the same inputs."""

import dataclasses
import json
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import optuna
import pytest
from optuna.distributions import FloatDistribution
from optuna.trial import create_trial

import ermrl
from ermrl.evolution.record import decode_study_record, encode_study_record
from ermrl import agent_files, envs, storage
from ermrl.agent import Agent, AgentConfig, Phi
from ermrl.errors import ConfigError
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.search_space import SearchSpace
from ermrl.ppo.config import SB3_DEFAULTS
from ermrl.ppo.networks import ActorCritic, PolicyParams
from ermrl.reservoir import ReservoirSpec
from ermrl.training import Population, TrainConfig, Trainer
from ermrl.training.results import Episodes, Policies, Results

CASES = {
    "CartPoleNoVel-v1": (AgentConfig(reservoirs=1), [0, 1], SB3_DEFAULTS),  # the test phase compiles the same
    "PendulumNoVel-v1": (AgentConfig(reservoirs=2, spec=ReservoirSpec(units=40), skip_connection=True,
                                     observed_units=30), [7], SB3_DEFAULTS),
    "PendulumNoVel-v1 relu": (AgentConfig(reservoirs=1, spec=ReservoirSpec(units=40)), [2],  # rl-zoo's policy
                              dataclasses.replace(SB3_DEFAULTS, hidden=(64,), activation="relu", ortho_init=False)),
}
"""{label: (agent, seeds, PPO settings)}; a label is the env id, then perhaps a word."""


def write_untrained_agent(folder, env_id, agent=AgentConfig(), seed=0, phi=Phi(0.95, 0.5, 1.0)):
    """A saved agent with freshly initialized policy parameters (no training): folder/agents/seedS.npz."""
    config = TrainConfig(env_id=env_id, agent=agent)
    info = envs.describe(env_id)
    net = ActorCritic(info.action, config.ppo.hidden, config.ppo.log_std_init)
    params = jax.device_get(net.init(jax.random.PRNGKey(seed), Agent(agent, info).context_dim))
    pop = Population.grid(phi, [seed], 3e-4, max(agent.reservoirs, 1))
    empty = Episodes(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64))
    phis = {f: np.asarray(v) for f, v in pop.phi._asdict().items()}
    policies = Policies.from_params(info, jax.tree.map(lambda x: np.asarray(x)[None], params), 1)
    results = Results(env_id, 0, config.ppo.buffer_size, pop.seeds, phis, pop.learning_rate, [empty], np.ones(1, bool),
                      {}, 0.0, 0.0, policies)
    return agent_files.write_agents(folder / "agents", config, results, "untrained")[0]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """{label: (config, results, saved paths, final params of a replayed training)} at 2048 steps."""
    out = {}
    for label, (agent, seeds, ppo) in CASES.items():
        env_id = label.split()[0]
        config = TrainConfig(env_id=env_id, total_timesteps=2048, agent=agent, ppo=ppo)
        population = Population.grid(Phi(0.9, 0.4, 1.2), seeds, 3e-4, agent.reservoirs)
        trainer = Trainer(config)
        results = trainer.run(population)
        state = trainer.init(population)  # the same training again, by hand, to compare the final params
        for _ in range(trainer.n_iterations):
            state, _ = trainer.step(state)
        folder = tmp_path_factory.mktemp(env_id) / "agents"
        out[label] = (config, results, agent_files.write_agents(folder, config, results, "ER-MRL"),
                      jax.device_get(state.learner.params))
    return out


@pytest.mark.parametrize("label", CASES)
def test_results_carry_the_final_policies_without_padding(trained, label):
    config, results, _, final = trained[label]
    n = len(CASES[label][1])
    policies = results.policies
    leaves = jax.tree.leaves((policies.actor, policies.critic, policies.log_std))
    assert all(x.shape[0] == n and isinstance(x, np.ndarray) for x in leaves)  # padded agents dropped
    for mine, ref in zip(leaves, jax.tree.leaves((final.actor, final.critic, final.log_std))):
        np.testing.assert_array_equal(mine, np.asarray(ref)[:n])
    assert (policies.log_std is None) == policies.env.action.discrete
    part = results.select([n - 1])
    assert part.policies.actor["params"]["Dense_0"]["kernel"].shape[0] == 1


def _jax_reference(config, results, i, obs, actions, rewards):
    """Contexts (T, N) and policy heads (T, A) that the training-time JAX code computes for one episode."""
    info = results.policies.env
    agent = Agent(config.agent, info)
    net = ActorCritic.of(info.action, config.ppo)
    take = lambda tree: jax.tree.map(lambda x: jnp.asarray(x[i]), tree)
    log_std = None if results.policies.log_std is None else jnp.asarray(results.policies.log_std[i])
    params = PolicyParams(take(results.policies.actor), take(results.policies.critic), log_std)
    phi = Phi(*(jnp.asarray(results.phi[f][i]) for f in Phi._fields))
    res = Agent.build(agent.unit_weights(int(results.seeds[i])), phi)
    start = jax.jit(lambda o: agent.start_episode(res, o))
    step = jax.jit(lambda s, o, a, r: agent.observe(res, s, o, agent.encode_action(a), r))
    head = jax.jit(lambda c: net.head(params, c))
    state, context = start(jnp.asarray(obs[0]))
    contexts, heads = [context], [head(context)]
    for t in range(1, len(obs)):
        state, context = step(state, jnp.asarray(obs[t]), jnp.asarray(actions[t - 1]), jnp.float32(rewards[t - 1]))
        contexts.append(context)
        heads.append(head(context))
    return np.stack(contexts), np.stack(heads)


@pytest.mark.parametrize("label", CASES)
def test_a_loaded_agent_acts_as_the_training_code(trained, label):
    config, results, paths, _ = trained[label]
    i = len(paths) - 1
    agent = ermrl.load_agent(paths[i], sampling_seed=3)
    assert agent.seed == int(results.seeds[i]) and agent.context_dim == Agent(config.agent, agent.env).context_dim
    env = agent.make_env()
    obs_, _ = env.reset(seed=5)
    agent.reset()
    obs, actions, rewards, contexts, heads = [], [], [], [], []
    reward, done = None, False
    while not done and len(obs) < 120:
        action = agent.act(obs_, reward, deterministic=len(obs) % 2 == 0)  # both modes
        obs.append(obs_), actions.append(action), contexts.append(agent.context), heads.append(agent.head)
        obs_, reward, terminated, truncated, _ = env.step(action)
        rewards.append(reward)
        done = terminated or truncated
    ref_context, ref_head = _jax_reference(config, results, i, obs, actions, rewards)
    np.testing.assert_allclose(np.stack(contexts), ref_context, atol=1e-5)
    if agent.env.action.discrete:
        probs = lambda h: np.exp(h - h.max(-1, keepdims=True)) / np.exp(h - h.max(-1, keepdims=True)).sum(-1)[:, None]
        np.testing.assert_allclose(probs(np.stack(heads)), probs(ref_head), atol=1e-5)
        assert all(a == np.argmax(h) for a, h in zip(actions[::2], ref_head[::2]))
    else:
        np.testing.assert_allclose(np.stack(heads), ref_head, atol=1e-5)
        low, high = env.action_space.low, env.action_space.high
        np.testing.assert_allclose(actions[::2], np.clip(ref_head[::2], low, high), atol=1e-5)
        assert all(np.all((a >= low) & (a <= high)) for a in actions)
        np.testing.assert_allclose(agent.std, np.exp(results.policies.log_std[i]))
    assert len(obs) > 10 and np.asarray(obs).shape[1] == agent.env.obs_dim


def test_every_saved_file_is_complete_and_reloads(trained):
    for label, (config, results, paths, _) in trained.items():
        folder = paths[0].parent
        assert sorted(p.name for p in folder.iterdir()) == sorted(f"seed{s}.npz" for s in results.seeds)
        for path, seed in zip(paths, results.seeds):
            agent = ermrl.load_agent(path)
            meta = agent.meta
            assert (meta["env_id"], meta["seed"], meta["model"]) == (label.split()[0], seed, "ER-MRL")
            assert meta["ermrl_version"] == ermrl.__version__ and meta["learning_rate"] == pytest.approx(3e-4)
            assert meta["phi"]["sr"] == [pytest.approx(0.9)] * max(config.agent.reservoirs, 1)
            assert storage.from_dict(TrainConfig, meta["train"]) == config
            assert agent.activation == config.ppo.activation
            assert path.stat().st_size < 200_000
    first = ermrl.load_agent(paths[0].parent.parent)  # a run folder gives its first agent
    assert first.path == paths[0]


def test_missing_or_damaged_agent_files_are_one_line_config_errors(trained, tmp_path):
    good = trained["CartPoleNoVel-v1"][2][0]
    (tmp_path / "agents").mkdir()
    cut = tmp_path / "agents" / "cut.npz"
    cut.write_bytes(good.read_bytes()[:5000])
    (tmp_path / "junk.npz").write_bytes(b"not a zip file")
    np.savez(tmp_path / "plain.npz", x=np.zeros(3))
    for path, message in [(tmp_path / "missing.npz", "does not exist"), (cut, "is not a readable ermrl agent file"),
                          (tmp_path / "junk.npz", "is not a readable ermrl agent file"),
                          (tmp_path / "plain.npz", "is not a readable ermrl agent file"),
                          (tmp_path / "empty", "has no saved agents")]:
        if path.name == "empty":
            path.mkdir()
        with pytest.raises(ConfigError, match=message) as e:
            ermrl.load_agent(path)
        assert "\n" not in str(e.value)


def test_act_checks_its_inputs(trained):
    agent = ermrl.load_agent(trained["CartPoleNoVel-v1"][2][0])
    with pytest.raises(ConfigError, match=r"expects observations of 2 dims \(dims \[0, 2\] of CartPole-v1\)"):
        agent.act(np.zeros(4))
    agent.act(np.zeros(2))
    with pytest.raises(ConfigError, match="needs the reward of the previous step"):
        agent.act(np.zeros(2))
    agent.reset()
    assert isinstance(agent.act(np.zeros(2)), int) and agent.probabilities.shape == (2,)
    assert agent.make_env().observation_space.shape == (2,)


def test_load_agent_is_imported_lazily():
    code = ("import sys, ermrl; assert 'ermrl.saved_agent' not in sys.modules and 'gymnasium' not in sys.modules; "
            "f = ermrl.load_agent; assert f.__module__ == 'ermrl.saved_agent'")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


def test_the_test_phase_saves_every_model_agents(tmp_path):
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    config = EvolveConfig(train=TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=2048),
                          space=SearchSpace(fixed_iss=1.0), trials=1, seeds=1)
    study = optuna.create_study(direction="maximize")
    study.set_user_attr("ermrl", encode_study_record(config))
    dists = {"sr": FloatDistribution(0.01, 10, log=True), "lr": FloatDistribution(0.01, 1, log=True)}
    study.add_trial(create_trial(params={"sr": 0.9, "lr": 0.4}, distributions=dists, value=1.0))
    from ermrl.experiments.evaluation import TestConfig, run_test_phase

    run_test_phase(study, tmp_path, TestConfig(seeds=1, timesteps=2048, learning_rates=(3e-4, 1e-4)))
    found = [p.relative_to(tmp_path).as_posix() for p in agent_files.find_agents(tmp_path)]
    assert found == ["agents/ermrl-learning-rate-0.0001/seed1000.npz", "agents/ermrl-learning-rate-0.0003/seed1000.npz",
                     "agents/ppo/seed1000.npz", "agents/ppo-full-observation/seed1000.npz"]
    # one model's folder, as `ermrl analyze fft test/agents/ermrl test/agents/ppo` gives them
    assert agent_files.find_agents(tmp_path / "agents" / "ppo") == [tmp_path / found[2]]
    slow = ermrl.load_agent(tmp_path / found[0])
    assert slow.learning_rate == pytest.approx(1e-4) and slow.phi.sr.tolist() == [pytest.approx(0.9)]
    full = ermrl.load_agent(tmp_path / found[3])
    assert (full.env_id, full.config.reservoirs, full.meta["model"]) == ("CartPole-v1", 0, "PPO (full observation)")
    obs, _ = full.make_env().reset(seed=0)
    full.act(obs)
    np.testing.assert_array_equal(full.context, obs)  # plain PPO sees the observation
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert len(summary) == 4


def test_config_files_set_save_agents(tmp_path):
    from ermrl.cli import parse

    toml = tmp_path / "c.toml"
    toml.write_text("save-agents = false\n")
    assert parse(["train", "--config", str(toml)]).save_agents is False
    assert parse(["train"]).save_agents is True and parse(["train", "--no-save-agents"]).save_agents is False
    toml.write_text("save-agents = 1\n")
    with pytest.raises(ConfigError, match="save-agents must be true or false"):
        parse(["train", "--config", str(toml)])


def test_untrained_agents_save_too(tmp_path):
    path = write_untrained_agent(tmp_path, "CartPoleNoVel-v1", seed=4)
    agent = ermrl.load_agent(tmp_path)
    assert agent.path == path and agent.seed == 4 and "seed 4" in repr(agent)
    assert dataclasses.asdict(agent.config) == dataclasses.asdict(AgentConfig())
