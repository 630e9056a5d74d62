"""`ermrl experiment run`'s test budgets (--test-seeds, --test-timesteps, --test-learning-rates, also from --config)
and a
test phase that resumes model by model, on the smoke study of CartPoleNoVel that conftest's ``evolved`` evolves
once per session (smoke_study.py)."""

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import optuna
import pytest
from optuna.trial import TrialState

from ermrl.cli import main
from ermrl.evolution.study import load_study
from ermrl.experiments import checkpoints, registry, runner
from ermrl.experiments import evaluation
from cli_runs import ermrl
from smoke_study import BUDGET, EXPERIMENT, RUN, STUDY, cli

optuna.logging.set_verbosity(optuna.logging.WARNING)


def run_in_process(folder, log, progress=None, budget=BUDGET):
    return runner.run_experiment(registry.get(EXPERIMENT), registry.get_scale("smoke"), folder, only=(STUDY,),
                                 log=log, progress=progress, budget=budget)


def trials(folder):
    study = load_study(runner.default_storage(folder), f"{EXPERIMENT}-smoke-{STUDY}")
    return [(t.number, t.state, t.value, t.datetime_complete) for t in study.trials], study.user_attrs["selection"]


@pytest.fixture(scope="module")
def interrupted(evolved, tmp_path_factory):
    """A copy of ``evolved`` without its test phase, whose rerun was stopped (Ctrl-C) as the test phase's second
    model (PPO) started, after the first (ER-MRL at both learning rates) had finished."""
    folder = tmp_path_factory.mktemp("interrupted") / "run"
    shutil.copytree(evolved, folder)
    shutil.rmtree(folder / STUDY / "test")
    started = []

    def progress(label):
        started.append(label)
        if label.startswith("PPO"):
            raise KeyboardInterrupt
        return None

    with pytest.raises(KeyboardInterrupt):
        run_in_process(folder, lambda s: None, progress)
    assert started[-2:] == ["ER-MRL", "PPO (same observation)"]
    assert not (folder / STUDY / "test").exists()
    assert sorted(p.name for p in (folder / STUDY / "test.partial").iterdir()) == ["ermrl.npz", "settings.json"]
    return folder


def test_budget_flags_reach_the_test_phase_and_a_rerun_with_others_redoes_only_the_test(evolved, interrupted,
                                                                                       tmp_path):
    config = json.loads((evolved / STUDY / "test" / "test_config.json").read_text())
    assert (config["seeds"], config["timesteps"], config["learning_rates"], config["auc_steps"]) == (
        2, 4096, [1e-4, 3e-4], 4096)
    rows = json.loads((evolved / STUDY / "test" / "summary.json").read_text())
    assert [(r["model"].split("; ")[0], r["n_seeds"], r["timesteps"]) for r in rows] == [
        ("ER-MRL (learning rate 0.0001", 2, 4096), ("ER-MRL (learning rate 0.0003", 2, 4096),
        ("PPO (same observation)", 2, 4096), ("PPO (full observation)", 2, 4096)]
    record = load_study(runner.default_storage(evolved), f"{EXPERIMENT}-smoke-{STUDY}").user_attrs["ermrl"]
    assert (record["seeds"], record["train"]["total_timesteps"]) == (1, 2048)  # the study's own budget, untouched

    # the stopped run's rerun with 1 test seed, given in a config file: the evolution and selection are kept, the
    # finished model (trained for 2 seeds) is discarded, and the test phase is written for 1 seed (populations of at
    # most 2 agents, whose programs other tests compile too)
    folder = tmp_path / "run"
    shutil.copytree(interrupted, folder)
    before = trials(folder)
    toml = tmp_path / "budgets.toml"
    toml.write_text("test-seeds = 1\ntest-timesteps = 4096\ntest-learning-rates = [1e-4, 3e-4]\n")
    r = cli(*RUN, "--out", str(folder), "--config", str(toml))
    assert r.returncode == 0, r.stderr
    assert "test on CartPoleNoVel-v1: 1 seeds × 4,096 steps, ER-MRL at learning rates 0.0001, 0.0003" in r.stdout
    assert "test on CartPoleNoVel-v1: discarded the models of an unfinished test phase with other settings" in r.stdout
    assert "from an earlier run" not in r.stdout
    assert trials(folder) == before
    config = json.loads((folder / STUDY / "test" / "test_config.json").read_text())
    assert (config["seeds"], config["timesteps"], config["learning_rates"]) == (1, 4096, [1e-4, 3e-4])
    assert [r["n_seeds"] for r in json.loads((folder / STUDY / "test" / "summary.json").read_text())] == [1] * 4
    assert not (folder / STUDY / "test.partial").exists()


def test_the_estimate_counts_only_the_test_phases_left(evolved, interrupted):
    """A finished test phase is not estimated again (for the Φ* and budget it was written with); one removed, or
    asked with another budget, is."""
    def estimate(folder, budget):
        (p,) = [p for p in runner.plan(registry.get(EXPERIMENT), registry.get_scale("smoke"), folder, budget=budget)
                if p.spec.name == STUDY]
        study = load_study(runner.default_storage(folder), p.study)
        done = {p.study: len(study.get_trials(states=(TrialState.COMPLETE,)))}
        left = runner.tests_left(p, study)
        return p, left, runner.estimate_seconds([p], done, {p.study: left})

    p, left, seconds = estimate(evolved, BUDGET)
    assert left == () and seconds == 0
    test_seconds = (len(BUDGET.learning_rates) + 2) * BUDGET.seeds * BUDGET.timesteps / runner.JAX_RATE
    assert runner.estimate_seconds([p], {p.study: p.config.trials}) == pytest.approx(runner.COMPILE_S + test_seconds)
    p, left, seconds_left = estimate(interrupted, BUDGET)
    assert left == p.tests and seconds_left == pytest.approx(runner.COMPILE_S + test_seconds)
    p, left, _ = estimate(evolved, runner.TestBudget(seeds=3, timesteps=4096, learning_rates=(1e-4, 3e-4)))
    assert left == p.tests


def as_an_older_version_kept_it(partial: Path) -> None:
    """Rewrites the unfinished test phase ``partial`` as versions before the learning rate's one name kept it: its
    settings with the TestConfig keys ``ermrl_lrs`` and ``ppo_lr``, its ER-MRL model under the labels of then
    ("ER-MRL lr 0.0001 (sr 0.95, lr 0.5, iss 1)")."""
    settings = json.loads((partial / "settings.json").read_text())
    old_names = {"learning_rates": "ermrl_lrs", "baseline_learning_rate": "ppo_lr"}
    settings["test"] = {old_names.get(k, k): v for k, v in settings["test"].items()}
    assert {"ermrl_lrs", "ppo_lr"} <= set(settings["test"])
    (partial / "settings.json").write_text(json.dumps(settings))
    with np.load(partial / "ermrl.npz") as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays["meta"]))
    phi = ", ".join(f"{n} {float(np.ravel(meta['identity']['phi'][n])[0]):.3g}" for n in ("sr", "lr", "iss"))
    meta["identity"]["labels"] = [f"ER-MRL lr {rate:g} ({phi})" for rate in BUDGET.learning_rates]
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(partial / "ermrl.npz", **arrays)


@pytest.mark.parametrize("kept_by", ["this version", "an older version"])
def test_a_stopped_test_phase_keeps_its_finished_models_and_ends_as_an_uninterrupted_one(evolved, interrupted,
                                                                                        tmp_path, kept_by):
    """The rerun of a stopped test phase trains only the models it lacks, also when an older version kept them
    (under the settings' old keys and the old labels), and writes what an uninterrupted run writes."""
    folder = tmp_path / "run"
    shutil.copytree(interrupted, folder)
    if kept_by == "an older version":
        as_an_older_version_kept_it(folder / STUDY / "test.partial")
    logs, started = [], []
    run_in_process(folder, logs.append, lambda label: started.append(label))
    kept = [line for line in logs if "from an earlier run" in line]
    assert len(kept) == 1 and kept[0].startswith("    test on CartPoleNoVel-v1: kept ER-MRL (learning rate 0.0001; sr ")
    assert "ER-MRL (learning rate 0.0003; sr " in kept[0] and ", leak rate " in kept[0]
    assert "ER-MRL" not in started and started[-2:] == ["PPO (same observation)", "PPO (full observation)"]
    assert not any(label.startswith("evolve ") for label in started)  # its evolution was complete: no bar
    assert not (folder / STUDY / "test.partial").exists()

    ours, theirs = folder / STUDY / "test", evolved / STUDY / "test"
    for name in ("summary.json", "summary.csv", "curves.csv", "test_config.json"):
        assert (ours / name).read_bytes() == (theirs / name).read_bytes(), name
    rows = json.loads((ours / "summary.json").read_text())
    assert all(len(r["per_seed"]) == 2 and None not in r["per_seed"] for r in rows)
    agents = sorted(p.relative_to(theirs) for p in theirs.rglob("*.npz"))
    assert len(agents) == 8 and sorted(p.relative_to(ours) for p in ours.rglob("*.npz")) == agents
    for path in agents:
        with np.load(ours / path) as a, np.load(theirs / path) as b:
            assert a.files == b.files and all(np.array_equal(a[k], b[k]) for k in a.files), path


def test_the_kept_model_reads_back_as_trained_and_is_refused_when_damaged_or_for_other_agents(evolved, interrupted,
                                                                                             tmp_path):
    """The stopped run's ER-MRL model (both learning rates) reads back with the per-seed scores of the uninterrupted
    run; a copy cut short, or asked for with another population, is not trusted (None: trained again)."""
    kept = interrupted / STUDY / "test.partial" / "ermrl.npz"
    with np.load(kept) as data:
        identity = json.loads(str(data["meta"]))["identity"]
    results = checkpoints.load_job(kept.parent, "ermrl", identity)
    rows = json.loads((evolved / STUDY / "test" / "summary.json").read_text())
    assert list(results.seeds) == [1000, 1001, 1000, 1001] and results.policies is not None
    assert results.fitness().tolist() == rows[0]["per_seed"] + rows[1]["per_seed"]
    assert checkpoints.load_job(kept.parent, "ermrl", {**identity, "seeds": [1000, 1001, 1002] * 2}) is None
    cut = tmp_path / "ermrl.npz"
    cut.write_bytes(kept.read_bytes()[:1000])
    assert checkpoints.load_job(tmp_path, "ermrl", identity) is None


def test_a_model_trained_in_groups_of_agents_resumes_group_by_group(evolved, tmp_path):
    """--test-agents-per-run 3: the 4-agent ER-MRL model (2 learning rates × 2 seeds) trains as agents 1–3, then
    agent 4, each group kept when it finishes. Stopped in the second group, the rerun keeps the first and ends
    with the scores and policies of the run that trained all 4 at once (to rounding: other batch sizes)."""
    folder = tmp_path / "run"
    shutil.copytree(evolved, folder)
    shutil.rmtree(folder / STUDY / "test")
    budget = dataclasses.replace(BUDGET, agents_per_run=3)
    started = []

    def stop_in_the_second_group(label):
        started.append(label)
        if label == "ER-MRL, agent 4 of 4":
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_in_process(folder, lambda s: None, stop_in_the_second_group, budget)
    assert started[-2:] == ["ER-MRL, agents 1–3 of 4", "ER-MRL, agent 4 of 4"]
    partial = folder / STUDY / "test.partial"
    assert sorted(p.name for p in partial.iterdir()) == ["ermrl.agents-0-2.npz", "settings.json"]

    logs, started = [], []
    run_in_process(folder, logs.append, started.append, budget)
    assert [line for line in logs if "from an earlier run" in line] == [
        f"    test on CartPoleNoVel-v1: kept ER-MRL, agents 1–3 of 4 from an earlier run ({partial}/ermrl.agents-0-2.npz)"]
    assert started[-3:] == ["ER-MRL, agent 4 of 4", "PPO (same observation)", "PPO (full observation)"]  # 2 agents: whole
    assert not any(s.startswith("ER-MRL, agents 1") for s in started)
    assert not partial.exists()
    ours, theirs = folder / STUDY / "test", evolved / STUDY / "test"
    rows, whole = (json.loads((f / "summary.json").read_text()) for f in (ours, theirs))
    assert [r["model"] for r in rows] == [r["model"] for r in whole]
    for r, w in zip(rows, whole):
        np.testing.assert_allclose(r["per_seed"], w["per_seed"], rtol=1e-6)
    agents = sorted(p.relative_to(theirs) for p in theirs.rglob("*.npz"))
    assert sorted(p.relative_to(ours) for p in ours.rglob("*.npz")) == agents
    for path in agents:
        with np.load(ours / path) as a, np.load(theirs / path) as b:
            for k in a.files:
                if a[k].dtype.kind == "f":
                    np.testing.assert_allclose(a[k], b[k], rtol=1e-3, atol=1e-5, err_msg=f"{path}: {k}")
                else:
                    assert np.array_equal(a[k], b[k]), f"{path}: {k}"


def test_agents_per_run_below_one_is_a_one_line_error_for_ermrl_test(evolved, tmp_path, capsys):
    out = tmp_path / "test-run"
    args = ["test", "--study", f"{EXPERIMENT}-smoke-{STUDY}", "--storage", runner.default_storage(evolved),
            "--out", str(out), "--seeds", "1", "--timesteps", "2048", "--agents-per-run", "0", "--quiet"]
    assert main(args) == 2
    assert capsys.readouterr().err == "ermrl test: error: --agents-per-run must be >= 1, got 0\n"
    assert not (out / "test.partial").exists() and not (out / "test").exists()


BAD = [
    (["--test-seeds", "0"], "--test-seeds must be >= 1, got 0"),
    (["--test-timesteps", "-5"], "--test-timesteps must be >= 1, got -5"),
    (["--test-learning-rates", "3e-4", "1.5"],
     "--test-learning-rates: learning rate 1.5 is outside (0, 1); the paper uses 3e-4 or 1e-4"),
    (["--test-learning-rates", "0"], "--test-learning-rates: learning rate 0 is outside (0, 1); the paper uses 3e-4 or "
                                     "1e-4"),
    (["--test-learning-rates", "1e-4", "1e-4"],
     "--test-learning-rates gives 0.0001 twice; give each learning rate once"),
    (["--test-agents-per-run", "0"], "--test-agents-per-run must be >= 1, got 0"),
    (["--test-seeds", "two"], "argument --test-seeds: invalid int value: 'two'; see `ermrl experiment run --help`"),
    (["--test-learning-rates"], "argument --test-learning-rates: expected at least one argument; see `ermrl experiment "
                                "run --help`"),
    (["--test-lrs", "1e-4"], "--test-lrs is now --test-learning-rates (ER-MRL's learning rates in every test phase); "
                             "see `ermrl experiment run --help`"),
]


@pytest.mark.parametrize("flags,message", BAD, ids=[" ".join(f) for f, _ in BAD])
def test_bad_test_budgets_are_one_line_errors_before_any_work(flags, message, tmp_path, capsys):
    out = tmp_path / "run"
    assert main([*RUN, "--out", str(out), *flags]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"ermrl experiment: error: {message}\n" and captured.out == ""
    assert not out.exists()


@pytest.mark.parametrize("text,message", [
    ("test-seeds = 0\n", "--test-seeds must be >= 1, got 0"),
    ("test-learning-rates = []\n",
     "config file {path}: test-learning-rates takes at least one value, got an empty list"),
    ("test-lrs = []\n", "config file {path}: test-lrs takes at least one value, got an empty list"),  # the old key
    ("test-timesteps = 1.5\n", "config file {path}: test-timesteps must be an integer, got 1.5"),
])
def test_bad_test_budgets_in_a_config_file_are_one_line_errors(text, message, tmp_path, capsys):
    path, out = tmp_path / "budgets.toml", tmp_path / "run"
    path.write_text(text)
    assert main([*RUN, "--out", str(out), "--config", str(path)]) == 2
    assert capsys.readouterr().err == f"ermrl experiment: error: {message.format(path=path)}\n"
    assert not out.exists()


@pytest.mark.parametrize("scale", list(registry.SCALES))
def test_budgets_override_every_test_phase_and_the_estimate_but_no_study(scale, tmp_path):
    experiment, s = registry.get(EXPERIMENT), registry.get_scale(scale)
    budget = runner.TestBudget(seeds=10, timesteps=3_000_000, learning_rates=(1e-4,))
    plain, plans = runner.plan(experiment, s, tmp_path), runner.plan(experiment, s, tmp_path, budget=budget)
    assert [p.config for p in plans] == [p.config for p in plain]
    for p in plans:
        assert [(t.seeds, t.timesteps, t.learning_rates, t.auc_steps, t.baseline_learning_rate) for t in p.tests] == [
            (10, 3_000_000, (1e-4,), 300_000, p.spec.baseline_learning_rate)]
    assert [p.tests[0].timesteps for p in runner.plan(experiment, s, tmp_path, budget=runner.TestBudget(seeds=4))] \
        == [s.long_test_timesteps if p.spec.long_test else s.test_timesteps for p in plain]
    # the estimate counts the test phases at the budget's size (JAX envs: nominal rate; NoVel: 3 models here)
    jax_only = lambda ps: [p for p in ps if not p.spec.envs[0].startswith("LunarLander")]
    extra = runner.estimate_seconds(jax_only(plans)) - runner.estimate_seconds(jax_only(plain))
    expected = sum(3 * 10 * 3_000_000 - (len(t.learning_rates) + 2) * t.seeds * t.timesteps
                   for p in jax_only(plain) for t in p.tests) / runner.JAX_RATE
    assert extra == pytest.approx(expected)


def test_the_scores_so_far_of_a_stopped_test_phase(evolved, interrupted, tmp_path):
    """`ermrl test-progress` reads the kept ER-MRL model (2 learning rates × 2 seeds) with the scores that the
    uninterrupted test phase wrote, given the test phase's folder or its .partial one; a finished test phase, a
    folder that is not a partial one, or one that holds no model, is a one-line error."""
    rows = json.loads((evolved / STUDY / "test" / "summary.json").read_text())
    per_seed = rows[0]["per_seed"] + rows[1]["per_seed"]
    for given in (interrupted / STUDY / "test.partial", interrupted / STUDY / "test"):
        r = ermrl("test-progress", given)
        assert r.returncode == 0, r.stderr
        (line,) = [x for x in r.stdout.splitlines() if "(`ermrl`)" in x]
        assert line.startswith(f"| {rows[0]['model']}, {rows[1]['model']} (`ermrl`) | 4 of 4 | "
                               "1000, 1001, 1000, 1001 |")
        assert line.endswith(" | " + ", ".join(f"{v:.1f}" for v in per_seed) + " |")
        assert f"{np.mean(per_seed):.1f} ± {np.std(per_seed):.1f}" in line
    (tmp_path / "empty.partial").mkdir()
    finished = evolved / STUDY / "test"
    for folder, message in (
            (tmp_path / "empty.partial", f"{tmp_path / 'empty.partial'} holds no kept model or snapshot yet (*.npz, "
                                         "*.snapshot)"),
            (tmp_path / "missing.partial", f"{tmp_path / 'missing.partial'} is not a folder; give an unfinished test "
                                           "phase's OUT or OUT.partial folder"),
            (finished, f"the test phase in {finished} is finished; its scores are in {finished / 'summary.json'}")):
        r = ermrl("test-progress", folder)
        assert (r.returncode, r.stdout, r.stderr) == (2, "", f"ermrl test-progress: error: {message}\n")


def test_a_model_stopped_while_it_trains_resumes_from_its_snapshot(evolved, tmp_path, monkeypatch):
    """Stopped in the middle of its first model (ER-MRL, after 1 of its 2 iterations), a test phase keeps that
    model's snapshot in OUT.partial/; the rerun, with other env workers, continues it and writes the scores of a
    run never stopped. The env workers asked for reach every model's training."""
    trained_with = []
    real_init = evaluation.Trainer.__init__

    def init(self, config, *args, **kwargs):
        trained_with.append(config.env_workers)
        real_init(self, config, *args, **kwargs)

    monkeypatch.setattr(evaluation.Trainer, "__init__", init)
    study = load_study(runner.default_storage(evolved), f"{EXPERIMENT}-smoke-{STUDY}")
    test = evaluation.TestConfig(seeds=2, timesteps=4096, learning_rates=(3e-4,))
    out = tmp_path / "test"

    def stop_in_the_second_iteration(label):
        def on_iteration(p):
            if p.iteration == 2:
                raise KeyboardInterrupt
        return on_iteration

    with pytest.raises(KeyboardInterrupt):
        evaluation.run_test_phase(study, out, test, stop_in_the_second_iteration, save_agents=False,
                                  snapshot_every_s=0, env_workers=1)
    partial = checkpoints.partial_dir(out)
    assert sorted(p.name for p in partial.iterdir()) == ["ermrl.snapshot", "settings.json"]
    logs = []
    rows = evaluation.run_test_phase(study, out, test, save_agents=False, log=logs.append, snapshot_every_s=0,
                                     env_workers=0)
    assert logs == [f"resumed from {partial}/ermrl.snapshot at iteration 1 of 2"]
    assert not partial.exists()
    assert trained_with == [1, 0, 0, 0]  # stopped in ER-MRL; then ER-MRL, PPO, PPO with full observation
    unbroken = evaluation.run_test_phase(study, tmp_path / "unbroken", test, save_agents=False)
    assert trained_with[4:] == ["auto"] * 3  # the evolution's setting
    assert [r["per_seed"] for r in rows] == [r["per_seed"] for r in unbroken]

