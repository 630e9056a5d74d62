"""Files written whole or not at all, as :mod:`ermrl.atomic` and :mod:`ermrl.storage` promise: a staged folder
appears complete or not at all and keeps the outputs of other commands; a killed writer's staging folder is
cleaned up; a torn journal tail is cut before the next append; a cut or empty curves file is refused; an
output that cannot be written is refused before any work. The
`kill -9` tests of whole commands are in test_crash_safety.py."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import optuna
import pytest

from ermrl.evolution.record import decode_study_record, encode_study_record
from ermrl import storage
from ermrl.agent_files import AGENT_FILES
from ermrl.errors import ConfigError

from cli_runs import ermrl


def test_a_staged_folder_appears_whole_or_not_at_all(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(RuntimeError):
        with storage.staged_folder(out) as stage:
            storage.write_text(stage / "curves.csv", "model\n")
            raise RuntimeError("crash while writing")
    assert not out.exists() and list(tmp_path.iterdir()) == []
    with storage.staged_folder(out) as stage:
        storage.write_text(stage / "curves.csv", "new\n")
        storage.write_text(stage / "agents" / "seed0.npz", "new")
        storage.write_json(stage / "summary.json", {"n": 1})
        assert not out.exists()
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")) == ["agents", "agents/seed0.npz", "curves.csv",
                                                                         "summary.json"]
    assert list(tmp_path.iterdir()) == [out]


def test_a_staged_folder_over_an_old_one_replaces_its_files_and_keeps_other_outputs(tmp_path):
    out = tmp_path / "run"
    for name, text in (("curves.csv", "old"), ("summary.json", "old"), ("agents/seed0.npz", "old"),
                       ("agents/seed9.npz", "old"), ("agents/PPO/seed3-1.npz", "old"), ("context.png", "analysis"),
                       ("agents/README.md", "mine"), ("agents/mine/policy.pt", "mine"), ("agents/seedling.npz", "mine")):
        storage.write_text(out / name, text)
    with pytest.raises(RuntimeError), storage.staged_folder(out, stale=AGENT_FILES) as stage:
        storage.write_text(stage / "curves.csv", "new")
        raise RuntimeError("crash while writing")
    assert (out / "curves.csv").read_text() == "old" and (out / "summary.json").read_text() == "old"
    with storage.staged_folder(out, stale=AGENT_FILES) as stage:
        for name in ("curves.csv", "summary.json", "agents/seed0.npz"):
            storage.write_text(stage / name, "new")
    files = {str(p.relative_to(out)): p.read_text() for p in out.rglob("*") if p.is_file()}
    # the old agents go (ermrl wrote them); whatever else is there stays, agents/ included
    assert files == {"curves.csv": "new", "summary.json": "new", "agents/seed0.npz": "new", "context.png": "analysis",
                     "agents/README.md": "mine", "agents/mine/policy.pt": "mine", "agents/seedling.npz": "mine"}


def test_a_killed_writers_staging_folder_is_removed_by_the_next_writer(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = __import__("socket").gethostname()
    left = tmp_path / f".run.partial-{host}-{dead.pid}"
    live = tmp_path / f".run.partial-{host}-{os.getppid()}"  # another writer, still running
    for d in (left, live):
        storage.write_text(d / "curves.csv", "half")
    with storage.staged_folder(tmp_path / "run") as stage:
        storage.write_text(stage / "summary.json", "{}")
    assert not left.exists() and live.exists() and (tmp_path / "run" / "summary.json").exists()


def test_a_torn_journal_tail_is_cut_so_that_the_next_append_keeps_the_journal_readable(tmp_path):
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    path = tmp_path / "studies.log"

    def study():
        return optuna.create_study(study_name="k", storage=JournalStorage(JournalFileBackend(str(path))),
                                   load_if_exists=True)

    for v in range(3):
        study().add_trial(optuna.trial.create_trial(value=float(v)))
    path.write_bytes(path.read_bytes()[:-20])  # the last append cut short: trial 2 torn
    assert storage.repair_journal(path) > 0 and path.read_bytes().endswith(b"\n")
    assert storage.repair_journal(path) == 0  # sound now: left alone
    study().add_trial(optuna.trial.create_trial(value=9.0))
    assert [t.value for t in study().trials] == [0.0, 1.0, 9.0]
    assert storage.repair_journal(tmp_path / "missing.log") == 0
    for text in ("notes without a newline", "a line\nthen a torn one"):  # not journals: never cut
        (tmp_path / "notes.log").write_text(text)
        assert storage.repair_journal(tmp_path / "notes.log") == 0 and (tmp_path / "notes.log").read_text() == text


def test_a_cut_or_empty_curves_file_is_refused(tmp_path):
    """What a writer without the rename would leave after a crash: a file cut mid-line, or an empty one."""
    path = tmp_path / "curves.csv"
    storage.write_curves_csv(path, {"PPO": (np.array([2048, 4096]), np.array([[20.0, 30.0]]))}, {"PPO": np.array([0])})
    whole = path.read_text()
    assert storage.read_curves_csv(path)["PPO"][1].tolist() == [[20.0, 30.0]]
    for text, why in ((whole[: whole.rindex(",")], "ValueError: line 3 has 3 fields, not 4"), ("", "ValueError: no rows")):
        path.write_text(text)
        with pytest.raises(ConfigError) as e:
            storage.read_curves_csv(path)
        assert str(e.value) == f"{path} is not a curves file written by ermrl ({why}); rerun the command that wrote it"


HUGE = ["--timesteps", str(10**9)]
"""A budget that would not end within the test's time limit: each error must come before any training."""


@pytest.mark.skipif(not Path("/proc/self").exists(), reason="needs Linux's /proc")
@pytest.mark.parametrize("argv, flag, path", [
    (["train", "--env", "CartPole-v1", *HUGE, "--out", "/proc/ermrl/run"], "--out", "/proc/ermrl/run"),
    (["test", "--study", "one", "--storage", "sqlite:///studies.db", *HUGE, "--out", "/proc/ermrl/run"], "--out",
     "/proc/ermrl/run"),
    (["test", "--study", "one", "--storage", "sqlite:///studies.db", *HUGE, "--tensorboard", "/proc/ermrl/tb"],
     "--tensorboard", "/proc/ermrl/tb"),
    (["plot", "run", "--out", "/proc/ermrl/fig.png"], "--out", "/proc/ermrl/fig.png"),
    (["baselines", "--env", "CartPole-v1", *HUGE, "--recompute", "--table", "/proc/ermrl/t.json"], "baselines table",
     "/proc/ermrl/t.json"),
], ids=["train", "test", "test-tensorboard", "plot", "baselines"])  # the other commands' checks: test_bad_input.py
def test_an_unwritable_output_is_refused_before_any_work(argv, flag, path, tmp_path):
    """/proc/ermrl: no one can create anything there, root included (permission bits do not bind root)."""
    from ermrl.evolution.config import EvolveConfig
    from ermrl.evolution.search_space import SearchSpace
    from ermrl.training import TrainConfig

    space = SearchSpace(1, fixed_iss=1.0)
    study = optuna.create_study(storage=f"sqlite:///{tmp_path / 'studies.db'}", study_name="one", direction="maximize")
    study.set_user_attr("ermrl", encode_study_record(EvolveConfig(
        train=TrainConfig(env_id="CartPole-v1", total_timesteps=2048), space=space, trials=1, seeds=1)))
    study.add_trial(optuna.trial.create_trial(params={"sr": 0.95, "lr": 0.5}, distributions=space.distributions(),
                                              value=20.0))
    storage.write_curves_csv(tmp_path / "run" / "curves.csv", {"PPO": (np.array([2048]), np.array([[20.0]]))},
                             {"PPO": np.array([0])})
    before = sorted(p.name for p in tmp_path.rglob("*"))
    r = ermrl(*argv, cwd=tmp_path)
    message = (rf"ermrl {argv[0]}: error: {re.escape(flag)} {re.escape(path)}: cannot write in /proc "
               r"\((no such file or directory|permission denied)\); give a folder you can write\n")  # mkdir's reason
    assert r.returncode == 2 and re.fullmatch(message, r.stderr), r.stderr
    assert sorted(p.name for p in tmp_path.rglob("*")) == before


@pytest.fixture
def read_only_mount(tmp_path):
    """A tmpfs at tmp_path/ro, for the test to fill, then remounted read-only by calling the fixture's value;
    skipped where this process may not mount (not root, or no CAP_SYS_ADMIN)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(ro)], capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs here")
    yield ro, lambda: subprocess.run(["mount", "-o", "remount,ro", str(ro)], check=True)
    subprocess.run(["umount", "-l", str(ro)])


def test_a_read_only_storage_is_named_before_any_work(read_only_mount, tmp_path):
    """A study on a read-only file system, resumed or selected with its results going elsewhere (--out): one line
    naming the storage and the reason, exit 2, before any training (before: the error came after training, and
    said to free some space)."""
    ro, remount = read_only_mount
    tiny = ["--env", "CartPole-v1", "--seeds", "1", "--timesteps", "512", "--units", "10", "--popsize", "2",
            "--no-estimate", "--quiet"]
    made = f"sqlite:///{tmp_path / 'study.db'}"
    assert ermrl("evolve", *tiny, "--trials", "2", "--study", "k", "--storage", made, cwd=tmp_path).returncode == 0
    shutil.copy(tmp_path / "study.db", ro / "study.db")  # a copy: this process holds the first one open
    remount()
    url = f"sqlite:///{ro / 'study.db'}"
    for argv in (["evolve", *tiny, "--trials", "4", *HUGE], ["select", "--top", "1", "--seeds", "1"]):
        r = ermrl(*argv, "--study", "k", "--storage", url, "--out", "elsewhere", cwd=tmp_path)
        assert (r.returncode, r.stderr) == (2, f"ermrl {argv[0]}: error: cannot write storage '{url}' ({ro}: "
                                               "read-only file system); give a storage you can write\n")
