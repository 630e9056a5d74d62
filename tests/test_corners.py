"""The corners of the search space (sr ∈ {1e-4, 1e2}, lr ∈ {1e-2, 1}, iss ∈ {0.1, 10}) and what an evolution does
with results that are not numbers.

- every corner trains to a finite fitness on a JAX env (CartPoleNoVel-v1, through ``evolve`` with the corners
  enqueued, so that the tell path records them) and, as one population, on a host env (LunarLanderNoVel-v3,
  Gymnasium's Box2D);
- a real Gymnasium env that misbehaves (NaN rewards for some seeds, episodes longer than the budget for
  others) on the host backend: the worker keeps going, and each trial is told either a finite fitness or a
  failure with its reason (user attribute ``failure``);
- the float32 accuracy of the spectral-radius rescaling at 1000 units.
"""

from __future__ import annotations

import itertools

import gymnasium as gym
import jax.numpy as jnp
import numpy as np
import optuna
import pytest
from optuna.trial import TrialState

from ermrl import reservoir
from ermrl.agent import Phi
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.evolve import evolve, tell_batch
from ermrl.evolution.search_space import SearchSpace
from ermrl.reservoir import ReservoirSpec
from ermrl.training import Population, TrainConfig, Trainer

optuna.logging.set_verbosity(optuna.logging.WARNING)

SPACE = SearchSpace()
CORNERS = [dict(zip(("sr", "lr", "iss"), c)) for c in itertools.product(SPACE.sr, SPACE.lr, SPACE.iss)]
"""The 8 corners: (1e-4, 1e-2, 0.1), ..., (1e2, 1, 10)."""


def test_the_corners_are_the_search_space_bounds():
    assert (SPACE.sr, SPACE.lr, SPACE.iss) == ((1e-4, 1e2), (1e-2, 1.0), (0.1, 10.0)) and len(CORNERS) == 8


def test_a_reservoir_stays_finite_and_bounded_at_every_corner():
    """x ← (1−lr)x + lr·tanh(·) is a convex combination of values in [−1, 1]: at sr 100 and iss 10, with inputs
    far larger than any env's (N(0, 100²)), the state saturates but stays finite, in [−1, 1]."""
    spec = ReservoirSpec(units=100)
    unit = reservoir.generate(spec, seed=0, input_dim=6)
    inputs = jnp.asarray(np.random.default_rng(0).normal(scale=100.0, size=(500, 6)), jnp.float32)
    for c in CORNERS:
        states = np.asarray(reservoir.run(reservoir.scale(unit, jnp.float32(c["sr"]), jnp.float32(c["iss"])),
                                          jnp.float32(c["lr"]), inputs))
        assert np.isfinite(states).all() and np.abs(states).max() <= 1.0, c
        assert np.abs(states[-100:]).max() > 0.01, c  # not stuck at zero either


def test_every_corner_trains_to_a_finite_fitness_on_a_jax_env_through_evolve():
    """The 8 corners (enqueued, so taken in order), in four batches of 2 × 2 seeds (a population size that other
    tests compile too), on CartPoleNoVel-v1 at 2 iterations (the second rollout uses the updated policy): every trial
    is told a finite fitness."""
    config = EvolveConfig(train=TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=4096), space=SPACE,
                          trials=8, seeds=2, sampler="random", popsize=2)
    study = optuna.create_study(direction="maximize", sampler=optuna.samplers.RandomSampler(seed=0))
    for c in CORNERS:
        study.enqueue_trial(c)
    evolve(study, config)
    trials = study.get_trials(deepcopy=False)
    assert len(trials) == 8 and {t.state for t in trials} == {TrialState.COMPLETE}
    assert sorted(tuple(t.params[k] for k in ("sr", "lr", "iss")) for t in trials) == \
        sorted(tuple(c.values()) for c in CORNERS)
    for t in trials:
        assert np.isfinite(t.value) and "failure" not in t.user_attrs
        assert all(v is not None and np.isfinite(v) for v in t.user_attrs["seed_fitness"])
        assert t.value == pytest.approx(np.mean(t.user_attrs["seed_fitness"]))
        assert 9 <= t.value <= 500  # CartPole returns: at least 9 steps an episode, at most 500


def test_every_corner_trains_to_a_finite_fitness_on_a_host_env():
    """The 8 corners as one population on LunarLanderNoVel-v3 (Box2D, host backend), 2 iterations."""
    config = TrainConfig(env_id="LunarLanderNoVel-v3", total_timesteps=4096, backend="host")
    phis = [Phi(c["sr"], c["lr"], c["iss"]) for c in CORNERS]
    results = Trainer(config).run(Population.grid(phis, 1, config.ppo.learning_rate, 1))
    fitness = results.fitness()
    assert results.finite.all() and np.isfinite(fitness).all(), (results.finite, fitness)
    assert all(len(e.ret) >= 10 for e in results.episodes)  # the fitness averages 10 whole episodes
    assert ((fitness > -1000) & (fitness < 300)).all(), fitness  # LunarLander's returns


class FaultyEnv(gym.Env):
    """A real Gymnasium env with the faults an evolution meets: by the seed of its first reset, a third of the
    envs give NaN rewards (a simulator that blew up), a third never end an episode (longer than the budget),
    and the rest are fine (20-step episodes, reward 1 a step). Box observations (3,) and Box actions (1,), so
    that a diverged policy's NaN actions reach ``step`` through the host backend's guard."""

    metadata = {"render_modes": []}

    def __init__(self):
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.kind, self.t = None, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if self.kind is None:
            self.kind = ("nan", "endless", "fine")[int(seed) % 3]
        self.t = 0
        return self.np_random.uniform(-1, 1, 3).astype(np.float32), {}

    def step(self, action):
        assert np.isfinite(action).all()  # the host backend never passes NaN actions to an env
        self.t += 1
        reward = float("nan") if self.kind == "nan" else 1.0
        done = self.kind != "endless" and self.t >= 20
        return self.np_random.uniform(-1, 1, 3).astype(np.float32), reward, done, False, {}


FAULTY = "ErmrlTest/Faulty-v0"


def test_the_tell_path_records_a_reason_for_every_trial_that_is_not_a_number():
    """12 trials, one seed each (seed i for trial i, so that the faults differ between trials), trained as one
    population on the host backend, then told: finite fitness -> COMPLETE with that value; NaN parameters ->
    FAIL "diverged (NaN/inf) on 1 of 1 seeds"; no finished episode -> FAIL "no episode completed within the
    budget". Nothing stores a NaN, and the sampler asks on."""
    if FAULTY not in gym.registry:
        gym.register(FAULTY, entry_point=FaultyEnv)
    config = EvolveConfig(train=TrainConfig(env_id=FAULTY, total_timesteps=2048, backend="host", env_workers=0),
                          space=SPACE, trials=12, seeds=1, sampler="cmaes", popsize=12)
    study = optuna.create_study(direction="maximize",
                                sampler=optuna.samplers.CmaEsSampler(popsize=12, seed=0, warn_independent_sampling=False))
    trials = [study.ask() for _ in range(12)]
    phis = [SPACE.suggest(t) for t in trials]
    population = Population(seeds=np.arange(12), phi=Phi(*(np.stack(f) for f in zip(*phis))),
                            learning_rate=np.full(12, config.train.ppo.learning_rate, np.float32))
    results = Trainer(config.train).run(population)
    done, failed = tell_batch(study, trials, {FAULTY: results}, config)

    fitness = results.fitness()
    outcomes = []
    for i, t in enumerate(study.get_trials(deepcopy=False)):
        if not results.finite[i]:
            assert (t.state, t.user_attrs["failure"]) == (TrialState.FAIL, "diverged (NaN/inf) on 1 of 1 seeds")
            assert t.user_attrs["seed_fitness"] == [None]
            outcomes.append("diverged")
        elif len(results.episodes[i].ret) == 0:
            assert (t.state, t.user_attrs["failure"]) == (TrialState.FAIL, "no episode completed within the budget")
            assert t.user_attrs["seed_fitness"] == [None]
            outcomes.append("no episode")
        else:
            assert t.state == TrialState.COMPLETE and "failure" not in t.user_attrs
            assert t.value == pytest.approx(fitness[i]) == 20.0
            outcomes.append("complete")
        assert all(v is None or np.isfinite(v) for v in t.user_attrs["curve_final"])
    assert sorted(set(outcomes)) == ["complete", "diverged", "no episode"], outcomes
    assert (done, failed) == (outcomes.count("complete"), 12 - outcomes.count("complete"))
    next_trial = study.ask()  # CMA-ES takes the failed trials in its stride
    assert set(SPACE.suggest(next_trial)._asdict()) == {"sr", "lr", "iss"}


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)])
def test_the_spectral_radius_of_1000_units_is_sr_to_float32_precision(seed):
    """``generate`` normalizes W to radius 1 in float64 and stores it in float32; ``scale`` multiplies by sr in
    float32 inside JAX. The radius of the matrix the agent uses, computed in float64, is sr to within 2^-23
    (float32's machine epsilon, 1.2e-7) relative. Why that tolerance: float32 cannot hold sr itself closer
    than 2^-24 relative (float32(1e-4) is 2.5e-8 off), and the ~10^5 roundings of W's entries (cast, then
    product), of random sign, move the dominant eigenvalue by first-order perturbation |yᴴ δW x| / |yᴴ x|,
    about 2^-24 · cond(λ) · ‖W‖_F / N ≈ 1e-8 here (cond(λ) 3 to 11). Measured: at most 2.7e-8."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as sla

    unit = reservoir.generate(ReservoirSpec(units=1000), seed, input_dim=5)
    errors = []
    for sr in (1e-4, 1e-2, 0.95, 1.0, 10.0, 100.0):
        W = np.asarray(reservoir.scale(unit, jnp.float32(sr), jnp.float32(1.0)).W)
        assert W.dtype == np.float32 and W.shape == (1000, 1000)
        # ARPACK's largest-modulus eigenvalues, to machine precision; 20 of them, with 100 Lanczos vectors,
        # so that the dominant pair is found where other eigenvalues come within 3e-4 of its modulus
        values = sla.eigs(sp.csr_matrix(W.astype(np.float64)), k=20, ncv=100, which="LM", tol=0,
                          return_eigenvectors=False)
        errors.append(abs(np.abs(values).max() - sr) / sr)
    assert max(errors) <= 2.0 ** -23, errors
    if seed == 0:  # ARPACK agrees with the dense eigenvalues
        W = np.asarray(reservoir.scale(unit, jnp.float32(100.0), jnp.float32(1.0)).W).astype(np.float64)
        assert abs(np.abs(np.linalg.eigvals(W)).max() - 100.0) / 100.0 == pytest.approx(errors[-1], abs=1e-12)
