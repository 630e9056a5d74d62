"""A journal file rewritten under a run that uses it (a git checkout, stash or pull of docs/data/, a copy over it)
stops that run with one line before it reads another copy's records or appends to the wrong copy; writers that
only append, and the repair of a torn last line, never trip it (ermrl/evolution/journal_file.py)."""

from __future__ import annotations

import re
import subprocess
import sys
import time

import optuna
import pytest

from ermrl.evolution.journal_file import JournalChanged
from ermrl.evolution.study import make_storage

from cli_runs import COMMAND


@pytest.fixture(autouse=True)
def _quiet():
    optuna.logging.set_verbosity(optuna.logging.WARNING)


def _trials(study: optuna.Study, n: int) -> None:
    for _ in range(n):
        trial = study.ask({"x": optuna.distributions.FloatDistribution(0, 1)})
        study.tell(trial, trial.params["x"])


def _study(path, create: bool = False) -> optuna.Study:
    storage = make_storage(f"journal:{path}")
    if create:
        return optuna.create_study(storage=storage, study_name="s")
    return optuna.load_study(storage=storage, study_name="s")


def test_a_journal_put_back_to_an_older_copy_and_grown_by_another_writer_stops_the_run(tmp_path):
    path = tmp_path / "studies.log"
    mine = _study(path, create=True)
    _trials(mine, 3)
    older = path.read_bytes()  # the copy a `git checkout` of an earlier commit would put back
    _trials(mine, 3)
    read = path.stat().st_size
    path.write_bytes(older)
    other = _study(path)  # another worker, started after the rewrite, reads it as it is and appends to it
    _trials(other, 4)
    assert path.stat().st_size > read  # so that a plain reader would go on from mid-record
    before = path.read_bytes()
    with pytest.raises(JournalChanged) as e:
        _trials(mine, 1)
    assert str(e.value) == (
        f"the journal {path} was rewritten while this run used it: it had read its first {read:,} bytes, and the "
        "file changed there (a git checkout, stash or pull, or a copy over it?); stop every run on it, put back the "
        "copy they wrote to, and rerun to continue")
    assert path.read_bytes() == before  # nothing appended from the stale state
    assert len(_study(path).trials) == 7  # the file as it stands: 3 + the other worker's 4


def test_a_shorter_journal_is_named_and_nothing_is_appended(tmp_path):
    path = tmp_path / "studies.log"
    mine = _study(path, create=True)
    _trials(mine, 2)
    older = path.read_bytes()
    _trials(mine, 2)
    read = path.stat().st_size
    path.write_bytes(older)
    with pytest.raises(JournalChanged, match=rf"it had read its first {read:,} bytes, and the file is now "
                                             rf"{len(older):,} bytes \(a git checkout"):
        mine.trials
    with pytest.raises(JournalChanged):
        _trials(mine, 1)  # an append is refused too
    assert path.read_bytes() == older


def test_an_append_that_waits_for_the_lock_checks_the_file_once_it_holds_it(tmp_path):
    """A tell whose append waits for another writer's lock while the file is put back to an older copy is refused
    when it gets the lock, and writes nothing: the check is made under the lock, just before the write."""
    import threading

    from ermrl.atomic import journal_lock

    path = tmp_path / "studies.log"
    mine = _study(path, create=True)
    _trials(mine, 2)
    older = path.read_bytes()
    _trials(mine, 1)
    trial = mine.ask({"x": optuna.distributions.FloatDistribution(0, 1)})
    other = journal_lock(path)
    assert other.acquire()  # another writer's append under way
    refused: list[JournalChanged] = []

    def tell() -> None:
        try:
            mine.tell(trial, 0.5)
        except JournalChanged as e:
            refused.append(e)

    thread = threading.Thread(target=tell)
    thread.start()
    time.sleep(0.5)  # its reads are done and checked; its append waits for the lock
    assert thread.is_alive()
    path.write_bytes(older)
    other.release()
    thread.join(30)
    assert len(refused) == 1 and "was rewritten while this run used it" in str(refused[0]), refused
    assert path.read_bytes() == older


def test_a_journal_removed_under_a_run_is_named(tmp_path):
    path = tmp_path / "studies.log"
    mine = _study(path, create=True)
    _trials(mine, 1)
    path.unlink()
    with pytest.raises(JournalChanged, match="and the file is gone"):
        mine.trials
    assert not path.exists()


def test_writers_that_only_append_and_the_repair_of_a_torn_line_never_trip_it(tmp_path):
    path = tmp_path / "studies.log"
    first = _study(path, create=True)
    second = _study(path)
    for k in range(5):
        _trials(first, 2)
        _trials(second, 1)
        if k == 2:  # a writer killed mid-append leaves a torn last line; the next storage opened cuts it
            with open(path, "ab") as f:
                f.write(b'{"op_code": 4, "worker_id"')
            _study(path)
            assert path.read_bytes().endswith(b"}\n")
    assert len(first.trials) == len(second.trials) == 15
    assert sorted(t.value for t in first.trials) == sorted(t.value for t in second.trials)


def _told(journal) -> int:
    """How many trials the journal file has seen finish (their state set)."""
    return journal.read_bytes().count(b'"op_code":6') if journal.exists() else 0


def _wait_for(condition, proc: subprocess.Popen, timeout: float = 180) -> None:
    end = time.monotonic() + timeout
    while not condition():
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < end, "timed out"
        time.sleep(0.05)


def test_an_evolution_whose_journal_is_put_back_to_an_older_copy_stops_with_one_line(tmp_path):
    journal = tmp_path / "d" / "j.log"
    proc = subprocess.Popen([*COMMAND, "evolve", "--env", "CartPole-v1", "--seeds", "1", "--timesteps", "512",
                             "--units", "10", "--popsize", "2", "--trials", "400", "--study", "s", "--storage",
                             str(journal), "--no-estimate", "--quiet"],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: _told(journal) >= 2, proc)
        older = journal.read_bytes()
        _wait_for(lambda: _told(journal) >= 6, proc)
        journal.write_bytes(older)  # as `git checkout` of the commit that holds the older copy does
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 1, err
    assert re.fullmatch(
        rf"ermrl evolve: error: the journal {re.escape(str(journal))} was rewritten while this run used it: it had "
        r"read its first [\d,]+ bytes, and the file (changed there|is now [\d,]+ bytes) \(a git checkout, stash or "
        r"pull, or a copy over it\?\); stop every run on it, put back the copy they wrote to, and rerun to continue",
        err.strip().splitlines()[-1]), err
    assert journal.read_bytes() == older  # nothing appended to the copy put back


STOPPED_BY_ITS_HEARTBEAT = """
import sys
import optuna
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.evolve import evolve
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import make_storage
from ermrl.evolution.worker_config import WorkerConfig
from ermrl.training import TrainConfig
study = optuna.create_study(storage=make_storage("journal:" + sys.argv[1]), study_name="s", direction="maximize",
                            sampler=optuna.samplers.RandomSampler(seed=0))
config = EvolveConfig(train=TrainConfig(env_id="CartPole-v1", total_timesteps=500_000_000), space=SearchSpace(1),
                      trials=2, seeds=1, sampler="random", popsize=2)
evolve(study, config, worker=WorkerConfig(heartbeat_interval=1))  # no progress_fn: nothing else reads the journal
"""


def test_an_evolution_stops_within_its_generation_once_its_heartbeat_finds_the_journal_rewritten(tmp_path):
    """Evolution through the library with no progress reports reads the journal only in its heartbeat thread
    until its generation ends; that generation would train for hours, so only the stop the heartbeat hands to
    the main thread (raised at the next PPO iteration) ends the run in time, and it writes nothing more."""
    journal = tmp_path / "j.log"
    proc = subprocess.Popen([sys.executable, "-c", STOPPED_BY_ITS_HEARTBEAT, str(journal)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: journal.exists() and journal.read_bytes().count(b'"ermrl:heartbeat"') >= 2, proc)
        lines = journal.read_bytes().splitlines(keepends=True)
        first_trial = next(k for k, line in enumerate(lines) if b'"op_code":4' in line)
        older = b"".join(lines[:first_trial])  # the study as an earlier commit held it, before these trials
        journal.write_bytes(older)
        # The stop is raised at the first PPO iteration, which waits for XLA to compile the population's program: on
        # a cold compilation cache beside the suite's other workers it once came after more than 2 min; the
        # generation would take hours.
        _, err = proc.communicate(timeout=600)
    finally:
        proc.kill()
    assert proc.returncode == 1, err
    assert err.strip().splitlines()[-1].startswith(
        f"ermrl.evolution.journal_file.JournalChanged: the journal {journal} was rewritten while this run used "
        "it: it had read its first "), err
    assert journal.read_bytes() == older
