"""Several studies evolved together (``evolve_together``), one population per env: studies of one training shape,
and studies that share one env (generalization groups). Each study's trials are those it gets alone, trial by
trial, on the JAX and the MuJoCo backends, and a kill during a joint generation resumes every study."""

import dataclasses
import os
import re
import signal
import subprocess
import sys
import textwrap
import time

import optuna
import pytest
from optuna.trial import TrialState

from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.convergence import Convergence
from ermrl.evolution.evolve import Member, evolve, evolve_together, make_trainers, shared_envs
from ermrl.evolution.scoring import Baseline
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import make_sampler, open_study
from ermrl.evolution.record import encode_study_record
from ermrl.evolution.worker_config import WorkerConfig
from ermrl.ppo.config import SB3_DEFAULTS, PPOConfig
from ermrl.training import TrainConfig

optuna.logging.set_verbosity(optuna.logging.WARNING)


def _configs(env_id: str, timesteps: int, backend: str = "auto", ppo: PPOConfig = SB3_DEFAULTS) -> list[EvolveConfig]:
    """Two studies of one shape that differ in what they search: another sampler seed, and iss searched or fixed."""
    train = TrainConfig(env_id=env_id, total_timesteps=timesteps, backend=backend, ppo=ppo)
    a = EvolveConfig(train=train, space=SearchSpace(fixed_iss=1.0), trials=6, seeds=2, popsize=2, sampler_seed=0)
    return [a, dataclasses.replace(a, space=SearchSpace(), sampler_seed=1)]


def _open(folder, name: str, config: EvolveConfig) -> optuna.Study:
    return open_study(f"sqlite:///{folder}/{name}.db", name, make_sampler("cmaes", 2, config.sampler_seed),
                      encode_study_record(config))


def _trials(study: optuna.Study) -> list[tuple]:
    return [(t.number, t.state, t.params, t.value, t.user_attrs["generation"], t.user_attrs["seeds"],
             t.user_attrs["seed_fitness"]) for t in study.trials]


@pytest.mark.parametrize("env_id, timesteps, backend, ppo", [
    ("CartPoleNoVel-v1", 2048, "auto", SB3_DEFAULTS),
    # two updates of 512 steps: an agent's update and its orthogonal init do not see the others; one 1000-step
    # episode for a fitness (MuJoCo's physics, not the compile, is the cost here, so the rollouts are short)
    ("Swimmer-v5", 1024, "mujoco", dataclasses.replace(SB3_DEFAULTS, n_steps=512)),
])
def test_studies_trained_as_one_population_get_the_trials_they_get_alone(env_id, timesteps, backend, ppo, tmp_path):
    configs = _configs(env_id, timesteps, backend, ppo)
    alone = []
    for k, config in enumerate(configs):
        study = _open(tmp_path, f"alone{k}", config)
        evolve(study, config)
        alone.append(_trials(study))
    together = [_open(tmp_path, f"together{k}", config) for k, config in enumerate(configs)]
    evolve_together([Member(study, config) for study, config in zip(together, configs)])
    for study, expected in zip(together, alone):
        assert _trials(study) == expected
    assert [len(t) for t in alone] == [6, 6] and all(t[1] == TrialState.COMPLETE for t in alone[0] + alone[1])
    assert {t[4] for t in alone[0]} == {0, 1, 2}  # the random startup and two CMA-ES generations


def test_studies_evolved_together_log_their_spread_under_their_names(tmp_path):
    """Each study's worker logs its own lines (`--until-converged`'s spread per generation), led by its name."""
    configs = [dataclasses.replace(c, trials=8) for c in _configs("CartPoleNoVel-v1", 2048)]
    lines = []
    evolve_together([Member(_open(tmp_path, f"s{k}", c), c, WorkerConfig(until_converged=Convergence()))
                     for k, c in enumerate(configs)], log=lines.append)
    assert [line.split(":")[0] for line in lines if re.match(r"s\d: generation 2: widest spread", line)] == ["s0", "s1"]


def _overlapping() -> list[EvolveConfig]:
    """Two normalized (nScore) studies, as two generalization groups, that share one env (CartPole-v1) and each
    evolve on one env of their own."""
    base = EvolveConfig(train=TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=2048), space=SearchSpace(),
                        trials=6, seeds=2, popsize=2, envs=("CartPoleNoVel-v1", "CartPole-v1"),
                        baselines=(Baseline("CartPoleNoVel-v1", 20.0, 1.0, 40.0),
                                   Baseline("CartPole-v1", 20.0, 1.0, 60.0)))
    other = dataclasses.replace(base, train=dataclasses.replace(base.train, env_id="CartPole-v1"), sampler_seed=1,
                                envs=("CartPole-v1", "PendulumNoVel-v1"),
                                baselines=(base.baselines[1], Baseline("PendulumNoVel-v1", -1200.0, -6.0, -900.0)))
    return [base, other]


def test_studies_that_share_one_env_train_it_as_one_population_and_get_the_trials_they_get_alone(tmp_path):
    configs = _overlapping()
    assert [shared_envs(configs[0], c) for c in configs] == [("CartPoleNoVel-v1", "CartPole-v1"), ("CartPole-v1",)]
    alone = []
    for k, config in enumerate(configs):
        study = _open(tmp_path, f"alone{k}", config)
        evolve(study, config)
        alone.append(_trials(study) + [t.user_attrs["env_nscores"] for t in study.trials])
    trainers = make_trainers(*configs)
    sizes = {e: [] for e in trainers}
    for env_id, trainer in trainers.items():  # a spy on the real trainers: the population each round trains
        real = trainer.run
        trainer.run = lambda population, report, real=real, env_id=env_id, **kwargs: (
            sizes[env_id].append(population.size) or real(population, report, **kwargs))
    together = [_open(tmp_path, f"together{k}", config) for k, config in enumerate(configs)]
    evolve_together([Member(study, config) for study, config in zip(together, configs)], trainers)
    for study, expected in zip(together, alone):
        assert _trials(study) + [t.user_attrs["env_nscores"] for t in study.trials] == expected
    # 3 generations of 2 trials × 2 seeds each: the shared env trains both studies' 8 agents at once
    assert sizes == {"CartPoleNoVel-v1": [4, 4, 4], "CartPole-v1": [8, 8, 8], "PendulumNoVel-v1": [4, 4, 4]}
    assert all(t[1] == TrialState.COMPLETE for t in alone[0][:6] + alone[1][:6])


def test_studies_that_train_a_shared_env_differently_are_refused(tmp_path):
    a, b = _configs("CartPoleNoVel-v1", 2048)
    b = dataclasses.replace(b, train=dataclasses.replace(b.train, total_timesteps=4096))
    assert shared_envs(a, b) == ()
    with pytest.raises(ValueError, match="^studies trained together must train each env they share alike; "
                                         "CartPoleNoVel-v1 differs$"):
        evolve_together([Member(_open(tmp_path, "a", a), a), Member(_open(tmp_path, "b", b), b)])


SCRIPT = textwrap.dedent("""
    import sys
    sys.path.insert(0, {tests!r})
    from test_joint_evolution import _configs, _open
    from ermrl.evolution.evolve import Member, evolve_together
    configs = _configs("CartPoleNoVel-v1", 16384)  # a generation of a few seconds: time to kill it
    configs = [c.__class__(**{{**c.__dict__, "trials": 8}}) for c in configs]
    evolve_together([Member(_open({folder!r}, f"s{{k}}", c), c) for k, c in enumerate(configs)])
""")


def test_a_kill_during_a_joint_generation_resumes_every_study(tmp_path):
    """SIGKILL while both studies have trials of one joint population running: the rerun fails those trials as
    interrupted (their process is gone), trains their generation again, and both studies reach their 8 trials,
    every generation with its 2 completed trials."""
    script = SCRIPT.format(tests=os.path.dirname(__file__), folder=str(tmp_path))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    run = subprocess.Popen([sys.executable, "-c", script], env=env, stderr=subprocess.PIPE)
    deadline = time.time() + 240
    try:
        while time.time() < deadline:
            time.sleep(0.3)
            assert run.poll() is None, run.stderr.read().decode()
            states = []
            for k in range(2):
                if not (tmp_path / f"s{k}.db").exists():
                    break
                try:  # read-only: a plain URL would create the tables the writer is creating ("already exists")
                    trials = optuna.load_study(study_name=f"s{k}",
                                               storage=f"sqlite:///file:{tmp_path}/s{k}.db?mode=ro&uri=true").trials
                except Exception:  # not created yet, or locked by the writer
                    break
                states.append([t.user_attrs.get("generation") for t in trials if t.state == TrialState.RUNNING])
            # every running trial sampled and placed (a kill between asking a trial and recording its generation
            # leaves it without one), all of one joint generation past the random startup
            joint = {g for s in states for g in s}
            if len(states) == 2 and all(states) and len(joint) == 1 and None not in joint and min(joint) >= 1:
                break
        else:
            pytest.fail("the joint generation never started")
        killed_generation = states[0][0]
        run.send_signal(signal.SIGKILL)
        run.wait(30)
    finally:
        if run.poll() is None:
            run.kill()
    subprocess.run([sys.executable, "-c", script], env=env, check=True, timeout=600)
    for k in range(2):
        trials = optuna.load_study(study_name=f"s{k}", storage=f"sqlite:///{tmp_path}/s{k}.db").trials
        complete = [t for t in trials if t.state == TrialState.COMPLETE]
        failed = [t for t in trials if t.state == TrialState.FAIL]
        assert len(complete) == 8
        assert failed and all(t.user_attrs["failure"] == "interrupted" for t in failed)
        assert {t.user_attrs["generation"] for t in failed} == {killed_generation}
        per_generation = [sum(t.user_attrs["generation"] == g for t in complete) for g in range(4)]
        assert per_generation == [2, 2, 2, 2]
