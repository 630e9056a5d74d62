"""A journal lock left by a process that died holding it never hangs a command, whatever the journal path's form.

Optuna's symlink lock is the link ``PATH.lock -> PATH``. Made from a relative path (``experiment run``'s default
``runs/experiments/NAME-SCALE/studies.log``), the link dangles; Optuna 5.0's wait cannot read its age and retried
at 100% CPU forever, and ermrl's journal repair waited on the same lock, so that even ``ermrl report`` hung.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cli_runs import ermrl, ermrl_process

TINY = ["--env", "CartPole-v1", "--seeds", "1", "--timesteps", "512", "--units", "10", "--popsize", "2",
        "--no-estimate", "--quiet"]


def _die_holding_the_lock(cwd: Path, journal: str) -> Path:
    """A process that takes Optuna's own lock on ``journal`` (as given, relative or absolute) and dies holding
    it; returns the lock link it leaves."""
    code = ("from optuna.storages.journal import JournalFileSymlinkLock as L; import os, sys; "
            "L(sys.argv[1]).acquire(); os._exit(0)")
    subprocess.run([sys.executable, "-c", code, journal], cwd=cwd, check=True)
    lock = cwd / f"{journal}.lock"
    assert lock.is_symlink()
    return lock


def _age(lock: Path, seconds: float) -> None:
    """Dates the lock link ``seconds`` back, as one left by a process that died that long ago."""
    then = time.time() - seconds
    os.utime(lock, (then, then), follow_symlinks=False)


@pytest.fixture(scope="module")
def journal_study(tmp_path_factory) -> Path:
    """A folder holding ``d/j.log``: a journal study 's' with 2 completed trials."""
    folder = tmp_path_factory.mktemp("lock")
    r = ermrl("evolve", *TINY, "--trials", "2", "--study", "s", "--storage", "d/j.log", cwd=folder)
    assert r.returncode == 0, r.stderr
    return folder


@pytest.mark.parametrize("form", ["relative", "absolute"])
def test_a_stale_lock_is_broken_and_the_evolution_resumes(journal_study, tmp_path, form):
    import shutil

    folder = tmp_path / "w"
    shutil.copytree(journal_study, folder)
    journal = "d/j.log" if form == "relative" else str(folder / "d/j.log")
    lock = _die_holding_the_lock(folder, journal)
    assert lock.exists() == (form == "absolute")  # the relative link dangles
    _age(lock, 60)
    start = time.monotonic()
    r = ermrl("evolve", *TINY, "--trials", "4", "--study", "s", "--storage", "d/j.log", cwd=folder)
    assert r.returncode == 0, r.stderr
    assert time.monotonic() - start < 100
    assert f"note: removed the stale lock {folder / 'd/j.log.lock'}" in r.stderr
    assert not os.path.lexists(lock)
    assert "2/4 trials done" in r.stdout


def test_report_on_a_torn_journal_under_a_stale_relative_lock_does_not_hang(journal_study, tmp_path):
    """The repair of a torn tail takes the lock too: it breaks a stale one, cuts the tail, and the report is written."""
    import shutil

    folder = tmp_path / "w"
    shutil.copytree(journal_study, folder)
    with open(folder / "d/j.log", "ab") as f:
        f.write(b'{"op_code": 5, "worker_id": "torn')
    _age(_die_holding_the_lock(folder, "d/j.log"), 60)
    r = ermrl_process("report", "--study", "s", "--storage", "d/j.log", cwd=folder, timeout=120)  # hung before
    assert r.returncode == 0, r.stderr
    assert (folder / "runs/s/report.html").is_file()
    assert (folder / "d/j.log").read_bytes().endswith(b"\n")


def test_the_wait_on_a_fresh_dangling_lock_sleeps_then_breaks_it_after_the_grace_period(tmp_path):
    """Optuna's rule, kept: a lock is broken once it has stood unchanged for the grace period, here 3 s; the wait
    sleeps between tries (little CPU), where Optuna's spun on a dangling link."""
    from ermrl.atomic import journal_lock

    (tmp_path / "d").mkdir()
    (tmp_path / "d/j.log").write_text("")
    lock = _die_holding_the_lock(tmp_path, "d/j.log")
    assert not lock.exists()  # dangling
    mine = journal_lock(tmp_path / "d/j.log", grace_period=3)
    wall, cpu = time.monotonic(), time.process_time()
    assert mine.acquire()
    wall, cpu = time.monotonic() - wall, time.process_time() - cpu
    assert 3 <= wall < 10
    assert cpu < 0.5 * wall
    assert os.readlink(tmp_path / "d/j.log.lock") == str(tmp_path / "d/j.log")  # an absolute target: never dangles
    mine.release()
    assert not os.path.lexists(lock)


def test_a_live_lock_is_waited_for_not_broken(tmp_path):
    """A lock that another process holds and releases within the grace period is waited for."""
    import threading

    from ermrl.atomic import journal_lock

    (tmp_path / "j.log").write_text("")
    holder = journal_lock(tmp_path / "j.log", grace_period=30)
    assert holder.acquire()
    threading.Timer(1.0, holder.release).start()
    start = time.monotonic()
    waiter = journal_lock(tmp_path / "j.log", grace_period=30)
    assert waiter.acquire()
    assert 0.9 < time.monotonic() - start < 5
    waiter.release()
