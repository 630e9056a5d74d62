"""The baseline store (--baseline-store): a second test phase with another Φ* loads the PPO baselines the first
one trained, and gets the results it would have trained, bit for bit. Real training on CartPoleNoVel (JAX)."""

import dataclasses
import json

import jax
import numpy as np
import optuna

from ermrl.evolution.record import decode_study_record, encode_study_record
from ermrl import storage
from ermrl.cli import main
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import ATTR, make_storage
from ermrl.experiments import baseline_models, checkpoints, evaluation
from ermrl.training import TrainConfig

optuna.logging.set_verbosity(optuna.logging.WARNING)
ENV = "CartPoleNoVel-v1"


def two_trial_study(journal):
    """A study in a journal file with two finished trials of different Φ, as `ermrl evolve` records them."""
    space = SearchSpace(1, fixed_iss=1.0)
    config = EvolveConfig(train=TrainConfig(env_id=ENV, total_timesteps=2048), space=space, trials=2, seeds=1)
    study = optuna.create_study(storage=make_storage(str(journal)), study_name="tiny", direction="maximize")
    study.set_user_attr(ATTR, encode_study_record(config))
    for params, value in (({"sr": 0.95, "lr": 0.5}, 20.0), ({"sr": 0.2, "lr": 0.9}, 10.0)):
        study.add_trial(optuna.trial.create_trial(params=params, distributions=space.distributions(), value=value))
    return study


def rows_by_model(rows):
    return {r["model"].split(" (sr")[0]: r["per_seed"] for r in rows}


def test_a_second_test_phase_reuses_the_stored_ppo_baselines_and_retrains_a_damaged_one(tmp_path, capsys):
    journal, store = tmp_path / "studies.log", tmp_path / "store"
    study = two_trial_study(journal)
    test = evaluation.TestConfig(seeds=2, timesteps=2048)
    first = evaluation.run_test_phase(study, tmp_path / "a" / "test", test, baseline_store=store)
    kept = sorted(p.relative_to(store).as_posix() for p in store.rglob("*.npz"))
    assert [k.rsplit("-", 1)[0] for k in kept] == ["CartPole-v1/ppo-full-observation", f"{ENV}/ppo"]  # no ER-MRL
    full, same = (store / k for k in kept)
    full_bytes = full.read_bytes()
    same.write_bytes(same.read_bytes()[:1000])  # damaged: trained again and replaced

    args = ["test", "--study", "tiny", "--storage", str(journal), "--out", str(tmp_path / "b"), "--seeds", "2",
            "--timesteps", "2048", "--trial", "1", "--baseline-store", str(store), "--quiet"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert f"reused PPO (full observation) from the baseline store ({full})\n" in out
    assert "reused PPO (same observation)" not in out
    second = json.loads((tmp_path / "b" / "test" / "summary.json").read_text())
    assert [r["phi_trial"] for r in second] == [1, 1, 1] and [r["phi_trial"] for r in first] == [0, 0, 0]
    ours, theirs = rows_by_model(second), rows_by_model(first)
    assert ours["PPO (same observation)"] == theirs["PPO (same observation)"]  # retrained: deterministic
    assert ours["PPO (full observation)"] == theirs["PPO (full observation)"]  # reused
    assert [r["model"] for r in (first[0], second[0])] == [
        "ER-MRL (learning rate 0.0003; sr 0.95, leak rate 0.5, iss 1)",
        "ER-MRL (learning rate 0.0003; sr 0.2, leak rate 0.9, iss 1)"]  # another Φ
    assert full.read_bytes() == full_bytes  # a hit leaves the file as it was
    identity, results = checkpoints.read_job(same)  # replaced by the retrained model, readable again
    assert results.fitness().tolist() == theirs["PPO (same observation)"]
    assert baseline_models.path_for(store, {**identity, "seeds": [1000, 1001, 1002]}) != same
    for model in ("ppo", "ppo-full-observation"):
        for seed in (1000, 1001):
            a, b = (tmp_path / r / "test" / "agents" / model / f"seed{seed}.npz" for r in ("a", "b"))
            with np.load(a) as x, np.load(b) as y:
                assert x.files == y.files and all(np.array_equal(x[k], y[k]) for k in x.files), (model, seed)

    # a baseline trained under other versions is still reused, and the log says which versions differ
    with np.load(full) as data:
        flat = {k: data[k] for k in data.files}
    meta = json.loads(str(flat.pop("meta")))
    assert meta["software"]["jax"] == jax.__version__
    meta["software"]["jax"] = "0.4.0"
    with open(full, "wb") as f:
        np.savez(f, meta=np.array(json.dumps(meta)), **flat)
    assert main([*args[:6], str(tmp_path / "c"), *args[7:]]) == 0
    assert (f"reused PPO (full observation) from the baseline store ({full}); it was trained with other versions "
            f"(jax 0.4.0 → {jax.__version__}), so it is not bit for bit what this machine would train\n"
            in capsys.readouterr().out)


def test_studies_evolved_at_other_rates_share_the_baselines_of_one_ppo_rate(tmp_path):
    """The baselines train at the test's PPO rate (the population's traced rate), so their place in the store must
    not depend on the rate the study was evolved at; it did, and a study evolved at 1e-4 trained again the PPO
    baselines that one evolved at 3e-4 had stored for the same seeds and budget."""
    def config(lr):
        train = TrainConfig(env_id=ENV, total_timesteps=2048)
        train = dataclasses.replace(train, ppo=dataclasses.replace(train.ppo, learning_rate=lr))
        return EvolveConfig(train=train, space=SearchSpace(1, fixed_iss=1.0), trials=2, seeds=1)

    store = tmp_path / "store"
    test = evaluation.TestConfig(seeds=2, timesteps=2048, baseline_learning_rate=3e-4)
    at_1e4, at_3e4 = (evaluation.baseline_files(config(lr), test, store) for lr in (1e-4, 3e-4))
    assert at_1e4 == at_3e4 and len(at_1e4) == 2
    for _, _, train, population, _ in evaluation.baseline_jobs(config(1e-4).train, [1000, 1001], 3e-4, True):
        assert train.ppo.learning_rate == 3e-4 and np.allclose(population.learning_rate, 3e-4)
    # without --baseline-learning-rate the baselines train at each study's own rate, so they are kept apart
    own = evaluation.TestConfig(seeds=2, timesteps=2048)
    assert evaluation.baseline_files(config(1e-4), own, store) != evaluation.baseline_files(config(3e-4), own, store)
