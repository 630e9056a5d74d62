"""Damaged files that ermrl reads, each named in one line with exit code 2 and nothing written or lost: a test
phase's summary.json that is not what ``ermrl test`` wrote (a report skips that test phase instead, and the
experiment runner redoes it), an agent file whose record and weights disagree, a study.db with a damaged page,
and a study.db that is no Optuna database (empty, or another program's), which a command that only reads a study
must not turn into one.

One small agent is trained per module (``ermrl train``, in-process); the study and its two test phases are
made by hand, as ``ermrl evolve`` and ``ermrl test`` lay them out (no training)."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from cli_runs import ermrl
from ermrl.evolution.record import decode_study_record, encode_study_record
from ermrl.errors import ConfigError

STUDY = "k"
EVOLVE = ["--env", "CartPole-v1", "--seeds", "1", "--timesteps", "512", "--units", "10", "--popsize", "2",
          "--study", STUDY, "--out", "run", "--no-estimate", "--quiet"]
TEST_ENVS = {"test": "CartPole-v1", "test-CartPoleNoVel-v1": "CartPoleNoVel-v1"}


def snapshot(folder: Path) -> dict[str, tuple[int, int, str]]:
    """Every path under ``folder``, each file with its size, modification time (ns) and content hash: any file
    written, added or removed shows. (A folder's own mtime is left out: checking that an output folder can be
    written makes and removes an empty folder in it.)"""
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns,
                                         hashlib.sha256(p.read_bytes()).hexdigest()) if p.is_file() else ()
            for p in sorted(folder.rglob("*"))}


def one_line(err: str) -> str:
    assert err.endswith("\n") and err.count("\n") == 1, err
    return err.rstrip("\n")


def _rows(env_id: str) -> list[dict]:
    """The summary rows of a test phase, as ``ermrl test`` writes them (experiments.evaluation.summarize)."""
    base = {"env_id": env_id, "n_seeds": 2, "learning_rate": 3e-4, "timesteps": 512, "final_mean": 21.0,
            "final_std": 1.0, "final_iqm": 21.0, "final_iqm_low": 20.0, "final_iqm_high": 22.0, "diverged": 0,
            "auc_mean": 18.0, "auc_std": 0.5, "per_seed": [20.0, 22.0], "evolved_on": ["CartPole-v1"],
            "phi_trial": 1, "phi_choice": "the best trial (1)"}
    return [{**base, "model": "ER-MRL (trial 1)", "kind": "ER-MRL", "final_mean": 25.0,
             "improvement": {"PPO (same observation)": [0.75, 0.5, 1.0]}},
            {**base, "model": "PPO (same observation)", "kind": "PPO", "final_mean": None, "final_std": None,
             "final_iqm": None, "final_iqm_low": None, "final_iqm_high": None, "diverged": 2, "per_seed": [None, None]}]


def _study_folder(folder: Path) -> None:
    """``folder``: study.db with study ``k`` (4 completed trials, the record `ermrl evolve` EVOLVE writes) and two
    test phases, ``test`` and ``test-CartPoleNoVel-v1``."""
    import dataclasses

    import optuna

    from ermrl import storage
    from ermrl.agent import AgentConfig
    from ermrl.evolution.config import EvolveConfig
    from ermrl.evolution.search_space import SearchSpace
    from ermrl.evolution.study import ATTR
    from ermrl.experiments.evaluation import TestConfig
    from ermrl.reservoir import ReservoirSpec
    from ermrl.training import TrainConfig

    folder.mkdir(parents=True)
    space = SearchSpace(1)
    config = EvolveConfig(train=TrainConfig(env_id="CartPole-v1", total_timesteps=512,
                                            agent=AgentConfig(spec=ReservoirSpec(units=10))),
                          space=space, trials=4, seeds=1, popsize=2)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(storage=f"sqlite:///{folder / 'study.db'}", study_name=STUDY, direction="maximize")
    study.set_user_attr(ATTR, encode_study_record(config))
    for i, value in enumerate((20.0, 30.0, 25.0, 22.0)):
        params = {"sr": 0.5 + i / 10, "lr": 0.3, "iss": 1.0}
        study.add_trial(optuna.trial.create_trial(
            params=params, distributions=space.distributions(), value=value,
            user_attrs={"phi": {k: [v] for k, v in params.items()}, "seed_fitness": [value], "generation": i // 2}))
    for name, env_id in TEST_ENVS.items():
        test = TestConfig(seeds=2, timesteps=512, env_id=None if name == "test" else env_id)
        storage.write_json(folder / name / "test_config.json", {**dataclasses.asdict(test), "phi_trial": 1})
        storage.write_test_summary(folder / name, _rows(env_id))


@pytest.fixture(scope="module")
def agent_template(tmp_path_factory) -> Path:
    """A folder with R/, the run of `ermrl train --env CartPole-v1 --seeds 1 --timesteps 512 --units 10`."""
    folder = tmp_path_factory.mktemp("agent")
    r = ermrl("train", "--env", "CartPole-v1", "--seeds", "1", "--timesteps", "512", "--units", "10", "--out", "R",
              "--quiet", cwd=folder)
    assert r.returncode == 0, r.stderr
    assert (folder / "R" / "agents" / "seed0.npz").is_file()
    return folder


@pytest.fixture(scope="module")
def study_template(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("study")
    _study_folder(folder / "run")
    return folder


@pytest.fixture
def work(study_template, tmp_path, monkeypatch) -> Path:
    """A copy of the study's folder, the current one: the commands name ``run/...``."""
    shutil.copytree(study_template, tmp_path, dirs_exist_ok=True)
    monkeypatch.chdir(tmp_path)
    return tmp_path


# -- a test phase's summary.json -------------------------------------------------------------------------

DAMAGED_SUMMARIES = {
    "object": (b"{}", "it holds a JSON object, not a list of models"),
    "empty-list": (b"[]", "it lists no models"),
    "number": (b"[1]", "entry 1 is a JSON number, not a table of fields"),
    "empty-row": (b"[{}]", "entry 1 has no model, env_id, n_seeds, ..."),
    "missing-keys": (json.dumps([{"model": "PPO", "kind": "PPO", "env_id": "CartPole-v1"}]).encode(),
                     "entry 1 has no n_seeds, final_mean, final_std, ..."),
    "wrong-type": (json.dumps([{**_rows("CartPole-v1")[1], "final_mean": "high"}]).encode(),
                   "entry 1's final_mean is \"high\", not a number or null"),
    "cut-short": (json.dumps(_rows("CartPole-v1")).encode()[:200], "JSONDecodeError: "),
    "not-utf8": ("é".encode("latin-1") + b"[]", "UnicodeDecodeError: 'utf-8' codec can't decode byte 0xe9"),
}


@pytest.mark.parametrize("fault", DAMAGED_SUMMARIES)
def test_a_damaged_test_summary_is_named(tmp_path, monkeypatch, fault):
    from ermrl import storage

    content, what = DAMAGED_SUMMARIES[fault]
    monkeypatch.chdir(tmp_path)
    for name in ("test", "test-CartPoleNoVel-v1"):
        storage.write_test_summary(Path(name), _rows("CartPole-v1"))
        assert storage.read_test_summary(Path(name)) == _rows("CartPole-v1")
        (Path(name) / "summary.json").write_bytes(content)
        with pytest.raises(ConfigError) as e:
            storage.read_test_summary(Path(name))
        message = str(e.value)
        assert "\n" not in message
        assert message.startswith(f"{name}/summary.json is damaged or was not written by `ermrl test` (")
        assert what in message
        fix = "`ermrl test`" if name == "test" else "`ermrl test --env CartPoleNoVel-v1`"
        assert message.endswith(f"; rerun {fix} to write it again")


@pytest.mark.parametrize("fault", ["cut-short", "empty-row", "not-utf8"])
def test_report_skips_a_damaged_test_phase_and_names_it(work, fault):
    damaged = work / "run" / "test" / "summary.json"
    damaged.write_bytes(DAMAGED_SUMMARIES[fault][0])
    before = snapshot(work / "run")
    r = ermrl("report", "--study", STUDY, "--out", "run")
    assert r.returncode == 0, r.stderr
    line = one_line(r.stderr)
    assert line.startswith("warning: skipped test phase run/test: run/test/summary.json is damaged"), line
    assert line.endswith("rerun `ermrl test` to write it again")
    html = (work / "run" / "report.html").read_text()
    assert "skipped test phase run/test: run/test/summary.json is damaged" in html
    assert "Test phase on CartPoleNoVel-v1" in html  # the other test phase is still there
    assert "Test phase on CartPole-v1<" not in html
    after = snapshot(work / "run")
    assert {k: v for k, v in after.items() if k.startswith("test")} == \
           {k: v for k, v in before.items() if k.startswith("test")}
    assert after["study.db"] == before["study.db"]


def test_experiment_report_skips_a_damaged_test_phase(tmp_path, capsys):
    from ermrl import storage
    from ermrl.analysis.experiment_report import write_experiment_report
    from ermrl.experiments import registry, runner

    experiment, scale = registry.get("partial-observability"), registry.get_scale("smoke")
    plans = runner.plan(experiment, scale, tmp_path)
    for p in plans[:2]:
        storage.write_test_summary(p.run_dir / "test", _rows(p.config.env_ids[0]))
    (plans[0].run_dir / "test" / "summary.json").write_bytes(b"[{}]")
    out = write_experiment_report(experiment, scale, plans, f"sqlite:///{tmp_path / 'none.db'}", tmp_path)
    line = one_line(capsys.readouterr().err)
    assert line.startswith(f"warning: skipped test phase {plans[0].run_dir / 'test'}: "
                           f"{plans[0].run_dir / 'test' / 'summary.json'} is damaged"), line
    html = out.read_text()
    assert f"skipped test phase {plans[0].run_dir / 'test'}" in html
    assert f"Test phase on {plans[1].config.env_ids[0]}" in html


@pytest.mark.parametrize("file, content", [("summary.json", b'[{"model": "ER'), ("summary.json", b"[]"),
                                           ("test_config.json", b'{"seeds": 2, "time'),
                                           ("test_config.json", b"[1]")])
def test_experiment_runner_redoes_a_test_phase_whose_files_are_damaged(study_template, file, content, tmp_path):
    from ermrl.experiments.evaluation import TestConfig
    from ermrl.experiments.runner import _test_done

    out = tmp_path / "test"
    shutil.copytree(study_template / "run" / "test", out)
    test = TestConfig(seeds=2, timesteps=512)
    assert _test_done(out, test, 1)  # the intact test phase is done
    (out / file).write_bytes(content)
    said = []
    assert not _test_done(out, test, 1, said.append)
    assert len(said) == 1 and said[0].startswith(f"{out / file} is damaged or was not written by `ermrl test` (") and \
        said[0].endswith("; redoing this test phase"), said


# -- an agent file whose record and weights disagree -------------------------------------------------------

def _rewrite(path: Path, fault: str) -> None:
    """``path`` (an agent file) rewritten with ``fault``: its record and weights no longer agree."""
    arrays = dict(np.load(path))
    meta = json.loads(str(arrays["meta"]))
    if fault == "units":
        meta["train"]["agent"]["spec"]["units"] = 20  # the weights are for 10 units
    elif fault == "dropped":
        del arrays["actor/params/Dense_1/kernel"]
    elif fault == "reshaped":  # the critic's: the actor acts on, so nothing failed before
        arrays["critic/params/Dense_1/kernel"] = arrays["critic/params/Dense_1/kernel"][:, :32]
    elif fault == "phi":
        meta["phi"]["sr"] = [0.9, 0.8]
    arrays["meta"] = np.array(json.dumps(meta))
    with open(path, "wb") as f:
        np.savez(f, **arrays)


AGENT_FAULTS = {
    "units": "its record says 1 reservoir of 20 units and hidden layers [64, 64], so actor/params/Dense_0/kernel "
             "should have shape (20, 64), but it has (10, 64)",
    "dropped": "it has no actor/params/Dense_1/kernel array, which its record (hidden layers [64, 64]) implies",
    "reshaped": "its record says hidden layers [64, 64], so critic/params/Dense_1/kernel should have shape (64, 64), "
                "but it has (64, 32)",
    "phi": "its record says 1 reservoir but its Φ has 2 sr values",
}
AGENT_COMMANDS = {"video": ["video", "--agent", "{F}", "--out", "agent.gif"],
                  "context": ["analyze", "context", "{F}", "--out", "context.png"],
                  "fft": ["analyze", "fft", "{F}", "--out", "fft.png"]}


@pytest.mark.parametrize("command", AGENT_COMMANDS)
@pytest.mark.parametrize("fault", AGENT_FAULTS)
def test_an_agent_whose_record_and_weights_disagree_is_named(agent_template, tmp_path, monkeypatch, fault, command):
    shutil.copytree(agent_template, tmp_path, dirs_exist_ok=True)
    monkeypatch.chdir(tmp_path)
    agent = Path("R/agents/seed0.npz")
    _rewrite(agent, fault)
    before = snapshot(tmp_path)
    r = ermrl(*[a.replace("{F}", str(agent)) for a in AGENT_COMMANDS[command]])
    prefix = "ermrl video" if command == "video" else "ermrl analyze"
    assert (r.returncode, one_line(r.stderr)) == (2, f"{prefix}: error: {agent} is damaged: {AGENT_FAULTS[fault]}; "
                                                     "retrain, or load another agent")
    assert snapshot(tmp_path) == before


def test_an_agent_file_without_its_record_keeps_its_message(agent_template, tmp_path, monkeypatch):
    shutil.copytree(agent_template, tmp_path, dirs_exist_ok=True)
    monkeypatch.chdir(tmp_path)
    agent = Path("R/agents/seed0.npz")
    arrays = dict(np.load(agent))
    del arrays["meta"]
    with open(agent, "wb") as f:
        np.savez(f, **arrays)
    before = snapshot(tmp_path)
    r = ermrl("video", "--agent", agent, "--out", "agent.gif")
    assert (r.returncode, one_line(r.stderr)) == (2, f"ermrl video: error: {agent} is not a readable ermrl agent file "
                                                     "(KeyError: 'meta'); it is damaged or was not written by ermrl: "
                                                     "retrain, or load another agent")
    assert snapshot(tmp_path) == before


# -- a study.db with a damaged page --------------------------------------------------------------------------

STUDY_COMMANDS = {
    "report": ["report", "--study", STUDY, "--out", "run"],
    "select": ["select", "--study", STUDY, "--out", "run", "--top", "1", "--seeds", "1"],
    "test": ["test", "--study", STUDY, "--out", "run", "--seeds", "1", "--timesteps", "512"],
    "evolve": ["evolve", *EVOLVE, "--trials", "6"],
    "hp-map": ["analyze", "hp-map", STUDY, "--storage", "sqlite:///run/study.db", "--out", "run/map.png"],
    "dashboard": ["dashboard", "--study", STUDY, "--out", "run", "--port", "0"],
}


@pytest.mark.parametrize("command", ["report", "select", "test", "evolve"])
def test_a_study_db_with_a_damaged_page_is_named(work, command):
    with open(work / "run" / "study.db", "r+b") as f:
        f.seek(8192)
        f.write(np.random.default_rng(0).bytes(4096))
    before = snapshot(work)
    r = ermrl(*STUDY_COMMANDS[command])
    assert (r.returncode, one_line(r.stderr)) == (2, f"ermrl {command}: error: storage 'sqlite:///run/study.db' is "
                                                     "damaged (database disk image is malformed); restore it from a "
                                                     "copy, or start a new study")
    assert snapshot(work) == before


def test_a_damaged_page_found_by_a_later_query_is_named(monkeypatch):
    """A damaged page that only a query after the storage opened reads, as Optuna raises it (cli.main's last
    resort), on a database server: its password is hidden."""
    import sqlite3

    import sqlalchemy.exc

    from ermrl.cli import commands

    def query(args):
        cause = sqlite3.DatabaseError("database disk image is malformed")
        try:
            raise sqlalchemy.exc.DatabaseError("SELECT 1", None, cause) from cause
        except sqlalchemy.exc.DatabaseError as e:
            raise RuntimeError("An exception is raised during the commit.") from e

    monkeypatch.setitem(commands.COMMANDS, "report", query)
    r = ermrl("report", "--study", STUDY, "--storage", "postgresql://me:secret@db/ermrl")
    assert (r.returncode, one_line(r.stderr)) == (2, "ermrl report: error: storage 'postgresql://me:***@db/ermrl' is "
                                                     "damaged (database disk image is malformed); restore it from a "
                                                     "copy, or start a new study")


# -- a study.db that is no Optuna database -----------------------------------------------------------------

def _not_a_study(path: Path, kind: str) -> None:
    import sqlite3

    path.unlink()
    if kind == "empty":
        path.touch()
    else:  # another program's SQLite database
        connection = sqlite3.connect(path)
        connection.execute("CREATE TABLE mine (x)")
        connection.commit()
        connection.close()


@pytest.mark.parametrize("command", ["report", "select", "test", "hp-map", "dashboard"])
@pytest.mark.parametrize("kind", ["empty", "foreign"])
def test_a_read_only_command_leaves_a_database_that_is_no_study_alone(work, kind, command):
    _not_a_study(work / "run" / "study.db", kind)
    os.utime(work / "run" / "study.db", ns=(1_000_000_000, 1_000_000_000))  # any write would show
    before = snapshot(work)
    r = ermrl(*STUDY_COMMANDS[command])
    prefix = "ermrl analyze" if command == "hp-map" else f"ermrl {command}"
    flags = "--storage" if command == "hp-map" else "--storage/--out"  # the flags that give the study's storage
    message = ("run/study.db is empty (0 bytes), not a study database; run `ermrl evolve` to create the study, or "
               f"pass {flags}" if kind == "empty" else
               "run/study.db is not an Optuna study database (no 'studies' table); give the study.db that `ermrl "
               f"evolve` wrote ({flags}), or run `ermrl evolve` to create the study")
    assert (r.returncode, one_line(r.stderr)) == (2, f"{prefix}: error: {message}")
    assert snapshot(work) == before
